"""``python -m companion``: the onboard flight computer process.

Connects to the plant's simulator link and, at every control period, steps the onboard
software, :class:`companion.onboard.Companion` (navigation and flight control: the same
object the offline runner steps), on the state it receives (HIL_STATE_QUATERNION), and
answers with the rotor commands. Ground stations and
scripts drive it as an ArduCopter (``companion.autopilot``) on TCP 127.0.0.1:5760 and UDP
pushed to 127.0.0.1:14550 and 14540; every frame is logged to ``--tlog``.

On its component link (TCP 5762) it sends the UAV's position to the winch component (the
ground-station process), takes its WINCH_STATUS as the winch's reports for the onboard
tether model, and routes messages between the winch and the ground stations.

If the plant starts the vehicle in the air, it starts armed in GUIDED, holding there (and
flies to ``--goto`` if given); on the ground it waits, disarmed, for a ground station.
"""

from __future__ import annotations

import argparse
import gc
import math
import select
import signal
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from pymavlink.dialects.v20 import common as mavlink2

from companion.autopilot import Autopilot
from companion.component_server import ComponentServer
from companion.ekf import ESTIMATOR_KINDS, EstimatorParams
from companion.flight_controller import VehicleState
from companion.flight_log import FlightLog, LogClock
from companion.gains import FlightControlParams
from companion.geofence import FenceParams
from companion.log_protocol import LogProtocol
from companion.mavlink_io import (
    GCS_TCP_PORT_DEFAULT,
    UDP_API_PORT_DEFAULT,
    UDP_GCS_PORT_DEFAULT,
    MavlinkEndpoints,
    TelemetryLog,
)
from companion.navigation import NavigationParams
from companion.onboard import Companion, OnboardInputs
from companion.param_names import build_defs
from companion.signing import VehicleSigning
from companion.sim_params import sim_param_defs
from companion.simlink_client import SimLinkClient
from companion.telemetry import Telemetry
from tuavdefs import component_link as cl
from tuavdefs import signing as sg
from tuavdefs import simlink as sl
from tuavdefs.jit import load_kernels, watch_compiles
from tuavdefs.logfile import guard_stdio, mb_to_bytes
from tuavdefs.params import SystemParams
from tuavdefs.paramspec import load_option

CLUTCH_ENGAGED = mavlink2.MAV_WINCH_STATUS_CLUTCH_ENGAGED
WINCH_HEALTHY = mavlink2.MAV_WINCH_STATUS_HEALTHY
#: Wall time without a state from the plant after which the companion gives up [s].
SIM_SILENCE_S = 30.0
#: Longest wait for input before the wall-clock duties (heartbeat, timeouts) run [s].
SELECT_TIMEOUT_S = 0.05


def _address(text: str) -> tuple[str, int]:
    host, _, port = text.rpartition(":")
    return (host or "127.0.0.1", int(port))


def _sim_address(text: str) -> tuple[str, int] | str:
    try:
        return sl.parse_sim_address(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


class _Waiter:
    """Waits for input on the plant's link (descriptor ``sim_fd``) and on sockets that
    change now and then (the autopilot's), with ``poll``: registered once per change, not
    converted at every call as ``select`` does."""

    def __init__(self, sim_fd: int) -> None:
        self.sim_fd = sim_fd
        self._watched: list | None = None
        self._poll = select.poll()
        self._by_fd: dict[int, Any] = {}

    def wait(self, watched: list, timeout_s: float) -> list:
        """What is readable (or closed) within ``timeout_s`` [s]: ``sim_fd`` and the
        sockets of ``watched`` (the same list object while they do not change)."""
        if watched is not self._watched:
            self._watched = watched
            self._poll = select.poll()
            self._by_fd = {self.sim_fd: self.sim_fd}
            for sock in watched:
                self._by_fd[sock.fileno()] = sock
            for fd in self._by_fd:
                self._poll.register(fd, select.POLLIN)
        try:
            events = self._poll.poll(timeout_s * 1000.0)
        except OSError:
            return [self.sim_fd]    # as a bare read of the plant would be
        by_fd = self._by_fd
        return [by_fd[fd] for fd, _ in events]


def build_parser() -> argparse.ArgumentParser:
    """Arguments of the companion process."""
    ap = argparse.ArgumentParser(prog="python -m companion", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sim", default=f"127.0.0.1:{sl.SIM_PORT_DEFAULT}",
                    type=_sim_address, metavar="ADDRESS",
                    help="the plant's simulator link: HOST:PORT or tcp:HOST:PORT, or "
                         "unix:PATH for a Unix-domain socket (unix:@NAME: Linux's abstract "
                         "namespace)")
    ap.add_argument("--home", type=float, nargs=3, default=sl.HOME_DEFAULT,
                    metavar=("LAT", "LON", "ALT"),
                    help="the winder's global position (ground altitude AMSL [m])")
    ap.add_argument("--params", default=None, help="system parameters TOML (the vehicle)")
    ap.add_argument("--gains", default=None, help="flight-control gains TOML")
    ap.add_argument("--nav", default=None, help="navigation parameters TOML (speeds, ...)")
    ap.add_argument("--estimator", default=None,
                    help="navigation filter parameters TOML (its sensor model, gates, ...)")
    ap.add_argument("--state", choices=ESTIMATOR_KINDS, default=None,
                    help="fly on the filter's estimate (ekf, the default) or on the "
                         "simulator's state (truth: HIL_STATE_QUATERNION)")
    ap.add_argument("--goto", type=float, nargs=3, default=None, metavar=("X", "Y", "Z"),
                    help="when starting in the air: fly here [m] (z-up frame), then hold")
    ap.add_argument("--gcs-tcp", type=int, default=GCS_TCP_PORT_DEFAULT,
                    help="TCP port for ground stations on 127.0.0.1 (0: any free port; "
                         "-1: none)")
    ap.add_argument("--gcs-udp", action="append", default=None, metavar="HOST:PORT",
                    help="push MAVLink by UDP here (repeatable; default 127.0.0.1:14550 and "
                         "127.0.0.1:14540; 'none' for none)")
    ap.add_argument("--tlog", default=None, help="telemetry log of all ground-station traffic")
    ap.add_argument("--log-max-mb", type=float, default=None, metavar="MB",
                    help="end the telemetry log when it reaches this size (default: no "
                         "cap); a full disk ends it too, and the vehicle flies on")
    ap.add_argument("--telemetry-batch", type=float, default=0.0, metavar="S",
                    help="write what a TCP ground station did not ask for (telemetry, "
                         "broadcasts) at most every S seconds of wall time, replies at once "
                         "(0: everything at once; tuav-sitl up uses 0.01 in lockstep faster "
                         "than real time)")
    ap.add_argument("--log-dir", default=None, metavar="DIR",
                    help="write an onboard DataFlash log per boot here (NNNNNNNN.BIN) and "
                         "serve them with LOG_REQUEST_LIST / LOG_REQUEST_DATA")
    ap.add_argument("--param-file", default=None,
                    help="parameters persisted here (.parm); loaded at start if present")
    ap.add_argument("--signing-key-file", default=None, metavar="FILE",
                    help="MAVLink 2 signing key (64 hexadecimal digits): signing is on from "
                         "the start if the file holds a key; a key a ground station sets "
                         "with SETUP_SIGNING is kept here")
    ap.add_argument("--connect-timeout", type=float, default=30.0, help="[s]")
    ap.add_argument("--component-port", type=int, default=cl.COMPONENT_PORT_DEFAULT,
                    help="TCP port of the component link (0: none)")
    return ap


def main(argv: Sequence[str] | None = None) -> int:
    """Run the companion process; returns the exit code."""
    args = build_parser().parse_args(argv)
    guard_stdio()   # a process log on a full disk loses lines, not the vehicle
    params = load_option(SystemParams, args.params, "companion")
    gains = load_option(FlightControlParams, args.gains, "companion")
    nav_params = load_option(NavigationParams, args.nav, "companion")
    estimator = load_option(EstimatorParams, args.estimator, "companion")
    # every kernel it calls made machine code now, not in its loop (docs/architecture.md)
    load_kernels(("companion", "tuavdefs"), sys.stdout, "companion")
    udp = ([] if args.gcs_udp == ["none"] else
           [_address(a) for a in args.gcs_udp] if args.gcs_udp else
           [("127.0.0.1", UDP_GCS_PORT_DEFAULT), ("127.0.0.1", UDP_API_PORT_DEFAULT)])
    try:
        key = (sg.read_key_file(args.signing_key_file) if args.signing_key_file else None)
    except sg.SigningError as exc:
        print(f"companion: {exc}", file=sys.stderr)
        return 2
    signing = VehicleSigning(key, args.signing_key_file)
    try:
        components = (ComponentServer(args.component_port, signing=signing.component)
                      if args.component_port else None)
        endpoints = MavlinkEndpoints(None if args.gcs_tcp < 0 else args.gcs_tcp, udp,
                                     tlog=(TelemetryLog(args.tlog, mb_to_bytes(args.log_max_mb))
                                           if args.tlog else None),
                                     batch_s=max(args.telemetry_batch, 0.0),
                                     signing=signing.gcs)
    except OSError as exc:
        print(f"companion: cannot listen: {exc.strerror} ({exc})", file=sys.stderr)
        return 1
    # the onboard software (and its compiled code) is ready before the plant's clock starts
    g = params.environment.gravity_m_s2
    if args.state is not None:
        estimator = estimator.replace(kind=args.state)
    onboard = Companion(params, gains, nav_params, estimator)
    nav = onboard.nav
    # the simulator's own state only for a vehicle told to fly on it
    on_truth = onboard.filter is None
    if isinstance(args.sim, str):
        client = SimLinkClient(home=tuple(args.home), unix_path=args.sim, truth=on_truth)
    else:
        client = SimLinkClient(*args.sim, tuple(args.home), truth=on_truth)
    # the start-up's objects (numpy, numba, pymavlink and their modules: most of the heap)
    # move to the collector's permanent generation, so its full collections during the
    # run no longer walk them: about a tenth of the loop's CPU (docs/performance.md). Done
    # before connecting: the plant's clock starts when the companion connects, and this
    # full collection takes tens of milliseconds (270 ms on a loaded host: 20-odd periods
    # unanswered at every start)
    gc.collect()
    gc.freeze()
    try:
        client.connect(timeout_s=args.connect_timeout)
    except TimeoutError as exc:
        print(f"companion: {exc}", file=sys.stderr)
        return 1

    fence_holder: list = []

    def set_fence(p: FenceParams) -> None:
        """New fence parameters: the geofence's, and SYS_STATUS's bits."""
        for ap in fence_holder:
            ap.fence.p = p
            ap.fence_changed()

    defs = build_defs(gains, nav_params, onboard.set_gains, onboard.set_nav_params,
                      lambda: onboard.arming_check,
                      lambda v: setattr(onboard, "arming_check", v),
                      FenceParams(), set_fence, onboard.failsafes.params,
                      lambda p: setattr(onboard.failsafes, "params", p))
    # the simulator's fault parameters, relayed to the plant (never read on board)
    defs += sim_param_defs(client.sim_params, client.set_sim_param)
    autopilot = Autopilot(endpoints, nav, tuple(args.home), defs,
                          param_file=Path(args.param_file) if args.param_file else None,
                          component=components, signing=signing)
    fence_holder.append(autopilot)
    if args.param_file and Path(args.param_file).exists():
        for warning in autopilot.params.load() or []:
            print(f"companion: {warning}", flush=True)

    def on_start() -> None:
        """The first state: fly to --goto if in the air; announce home."""
        if nav.flying and args.goto is not None:
            why = nav.goto(tuple(args.goto))
            if why is not None:
                print(f"companion: --goto refused: {why}", flush=True)
        autopilot.armed_changed()

    autopilot.on_gcs_heartbeat(lambda: onboard.gcs_heard(last_t[0]))
    autopilot.on_external_position(onboard.external_position)
    autopilot.on_tether_reading(onboard.tether_reading)
    autopilot.streams.wind_source = onboard.wind_estimate
    autopilot.streams.estimator_ready = onboard.estimator_ready

    def reboot() -> None:
        """The onboard state restarted; ground stations see the new state at once."""
        onboard.reboot()
        if args.log_dir:
            new_log()
        autopilot.streams.mission_started = autopilot.streams.mission_complete = False
        autopilot.send_heartbeat()

    autopilot.commands.reboot = reboot

    log_clock = LogClock()     # the real time of the simulated clock, for every boot's log

    def new_log() -> None:
        """This boot's onboard log, its parameters first."""
        if autopilot.flight_log is not None:
            autopilot.flight_log.close()
        autopilot.flight_log = fl = FlightLog(Path(args.log_dir), tuple(args.home),
                                              log_clock)
        for d in defs:
            fl.param(d.name, d.get())

    if args.log_dir:
        new_log()
        autopilot.logs = LogProtocol(
            Path(args.log_dir), autopilot._send_to,
            lambda: autopilot.flight_log.number if autopilot.flight_log else None)
    def on_winch_status(m: Any) -> None:
        tension_n = m.tension * g if math.isfinite(m.tension) else None
        onboard.winch_report(last_t[0], m.line_length, m.speed, tension_n,
                             bool(m.status & CLUTCH_ENGAGED), bool(m.status & WINCH_HEALTHY))
        if autopilot.flight_log is not None:
            autopilot.flight_log.tether(last_t[0], m.line_length, m.speed,
                                        tension_n if tension_n is not None else math.nan)

    autopilot.on_winch_status(on_winch_status)
    stop = {"signal": None}
    signal.signal(signal.SIGTERM, lambda s, _f: stop.update(signal=s))
    signal.signal(signal.SIGINT, lambda s, _f: stop.update(signal=s))
    udp_text = ", ".join(f"udp:{h}:{p}" for h, p in udp) or "no udp"
    tcp_text = f"tcp:127.0.0.1:{endpoints.tcp_port}" if endpoints.tcp_port else "no tcp"
    watch_compiles("companion", sys.stdout)
    print(f"companion: connected to the plant at {client.address}; MAVLink on {tcp_text}, "
          f"{udp_text}"
          + (f"; component link on tcp:127.0.0.1:{components.port}" if components else "")
          + ("; MAVLink signing on" if signing.enabled else ""),
          flush=True)
    last_t = [0.0]
    was_armed = False
    last_state_wall = time.monotonic()
    reason = "link closed"
    sim_fd = client.fileno()
    waiter = _Waiter(sim_fd)
    # what the set-up since made joins them (a freeze moves objects, it walks none)
    gc.freeze()
    try:
        while stop["signal"] is None:
            # one wait for the plant's next batch, the ground stations and the winch
            buffered = client.has_buffered_state()
            ready = [] if buffered else waiter.wait(
                autopilot.selectables(), min(SELECT_TIMEOUT_S, autopilot.receive_wait_s()))
            sim = None
            if buffered or sim_fd in ready:
                try:
                    sim = client.receive_state(timeout_s=SELECT_TIMEOUT_S)
                except TimeoutError:
                    sim = None      # the batch did not complete in time
            if sim is None:
                # between periods: what they ask applies from the next period
                if ready or autopilot.backlogged:
                    autopilot.receive(ready)
                autopilot.service(None)
                if time.monotonic() - last_state_wall > SIM_SILENCE_S:
                    reason = "no state from the plant"
                    break
                continue
            last_state_wall = time.monotonic()
            t = sim.sim_time_s
            last_t[0] = t
            truth = sim.truth
            inputs = OnboardInputs(
                t, None if truth is None else VehicleState(
                    truth.position_enu_m, truth.velocity_enu_m_s, truth.quaternion,
                    truth.body_rates_flu_rad_s),
                sim.imu, sim.gps if sim.gps_updated else None)
            if onboard.begin(inputs):   # the first state: before the navigator's first step
                on_start()
            out = onboard.finish()
            cmds, armed, state = out.rotor_commands, out.armed, out.state
            client.send_actuators(sim.time_usec, cmds, armed=armed)
            if autopilot.flight_log is not None:   # its sensors, filter and events
                autopilot.flight_log.period(inputs, out, onboard)
            # the answer is out (in lockstep the plant waits for it); now the ground
            # stations and the winch: what they ask applies from the next period
            if len(ready) > 1 or autopilot.backlogged:
                autopilot.receive(ready)
            if state is None:       # no estimate yet: nothing to report but heartbeats
                autopilot.service(None)
                continue
            throttle = sum(cmds) / 4.0 if armed else 0.0
            autopilot.service(Telemetry(t, state.pos_m, state.vel_m_s, state.quat,
                                        state.rates_rad_s, throttle, onboard.imu,
                                        onboard.gps, onboard.last_status, cmds))
            if nav.armed and not was_armed:
                autopilot.armed_changed()
            was_armed = nav.armed
            if components is not None:
                components.send_position(t, state.pos_m, state.vel_m_s)
                components.send_wind(t, onboard.wind_estimate)
    except ConnectionError:
        pass
    finally:
        client.close()
        autopilot.params.close()   # the parameter file written out
        signing.close()            # and the signing key
        if autopilot.flight_log is not None:
            autopilot.flight_log.close()
        if autopilot.logs is not None:
            autopilot.logs.close()
        endpoints.close()
        if endpoints.tlog is not None:
            endpoints.tlog.close()
        if components is not None:
            components.close()
    if stop["signal"] is not None:
        reason = "stopped"
    c = autopilot.counters
    print(f"companion: {reason} after {onboard.steps} control periods; {c['commands']} commands "
          f"({c['unsupported']} unsupported), {c['rejected_targets']} targets refused; "
          f"{endpoints.bad_frames} bad MAVLink frames dropped"
          + (f" ({signing.refused} unsigned or badly signed)" if signing.refused else ""),
          flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
