"""The benchmarks that need the processes and the CAN bus, run inside one private network
namespace by ``python -m benchmarks``: ``python -m benchmarks.session WORK [--quick]``.

- the three-process stack in lockstep flying the scripted MAVLink mission
  (``examples/fly_mission.py`` from the ground; ``--quick``: its ``--short`` hop):
  simulated s per wall s, each process's CPU time, and where each process's time goes
  (cProfile from the flight's start to its end, by category);
- real time at 250 Hz and 500 Hz with every core also running a busy loop: the plant's
  pacing (period jitter, late batches) and the companion's missed deadlines (the goto
  flight from hover trim for a fixed time: in real time the mission would take its 86 s);
- the latency of a ``Set_Input_Torque`` frame to the plant steps that apply it.

Prints one JSON line.
"""

from __future__ import annotations

import argparse
import json
import os
import pstats
import re
import sys
from collections.abc import Sequence
from pathlib import Path

from benchmarks import latency, stack
from tuav_sitl.realtime import PRIORITIES

#: The plant's summary of a real-time run (sitl/__main__.py's last line).
_NUM = r"([\d.]+|nan)"
_PACING = re.compile(
    rf"period jitter p50 {_NUM} ms, p99 {_NUM} ms, max {_NUM} ms, batches late p99 "
    rf"{_NUM} ms, missed deadlines {_NUM} % of (\d+) periods")


def _mission_outcome(client_log: str) -> str:
    """The mission client's last line (``landed and disarmed; items reached: [...]``), or
    its last words if it failed."""
    lines = client_log.strip().splitlines()
    return lines[-1][-200:] if lines else "no output"


#: Flights of the mission whose median the lockstep row reports (one with ``--quick``).
LOCKSTEP_RUNS = 3


def lockstep(work: Path, quick: bool) -> dict:
    """The stack in lockstep flying the scripted mission :data:`LOCKSTEP_RUNS` times (after a
    warm-up flight): speed
    and CPU of the median flight (by speed; every flight's speed listed), one flight with
    the simulator link on TCP when up's default is a Unix-domain socket (not with
    ``quick``), one on the lumped truth tether, then where the time goes (one more
    flight, every process under cProfile from the flight's start to its end)."""
    flight = stack.mission_flight(short=quick)
    # a first flight whose outcome is not kept: the processes' compiled kernels are cached
    # by it (on a fresh clone, compiling them in the companion outlasted the mission
    # client's waits); the flights measured are a user's second and later runs. --quick
    # measures nothing to keep: only what the cache lacks is compiled first, as up does
    if quick:
        from tuav_sitl.warmup import compile_if_cold

        compile_if_cold(None)
    else:
        stack.run_stack(work / "warm-up", flight=flight)
    runs = []
    for i in range(1 if quick else LOCKSTEP_RUNS):
        run = stack.run_stack(work / f"lockstep-{i}", flight=flight)
        client = run.processes["client"]
        if client.exit_code != 0:
            raise RuntimeError(f"the mission client failed ({client.exit_code}): "
                               f"{client.log[-300:]}")
        runs.append(run)
    run = sorted(runs, key=lambda r: r.real_time_factor)[len(runs) // 2]
    out: dict = {"flight": f"{stack.MISSION_SCRIPT}{' --short' if quick else ''}",
                 "sim_s": run.sim_s, "wall_s": run.wall_s, "rtf": run.real_time_factor,
                 "rtf_runs": [r.real_time_factor for r in runs],
                 "cpu_s": {k: v.cpu_s for k, v in run.processes.items()},
                 "exit": {k: v.exit_code for k, v in run.processes.items()},
                 "mission": _mission_outcome(run.processes["client"].log)}
    out["sim_link"] = stack.SIM_LINK_DEFAULT
    if not quick and stack.SIM_LINK_DEFAULT != "tcp":
        # one flight with the other simulator link, for comparison
        tcp = stack.run_stack(work / "lockstep-tcp", flight=flight, sim_link="tcp")
        out["rtf_tcp"] = tcp.real_time_factor
    # one flight with the plant's truth tether the lumped line (issue 16's row)
    params = work / "lumped.toml"
    params.write_text('[tether]\nmodel = "lumped"\n')
    lumped = stack.run_stack(work / "lockstep-lumped", flight=flight,
                             plant_extra=["--params", str(params)])
    out["rtf_lumped"] = lumped.real_time_factor
    out["lumped_mission"] = _mission_outcome(lumped.processes["client"].log)
    prof = stack.run_stack(work / "profile", flight=flight, profile=True)
    out["profiled_rtf"] = prof.real_time_factor
    out["profiled_sim_s"] = prof.sim_s
    out["profiled_mission"] = _mission_outcome(prof.processes["client"].log)
    out["shares"], out["profiled_s"] = {}, {}
    for name in (*stack.PROCESSES, "client"):
        path = work / "profile" / f"{name}.prof"
        out["shares"][name] = prof.processes[name].shares
        out["profiled_s"][name] = pstats.Stats(str(path)).total_tt  # type: ignore[attr-defined]
    return out


def real_time(work: Path, quick: bool, rate_hz: float, priority: str | None = None) -> dict:
    """Real time at ``rate_hz`` [Hz] with a busy loop per core (started when the companion
    connects, so that the processes start as they would); ``priority``: scheduling given to
    the three processes (:data:`tuav_sitl.realtime.PRIORITIES`; None: as they start)."""
    loads: list = []
    try:
        run = stack.run_stack(
            work / f"realtime-{rate_hz:.0f}", 2.0 if quick else 10.0,
            flight=stack.goto_flight(), real_time=True,
            control_rate_hz=rate_hz, priority=priority,
            on_connected=lambda: loads.extend(stack.busy_loads(os.cpu_count() or 2)))
    finally:
        for p in loads:
            p.kill()
            p.wait()
    line = run.processes["plant"].log.strip().splitlines()[-1] if run.processes[
        "plant"].log.strip() else ""
    m = _PACING.search(line)
    if not m:
        return {"error": line[-300:]}
    p50, p99, mx, late99, missed, periods = m.groups()
    return {"jitter_p50_ms": float(p50), "jitter_p99_ms": float(p99),
            "jitter_max_ms": float(mx), "late_p99_ms": float(late99),
            "missed_percent": float(missed), "periods": int(periods), "loads": len(loads),
            "priority": priority or "normal"}


def main(argv: Sequence[str] | None = None) -> int:
    """Run the process benchmarks; print one JSON line."""
    ap = argparse.ArgumentParser(prog="python -m benchmarks.session", description=__doc__)
    ap.add_argument("work", help="folder for logs and profiles")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--only", action="append", default=None,
                    choices=("lockstep", "realtime_250", "realtime_500",
                             "realtime_250_normal", "latency"),
                    help="run only these (repeatable)")
    ap.add_argument("--priority", choices=PRIORITIES, default=None,
                    help="experiment: give the processes of the real-time runs this "
                         "scheduling (fifo, nice: root; slice: Linux 6.12+)")
    args = ap.parse_args(argv)
    work = Path(args.work)
    out: dict = {}
    # the real-time runs get the scheduling tuav-sitl up gives (SCHED_FIFO where
    # permitted), and one run at 250 Hz as the processes start, for comparison
    prio = args.priority or ("fifo" if os.geteuid() == 0 else None)
    for name, fn in (("lockstep", lambda: lockstep(work, args.quick)),
                     ("realtime_250", lambda: real_time(work, args.quick, 250.0, prio)),
                     ("realtime_500", lambda: real_time(work, args.quick, 500.0, prio)),
                     ("realtime_250_normal", lambda: real_time(work, args.quick, 250.0,
                                                               None)),
                     ("latency", lambda: latency.measure(work / "latency",
                                                         1.0 if args.quick else 5.0))):
        if args.only and name not in args.only:
            continue
        try:
            out[name] = fn()
        except Exception as exc:  # noqa: BLE001 - one failed benchmark must not hide the rest
            out[name] = {"error": f"{type(exc).__name__}: {exc}"[-300:]}
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
