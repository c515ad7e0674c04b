"""Ground-station floods against a hovering stack in real time (issue: the stack holds under
floods): for each kind of flood (tests/netns/flood_session.py: PARAM_SET, PARAM_REQUEST_LIST,
COMMAND_LONG, mission uploads, stream-rate changes, 300 UDP peers; each at 1,000 messages a
second) and for all of them at once, the plant's missed real-time deadlines (from the
companion's first answer: :mod:`benchmarks.deadlines`) and the
vehicle's drift from where the flood found it, beside the same hover without a flood.
Goals: missed at most 0.1 % of the periods, drift within 0.5 m. In a private network
namespace (the CAN bus), skipped without root. ``--quick``: all kinds at once for 10 s
(no reference).
"""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

from benchmarks.deadlines import parse_plant_summary
from tests.netns.flood_session import KINDS

ROOT = Path(__file__).resolve().parents[1]
MISSED_GOAL_PERCENT = 0.1
DRIFT_GOAL_M = 0.5


def flood(work: Path, kinds: tuple[str, ...], seconds: float) -> dict:
    """One flooded hover (tests/netns/flood_session.py) in a private network namespace."""
    from tuav_sitl.netns import run_in_netns

    logdir = work / ("-".join(kinds) or "none")
    res = run_in_netns([sys.executable, "-m", "tests.netns.flood_session", str(logdir),
                        ",".join(kinds), repr(seconds)], timeout_s=seconds * 20 + 600,
                       cwd=str(ROOT))
    if res.returncode != 0:
        raise RuntimeError(res.stderr.strip()[-300:])
    return json.loads(res.stdout.strip().splitlines()[-1])


def bench_flood(quick: bool) -> list:
    """The rows of this benchmark (``benchmarks.__main__.Row``)."""
    from benchmarks.__main__ import Row
    from tuav_sitl.netns import netns_available

    why = netns_available()
    if why is not None:
        return [Row("ground-station floods", float("nan"), "", note=f"skipped: {why}")]
    seconds = 10.0 if quick else 40.0
    cases: list[tuple[str, ...]] = [KINDS] if quick else [(), *((k,) for k in KINDS), KINDS]
    rows = []
    reference = None
    with tempfile.TemporaryDirectory(prefix="tuav-bench-flood-") as work:
        for kinds in cases:
            name = ("hover in real time, no flood" if not kinds else
                    f"flood of {'all kinds' if kinds == KINDS else kinds[0]}, 1000/s each")
            try:
                r = flood(Path(work), kinds, seconds)
            except (RuntimeError, OSError) as exc:
                rows.append(Row(name, float("nan"), "", note=f"failed: {exc}"))
                continue
            try:
                d = parse_plant_summary(r["plant_summary"])
            except ValueError as exc:
                rows.append(Row(name, float("nan"), "", note=f"failed: {exc}"))
                continue
            missed = d.percent
            if not kinds:
                reference = missed
            ok = missed <= MISSED_GOAL_PERCENT and r["max_drift_m"] <= DRIFT_GOAL_M
            sent = sum(r["sent"].values())
            rows.append(Row(
                name, missed, "% missed", reference=None if not kinds else reference,
                note=(f"drift {r['max_drift_m']:.3f} m; {sent} messages sent over "
                      f"{(r['flood_to_s'] or 0) - (r['flood_from_s'] or 0):.1f} s; "
                      f"{d.missed_in_service} of {d.periods_in_service} periods missed "
                      f"from the companion's first answer ({d.startup_missed} before it)"),
                goal=(f"missed <= {MISSED_GOAL_PERCENT} %, drift <= {DRIFT_GOAL_M} m: "
                      + ("met" if ok else "NOT met"))))
    return rows
