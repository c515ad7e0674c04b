"""Latency of a ground station's command: ``COMMAND_LONG`` sent to the companion's MAVLink
TCP endpoint to its ``COMMAND_ACK`` received. ``python -m benchmarks.command_latency
[--n N] [--lockstep]``.

The plant (``python -m sitl``, no CAN: the winder stays braked; the UAV resting on its
gear at (2, 0, 0) m with 40 m of slack tether on the ground) and the companion (``python -m
companion --gcs-tcp 0 --gcs-udp none``, no component link) run as processes, in real time
(``--real-time``) or in lockstep as fast as they go; a pymavlink client in this process
sends ``MAV_CMD_DO_CHANGE_SPEED`` with speed −1 (no change: answered at once with
``MAV_RESULT_ACCEPTED`` and nothing else), one at a time after a random pause, and times
each from just before the send to the matching ``COMMAND_ACK`` returned by pymavlink
(``time.perf_counter``), parsing the vehicle's telemetry on the way as a ground station
does. The companion services its ground stations once per control period, after it has
answered the plant, so in real time the floor is up to one period (4 ms at 250 Hz).

Only TCP on 127.0.0.1: no network namespace needed. Prints one JSON line.
"""

from __future__ import annotations

import argparse
import json
import math
import random
import re
import signal
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: How long a process may take to say it is ready [s].
READY_TIMEOUT_S = 60.0
#: The timed command: DO_CHANGE_SPEED (ground speed, −1: no change).
COMMAND = 178   # MAV_CMD_DO_CHANGE_SPEED
COMMAND_PARAMS = (1.0, -1.0, -1.0, 0.0, 0.0, 0.0, 0.0)
#: Pause before each command [s]: random in this range, so that sends fall at every phase
#: of the control period.
GAP_S = (0.0, 0.01)
#: Commands sent first and not counted (the first handling of each kind warms caches) .
WARMUP = 5
#: How long to wait for one ACK [s].
ACK_TIMEOUT_S = 5.0


def _wait_for(proc: subprocess.Popen, log: Path, pattern: str) -> re.Match[str]:
    """The first match of ``pattern`` in ``log`` (waiting at most :data:`READY_TIMEOUT_S`)."""
    end = time.monotonic() + READY_TIMEOUT_S
    while time.monotonic() < end:
        m = re.search(pattern, log.read_text())
        if m:
            return m
        if proc.poll() is not None:
            raise RuntimeError(f"{log.stem} exited while starting: {log.read_text()[-500:]}")
        time.sleep(0.02)
    raise RuntimeError(f"{log.stem} did not become ready: {log.read_text()[-500:]}")


def quantile(sorted_values: Sequence[float], p: float) -> float:
    """The nearest-rank ``p`` quantile (0 < p <= 1) of sorted values (nan if empty)."""
    if not sorted_values:
        return math.nan
    n = len(sorted_values)
    return sorted_values[min(n - 1, max(0, math.ceil(p * n) - 1))]


def time_commands(port: int, n: int, seed: int = 1) -> tuple[list[float], int, int]:
    """Connect to the companion's MAVLink TCP ``port`` and time ``n`` commands (after
    :data:`WARMUP` more); returns the latencies [s], the ACKs that were not
    ``MAV_RESULT_ACCEPTED`` and the commands left unanswered."""
    from pymavlink import mavutil

    m = mavutil.mavlink_connection(f"tcp:127.0.0.1:{port}", source_system=255,
                                   source_component=190)
    try:
        if m.wait_heartbeat(timeout=30) is None:
            raise RuntimeError("no heartbeat from the companion")
        rng = random.Random(seed)
        latencies: list[float] = []
        refused = unanswered = 0
        for k in range(WARMUP + n):
            pause_end = time.perf_counter() + rng.uniform(*GAP_S)
            while True:   # drain what arrived (telemetry) while pausing
                while m.recv_msg() is not None:
                    pass
                left = pause_end - time.perf_counter()
                if left <= 0:
                    break
                m.select(min(left, 0.002))
            t0 = time.perf_counter()
            m.mav.command_long_send(1, 1, COMMAND, 0, *COMMAND_PARAMS)
            ack = m.recv_match(type="COMMAND_ACK", blocking=True, timeout=ACK_TIMEOUT_S,
                               condition=f"COMMAND_ACK.command=={COMMAND}")
            t1 = time.perf_counter()
            if k < WARMUP:
                continue
            if ack is None:
                unanswered += 1
                continue
            latencies.append(t1 - t0)
            if ack.result != mavutil.mavlink.MAV_RESULT_ACCEPTED:
                refused += 1
    finally:
        m.close()
    return latencies, refused, unanswered


def measure(work: Path, n: int, real_time: bool) -> dict:
    """Start the plant and the companion (``real_time`` or lockstep) in ``work``, time ``n``
    commands, stop both; returns the statistics [s] and counts, and the plant's summary."""
    from benchmarks.stack import _free_port, _reap

    work.mkdir(parents=True, exist_ok=True)
    py = sys.executable
    sim_port = _free_port()
    plant_log, comp_log = work / "plant.log", work / "companion.log"
    procs: list[subprocess.Popen] = []
    try:
        with open(plant_log, "w") as log:
            plant = subprocess.Popen(
                [py, "-m", "sitl", "--port", str(sim_port), "--position", "2", "0", "0",
                 "--tether-length", "40", "--accept-timeout", "60",
                 *(["--real-time"] if real_time else [])],
                cwd=ROOT, stdout=log, stderr=subprocess.STDOUT)
        procs.append(plant)
        _wait_for(plant, plant_log, "listening on")
        with open(comp_log, "w") as log:
            comp = subprocess.Popen(
                [py, "-m", "companion", "--sim", f"127.0.0.1:{sim_port}", "--component-port",
                 "0", "--gcs-tcp", "0", "--gcs-udp", "none"],
                cwd=ROOT, stdout=log, stderr=subprocess.STDOUT)
        procs.append(comp)
        port = int(_wait_for(comp, comp_log, r"MAVLink on tcp:127\.0\.0\.1:(\d+)").group(1))
        latencies, refused, unanswered = time_commands(port, n)
        plant.send_signal(signal.SIGTERM)   # it prints its summary and exits
        _reap(plant, 30.0)
        _reap(comp, 30.0)
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
                p.wait()
    latencies.sort()
    summary = re.search(r"([\d.]+) s simulated in ([\d.]+) s", plant_log.read_text())
    return {"mode": "real time" if real_time else "lockstep", "n": len(latencies),
            "refused": refused, "unanswered": unanswered,
            "p50_s": quantile(latencies, 0.5), "p99_s": quantile(latencies, 0.99),
            "max_s": latencies[-1] if latencies else math.nan,
            "mean_s": sum(latencies) / len(latencies) if latencies else math.nan,
            "sim_s": float(summary.group(1)) if summary else math.nan,
            "wall_s": float(summary.group(2)) if summary else math.nan}


def main(argv: Sequence[str] | None = None) -> int:
    """Measure in WORK (real time, or ``--lockstep``); print one JSON line."""
    ap = argparse.ArgumentParser(prog="python -m benchmarks.command_latency",
                                 description=__doc__)
    ap.add_argument("work", nargs="?", default="command-latency",
                    help="folder for the logs")
    ap.add_argument("--n", type=int, default=300, help="commands timed")
    ap.add_argument("--lockstep", action="store_true",
                    help="lockstep as fast as possible instead of real time")
    args = ap.parse_args(argv)
    print(json.dumps(measure(Path(args.work), args.n, not args.lockstep)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
