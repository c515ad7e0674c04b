"""``python -m companion``: the onboard flight computer process.

Connects to the plant's simulator link, and at every control period runs the shared
:class:`companion.flight_controller.FlightController` on the truth state it receives
(HIL_STATE_QUATERNION) and answers with the rotor commands. For now it holds its starting
position or flies to ``--goto``; the ArduCopter-compatible ground-station side comes next
(docs/architecture.md). On its component link (TCP 5762) it sends the UAV's position to the
winch component (the ground-station process) and takes its WINCH_STATUS as the winch's
reports for the onboard tether model; without them the tether's pull is left to the
disturbance estimate.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Sequence
from pathlib import Path

from companion.component_server import ComponentServer
from companion.flight_controller import FlightController, VehicleState
from companion.gains import FlightControlParams
from companion.simlink_client import SimLinkClient
from companion.trajectory import Hold, SequenceBuilder, Trajectory
from tuavdefs import component_link as cl
from tuavdefs import simlink as sl
from tuavdefs.frames import quat_to_euler
from tuavdefs.params import SystemParams
from tuavdefs.paramspec import ParameterError, load_toml


def build_parser() -> argparse.ArgumentParser:
    """Arguments of the companion process."""
    ap = argparse.ArgumentParser(prog="python -m companion", description=__doc__)
    ap.add_argument("--sim", default=f"127.0.0.1:{sl.SIM_PORT_DEFAULT}",
                    help="HOST:PORT of the plant's simulator link")
    ap.add_argument("--home", type=float, nargs=3, default=sl.HOME_DEFAULT,
                    metavar=("LAT", "LON", "ALT"), help="the winder's global position")
    ap.add_argument("--params", default=None, help="system parameters TOML (the vehicle)")
    ap.add_argument("--gains", default=None, help="flight-control gains TOML")
    ap.add_argument("--goto", type=float, nargs=3, default=None, metavar=("X", "Y", "Z"),
                    help="fly here [m] (z-up frame) after 0.5 s, then hold")
    ap.add_argument("--max-speed", type=float, default=2.0, help="[m/s]")
    ap.add_argument("--max-acc", type=float, default=1.5, help="[m/s^2]")
    ap.add_argument("--connect-timeout", type=float, default=30.0, help="[s]")
    ap.add_argument("--component-port", type=int, default=cl.COMPONENT_PORT_DEFAULT,
                    help="TCP port of the component link (0: none)")
    return ap


def main(argv: Sequence[str] | None = None) -> int:
    """Run the companion process; returns the exit code."""
    args = build_parser().parse_args(argv)
    try:
        params = SystemParams() if args.params is None else load_toml(SystemParams,
                                                                       Path(args.params))
        gains = (FlightControlParams() if args.gains is None
                 else load_toml(FlightControlParams, Path(args.gains)))
    except ParameterError as exc:
        print(f"companion: bad parameter: {exc}", file=sys.stderr)
        return 2
    components = ComponentServer(args.component_port) if args.component_port else None
    host, _, port = args.sim.rpartition(":")
    client = SimLinkClient(host, int(port), tuple(args.home))
    client.connect(timeout_s=args.connect_timeout)
    print(f"companion: connected to the plant at {args.sim}"
          + (f", component link on tcp:127.0.0.1:{components.port}" if components else ""),
          flush=True)
    g = params.environment.gravity_m_s2
    flight = FlightController(gains, params.vehicle, params.tether, g)
    veh = params.vehicle
    hover_speed = math.sqrt(veh.mass_kg * g / (4.0 * veh.rotor_thrust_coeff))
    ref: Trajectory | None = None
    steps = 0
    try:
        while True:
            sim = client.receive_state(timeout_s=30.0)
            truth = sim.truth
            if truth is None:
                continue
            state = VehicleState(truth.position_enu_m, truth.velocity_enu_m_s,
                                 truth.quaternion, truth.body_rates_flu_rad_s)
            t = sim.sim_time_s
            if ref is None:
                flight.reset(state, (hover_speed,) * 4)
                yaw = quat_to_euler(state.quat)[2]
                if args.goto is None:
                    ref = Hold(state.pos_m, yaw, t)
                else:
                    b = SequenceBuilder(state.pos_m, t, args.max_speed, args.max_acc, yaw=yaw)
                    ref = b.hold(0.5).goto(tuple(args.goto)).build()
            if components is not None:
                for msg in components.poll():
                    if msg.get_type() == "WINCH_STATUS":
                        flight.winch_report(t, msg.line_length, msg.speed, msg.tension * g)
                components.send_position(t, state.pos_m, state.vel_m_s)
            step = flight.update(t, state, ref.sample(t))
            client.send_actuators(sim.time_usec, step.rotor_commands, armed=True)
            steps += 1
    except ConnectionError:
        pass
    finally:
        client.close()
        if components is not None:
            components.close()
    print(f"companion: link closed after {steps} control periods", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
