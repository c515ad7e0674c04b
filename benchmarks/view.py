"""What the Rerun recording and live view cost (tuav_sitl/view).

Rows: ``tuav-sitl run circle`` as a command (figures and animation included, as a user
runs it) with its recording.rrd against ``--no-recording``, the two interleaved, the median
of each (goal: at most 10 % slower); and ``tuav-sitl up`` flying in real time for a while
with ``--view web`` (the live view's web server and gRPC stream beside the recording)
against ``up`` without it (the recording only): the plant's missed real-time deadlines of
each (goal: under 0.1 %), in a private network namespace (the CAN bus), skipped without
root. ``--quick``: a 6 s circle without figures once each, a 10 s flight.
"""

from __future__ import annotations

import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: Goals (docs/performance.md): the recording's cost, the deadlines missed.
RATIO_GOAL = 1.10
MISSED_GOAL_PERCENT = 0.1


def _run(out: Path, *extra: str) -> float:
    """Wall time [s] of ``tuav-sitl run circle --out OUT EXTRA...`` in a fresh interpreter
    (the recording's background job included: the command waits for it)."""
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "tuav_sitl", "run", "circle", "--quiet",
                    "--out", str(out), *extra], cwd=ROOT, env=dict(os.environ),
                   check=True, capture_output=True, timeout=900)
    return time.perf_counter() - t0


def _up_missed(work: Path, seconds: float, *extra: str) -> tuple[int, int]:
    """(missed deadlines, periods) of the plant over ``seconds`` of a real-time ``up``
    (in a private network namespace), from its own summary."""
    from tuav_sitl.netns import run_in_netns

    logdir = work / ("view" if extra else "plain")
    res = run_in_netns([sys.executable, "-m", "tuav_sitl", "up", "--can", "udp_multicast",
                        "--headless", "--logdir", str(logdir), "--position", "4", "0", "10",
                        "--goto", "6", "2", "12", "--duration", repr(seconds), *extra],
                       timeout_s=seconds * 4 + 300, cwd=str(ROOT))
    if res.returncode != 0:
        raise RuntimeError(res.stderr.strip()[-300:])
    run = next(logdir.iterdir())
    last = (run / "plant.log").read_text().strip().splitlines()[-1]
    periods = re.search(r"(\d+) periods", last)
    missed = re.search(r"(\d+) missed deadlines", last)
    if periods is None or missed is None:
        raise RuntimeError(f"no summary in plant.log: {last}")
    return int(missed.group(1)), int(periods.group(1))


def bench_view(quick: bool) -> list:
    """The rows of this benchmark (``benchmarks.__main__.Row``)."""
    from benchmarks.__main__ import Row
    from tuav_sitl.view import available

    if not available():
        return [Row("run circle: with recording.rrd vs without", float("nan"), "",
                    note="skipped: rerun-sdk is not installed (the extra 'view')")]
    rows = []
    rounds = 1 if quick else 3
    extra = ("--duration", "6", "--no-figures") if quick else ()
    with_rec: list[float] = []
    without: list[float] = []
    with tempfile.TemporaryDirectory(prefix="tuav-bench-view-") as work:
        for i in range(rounds):
            with_rec.append(_run(Path(work) / f"rec{i}", *extra))
            without.append(_run(Path(work) / f"plain{i}", *extra, "--no-recording"))
    a, b = statistics.median(with_rec), statistics.median(without)
    ratio = a / b
    rows.append(Row(
        "run circle: with recording.rrd vs without", a, "s", reference=b,
        ratio_text=f"{ratio:.3f}x",
        note=(("a 6 s circle without figures" if quick else
               "the command as a user runs it (figures and animation)")
              + f", median of {rounds} each, interleaved; the recording written by a "
                "process forked before the run (it imports rerun meanwhile)"),
        goal=f"<= {RATIO_GOAL:.2f}x: {'met' if ratio <= RATIO_GOAL else 'NOT met'}"))
    from tuav_sitl.netns import netns_available

    why = netns_available()
    name = "up in real time: missed deadlines, --view web vs recording only"
    if why is not None:
        rows.append(Row(name, float("nan"), "", note=f"skipped: {why}"))
        return rows
    seconds = 10.0 if quick else 60.0
    try:
        with tempfile.TemporaryDirectory(prefix="tuav-bench-upview-") as work:
            plain = _up_missed(Path(work), seconds)
            view = _up_missed(Path(work), seconds, "--view", "web")
    except (RuntimeError, OSError, subprocess.TimeoutExpired) as exc:
        rows.append(Row(name, float("nan"), "", note=f"failed: {exc}"))
        return rows
    pv, pp = (100.0 * view[0] / max(view[1], 1), 100.0 * plain[0] / max(plain[1], 1))
    rows.append(Row(
        name, pv, "% missed", reference=pp,
        note=f"{view[0]} of {view[1]} periods with the view, {plain[0]} of {plain[1]} "
             f"without; {seconds:.0f} s flights at 250 Hz, the live view at idle priority",
        goal=f"< {MISSED_GOAL_PERCENT} %: "
             f"{'met' if pv < MISSED_GOAL_PERCENT else 'NOT met'}"))
    return rows
