"""The onboard flight controller: one control step from the vehicle's state to rotor commands.

This is what the companion process runs at its control rate and what the offline runner
runs in-process: the reference (from the mission logic) and the vehicle's state go in, four
normalised rotor commands come out, through the onboard tether model (fed by the winch's
reports), the backstepping position loop, the command-filtered attitude loop, the mixer and
the controller's model of its own motors (docs/control.md).

One step is one compiled call (:func:`flight_step`) through the same kernels the
components run on their own, on their parameters and states: the period's inputs as one
packed record of numbers (:data:`IN_*` indices) and one of flags (:data:`FL_*`), then each
component's public packed view (its ``packed`` record), its arrays updated in place.
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
from tuavdefs.jit import BOOL, Signature, entry_point, njit, vec
from tuavdefs.params import TetherParams, VehicleParams

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


#: :func:`flight_step`'s period inputs (a tuple of floats), by index: the step [s], the
#: vehicle's position [m], velocity [m/s], attitude quaternion (w, x, y, z) and body rates
#: [rad/s], the reference's position, velocity, acceleration and yaw [rad], the winch's
#: paid-out length at the step [m] and its tension [N] (when measured).
(IN_DT, IN_POS, IN_VEL, IN_QUAT, IN_RATES, IN_REF_POS, IN_REF_VEL, IN_REF_ACC, IN_REF_YAW,
 IN_LENGTH, IN_TENSION, N_IN) = (0, 1, 4, 7, 11, 14, 17, 20, 23, 24, 25, 26)
#: :func:`flight_step`'s flags (a tuple of bools), by index: the tension is measured, the
#: tether model is on, the command filter was initialised, the motors are armed.
FL_MEASURED, FL_USE_TETHER, FL_INITIALISED, FL_ARMED, N_FLAGS = range(5)
#: :func:`flight_step`'s (and :func:`flight_commands`') arguments, declared once.
STEP_SIGNATURE = Signature(vec(N_IN), vec(N_FLAGS, BOOL), TetherModel.RECORD,
                           PositionController.RECORD, AttitudeController.RECORD,
                           Mixer.RECORD, ActuatorModel.RECORD)


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
        self._records = self._packed_records()
        # load (or compile) the step's machine code now, not at the first control step (a
        # process with deadlines must not wait for it there), and call it without numba's
        # dispatch: the arguments' types never change
        self._step = entry_point(flight_step, STEP_SIGNATURE)
        self._commands = entry_point(flight_commands, STEP_SIGNATURE)

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
        self._records = self._packed_records()

    def reset(self, state: VehicleState, rotor_speeds_rad_s: tuple[float, ...]) -> None:
        """Start from the vehicle's current attitude and rotor speeds (e.g. hover trim)."""
        self.attitude.reset(quat_to_euler(state.quat))
        self.actuators.reset(rotor_speeds_rad_s)
        self.position.reset()
        self._records = self._packed_records()

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
        return self._commands(*self._arguments(t_s, state, ref, armed))

    def _arguments(self, t_s: float, state: VehicleState, ref: RefSample, armed: bool
                   ) -> tuple[Any, ...]:
        """:func:`flight_step`'s arguments (:data:`STEP_SIGNATURE`) for the step at ``t_s``
        [s]; the command filter counts as initialised from then on."""
        g, winch = self.gains, self.winch
        tension = winch.tension_n if g.use_measured_tension else None
        measured = tension is not None
        f = self.attitude.filter
        inputs = (self.dt_s, *state.pos_m, *state.vel_m_s, *state.quat, *state.rates_rad_s,
                  *ref.pos_m, *ref.vel_m_s, *ref.acc_m_s2, ref.yaw_rad, winch.length_at(t_s),
                  tension if measured else 0.0)
        flags = (measured, g.use_tether_model, f.initialised, bool(armed))
        f.initialised = True
        return (inputs, flags, *self._records)

    def _packed_records(self) -> tuple[Any, ...]:
        """The components' packed records (:data:`STEP_SIGNATURE` after the flags), taken
        again whenever :meth:`set_gains` or :meth:`reset` may have changed one: the
        components change their parameters through those, and their states in place."""
        return (self.tether_model.packed, self.position.packed, self.attitude.packed,
                self.mixer.packed, self.actuators.packed)


@njit
def flight_step(inputs: tuple[float, ...], flags: tuple[bool, ...],
                tether: tuple[float, float], position: tuple[np.ndarray, np.ndarray],
                attitude: tuple[np.ndarray, ...], mixer: tuple[np.ndarray, np.ndarray],
                actuators: tuple[Any, ...]) -> tuple[Any, ...]:
    """:meth:`FlightController.update` on the period's ``inputs`` and ``flags``
    (:data:`IN_*`, :data:`FL_*`) and the components' packed records (their arrays updated
    in place): the onboard tether model, the modelled rotors' wrench, the position loop,
    the attitude loop, the mixer and the motor model's step. Returns (commands, mixer
    saturated, position_law's and attitude_law's results, tether force)."""
    dt_s = inputs[IN_DT]
    pos = (inputs[IN_POS], inputs[IN_POS + 1], inputs[IN_POS + 2])
    vel = (inputs[IN_VEL], inputs[IN_VEL + 1], inputs[IN_VEL + 2])
    q = (inputs[IN_QUAT], inputs[IN_QUAT + 1], inputs[IN_QUAT + 2], inputs[IN_QUAT + 3])
    rates = (inputs[IN_RATES], inputs[IN_RATES + 1], inputs[IN_RATES + 2])
    ref_pos = (inputs[IN_REF_POS], inputs[IN_REF_POS + 1], inputs[IN_REF_POS + 2])
    ref_vel = (inputs[IN_REF_VEL], inputs[IN_REF_VEL + 1], inputs[IN_REF_VEL + 2])
    ref_acc = (inputs[IN_REF_ACC], inputs[IN_REF_ACC + 1], inputs[IN_REF_ACC + 2])
    kf, decay, speed_min, speed_max = actuators[0]
    alloc, speeds, setpoints = actuators[1], actuators[2], actuators[3]
    rotation = quat_to_matrix_kernel(q)
    ftx, fty, ftz = 0.0, 0.0, 0.0
    if flags[FL_USE_TETHER]:
        ftx, fty, ftz, _, _, _ = estimate_kernel(tether[0], tether[1], pos[0], pos[1],
                                                 pos[2], inputs[IN_LENGTH],
                                                 flags[FL_MEASURED], inputs[IN_TENSION])
    u_ach, ta0, ta1, ta2 = wrench_kernel(alloc, kf, speeds)
    po = position_law(position, dt_s, pos, vel, ref_pos, ref_vel, ref_acc,
                      inputs[IN_REF_YAW], rotation, (ftx, fty, ftz), True, u_ach)
    ao = attitude_law(attitude, quat_to_euler_kernel(q), rates, po[1],
                      flags[FL_INITIALISED], True, (ta0, ta1, ta2))
    tx, ty, tz = ao[0]
    c0, c1, c2, c3, saturated = mix_kernel(mixer[0], mixer[1], po[0], tx, ty, tz)
    rotor_speed_setpoints(setpoints, c0, c1, c2, c3, flags[FL_ARMED], speed_min, speed_max)
    advance_kernel(speeds, setpoints, decay)
    return (c0, c1, c2, c3), saturated, po, ao, (ftx, fty, ftz)


@njit
def flight_commands(inputs: tuple[float, ...], flags: tuple[bool, ...],
                    tether: tuple[float, float], position: tuple[np.ndarray, np.ndarray],
                    attitude: tuple[np.ndarray, ...], mixer: tuple[np.ndarray, np.ndarray],
                    actuators: tuple[Any, ...]) -> tuple[float, float, float, float]:
    """:func:`flight_step` (the same updates in place) returning only the rotor commands:
    no diagnostics to hand back to Python."""
    return flight_step(inputs, flags, tether, position, attitude, mixer, actuators)[0]
