"""What the Rerun recording and live view cost (tuav_sitl/view).

Rows: ``tuav-sitl run circle`` as a command (figures and animation included, as a user
runs it) with its recording.rrd against ``--no-recording``, the two interleaved, the median
of each (goal: at most 10 % slower); and ``tuav-sitl up`` flying in real time for a while
in three ways, interleaved — ``--no-recording`` (no recorder at all), the recording only
(the live view's process writing recording.rrd), ``--view web`` (its web server and gRPC
stream too) — the plant's missed real-time deadlines of each from the companion's first
answer (:mod:`benchmarks.deadlines`; goal: under 0.1 %) and the live view's own CPU per
simulated second, in a private network namespace (the CAN bus), skipped without root.
``--quick``: a 6 s circle without figures once each, one 10 s flight of each kind.
"""

from __future__ import annotations

import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from benchmarks.deadlines import PlantDeadlines, parse_plant_summary, total

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


#: The three ways ``up`` is flown for the deadlines: (name, its options).
UP_CONFIGS = (("no recorder", ("--no-recording",)), ("recording only", ()),
              ("--view web", ("--view", "web")))


@dataclass
class UpFlight:
    """What one real-time ``up`` flight gives: the plant's deadlines
    (:mod:`benchmarks.deadlines`), and the live view's CPU time after its start [s] (None
    without one)."""

    deadlines: PlantDeadlines
    view_cpu_s: float | None
    sim_s: float


def _up_flight(logdir: Path, seconds: float, *extra: str) -> UpFlight:
    """One ``up`` flying ``seconds`` in real time (in a private network namespace), from
    the plant's own summary and the live view's last line."""
    from tuav_sitl.netns import run_in_netns

    res = run_in_netns([sys.executable, "-m", "tuav_sitl", "up", "--can", "udp_multicast",
                        "--headless", "--logdir", str(logdir), "--position", "4", "0", "10",
                        "--goto", "6", "2", "12", "--duration", repr(seconds), *extra],
                       timeout_s=seconds * 4 + 600, cwd=str(ROOT))
    if res.returncode != 0:
        raise RuntimeError(res.stderr.strip()[-300:])
    run = next(logdir.iterdir())
    last = (run / "plant.log").read_text().strip().splitlines()[-1]
    sim = re.search(r"([\d.]+) s simulated", last)
    try:
        deadlines = parse_plant_summary(last)
    except ValueError as exc:
        raise RuntimeError(f"no summary in plant.log: {last}") from exc
    if sim is None:
        raise RuntimeError(f"no summary in plant.log: {last}")
    view_log = run / "view.log"
    cpu = (re.search(r"([\d.]+) s of CPU", view_log.read_text())
           if view_log.is_file() else None)
    return UpFlight(deadlines, float(cpu.group(1)) if cpu else None, float(sim.group(1)))


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
    name = "up in real time: missed deadlines, --view web vs no recorder"
    if why is not None:
        rows.append(Row(name, float("nan"), "", note=f"skipped: {why}"))
        return rows
    seconds = 10.0 if quick else 60.0
    flights: dict[str, list[UpFlight]] = {config: [] for config, _ in UP_CONFIGS}
    try:
        with tempfile.TemporaryDirectory(prefix="tuav-bench-upview-") as work:
            for i in range(1 if quick else 2):      # interleaved: the host's load shared
                for config, extra in UP_CONFIGS:
                    logdir = Path(work) / f"{i}-{config.replace(' ', '_')}"
                    flights[config].append(_up_flight(logdir, seconds, *extra))
    except (RuntimeError, OSError, subprocess.TimeoutExpired) as exc:
        rows.append(Row(name, float("nan"), "", note=f"failed: {exc}"))
        return rows

    base = total([f.deadlines for f in flights["no recorder"]])
    for config in ("--view web", "recording only"):
        d = total([f.deadlines for f in flights[config]])
        pv = d.percent
        rows.append(Row(
            f"up in real time: missed deadlines, {config} vs no recorder", pv, "% missed",
            reference=base.percent,
            note=f"{d.missed_in_service} of {d.periods_in_service} periods with it, "
                 f"{base.missed_in_service} of {base.periods_in_service} without "
                 f"(--no-recording), from the companion's first answer (start-up: "
                 f"{d.startup_missed} and {base.startup_missed} periods before it); "
                 f"{len(flights[config])} x {seconds:.0f} s flights at 250 Hz each, the "
                 "three kinds interleaved; the live view and the bus recorder at idle "
                 "priority",
            goal=f"< {MISSED_GOAL_PERCENT} %: "
                 f"{'met' if pv < MISSED_GOAL_PERCENT else 'NOT met'}"))
    views = [f for f in flights["--view web"] + flights["recording only"]
             if f.view_cpu_s is not None]
    if views:
        ms = 1e3 * sum(f.view_cpu_s for f in views) / sum(f.sim_s for f in views)
        rows.append(Row(
            "up: the live view's CPU per simulated second", ms, "ms/s",
            note=f"its own process (view.log), over {len(views)} flights with it, the "
                 "web server's and the recording's threads included"))
    return rows
