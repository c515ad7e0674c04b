"""``python -m sitl``: the plant process.

Serves the PX4 simulator MAVLink API to one companion (lockstep by default, or paced by the
wall clock with ``--real-time``) and writes the plant's truth time series. With ``--can``
the winder motor is a simulated ODrive axis (and the winch's sensors a second node) on that
CAN bus, driven by whoever commands it there (the ground-station process); without it the
winder stays braked.
"""

from __future__ import annotations

import argparse
import gc
import math
import signal
import sys
from collections.abc import Sequence

from sitl.faults import FaultSchedule, FaultsFile
from sitl.plant import Plant, initial_state
from sitl.plant_loop import PlantLoop
from sitl.sensors import GnssPreset, SensorNoise
from sitl.simlink_server import SimLinkConfig, SimLinkServer, WinderInputs
from sitl.trim import hover_trim
from sitl.truth_log import TruthLog
from sitl.winder_node import WinderCanNode
from tuavdefs import simlink as sl
from tuavdefs.canbus import CanBusError, CanLink
from tuavdefs.frames import quat_multiply
from tuavdefs.jit import load_kernels, watch_compiles
from tuavdefs.logfile import LogFile, guard_stdio, mb_to_bytes
from tuavdefs.params import SystemParams
from tuavdefs.paramspec import ParameterError, load_option


def build_parser() -> argparse.ArgumentParser:
    """Arguments of the plant process."""
    ap = argparse.ArgumentParser(prog="python -m sitl", description=__doc__)
    ap.add_argument("--port", type=int, default=sl.SIM_PORT_DEFAULT,
                    help="TCP port of the simulator link on 127.0.0.1")
    ap.add_argument("--socket", default=None, metavar="PATH",
                    help="listen on a Unix-domain socket at PATH instead of TCP (@NAME: a "
                         "name in Linux's abstract namespace); the companion connects with "
                         "--sim unix:PATH")
    ap.add_argument("--control-rate", type=float, default=sl.CONTROL_RATE_HZ_DEFAULT,
                    help="control periods per simulated second [Hz]")
    ap.add_argument("--real-time", action="store_true", help="pace by the wall clock")
    ap.add_argument("--speedup", type=float, default=None, metavar="N",
                    help="lockstep paced at N x real time (1: the same as --real-time; "
                         "default: lockstep as fast as possible)")
    ap.add_argument("--duration", type=float, default=None, help="stop after [s] of sim time")
    ap.add_argument("--params", default=None, help="system parameters TOML")
    ap.add_argument("--faults", default=None, metavar="FILE",
                    help="faults to inject: a TOML file of [[faults]] tables (sitl/faults.py: "
                         "kind = gnss_loss | wind | motor | winder_motor | can_loss | can | "
                         "tether_snag, start_s, end_s, ...)")
    ap.add_argument("--position", type=float, nargs=3, default=(2.0, 0.0, 10.0),
                    metavar=("X", "Y", "Z"),
                    help="start here [m], z-up frame: in hover trim, or resting on the "
                         "ground if Z is at most the gear height (e.g. 0)")
    ap.add_argument("--tether-length", type=float, default=None,
                    help="paid-out length at the start [m] (default 1.15 x the distance)")
    ap.add_argument("--home", type=float, nargs=3, default=sl.HOME_DEFAULT,
                    metavar=("LAT", "LON", "ALT"), help="the winder's global position")
    ap.add_argument("--heading", type=float, default=None, metavar="DEG",
                    help="the vehicle's heading at start, clockwise from north (default: "
                         "facing east)")
    ap.add_argument("--no-noise", action="store_true",
                    help="exact sensor readings (no noise, no bias, no GNSS latency)")
    ap.add_argument("--gnss", choices=[p.value for p in GnssPreset],
                    default=GnssPreset.RTK.value,
                    help="the GNSS receiver: rtk (u-blox ZED-F9P class, 1 cm, 10 Hz, 50 ms "
                         "late; the default) or gnss (standalone M9N/M10 class, 0.8 m "
                         "wandering over 8 s, 5 Hz, 100 ms late); HIL_GPS's rate and "
                         "latency follow it")
    ap.add_argument("--sensor-seed", type=int, default=0, metavar="N",
                    help="seed of the sensors' noise and biases (>= 0)")
    ap.add_argument("--truth-log", default=None, help="CSV of the plant's truth")
    ap.add_argument("--log-every", type=int, default=5, help="log every N control periods")
    ap.add_argument("--log-max-mb", type=float, default=None, metavar="MB",
                    help="end the truth log when it reaches this size (default: no cap); "
                         "a full disk ends it too, and the simulation goes on")
    ap.add_argument("--can", default=None, metavar="SPEC",
                    help="CAN bus of the winder: auto, socketcan:IFACE, udp_multicast[:GROUP] "
                         "(default: none, the winder stays braked)")
    ap.add_argument("--lockstep-spin-us", type=float, default=0.0, metavar="US",
                    help="in lockstep, spin this long [us] waiting for the companion's "
                         "answer and the ground station's torque before sleeping (for a "
                         "plant with a CPU of its own, as with tuav-sitl up --no-pin on "
                         "many CPUs; 0, the default: sleep at once)")
    ap.add_argument("--accept-timeout", type=float, default=60.0,
                    help="give up if no companion connects within [s]")
    return ap


def _log_ended(why: str) -> None:
    """A log of the plant's ended (full disk, lost file, cap): said; the plant flies on."""
    print(f"plant: {why}; the simulation goes on", file=sys.stderr, flush=True)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the plant process; returns the exit code."""
    args = build_parser().parse_args(argv)
    guard_stdio()   # a process log on a full disk loses lines, not the plant
    real_time = args.real_time or args.speedup == 1.0
    if not args.lockstep_spin_us >= 0.0:
        print("plant: --lockstep-spin-us must be >= 0", file=sys.stderr)
        return 2
    spin_s = 0.0 if real_time else args.lockstep_spin_us * 1e-6
    try:
        noise = (SensorNoise.off(args.gnss) if args.no_noise
                 else SensorNoise.preset(args.gnss, seed=args.sensor_seed))
    except ValueError as exc:
        print(f"plant: --sensor-seed: {exc}", file=sys.stderr)
        return 2
    params = load_option(SystemParams, args.params, "plant")
    faults = load_option(FaultsFile, args.faults, "plant").faults
    # every kernel it calls made machine code now, not in its loop (docs/architecture.md)
    load_kernels(("sitl", "tuavdefs"), sys.stdout, "plant")
    pos = tuple(args.position)
    gear = params.vehicle.gear_height_m
    try:        # (a line the plant cannot integrate is refused as it is built)
        if pos[2] <= gear:
            # resting on its gear, rotors stopped, the tether lying out to it with a little
            # slack
            pos = (pos[0], pos[1], gear)
            length = args.tether_length or math.dist(pos, (0.0, 0.0, 0.0)) + 0.1
            plant = Plant(params)
            plant.x[:] = initial_state(plant.model, pos, tether_length_m=length)
            plant.lay_line()    # a lumped tether laid out to it
        else:
            length = args.tether_length or 1.15 * math.dist(pos, (0.0, 0.0, 0.0))
            x0, _ = hover_trim(params, pos, length)
            plant = Plant(params, state=x0)
    except ParameterError as exc:
        print(f"plant: bad parameter: {exc}", file=sys.stderr)
        return 2
    if args.heading is not None and math.isfinite(args.heading):
        # the start's attitude turned about z-up to the heading (yaw-symmetric otherwise)
        yaw = math.radians(90.0 - args.heading)
        q = quat_multiply((math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)),
                          tuple(float(v) for v in plant.x[6:10]))
        plant.x[6:10] = q
    node = None
    if args.can:
        try:
            node = WinderCanNode(CanLink(args.can), plant, lockstep=not real_time,
                                 spin_s=spin_s)
        except CanBusError as exc:
            print(f"plant: {exc}", file=sys.stderr)
            return 1
    log = (TruthLog(LogFile(args.truth_log, text=True, max_bytes=mb_to_bytes(args.log_max_mb),
                            on_end=_log_ended), args.log_every)
           if args.truth_log else None)
    try:
        server = SimLinkServer(plant, SimLinkConfig(
            control_rate_hz=args.control_rate, home=tuple(args.home), port=args.port,
            unix_path=args.socket, real_time=real_time, speedup=args.speedup,
            lockstep_spin_s=spin_s, sensor_noise=noise))
    except OSError as exc:
        where = sl.format_sim_address(args.socket if args.socket is not None
                                      else (sl.SIM_HOST_DEFAULT, args.port))
        print(f"plant: cannot listen on {where}: {exc.strerror}", file=sys.stderr)
        return 1
    # the scenario's faults and the run-time SIM_* parameters the companion forwards
    schedule = FaultSchedule(faults, plant, server.batches)
    server.sim_params = schedule

    def before_physics(srv: SimLinkServer) -> None:
        for line in schedule.apply(plant.t_s):
            print(f"plant: {line}", flush=True)
        if node is not None:
            node.can = schedule.can
        if schedule.winder_motor_failed and srv.winder_inputs.torque_n_m != 0.0:
            srv.winder_inputs = WinderInputs(0.0, srv.winder_inputs.enabled)
    # the faults of the start in force before the first batch goes out (a GNSS lost from
    # 0 s: not even the first fix)
    before_physics(server)
    loop = PlantLoop(server, node=node, truth_log=log, before_physics=before_physics)
    signal.signal(signal.SIGTERM, lambda *_: loop.stop())
    signal.signal(signal.SIGINT, lambda *_: loop.stop())
    can_text = f", winder on CAN {node.link.description}" if node else ", winder braked"
    gnss_text = ("exact sensors" if args.no_noise else
                 f"GNSS {args.gnss} at {noise.gps_rate_hz:g} Hz, "
                 f"{noise.gps_latency_s * 1e3:g} ms late, sensor seed {args.sensor_seed}")
    watch_compiles("plant", sys.stdout)
    print(f"plant: listening on {server.address} "
          f"({loop.pacing.replace('-', ' ')}{can_text}; {gnss_text})", flush=True)
    # the start-up's objects (numpy, numba, pymavlink and their modules: most of the heap)
    # move to the collector's permanent generation, so its full collections during the
    # run no longer walk them: about a tenth of the loop's CPU (docs/performance.md)
    gc.collect()
    gc.freeze()
    try:
        summary = loop.run(max_sim_time_s=args.duration, accept_timeout_s=args.accept_timeout)
    finally:
        loop.close()    # (the server's Unix-domain socket file, the log, the CAN bus)
    can_text = (f", CAN: {node.frames_received} frames in, {node.frames_sent} out, "
                f"{node.late_answers} late answers" if node else "")
    pacing_text = ""
    if summary.pacing == "real-time" and summary.steps > 1:
        ms = 1e3
        pacing_text = (f"; pacing: period jitter p50 {summary.jitter_p50_s * ms:.3f} ms, "
                       f"p99 {summary.jitter_p99_s * ms:.3f} ms, "
                       f"max {summary.jitter_max_s * ms:.3f} ms, batches late p99 "
                       f"{summary.lateness_p99_s * ms:.3f} ms, missed deadlines "
                       f"{100.0 * summary.missed_fraction:.3f} % of "
                       f"{summary.periods_in_service} periods from the first answer, "
                       f"{summary.overruns} overruns")
    if spin_s > 0.0:
        spins = [server.spin, *([node.spin] if node is not None else [])]
        pacing_text += (f"; spun {sum(w.spins for w in spins)} waits, "
                        f"{sum(w.hits for w in spins)} answered awake")
    print(f"plant: {summary.end_reason}: {summary.steps} periods, "
          f"{summary.sim_time_s:.2f} s simulated in {summary.wall_time_s:.3f} s, "
          f"{summary.bad_frames} bad frames, {summary.missed_deadlines} missed deadlines"
          f"{can_text}{pacing_text}", flush=True)
    return 0 if summary.end_reason != "no_client" else 1


if __name__ == "__main__":
    sys.exit(main())
