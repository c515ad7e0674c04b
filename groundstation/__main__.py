"""``python -m groundstation``: the ground station's winder controller process.

CAN host of the winder motor (ODrive CAN Simple): brings the axis to closed-loop torque
control, and for every encoder frame it receives runs the shared
:class:`groundstation.winder_host.WinderHost` (L-bar from the UAV's position and velocity,
then the backstepping torque law, with the load cell's tension as feed-forward) and answers
with ``Set_Input_Torque`` — which also feeds the axis's watchdog. It follows simulated time
because it acts only on the frames the plant sends.

The UAV's position and velocity come from the companion's component link (MAVLink
``LOCAL_POSITION_NED`` over TCP, ``--mavlink``); the winch's state goes back on the same
link as ``WINCH_STATUS`` (line length [m], speed [m/s], tension [kg] as the message defines)
from component 169, so the companion can use it. Until the first position arrives the law
holds the current length. A lost encoder stream (> 100 ms without a frame) is reported.
"""

from __future__ import annotations

import argparse
import math
import signal
import sys
import threading
import time
from collections.abc import Sequence
from pathlib import Path

from groundstation.lbar import LBarParams
from groundstation.winch_link import WinchLinkClient
from groundstation.winder_control import WinderControlParams
from groundstation.winder_host import WinderHost
from tuavdefs import can_protocol as cp
from tuavdefs.canbus import CanBusError, CanLink
from tuavdefs.component_link import COMPONENT_PORT_DEFAULT
from tuavdefs.params import SystemParams
from tuavdefs.paramspec import ParameterError, load_toml

#: Encoder silence after which the ground station reports the stream lost [s, wall].
ENCODER_TIMEOUT_S = 0.1


def build_parser() -> argparse.ArgumentParser:
    """Arguments of the ground-station process."""
    ap = argparse.ArgumentParser(prog="python -m groundstation", description=__doc__)
    ap.add_argument("--can", default="auto", metavar="SPEC",
                    help="CAN bus: auto, socketcan:IFACE, udp_multicast[:GROUP]")
    ap.add_argument("--mavlink", default=f"127.0.0.1:{COMPONENT_PORT_DEFAULT}",
                    help="HOST:PORT of the companion's component link ('none' to run alone)")
    ap.add_argument("--params", default=None, help="system parameters TOML (winder, tether)")
    ap.add_argument("--node", type=int, default=cp.AXIS_NODE_ID_DEFAULT, help="axis node id")
    ap.add_argument("--duration", type=float, default=None, help="stop after [s] of wall time")
    return ap


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ground-station process; returns the exit code."""
    args = build_parser().parse_args(argv)
    try:
        params = SystemParams() if args.params is None else load_toml(SystemParams,
                                                                       Path(args.params))
    except ParameterError as exc:
        print(f"groundstation: bad parameter: {exc}", file=sys.stderr)
        return 2
    try:
        link = CanLink(args.can)
    except CanBusError as exc:
        print(f"groundstation: {exc}", file=sys.stderr)
        return 1
    g = params.environment.gravity_m_s2
    host = WinderHost(WinderControlParams(), LBarParams(), params.winder, params.tether, g)
    r_w = params.winder.drum_radius_m
    mav = None if args.mavlink == "none" else WinchLinkClient(args.mavlink)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    print(f"groundstation: CAN {link.description}, axis node {args.node}, "
          f"MAVLink {args.mavlink}", flush=True)
    node = args.node
    send = link.send
    send(cp.frame_id(node, cp.Cmd.CLEAR_ERRORS), cp.encode_clear_errors())
    send(cp.frame_id(node, cp.Cmd.SET_CONTROLLER_MODE), cp.encode_set_controller_mode(
        cp.ControlMode.TORQUE, cp.InputMode.PASSTHROUGH))
    send(cp.frame_id(node, cp.Cmd.SET_AXIS_STATE),
         cp.encode_set_axis_state(cp.AxisState.CLOSED_LOOP_CONTROL))
    tension_n = 0.0
    length_m = math.nan
    speed_m_s = 0.0
    brake = True
    last_encoder = time.monotonic()
    lost = False
    frames = torques = 0
    start = time.monotonic()
    try:
        while not stop.is_set():
            if args.duration is not None and time.monotonic() - start > args.duration:
                break
            if mav is not None:
                mav.poll()
            rx = link.recv(timeout_s=0.01)
            now = time.monotonic()
            if rx is None:
                if not lost and frames and now - last_encoder > ENCODER_TIMEOUT_S:
                    lost = True
                    print("groundstation: encoder frames lost", flush=True)
                continue
            nid, cmd = cp.split_id(rx.arbitration_id)
            if nid == cp.WINCH_SENSOR_NODE_ID_DEFAULT and not rx.is_remote:
                if cmd == cp.SensorCmd.WINCH_TENSION:
                    wt = cp.decode_winch_tension(rx.data)
                    tension_n, brake = wt.tension_n, wt.brake_engaged
                elif cmd == cp.SensorCmd.WINCH_LENGTH:
                    wl = cp.decode_winch_length(rx.data)
                    length_m, speed_m_s = wl.length_m, wl.speed_m_s
                continue
            if nid != node or rx.is_remote or cmd != cp.Cmd.GET_ENCODER_ESTIMATES:
                continue
            frames += 1
            last_encoder = now
            if lost:
                lost = False
                print("groundstation: encoder frames back", flush=True)
            enc = cp.decode_encoder_estimates(rx.data)
            theta = enc.pos_rev * 2.0 * math.pi
            omega = enc.vel_rev_s * 2.0 * math.pi
            length = theta * r_w
            pos_vel = mav.uav_state() if mav is not None else None
            if pos_vel is None:
                # no UAV position yet: hold the present length
                step = host.controller.update(host.dt_s, length, omega, tension_n, length, 0.0)
                torque = step.torque_n_m
            else:
                torque = host.update(length, omega, tension_n, *pos_vel).torque_n_m
            send(cp.frame_id(node, cp.Cmd.SET_INPUT_TORQUE), cp.encode_set_input_torque(torque))
            torques += 1
            if mav is not None and not math.isnan(length_m):
                mav.winch_status(length_m, speed_m_s, tension_n / g, brake)
    finally:
        link.close()
        if mav is not None:
            mav.close()
    print(f"groundstation: {frames} encoder frames, {torques} torque commands", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
