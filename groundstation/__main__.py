"""``python -m groundstation``: the ground station's winder controller process.

CAN host of the winder motor (ODrive CAN Simple) and MAVLink winch component (system 1,
component 169). The winch's behaviour is :class:`groundstation.winch.Winch`: when the axis
first shows itself (its first encoder frame) it clears errors, selects torque control and
arms closed loop; it answers every encoder frame with ``Set_Input_Torque`` from the shared
:class:`groundstation.winder_host.WinderHost` (L-bar from the UAV's position and velocity,
then the backstepping torque law with the load cell's tension as feed-forward) or from the
same law tracking the length reference of a ``MAV_CMD_DO_WINCH`` mode; LOCK and HOLD put
the axis in IDLE so its brake holds the drum. It follows simulated time because it acts
only on the frames the plant sends.

The UAV's position and velocity come from the companion's component link (MAVLink
``LOCAL_POSITION_NED`` over TCP, ``--mavlink``), with the ground stations' commands
(``COMMAND_LONG``/``COMMAND_INT``, answered with ``COMMAND_ACK``); the winch's state goes
back on the same link as ``WINCH_STATUS`` (20 Hz of simulated time, at least every 0.1 s of
the winch's time) and ``STATUSTEXT``. Until the first position arrives, and while the UAV
is on the ground, the drum holds a small pre-tension on the line. Encoder frames missing
for 0.1 s of the winch's time brake the drum until they come back. The winch's time is this
host's monotonic clock (``--clock wall``, the default: a real winder, or a plant in real
time) or the winch sensor node's sample times (``--clock frames``: a plant in lockstep,
which ``tuav-sitl up`` passes whenever it is not in real time).
"""

from __future__ import annotations

import argparse
import gc
import signal
import sys
import threading
import time
from collections.abc import Sequence

from pymavlink.dialects.v20 import common as mavlink2

from groundstation.station_params import GroundStationParams
from groundstation.winch import ENCODER_TIMEOUT_S, Notice, Winch, WinchOutput
from groundstation.winch_link import WinchLinkClient
from groundstation.winder_host import WinderHost
from tuavdefs import can_protocol as cp
from tuavdefs import signing as sg
from tuavdefs.canbus import CanBusError, CanLink
from tuavdefs.component_link import COMPONENT_PORT_DEFAULT
from tuavdefs.jit import load_kernels, watch_compiles
from tuavdefs.logfile import guard_stdio
from tuavdefs.params import SystemParams
from tuavdefs.paramspec import load_option

__all__ = ["ENCODER_TIMEOUT_S", "build_parser", "main"]

#: The longest wait for a CAN frame [s]: the wall-clock duties (encoder loss, WINCH_STATUS,
#: the heartbeat, commands) are looked at least this often.
LOOP_S = 0.01


def build_parser() -> argparse.ArgumentParser:
    """Arguments of the ground-station process."""
    ap = argparse.ArgumentParser(prog="python -m groundstation", description=__doc__)
    ap.add_argument("--can", default="auto", metavar="SPEC",
                    help="CAN bus: auto, socketcan:IFACE, udp_multicast[:GROUP]")
    ap.add_argument("--mavlink", default=f"127.0.0.1:{COMPONENT_PORT_DEFAULT}",
                    help="HOST:PORT of the companion's component link ('none' to run alone)")
    ap.add_argument("--params", default=None, help="system parameters TOML (winder, tether)")
    ap.add_argument("--control", default=None, metavar="FILE",
                    help="the ground station's own parameters TOML: [winder_control] (its "
                         "law: paper or tension), [lbar], [winch], as a scenario's tables")
    ap.add_argument("--node", type=int, default=cp.AXIS_NODE_ID_DEFAULT, help="axis node id")
    ap.add_argument("--signing-key-file", default=None, metavar="FILE",
                    help="MAVLink 2 signing key of the component link (64 hexadecimal "
                         "digits; a missing or empty file: unsigned until the vehicle "
                         "sets a key)")
    ap.add_argument("--clock", choices=("wall", "frames"), default="wall",
                    help="the winch's time: wall (this host's monotonic clock: a real winder, "
                         "or a plant in real time) or frames (the winch sensor node's sample "
                         "times: a plant in lockstep, whose stalls are no lost encoder)")
    ap.add_argument("--duration", type=float, default=None, help="stop after [s] of wall time")
    return ap


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ground-station process; returns the exit code."""
    args = build_parser().parse_args(argv)
    guard_stdio()   # a process log on a full disk loses lines, not the winder's control
    params = load_option(SystemParams, args.params, "groundstation")
    station = load_option(GroundStationParams, args.control, "groundstation")
    # every kernel it calls made machine code now, not in its loop (docs/architecture.md)
    load_kernels(("groundstation", "tuavdefs"), sys.stdout, "groundstation")
    try:
        key = sg.read_key_file(args.signing_key_file) if args.signing_key_file else None
    except sg.SigningError as exc:
        print(f"groundstation: {exc}", file=sys.stderr)
        return 2
    try:
        link = CanLink(args.can)
    except CanBusError as exc:
        print(f"groundstation: {exc}", file=sys.stderr)
        return 1
    g = params.environment.gravity_m_s2
    host = WinderHost(station.winder_control, station.lbar, params.winder, params.tether, g)
    winch = Winch(host, params.winder, params.tether, g, station.winch, axis_node_id=args.node,
                  fix_params=station.tether_fix)
    mav = None if args.mavlink == "none" else WinchLinkClient(args.mavlink, signing_key=key)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    watch_compiles("groundstation", sys.stdout)
    print(f"groundstation: CAN {link.description}, axis node {args.node}, "
          f"MAVLink {args.mavlink}, law {host.controller.law.value}", flush=True)

    def emit(out: WinchOutput) -> None:
        if out.frames:
            link.send_frames(out.frames)
        for n in out.notices:
            print(f"groundstation: {n.text}", flush=True)
            if mav is not None:
                mav.statustext(n.severity, n.text)
        fix = out.fix
        if fix is not None and mav is not None:
            mav.tether_fix(fix.sample_time_ms * 1e-3, fix.pos_m, fix.cov_m2)
            reading = winch.sensors.tether_reading(fix, winch.length_m, winch.host.lbar)
            if reading is not None:
                mav.tether_reading(reading)
        st = out.status
        if st is not None and mav is not None:
            mav.winch_status(st.line_length_m, st.speed_m_s, st.tension_kg,
                             bool(st.flags & mavlink2.MAV_WINCH_STATUS_CLUTCH_ENGAGED),
                             flags=st.flags, voltage_v=st.voltage_v, current_a=st.current_a,
                             temperature_c=st.temperature_c)

    handle = winch.handle_frame
    start = time.monotonic()
    if args.clock == "frames":
        # the plant's simulated time, as the frames bring it (ArduPilot's SITL runs its
        # timers on simulated time likewise): a plant that waits is not a lost encoder
        def now_s() -> float:
            c = winch.sensor_clock_s
            return 0.0 if c is None else c
    else:
        now_s = time.monotonic
    was_lost = False
    positions_seen = 0
    winds_seen = 0
    # the start-up's objects (numpy, numba, pymavlink and their modules: most of the heap)
    # move to the collector's permanent generation, so its full collections during the
    # run no longer walk them: about a tenth of the loop's CPU (docs/performance.md)
    gc.collect()
    gc.freeze()
    try:
        while not stop.is_set():
            if args.duration is not None and time.monotonic() - start > args.duration:
                break
            # the bus first: each encoder frame is answered before anything else is done
            # (in lockstep the plant waits for that answer); then the MAVLink side. One wait
            # per turn, on the bus alone: the plant sends the frames of an instant back to
            # back, and what the component link brought meanwhile is read after them
            rx = link.recv(timeout_s=LOOP_S)
            frames = () if rx is None else [rx, *link.recv_ready()]
            if mav is not None:
                # the turn's messages to the vehicle (the fix, WINCH_STATUS) in one write,
                # after the torque: it wakes the companion once
                mav.hold()
            for rx in frames:
                out = handle(now_s(), rx.arbitration_id, rx.data, rx.is_remote)
                if out is not None:
                    emit(out)
            now = now_s()
            if now >= winch.next_poll_s():
                emit(winch.poll(now))
            if mav is not None:
                mav.poll()
                if mav.positions_received != positions_seen:   # a new UAV state
                    if not positions_seen:
                        # the link works: the law this station runs, said once
                        emit(WinchOutput(notices=[Notice(
                            mavlink2.MAV_SEVERITY_INFO,
                            f"winch: {host.controller.law.value} law")]))
                    positions_seen = mav.positions_received
                    winch.set_uav(mav.uav_state(), mav.uav_state_time_ms())
                if mav.winds_received != winds_seen:    # the vehicle's wind, after its position
                    winds_seen = mav.winds_received
                    wind = mav.uav_wind()
                    if wind is not None:
                        winch.sensors.set_wind(wind, winch.uav, winch.uav_time_ms)
                if mav.commands_waiting:
                    for req in mav.take_commands():
                        reply = winch.command(req, now_s())
                        if reply is None:
                            continue
                        mav.command_ack(reply.command, reply.result, reply.target_system,
                                        reply.target_component)
                        emit(WinchOutput(notices=list(reply.notices)))
                mav.flush()
            if winch.lost != was_lost:      # the log lines of the stream itself
                was_lost = winch.lost
                print(f"groundstation: encoder frames {'lost' if was_lost else 'back'}",
                      flush=True)
    finally:
        link.close()
        if mav is not None:
            mav.close()
    print(f"groundstation: {winch.encoder_frames} encoder frames, "
          f"{winch.torque_commands} torque commands", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
