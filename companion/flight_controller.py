"""The onboard flight controller: one control step from the vehicle's state to rotor commands.

This is what the companion process runs at its control rate and what the offline runner
runs in-process: the reference (from the mission logic) and the vehicle's state go in, four
normalised rotor commands come out, through the onboard tether model (fed by the winch's
reports), the backstepping position loop, the command-filtered attitude loop, the mixer and
the controller's model of its own motors (docs/control.md).

One step is one compiled call (:func:`flight_step`) through the same kernels the
components run on their own, on their parameters and states.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from companion.actuators import ActuatorModel, advance_kernel, wrench_kernel
from companion.attitude import AttitudeController, AttitudeOutput, attitude_law
from companion.gains import FlightControlParams
from companion.position import PositionController, PositionOutput, position_law
from companion.reference import RefSample
from companion.tether_model import TetherModel, WinchReport, estimate_kernel
from tuavdefs.airframe import Mixer, mix_kernel, rotor_speed_setpoints
from tuavdefs.frames import Quat, Vec3, quat_to_euler, quat_to_euler_kernel, quat_to_matrix_kernel
from tuavdefs.jit import entry_point, njit
from tuavdefs.params import TetherParams, VehicleParams

_ZERO3 = (0.0, 0.0, 0.0)
#: Records built as the tuples they are (tuple.__new__), without their Python-level
#: constructors: the step's results, every control period
_new = tuple.__new__


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
        # load (or compile) the step's machine code now, not at the first control step (a
        # process with deadlines must not wait for it there), and call it without numba's
        # dispatch: the arguments' types never change
        at = (0.0, 0.0, 10.0)
        example = (self.dt_s, *at, *_ZERO3, 1.0, 0.0, 0.0, 0.0, *_ZERO3, *at, *_ZERO3,
                   *_ZERO3, 0.0, 12.0, True, 1.0, True, False, True, *self._components())
        self._step = entry_point(flight_step, *example)
        self._commands = entry_point(flight_commands, example)

    def set_gains(self, gains: FlightControlParams) -> None:
        """Fly with ``gains`` from the next step on (a ground station changed a parameter),
        keeping every internal state: the disturbance estimate, the compensation signals,
        the command filter and the motor model. The control rate is that of the running
        loop: ``gains.rate_hz`` must equal it (ValueError otherwise, nothing changed)."""
        if gains.rate_hz != self.gains.rate_hz:
            raise ValueError(f"rate_hz: the control loop runs at {self.gains.rate_hz} Hz; "
                             f"it cannot change to {gains.rate_hz} Hz while running")
        self.gains = gains
        self.position.set_gains(gains)
        self.attitude.set_gains(gains)

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
        commands, saturated, p, a, tether_force = self._step(*self._arguments(
            t_s, state, ref, armed))
        return _new(FlightStep, (commands, saturated, _new(PositionOutput, p),
                                 _new(AttitudeOutput, a), tether_force))

    def commands(self, t_s: float, state: VehicleState, ref: RefSample,
                 armed: bool = True) -> tuple[float, float, float, float]:
        """The rotor commands of :meth:`update` (the same step, the same states after
        it) without its diagnostics, which the control loop does not need."""
        return self._commands(self._arguments(t_s, state, ref, armed))

    def _arguments(self, t_s: float, state: VehicleState, ref: RefSample, armed: bool
                   ) -> tuple[Any, ...]:
        """:func:`flight_step`'s arguments for the step at ``t_s`` [s]; the command
        filter counts as initialised from then on."""
        g, winch = self.gains, self.winch
        tension = winch.tension_n if g.use_measured_tension else None
        measured = tension is not None
        f = self.attitude.filter
        args = (self.dt_s, *state.pos_m, *state.vel_m_s, *state.quat, *state.rates_rad_s,
                *ref.pos_m, *ref.vel_m_s, *ref.acc_m_s2, ref.yaw_rad, winch.length_at(t_s),
                measured, tension if measured else 0.0, g.use_tether_model, f.initialised,
                bool(armed), *self._components())
        f.initialised = True
        return args

    def _components(self) -> tuple[Any, ...]:
        """What :func:`flight_step` takes from the components: their scalar parameters,
        then their packed parameters and states (arrays, updated in place)."""
        tm, pc, ac, mx, act = (self.tether_model, self.position, self.attitude, self.mixer,
                               self.actuators)
        f, v = ac.filter, act.vehicle
        return (tm.w, tm.taut_stiffness_n, v.rotor_thrust_coeff, act._decay,
                v.rotor_speed_min_rad_s, v.rotor_speed_max_rad_s, pc.params(), pc._state,
                ac.params(), f.coeffs, f.state, ac.xi_eta, ac.xi_w, ac.tau_hat, mx._inv,
                mx.params(),
                act._a, act.speeds, act._setpoints)


@njit
def flight_step(dt_s: float, px: float, py: float, pz: float, vx: float, vy: float,
                vz: float, qw: float, qx: float, qy: float, qz: float, wx: float, wy: float,
                wz: float, rpx: float, rpy: float, rpz: float, rvx: float, rvy: float,
                rvz: float, rax: float, ray: float, raz: float, ref_yaw: float,
                length_m: float, measured: bool, tension_n: float, use_tether: bool,
                initialised: bool, armed: bool, w_n_m: float, taut_stiffness_n: float,
                kf: float, decay: float, speed_min: float, speed_max: float,
                pos_p: np.ndarray, pos_s: np.ndarray, att_p: np.ndarray,
                filt_c: np.ndarray, filt_s: np.ndarray, xi_eta: np.ndarray,
                xi_w: np.ndarray, tau_hat: np.ndarray, mix_inv: np.ndarray, mix_p: np.ndarray,
                alloc: np.ndarray, speeds: np.ndarray, setpoints: np.ndarray
                ) -> tuple[Any, ...]:
    """:meth:`FlightController.update` in scalars, on the components' packed parameters
    and states (updated in place): the onboard tether model, the modelled rotors' wrench,
    the position loop, the attitude loop, the mixer and the motor model's step. Returns
    (commands, mixer saturated, position_law's and attitude_law's results, tether force)."""
    q = (qw, qx, qy, qz)
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = quat_to_matrix_kernel(q)
    ftx, fty, ftz = 0.0, 0.0, 0.0
    if use_tether:
        ftx, fty, ftz, _, _, _ = estimate_kernel(w_n_m, taut_stiffness_n, px, py, pz,
                                                 length_m, measured, tension_n)
    u_ach, ta0, ta1, ta2 = wrench_kernel(alloc, kf, speeds)
    po = position_law(pos_p, pos_s, dt_s, px, py, pz, vx, vy, vz, rpx, rpy, rpz, rvx, rvy,
                      rvz, rax, ray, raz, ref_yaw, r00, r01, r02, r10, r11, r12, r20, r21,
                      r22, ftx, fty, ftz, True, u_ach)
    roll, pitch, yaw = quat_to_euler_kernel(q)
    des_roll, des_pitch, des_yaw = po[1]
    ao = attitude_law(att_p, filt_c, filt_s, xi_eta, xi_w, tau_hat, roll, pitch, yaw, wx,
                      wy, wz, des_roll, des_pitch, des_yaw, initialised, True, ta0, ta1, ta2)
    tx, ty, tz = ao[0]
    c0, c1, c2, c3, saturated = mix_kernel(mix_inv, mix_p, po[0], tx, ty, tz)
    rotor_speed_setpoints(setpoints, c0, c1, c2, c3, armed, speed_min, speed_max)
    advance_kernel(speeds, setpoints, decay)
    return (c0, c1, c2, c3), saturated, po, ao, (ftx, fty, ftz)


@njit
def flight_commands(args: tuple[Any, ...]) -> tuple[float, float, float, float]:
    """``flight_step(*args)`` (the same updates in place) returning only the rotor
    commands: no diagnostics to hand back to Python."""
    return flight_step(*args)[0]
