"""The plant: the truth model of the UAV, the tether, the winder and the wind, integrated.

State vector ``x`` (19 floats, SI units, inertial frame z-up with origin at the winder exit,
x east, y north; body frame x forward, y left, z up):

====== ======================= =======================================================
index  symbol                  meaning
====== ======================= =======================================================
0..2   p                       UAV centre of mass [m]
3..5   v                       UAV velocity [m/s]
6..9   q = (w, x, y, z)        attitude, body -> inertial unit quaternion
10..12 omega                   body rates [rad/s]
13..16 Omega_1..4              rotor speeds [rad/s] (rotor order of tuavdefs.airframe)
17     theta                   drum angle [rad]; paid-out length L = r_w * theta
18     omega_d                 drum rate [rad/s], positive paying out
====== ======================= =======================================================

Equations (derived in docs/model.md):

    m dv/dt       = sum_i T_i * R e3 - m g e3 + F_tether + F_drag + F_ground
    dq/dt         = q * (0, omega) / 2
    J domega/dt   = tau_rotors - c_w omega - omega x J omega
    dOmega_i/dt   = (Omega_cmd_i - Omega_i) / tau_m
    I_w domega_d/dt = tau_motor + r_w T_drum - beta_w omega_d (+ brake, stops)

``rhs`` is the pure state derivative and :func:`sitl.kernel.rk4_kernel` the fixed-step
integrator (both compiled, in ``sitl/kernel.py``); :class:`Plant` couples them with the
wind, the constraint projections (ground, brake, drum stops, quaternion norm) and
convenient read-outs.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from typing import Any, NamedTuple

import numpy as np

from sitl._jit import njit
from sitl.catenary import CatenaryInfo, CatenaryRegime
from sitl.kernel import (
    GROUND_EPS_M,
    N_WARM,
    P_CONTACT_X,
    P_CONTACT_Y,
    P_CONTACT_Z,
    P_GEAR,
    P_LUMPED,
    P_RW,
    P_THETA_MAX,
    P_THETA_MIN,
    STICK_SPEED_M_S,
    W_DRUM,
    W_EX,
    W_EY,
    W_EZ,
    W_FX,
    W_FY,
    W_FZ,
    W_GROUNDED,
    W_LOWEST,
    attachment_point,
    coupled_rhs_into,
    coupled_rk4_into,
    drum_projection,
    max_line_nodes,
    pack_line_params,
    pack_params,
    rhs_into,
    rhs_kernel,
    rk4_into,
    tether_pull,
)
from sitl.lumped import (
    L_HMAX,
    L_LS,
    lay_line,
    line_energy_j,
    line_state_size,
    line_wind,
    manage_nodes,
    relax,
    substeps,
)
from sitl.tether import Tether, TetherForces, _new, tether_forces_kernel
from sitl.wind import WindModel, wind_kernel
from sitl.winder import WinderModel
from tuavdefs.airframe import command_to_rotor_speed, rotor_speed_setpoints
from tuavdefs.frames import euler_to_quat, quat_rotate, quat_to_euler
from tuavdefs.jit import BOOL, F64, I64, Signature, array, entry_point, record
from tuavdefs.params import SystemParams, TetherModel, WindParams
from tuavdefs.paramspec import ParameterError

N_STATES = 19
#: The most RK4 sub-steps a plant step may take on the lumped line (it is 1 on the paper's
#: line at 1 kHz); a line needing more is refused when the plant is built.
MAX_LUMPED_SUBSTEPS = 64

#: Time constant of the critically damped fade of the lumped line's exit allowance
#: (:func:`sitl.lumped.manage_nodes`) [s].
ALLOWANCE_TAU_S = 0.1
#: The rotors' gains when every rotor gives all of its command (:attr:`Plant.rotor_gains`).
_FULL_GAINS = (1.0, 1.0, 1.0, 1.0)
POS, VEL, QUAT, RATES, ROTORS, DRUM_ANGLE, DRUM_RATE = (
    slice(0, 3), slice(3, 6), slice(6, 10), slice(10, 13), slice(13, 17), 17, 18)


@njit
def _rk4_step(x: np.ndarray, scratch: np.ndarray, dt: float, p: np.ndarray,
              setpoints: np.ndarray, winder_cmd_n_m: float, winder_enabled: bool,
              wind: np.ndarray, warm: np.ndarray) -> float:
    """:func:`sitl.kernel.rk4_kernel` on ``x`` in place (``scratch``: (6, 19) floats), then
    the quaternion scaled to unit norm; returns the drum rate before the step."""
    omega_before = x[DRUM_RATE]
    out = scratch[5]
    rk4_into(out, scratch, x, dt, p, setpoints, winder_cmd_n_m, winder_enabled, wind, warm)
    n = math.sqrt(out[6] * out[6] + out[7] * out[7] + out[8] * out[8] + out[9] * out[9])
    for i in range(6, 10):
        out[i] = out[i] / n
    for i in range(N_STATES):
        x[i] = out[i]
    return omega_before


#: What :func:`advance_kernel` stopped at: all steps done; a step that ended at or below
#: the gear's height (integrated and normalised, its ground contact, drum projection and
#: time left to the caller); the wind's noise block used up (that step not begun).
ADVANCE_DONE, ADVANCE_GROUND, ADVANCE_NOISE = 0, 1, 2


#: :func:`advance_kernel`'s inputs, held over its steps: the four rotor commands in
#: [0, 1], armed, the winder motor's torque request [N m] and whether it is enabled.
INPUTS_RECORD = record(F64, F64, F64, F64, BOOL, F64, BOOL)
#: :func:`advance_kernel`'s stepping: the step [s], the lumped line's RK4 sub-steps a
#: step, the rotors' least and greatest speed [rad/s].
STEPPING_RECORD = record(F64, I64, F64, F64)
#: :func:`advance_kernel`'s air: the wind at the UAV (and the part the same at every
#: height), whether it varies, and the wind model's packed state.
AIR_RECORD = record(array(), BOOL, WindModel.RECORD)


@njit
def advance_kernel(x: np.ndarray, t_s: float, n: int, inputs: tuple, stepping: tuple,
                   model: tuple, air: tuple) -> tuple[int, int, float, float]:
    """Up to ``n`` plant steps from time ``t_s`` [s] with the ``inputs`` held
    (:data:`INPUTS_RECORD`), ``x`` updated in place; ``stepping`` (:data:`STEPPING_RECORD`)
    gives the step ``dt`` [s], ``model`` is :attr:`PlantModel.packed` (updated in place),
    ``air`` :data:`AIR_RECORD`. The rotor commands ``c0..c3`` in [0, 1] (and ``armed``)
    set the rotors' speed set-points (:func:`tuavdefs.airframe.rotor_speed_setpoints` for
    the speed range [``speed_min``, ``speed_max``] [rad/s], into ``setpoints``); each step
    samples the wind (when it varies: :func:`sitl.wind.wind_kernel` on the model's packed
    state, into ``wind``), takes :func:`_rk4_step`, then projects the drum's angle and rate
    (brake, hard stops: :meth:`sitl.winder.WinderModel.project`). With the lumped line
    (``p[P_LUMPED]``), each step is ``n_sub`` coupled RK4 sub-steps of the UAV and
    ``line`` (:func:`_lumped_step`) and the line's pull at the state reached is left in
    ``warm``. Returns (steps completed, why it stopped (``ADVANCE_*``), the time after
    them [s], the drum rate before a step that ended on the ground [rad/s])."""
    c0, c1, c2, c3, armed, winder_cmd_n_m, winder_enabled = inputs
    dt, n_sub, speed_min, speed_max = stepping
    p, lp, warm, line, line_scratch, node_wind, setpoints = model
    wind, wind_varies, wind_model = air
    wind_p, gusts, wind_s, noise, noise_next = wind_model
    rotor_speed_setpoints(setpoints, c0, c1, c2, c3, armed, speed_min, speed_max)
    scratch = np.empty((6, N_STATES))
    braked = not winder_enabled
    ground = p[P_GEAR] + GROUND_EPS_M
    lumped = p[P_LUMPED] != 0.0
    for i in range(n):
        if wind_varies and not wind_kernel(wind_p, gusts, wind_s, noise, noise_next, t_s,
                                           x[2], x[3], x[4], x[5], wind):
            if lumped:
                _line_forces(x, line, p, lp, setpoints, winder_cmd_n_m, winder_enabled, wind,
                             node_wind, warm, scratch, line_scratch)
            return i, ADVANCE_NOISE, t_s, 0.0
        if lumped:
            omega_before = _lumped_step(x, line, scratch, line_scratch, dt, n_sub, p, lp,
                                        setpoints, winder_cmd_n_m, winder_enabled, wind,
                                        node_wind, warm, wind_p)
        else:
            omega_before = _rk4_step(x, scratch, dt, p, setpoints, winder_cmd_n_m,
                                     winder_enabled, wind, warm)
        if x[2] <= ground:
            if lumped:
                _line_forces(x, line, p, lp, setpoints, winder_cmd_n_m, winder_enabled, wind,
                             node_wind, warm, scratch, line_scratch)
            return i, ADVANCE_GROUND, t_s, omega_before
        x[DRUM_ANGLE], x[DRUM_RATE] = drum_projection(p, x[DRUM_ANGLE], x[DRUM_RATE],
                                                      omega_before, braked)
        t_s += dt
    if lumped:
        _line_forces(x, line, p, lp, setpoints, winder_cmd_n_m, winder_enabled, wind,
                     node_wind, warm, scratch, line_scratch)
    return n, ADVANCE_DONE, t_s, 0.0


@njit
def _normalise_quaternion(x: np.ndarray) -> None:
    n = math.sqrt(x[6] * x[6] + x[7] * x[7] + x[8] * x[8] + x[9] * x[9])
    for i in range(6, 10):
        x[i] = x[i] / n


@njit
def _lumped_step(x: np.ndarray, line: np.ndarray, scratch: np.ndarray,
                 line_scratch: np.ndarray, dt: float, n_sub: int, p: np.ndarray,
                 lp: np.ndarray, setpoints: np.ndarray, winder_cmd_n_m: float,
                 winder_enabled: bool, wind: np.ndarray, node_wind: np.ndarray,
                 warm: np.ndarray, wind_p: np.ndarray) -> float:
    """One plant step of ``dt`` [s] with the lumped line: the air at the nodes sampled once,
    ``n_sub`` coupled RK4 sub-steps (quaternion normalised and drum projected after each but
    the last, whose projection the caller makes), then nodes added or removed at the exit.
    Returns the drum rate before the last sub-step [rad/s]."""
    line_wind(line, wind_p, wind, node_wind)
    h = dt / n_sub
    braked = not winder_enabled
    omega_before = x[DRUM_RATE]
    for s in range(n_sub):
        omega_before = x[DRUM_RATE]
        coupled_rk4_into(x, line, scratch, line_scratch, h, p, lp, setpoints, winder_cmd_n_m,
                         winder_enabled, wind, node_wind, warm)
        _normalise_quaternion(x)
        if s < n_sub - 1:
            x[DRUM_ANGLE], x[DRUM_RATE] = drum_projection(p, x[DRUM_ANGLE], x[DRUM_RATE],
                                                          omega_before, braked)
    top = scratch[0, :6]
    top[0], top[1], top[2], top[3], top[4], top[5] = attachment_point(x, p)
    manage_nodes(line, lp, p[P_RW] * x[DRUM_ANGLE], p[P_RW] * x[DRUM_RATE],
                 math.exp(-dt / ALLOWANCE_TAU_S), top)
    return omega_before


@njit
def _line_forces(x: np.ndarray, line: np.ndarray, p: np.ndarray, lp: np.ndarray,
                 setpoints: np.ndarray, winder_cmd_n_m: float, winder_enabled: bool,
                 wind: np.ndarray, node_wind: np.ndarray, warm: np.ndarray,
                 scratch: np.ndarray, line_scratch: np.ndarray) -> None:
    """The lumped line's pull at the state ``x``, ``line`` into ``warm``, with its lowest
    node's height and the number of nodes on the ground."""
    coupled_rhs_into(scratch[0], line_scratch[0], x, line, p, lp, setpoints, winder_cmd_n_m,
                     winder_enabled, wind, node_wind, warm)
    n = int(line[0])
    lowest = 0.0
    grounded = 0
    for k in range(n):
        z = line[3 + 6 * k]
        if k == 0 or z < lowest:
            lowest = z
        if z <= 0.0:
            grounded += 1
    warm[W_LOWEST] = lowest
    warm[W_GROUNDED] = grounded


@njit
def _truth_kernel(x: np.ndarray, p: np.ndarray, ea_n: float, w_n_per_m: float, hf0: float,
                  vf0: float) -> tuple:
    """:func:`sitl.tether.tether_forces_kernel` at the state ``x`` (the paid-out length
    from its drum angle, as :attr:`Plant.tether_length_m`); its last field (converged)
    is False also for a state the tether cannot take (non-finite, below the exit)."""
    px, py, pz, _, _, _ = attachment_point(x, p)
    length = p[P_RW] * x[DRUM_ANGLE]
    if not (-math.inf < px < math.inf and -math.inf < py < math.inf
            and 0.0 <= pz < math.inf and 0.0 < length < math.inf):
        return (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0, 0, 0.0,
                False, False)
    return tether_forces_kernel(px, py, pz, length, ea_n, w_n_per_m, hf0, vf0)


quat_rotate_kernel = njit(quat_rotate)


@njit
def specific_force_kernel(x: np.ndarray, p: np.ndarray, wind_e: float, wind_n: float,
                           wind_u: float, warm: np.ndarray, g: float
                           ) -> tuple[float, float, float]:
    """What an ideal accelerometer at the centre of mass reads at the state ``x`` [m/s^2],
    body FLU: ``R^T (a + g e3)`` (:func:`sitl.sensors.specific_force_flu`) with the
    acceleration ``a`` of the state derivative (:func:`rhs`: rotor set-points at the
    rotors' speeds, winder unpowered, the wind (east, north, up) [m/s]) plus the ground's
    impact over the IMU's sample, ``p[P_CONTACT_X:P_CONTACT_Z + 1]`` [m/s^2]
    (:meth:`Plant.take_contact_impulse`); the tether solver's warm start ``warm`` is
    restored."""
    wind = np.empty(3)
    wind[0], wind[1], wind[2] = wind_e, wind_n, wind_u
    dx = np.empty(N_STATES)
    h, v = warm[0], warm[1]
    rhs_into(dx, x, p, x[13:17], 0.0, False, wind, warm)
    warm[0], warm[1] = h, v
    return quat_rotate_kernel((x[6], -x[7], -x[8], -x[9]),
                              (dx[3] + p[P_CONTACT_X], dx[4] + p[P_CONTACT_Y],
                               dx[5] + g + p[P_CONTACT_Z]))


#: :func:`_truth_kernel`'s and :func:`specific_force_kernel`'s arguments.
TRUTH_SIGNATURE = Signature(array(), array(), F64, F64, F64, F64)
SPECIFIC_FORCE_SIGNATURE = Signature(array(), array(), F64, F64, F64, array(), F64)


class PlantInputs(NamedTuple):
    """Everything the actuators are told during one step.

    ``rotor_commands`` are the normalised commands in [0, 1] of tuavdefs.airframe;
    ``winder_torque_n_m`` is the motor torque request (positive pays out);
    ``winder_enabled`` powers the motor and releases the brake.
    """

    rotor_commands: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    armed: bool = False
    winder_torque_n_m: float = 0.0
    winder_enabled: bool = False


class PlantModel:
    """Parameters digested for the state derivative, plus the tether solver (warm start) and
    the lumped line's state (``line``, used when ``lumped``)."""

    #: The type of :attr:`packed` (:class:`tuavdefs.jit.Signature` texts).
    RECORD = record(array(), array(), array(), array(), array(2), array(2), array())

    def __init__(self, params: SystemParams) -> None:
        self.params = params
        v, env = params.vehicle, params.environment
        self.g = env.gravity_m_s2
        self.m = v.mass_kg
        self.ixx, self.iyy, self.izz = v.inertia_diag
        self.kf = v.rotor_thrust_coeff
        self.km = v.rotor_torque_coeff
        self.d = v.arm_length_m / math.sqrt(2.0)
        self.tau_m = v.motor_time_constant_s
        self.drag = v.drag_coeff_n_s_m
        self.rot_damp = v.rotational_damping_n_m_s_rad
        self.gear = v.gear_height_m
        self.mu = v.ground_friction_coeff
        self.tether = Tether(params.tether, self.g)
        self.winder = WinderModel(params.winder, params.tether)
        self.p = pack_params(params)
        # the kernel's tether array: the catenary's warm start (H, V), the lumped line's pull
        self.warm = np.zeros(N_WARM)
        self.lumped = params.tether.kind == TetherModel.LUMPED
        self.lp = pack_line_params(params)
        n_max = max_line_nodes(params)
        self.line = np.zeros(line_state_size(n_max))
        self.line_scratch = np.zeros((5, line_state_size(n_max)))
        self.node_wind = np.zeros((n_max, 3))
        #: the rotors' speed set-points [rad/s] the kernels hold over a step
        self.setpoints = np.zeros(4)

    @property
    def packed(self) -> tuple[np.ndarray, ...]:
        """The model for the compiled steps (:attr:`RECORD`, every array updated in
        place): the packed parameters, the lumped line's parameters, the tether's
        auxiliary array (``warm``), the line's state and its RK4 stages, the air at its
        nodes, the rotors' speed set-points."""
        return (self.p, self.lp, self.warm, self.line, self.line_scratch, self.node_wind,
                self.setpoints)

    def rotor_setpoints(self, u: PlantInputs) -> tuple[float, ...]:
        """Rotor-speed set-points [rad/s] for the commands in ``u``."""
        veh = self.params.vehicle
        return tuple(command_to_rotor_speed(c, veh, u.armed) for c in u.rotor_commands)


def rhs(t: float, x: Sequence[float], u: PlantInputs, model: PlantModel,
        wind_m_s: Sequence[float] = (0.0, 0.0, 0.0),
        rotor_setpoints: Sequence[float] | None = None) -> np.ndarray:
    """dx/dt of the whole plant at time ``t`` [s] for state ``x`` and inputs ``u``.

    ``wind_m_s`` is the air velocity at the UAV (held over a step). With the lumped line,
    its pull is the one the model holds for the plant's current state. ``rotor_setpoints``
    may pass the rotor-speed set-points precomputed from ``u``. The equations live in the
    compiled kernel (:func:`sitl.kernel.rhs_kernel`); the time does not enter them (the
    plant is autonomous given its inputs). Pure apart from the tether solver's warm start,
    which changes only how fast it converges.
    """
    sp = model.rotor_setpoints(u) if rotor_setpoints is None else rotor_setpoints
    return rhs_kernel(np.asarray(x, dtype=float), model.p, np.asarray(sp, dtype=float),
                      float(u.winder_torque_n_m), bool(u.winder_enabled),
                      np.asarray(wind_m_s[:3], dtype=float), model.warm)


def initial_state(model: PlantModel, position_m: Sequence[float] | None = None,
                  velocity_m_s: Sequence[float] = (0.0, 0.0, 0.0),
                  euler_rad: Sequence[float] = (0.0, 0.0, 0.0),
                  tether_length_m: float | None = None,
                  rotor_speed_rad_s: float = 0.0, drum_rate_rad_s: float = 0.0) -> np.ndarray:
    """A state vector. By default the UAV rests on its gear 2 m east of the winder, level,
    rotors stopped, with 5 % more tether out than the straight-line distance."""
    if position_m is None:
        position_m = (2.0, 0.0, model.gear)
    if tether_length_m is None:
        tether_length_m = 1.05 * math.dist(position_m, (0.0, 0.0, 0.0))
    x = np.zeros(N_STATES)
    x[POS] = position_m
    x[VEL] = velocity_m_s
    x[QUAT] = euler_to_quat(*euler_rad)
    x[ROTORS] = rotor_speed_rad_s
    x[DRUM_ANGLE] = model.winder.theta_rad(tether_length_m)
    x[DRUM_RATE] = drum_rate_rad_s
    return x


#: :func:`advance_kernel`'s arguments.
ADVANCE_SIGNATURE = Signature(array(), F64, I64, INPUTS_RECORD, STEPPING_RECORD,
                              PlantModel.RECORD, AIR_RECORD)


class Plant:
    """The integrated truth model, stepped at a fixed rate.

    ``step(u)`` samples the wind once, takes one RK4 step of ``dt_s`` with the inputs and
    wind held, then applies the constraints (quaternion norm, ground, brake, drum stops).
    Deterministic for given parameters (including the wind seed) and inputs.
    """

    def __init__(self, params: SystemParams | None = None, dt_s: float = 0.001,
                 state: np.ndarray | None = None, t_s: float = 0.0) -> None:
        self.params = params or SystemParams()
        self.model = PlantModel(self.params)
        self.dt_s = dt_s
        self.wind = WindModel(self.params.wind, dt_s)
        self.t_s = t_s
        self.x = initial_state(self.model) if state is None else np.array(state, float)
        #: the state array :meth:`advance_held` owns and advances in place (a state set
        #: from outside is copied into a new one first)
        self._owned: np.ndarray | None = None
        if self.x.shape != (N_STATES,) or not np.all(np.isfinite(self.x)):
            raise ValueError(f"state must be {N_STATES} finite floats")
        self.wind_m_s: tuple[float, float, float] = tuple(self.params.wind.steady_m_s)
        # what the kernel is handed besides the state: the wind at the UAV, the rotors'
        # speed set-points, the wind model's packed state
        self._wind = np.zeros(6)   # at the UAV, then the part the same at every height
        self._wind[:3] = self.wind_m_s
        #: the kernel's air record (:data:`AIR_RECORD`), made again for a new wind or a new
        #: block of its draws (``kernel_args`` renewed)
        self._air: tuple[Any, ...] = (self._wind, not self.wind.constant,
                                      self.wind.kernel_args)
        self._n_sub = substeps(dt_s, self.model.lp)
        if self.model.lumped and self._n_sub > MAX_LUMPED_SUBSTEPS:
            # (an extremely light or stiff line: its sub-steps would stall the plant)
            t = self.params.tether
            raise ParameterError(
                "TetherParams.model",
                f"the lumped line ({t.linear_density_kg_m:g} kg/m, EA "
                f"{t.axial_stiffness_n:g} N, {t.segment_length_m:g} m segments) is stable only "
                f"at RK4 steps of {self.model.lp[L_HMAX] * 1e6:.3g} us: {self._n_sub} "
                f"sub-steps a plant step, at most {MAX_LUMPED_SUBSTEPS}; use the "
                "catenary, or a heavier, less stiff or more coarsely segmented line")
        self._segment_m = float(self.model.lp[L_LS])
        veh = self.params.vehicle
        self._stepping = (float(dt_s), int(self._n_sub), veh.rotor_speed_min_rad_s,
                          veh.rotor_speed_max_rad_s)
        #: What each rotor gives of its command (1: all; a failed motor less: sitl.faults).
        self.rotor_gains: tuple[float, float, float, float] = (1.0, 1.0, 1.0, 1.0)
        #: The velocity [m/s] (ENU) the ground has taken from the UAV on touching down since
        #: the IMU last read it (:meth:`take_contact_impulse`).
        self.contact_dv = np.zeros(3)
        #: whether the accelerometer has a contact impulse to take, or its last one to
        #: clear from the model (False: :meth:`take_contact_impulse` has nothing to do)
        self._contact_live = False
        # load (or compile) the kernels' machine code now, not in the first step, and call
        # it without numba's dispatch (the arguments' types never change)
        m = self.model
        self._model_record = m.packed   # (its arrays are the model's for good)
        self._advance = entry_point(advance_kernel, ADVANCE_SIGNATURE)
        self._truth = entry_point(_truth_kernel, TRUTH_SIGNATURE)
        self._specific_force = entry_point(specific_force_kernel, SPECIFIC_FORCE_SIGNATURE)
        if m.lumped:
            self.lay_line()

    def step(self, u: PlantInputs) -> None:
        """Advance the plant by one step of ``dt_s`` with inputs ``u``."""
        self.advance(u, 1)

    def advance(self, u: PlantInputs, n: int) -> None:
        """Advance the plant by ``n`` steps of ``dt_s`` with inputs ``u`` held: the same as
        ``n`` calls of :meth:`step`, to the bit, in one compiled call (the wind sampled at
        every step; the interpreter is back only for a new block of the wind's random
        draws and for ground contact)."""
        self.advance_held(u.rotor_commands, u.armed, u.winder_torque_n_m, u.winder_enabled, n)

    def advance_held(self, rotor_commands: Sequence[float], armed: bool,
                     winder_torque_n_m: float, winder_enabled: bool, n: int) -> None:
        """:meth:`advance` with the fields of its :class:`PlantInputs` given one by one."""
        if n <= 0:
            return
        c0, c1, c2, c3 = rotor_commands
        gains = self.rotor_gains
        if gains != _FULL_GAINS:
            c0, c1, c2, c3 = c0 * gains[0], c1 * gains[1], c2 * gains[2], c3 * gains[3]
        enabled = winder_enabled
        wind = self.wind
        air = self._air
        if air[2] is not wind.kernel_args:   # a new wind, or a new block of its draws
            air = self._air = (self._wind, not wind.constant, wind.kernel_args)
        varies = air[1]
        x = self.x
        if x is not self._owned:
            # a state set from outside: the kernel takes a float64 array of its own (the
            # entry point checks neither dtype nor layout); the plant's own it advances in
            # place
            x = self._owned = np.array(x, dtype=float)
        t = self.t_s
        # (the entry point converts the numbers to the kernel's float and bool)
        inputs = (c0, c1, c2, c3, bool(armed), winder_torque_n_m, bool(enabled))
        while True:
            done, why, t, omega_before = self._advance(
                x, t, n, inputs, self._stepping, self._model_record, air)
            if why == ADVANCE_DONE:
                break
            n -= done
            if why == ADVANCE_NOISE:
                wind.refill()
                air = self._air = (self._wind, varies, wind.kernel_args)
            else:
                # the step ended at or below the gear: ground contact, then the drum
                self._ground(x)
                x[DRUM_ANGLE], x[DRUM_RATE] = self.model.winder.project(
                    float(x[DRUM_ANGLE]), float(x[DRUM_RATE]), omega_before, not enabled)
                t += self.dt_s
                n -= 1
                if not n:
                    break
        self.x = x
        self.t_s = t
        if varies:
            self.wind_m_s = tuple(self._wind[:3].tolist())  # type: ignore[assignment]
        else:  # what sample returns for a constant wind
            self.wind_m_s = wind.steady_m_s

    def set_wind(self, params: WindParams) -> None:
        """From now on the wind of ``params`` (a wind fault, sitl.faults): its model
        started afresh, the state of the plant kept."""
        self.params = replace(self.params, wind=params)
        self.wind = WindModel(params, self.dt_s)
        self.wind_m_s = tuple(params.steady_m_s)  # type: ignore[assignment]
        self._wind[:3] = self.wind_m_s

    def set_snag(self, snagged: bool) -> None:
        """The tether snagged at the winder's exit (a fault, sitl.faults): the drum's hard
        stops close on its angle now, so it turns neither way and the length paid out stays
        as it is; False opens them to the drum's own stops again."""
        m = self.model
        lo, hi = m.winder.theta_min, m.winder.theta_max
        if snagged:
            lo = hi = min(max(float(self.x[DRUM_ANGLE]), lo), hi)
            self.x[DRUM_RATE] = 0.0      # the jam stops the line, and the drum with it
        m.p[P_THETA_MIN], m.p[P_THETA_MAX] = lo, hi
        m.winder.set_stops(lo, hi)

    def take_contact_impulse(self, sample_s: float) -> None:
        """The IMU's sample of ``sample_s`` [s] begins to be read: the velocity the ground
        took from the UAV since the last (the projection of a touchdown, which the state
        derivative does not see) becomes the average acceleration over the sample that the
        accelerometer adds (:func:`specific_force_kernel`), and is forgotten; 0 without."""
        if not self._contact_live:
            return
        p = self.model.p
        dv = self.contact_dv
        k = 1.0 / sample_s if sample_s > 0.0 else 0.0
        p[P_CONTACT_X], p[P_CONTACT_Y], p[P_CONTACT_Z] = dv[0] * k, dv[1] * k, dv[2] * k
        self._contact_live = bool(dv.any())    # (if so, the next sample clears it)
        dv[:] = 0.0

    def _ground(self, x: np.ndarray) -> None:
        """Ground contact after a step that ended at or below the gear's height (the
        velocity it takes away kept for the accelerometer: :attr:`contact_dv`)."""
        v_before = x[3:6].copy()
        self._project_ground(x)
        self.contact_dv += x[3:6] - v_before
        self._contact_live = True

    def _project_ground(self, x: np.ndarray) -> None:
        m = self.model
        x[2] = max(x[2], m.gear)
        if x[5] < 0.0:
            x[5] = 0.0
        fz_up = self._vertical_force_n(x)
        if fz_up <= 0.0 and math.hypot(x[3], x[4]) < STICK_SPEED_M_S:
            # resting on the gear: no creeping below stick speed (the gear levels a tilted
            # vehicle in the dynamics, at rates the gyroscope sees: sitl.kernel)
            x[3] = x[4] = 0.0

    def _vertical_force_n(self, x: np.ndarray) -> float:
        """Net upward force on the UAV from rotors, gravity and tether [N] (no drag)."""
        m = self.model
        o = x[ROTORS]
        thrust = m.kf * float(o @ o)
        qw, qx, qy, _ = x[QUAT]
        r22 = 1 - 2 * (qx * qx + qy * qy)
        if m.lumped:
            pull_z = float(m.warm[W_FZ])
        else:
            bx, by, bz, _, _, _ = attachment_point(x, m.p)
            pull_z = tether_pull(m.p, bx, by, bz, m.winder.length_m(float(x[DRUM_ANGLE])),
                                 m.warm)[2]
        return thrust * r22 + pull_z - m.m * m.g

    # ----- read-outs
    @property
    def position_m(self) -> np.ndarray:
        """UAV centre of mass, inertial z-up frame [m]."""
        return self.x[POS].copy()

    @property
    def velocity_m_s(self) -> np.ndarray:
        """UAV velocity, inertial frame [m/s]."""
        return self.x[VEL].copy()

    @property
    def quaternion(self) -> tuple[float, float, float, float]:
        """Attitude quaternion (w, x, y, z), body FLU -> inertial."""
        return tuple(float(v) for v in self.x[QUAT])  # type: ignore[return-value]

    @property
    def euler_rad(self) -> tuple[float, float, float]:
        """(roll, pitch, yaw) [rad], Z-Y-X, z-up convention."""
        return quat_to_euler(self.quaternion)

    @property
    def body_rates_rad_s(self) -> np.ndarray:
        """Body rates (x forward, y left, z up) [rad/s]."""
        return self.x[RATES].copy()

    @property
    def rotor_speeds_rad_s(self) -> np.ndarray:
        """Rotor speeds, rotors 1..4 [rad/s]."""
        return self.x[ROTORS].copy()

    @property
    def tether_length_m(self) -> float:
        """Paid-out unstretched tether length [m]."""
        return self.model.winder.length_m(float(self.x[DRUM_ANGLE]))

    @property
    def drum_rate_rad_s(self) -> float:
        """Drum rate, positive paying out [rad/s]."""
        return float(self.x[DRUM_RATE])

    def specific_force_flu(self) -> tuple[float, float, float]:
        """What an ideal accelerometer at the UAV's centre of mass reads [m/s^2], body FLU,
        with the wind of the last step: ``specific_force_flu(plant_acceleration_enu(plant),
        ...)`` of :mod:`sitl.sensors` in one compiled call, to the bit
        (``tests/test_fast_paths.py``). Leaves the plant untouched."""
        w = self.wind_m_s
        m = self.model
        return self._specific_force(self.x, m.p, w[0], w[1], w[2], m.warm, m.g)

    def tether_forces(self) -> TetherForces:
        """The tether's forces at the current state (:meth:`sitl.tether.Tether.forces`,
        warm-started from its last solution; for the lumped line, its pull as the last step
        left it, with a :class:`~sitl.catenary.CatenaryInfo` describing the nodes: the
        top's and exit's force components, the line lying on the ground, SUSPENDED or
        TOUCHDOWN, its lowest node)."""
        if self.model.lumped:
            return self._line_forces()
        tether = self.model.tether
        hf0, vf0 = tether.warm_start
        r = self._truth(self.x, self.model.p, tether.ea_n, tether.w_n_per_m, hf0, vf0)
        if not r[-1]:   # an invalid state or no convergence: forces() raises, saying which
            x = self.x
            return tether.forces(float(x[0]), float(x[1]), float(x[2]), self.tether_length_m)
        return tether.accept(r)

    def _line_forces(self) -> TetherForces:
        w = self.model.warm.tolist()
        lowest = w[W_LOWEST]
        on_ground = w[W_GROUNDED] * self._segment_m
        top = (w[W_FX], w[W_FY], w[W_FZ])
        exit_ = (w[W_EX], w[W_EY], w[W_EZ])
        regime = CatenaryRegime.TOUCHDOWN if on_ground > 0.0 else CatenaryRegime.SUSPENDED
        # (the records built as the tuples they are: every control and winder period)
        info = _new(CatenaryInfo, (-math.hypot(top[0], top[1]), -top[2],
                                   math.hypot(exit_[0], exit_[1]), exit_[2], on_ground,
                                   regime, 0, lowest, False))
        return _new(TetherForces, (top, exit_, w[W_DRUM], math.hypot(*top), info))

    def lay_line(self, settle_s: float = 2.0) -> None:
        """The lumped line laid at rest on the catenary from the exit to the attachment
        point, then relaxed towards its own static shape for ``settle_s`` [s] of simulated
        time with the UAV held (velocities damped), and its pull left for the read-outs.
        Call it after setting the state by hand; nothing for the catenary."""
        m = self.model
        if not m.lumped:
            return
        x = self.x
        bx, by, bz, _, _, _ = attachment_point(x, m.p)
        length = self.tether_length_m
        points = m.tether.shape(bx, by, max(bz, 0.0), length, n_points=401)
        lay_line(m.line, m.lp, points, length)
        top = np.array([bx, by, bz, 0.0, 0.0, 0.0])
        steps = round(settle_s / (self.dt_s / self._n_sub))
        line_wind(m.line, self.wind.packed, self._wind, m.node_wind)
        if steps > 0:
            relax(m.line, m.line_scratch, m.lp, self.dt_s / self._n_sub, steps, top, length,
                  m.node_wind, self._wind, 0.995)
        _line_forces(x, m.line, m.p, m.lp, m.setpoints, 0.0, False, self._wind,
                     m.node_wind, m.warm, np.empty((6, N_STATES)), m.line_scratch)

    def line_nodes_m(self) -> np.ndarray:
        """The lumped line's points from the exit to the attachment point, (n + 2, 3) [m]
        (empty for the catenary)."""
        m = self.model
        if not m.lumped:
            return np.zeros((0, 3))
        out = np.empty((int(m.line[0]) + 2, 3))
        self.line_nodes_into(out)
        return out

    def line_nodes_into(self, out: np.ndarray) -> int:
        """:meth:`line_nodes_m` written into the first rows of ``out`` (at least n + 2
        rows of 3, any float dtype: a recorder's preallocated frame), the rest left as they
        are; returns the number of points written (0 for the catenary)."""
        m = self.model
        if not m.lumped:
            return 0
        line = m.line
        n = int(line[0])
        out[0] = 0.0
        out[1:n + 1] = line[1:1 + 6 * n].reshape(n, 6)[::-1, :3]
        out[n + 1] = attachment_point(self.x, m.p)[:3]
        return n + 2

    def line_energy_j(self) -> float:
        """The lumped line's kinetic, gravitational and elastic energy [J] (0 for the
        catenary)."""
        m = self.model
        if not m.lumped:
            return 0.0
        bx, by, bz, _, _, _ = attachment_point(self.x, m.p)
        return float(line_energy_j(m.line, m.lp, bx, by, bz, self.tether_length_m))

    def energy_j(self) -> float:
        """Kinetic plus gravitational energy of the UAV (reference: ground) [J]."""
        m = self.model
        v = self.x[VEL]
        w = self.x[RATES]
        rot = 0.5 * (m.ixx * w[0] ** 2 + m.iyy * w[1] ** 2 + m.izz * w[2] ** 2)
        return 0.5 * m.m * float(v @ v) + rot + m.m * m.g * float(self.x[2])
