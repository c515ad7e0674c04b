"""Latency of the winder's torque command: a ``Set_Input_Torque`` frame on the CAN bus to
the first plant step that applies it. ``python -m benchmarks.latency WORK``.

The plant loop runs in this process as the plant process runs it
(:class:`sitl.plant_loop.PlantLoop` over :class:`sitl.simlink_server.SimLinkServer` in real
time, through :meth:`~sitl.simlink_server.SimLinkServer.serve`; the simulated ODrive axis
:class:`sitl.winder_node.WinderCanNode` on a udp_multicast bus, serviced once per control
period), with the real companion process answering; a CAN host process (:func:`host`)
puts the axis in closed-loop torque control and then sends torque commands of distinct
values at random moments, noting the wall time (CLOCK_MONOTONIC, shared by the processes)
just before each send. The plant notes when each period's physics steps begin and with
which torque; the latency of a command is the time from its send to the first steps that
use it. Run inside a private network namespace (IPv4 multicast); prints one JSON line.
"""

from __future__ import annotations

import argparse
import json
import math
import random
import struct
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: The host's torque commands [N m]: distinct, small, and exact in float32 (the frame's type).
TORQUE_BASE_N_M = -0.125
TORQUE_STEP_N_M = 2.0 ** -12
#: Gap between two commands [s]: random in this range (the axis's watchdog wants < 0.1 s).
GAP_S = (0.006, 0.016)


def _f32(x: float) -> float:
    return float(struct.unpack("<f", struct.pack("<f", x))[0])


def host(duration_s: float, seed: int = 1) -> int:
    """The CAN host: closed-loop torque mode, then a command every 6-16 ms for
    ``duration_s`` [s]; prints the sends as JSON [(torque, wall time)]."""
    from tuavdefs import can_protocol as cp
    from tuavdefs.canbus import CanLink

    link = CanLink("udp_multicast")
    node = cp.AXIS_NODE_ID_DEFAULT
    link.send(cp.frame_id(node, cp.Cmd.CLEAR_ERRORS), cp.encode_clear_errors())
    link.send(cp.frame_id(node, cp.Cmd.SET_CONTROLLER_MODE), cp.encode_set_controller_mode(
        cp.ControlMode.TORQUE, cp.InputMode.PASSTHROUGH))
    link.send(cp.frame_id(node, cp.Cmd.SET_AXIS_STATE),
              cp.encode_set_axis_state(cp.AxisState.CLOSED_LOOP_CONTROL))
    rng = random.Random(seed)
    sends: list[tuple[float, float]] = []
    torque_id = cp.frame_id(node, cp.Cmd.SET_INPUT_TORQUE)
    end = time.monotonic() + duration_s
    k = 0
    while time.monotonic() < end:
        wake = time.monotonic() + rng.uniform(*GAP_S)
        while True:   # drain the bus (the plant's frames) while waiting
            left = wake - time.monotonic()
            if left <= 0:
                break
            link.recv(timeout_s=min(left, 0.002))
        torque = _f32(TORQUE_BASE_N_M + TORQUE_STEP_N_M * k)
        k += 1
        frame = cp.encode_set_input_torque(torque)
        t = time.monotonic()
        link.send(torque_id, frame)
        sends.append((torque, t))
    link.close()
    print(json.dumps(sends))
    return 0


def measure(work: Path, duration_s: float, control_rate_hz: float = 250.0) -> dict:
    """Run the plant loop in real time for ``duration_s`` [s] with the companion and the
    host; returns the latencies' statistics [s] and counts."""
    from benchmarks.stack import START_M, _free_port
    from sitl.plant import Plant
    from sitl.simlink_server import SimLinkServer, WinderInputs
    from sitl.trim import hover_trim
    from sitl.winder_node import WinderCanNode
    from tuavdefs.canbus import CanLink
    from tuavdefs.params import SystemParams

    work.mkdir(parents=True, exist_ok=True)
    params = SystemParams()
    x0, _ = hover_trim(params, START_M, 1.15 * math.dist(START_M, (0.0, 0.0, 0.0)))
    plant = Plant(params, state=x0)
    node = WinderCanNode(CanLink("udp_multicast"), plant, lockstep=False)
    applied: list[tuple[float, float]] = []   # (wall time the period's steps begin, torque)

    class TracedServer(SimLinkServer):
        def advance(self) -> None:
            applied.append((time.monotonic(), float(self.winder_inputs.torque_n_m)))
            super().advance()

    def on_step(server: SimLinkServer) -> None:
        t = server.plant.t_s
        node.service(t)
        node.tick(t)

    def before_physics(server: SimLinkServer) -> None:
        server.winder_inputs = WinderInputs(*node.inputs(server.plant.t_s))

    port = _free_port()
    server = TracedServer(plant, control_rate_hz=control_rate_hz, port=port, real_time=True,
                          on_step=on_step, before_physics=before_physics)
    py = sys.executable
    with open(work / "companion.log", "w") as log:
        comp = subprocess.Popen([py, "-m", "companion", "--sim", f"127.0.0.1:{port}",
                                 "--component-port", "0"], cwd=ROOT, stdout=log,
                                stderr=subprocess.STDOUT)
    try:
        server_thread_result: dict = {}
        # the host starts once the plant is serving (its first commands need the axis)
        import threading

        def serve() -> None:
            server_thread_result["summary"] = server.serve(max_sim_time_s=duration_s + 1.0,
                                                           accept_timeout_s=60.0)

        th = threading.Thread(target=serve)
        th.start()
        while not applied and th.is_alive():
            time.sleep(0.01)
        time.sleep(0.3)   # past the companion's start
        res = subprocess.run([py, "-m", "benchmarks.latency", "--host", str(duration_s)],
                             cwd=ROOT, capture_output=True, text=True, timeout=60 + duration_s)
        th.join(timeout=30.0 + duration_s)
    finally:
        server.close()
        node.link.close()
        comp.terminate()
        comp.wait(timeout=10)
    sends = json.loads(res.stdout.strip().splitlines()[-1]) if res.returncode == 0 else []
    latencies: list[float] = []
    superseded = 0
    i = 0
    for torque, t in sends:
        while i < len(applied) and applied[i][0] < t:
            i += 1
        j = i
        while j < len(applied) and applied[j][1] != torque:
            j += 1
            if j - i > 50:   # never applied: the next command replaced it first
                break
        if j < len(applied) and applied[j][1] == torque:
            latencies.append(applied[j][0] - t)
        else:
            superseded += 1
    latencies.sort()

    def q(p: float) -> float:
        if not latencies:
            return math.nan
        return latencies[min(len(latencies) - 1, max(0, math.ceil(p * len(latencies)) - 1))]

    return {"n": len(latencies), "superseded": superseded, "p50_s": q(0.5), "p99_s": q(0.99),
            "max_s": latencies[-1] if latencies else math.nan,
            "period_s": 1.0 / control_rate_hz, "host_error": res.stderr[-500:]}


def main(argv: Sequence[str] | None = None) -> int:
    """``--host D``: be the CAN host for D seconds; else measure in WORK."""
    ap = argparse.ArgumentParser(prog="python -m benchmarks.latency", description=__doc__)
    ap.add_argument("work", nargs="?", default=None)
    ap.add_argument("--host", type=float, default=None, metavar="SECONDS")
    ap.add_argument("--duration", type=float, default=5.0, help="[s] of wall time")
    args = ap.parse_args(argv)
    if args.host is not None:
        return host(args.host)
    print(json.dumps(measure(Path(args.work or "latency"), args.duration)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
