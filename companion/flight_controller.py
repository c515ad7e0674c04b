"""The onboard flight controller: one control step from the vehicle's state to rotor commands.

This is what the companion process runs at its control rate and what the offline runner
runs in-process: the reference (from the mission logic) and the vehicle's state go in, four
normalised rotor commands come out, through the onboard tether model (fed by the winch's
reports), the backstepping position loop, the command-filtered attitude loop, the mixer and
the controller's model of its own motors (docs/control.md).
"""

from __future__ import annotations

from typing import NamedTuple

from companion.actuators import ActuatorModel
from companion.attitude import AttitudeController, AttitudeOutput
from companion.gains import FlightControlParams
from companion.position import PositionController, PositionOutput
from companion.tether_model import TetherModel, WinchReport
from companion.trajectory import RefSample
from tuavdefs.airframe import Mixer
from tuavdefs.frames import Quat, Vec3, quat_to_euler, quat_to_matrix
from tuavdefs.params import TetherParams, VehicleParams


class VehicleState(NamedTuple):
    """What the controller knows of the vehicle (inertial z-up frame, body FLU, SI)."""

    pos_m: Vec3
    vel_m_s: Vec3
    quat: Quat                  # body -> inertial, (w, x, y, z)
    rates_rad_s: Vec3           # body rates


class FlightStep(NamedTuple):
    """One control step's output and diagnostics."""

    rotor_commands: tuple[float, float, float, float]
    mixer_saturated: bool
    position: PositionOutput
    attitude: AttitudeOutput
    tether_force_est_n: Vec3


class FlightController:
    """Reference + state -> rotor commands, at ``gains.rate_hz``."""

    def __init__(self, gains: FlightControlParams, vehicle: VehicleParams,
                 tether: TetherParams, gravity_m_s2: float) -> None:
        self.gains = gains
        self.dt_s = 1.0 / gains.rate_hz
        t_idle = 4 * vehicle.rotor_thrust_coeff * vehicle.rotor_speed_min_rad_s ** 2
        self.position = PositionController(gains, vehicle.mass_kg, gravity_m_s2,
                                           vehicle.max_total_thrust_n, t_idle,
                                           vehicle.drag_coeff_n_s_m)
        self.attitude = AttitudeController(gains, vehicle.inertia_diag,
                                           vehicle.rotational_damping_n_m_s_rad, self.dt_s)
        self.actuators = ActuatorModel(vehicle, self.dt_s)
        self.mixer = Mixer(vehicle)
        self.tether_model = TetherModel(tether.weight_per_length_n_m(gravity_m_s2),
                                        tether.axial_stiffness_n)
        self.winch = WinchReport()

    def reset(self, state: VehicleState, rotor_speeds_rad_s: tuple[float, ...]) -> None:
        """Start from the vehicle's current attitude and rotor speeds (e.g. hover trim)."""
        self.attitude.reset(quat_to_euler(state.quat))
        self.actuators.reset(rotor_speeds_rad_s)
        self.position.reset()

    def winch_report(self, t_s: float, length_m: float, speed_m_s: float,
                     tension_n: float | None) -> None:
        """A report of the winch: paid-out length [m], line speed [m/s], drum tension [N]."""
        self.winch.update(t_s, length_m, speed_m_s, tension_n)

    def update(self, t_s: float, state: VehicleState, ref: RefSample,
               armed: bool = True) -> FlightStep:
        """One control step at time ``t_s`` [s]."""
        g = self.gains
        r = quat_to_matrix(state.quat)
        est = self.tether_model.estimate(
            state.pos_m, self.winch.length_at(t_s),
            self.winch.tension_n if g.use_measured_tension else None)
        f_t = est.force_n if g.use_tether_model else (0.0, 0.0, 0.0)
        u_ach, tau_ach = self.actuators.wrench()
        po = self.position.update(self.dt_s, state.pos_m, state.vel_m_s, ref.pos_m,
                                  ref.vel_m_s, ref.acc_m_s2, ref.yaw_rad, r, f_t, u_ach)
        ao = self.attitude.update(quat_to_euler(state.quat), state.rates_rad_s,
                                  po.attitude_rad, tau_ach)
        mix = self.mixer.mix(po.thrust_n, ao.torque_n_m)
        self.actuators.command(mix.commands, armed)
        self.actuators.advance()
        return FlightStep(mix.commands, mix.saturated, po, ao, f_t)
