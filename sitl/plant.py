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

``rhs`` is the pure state derivative; :func:`rk4_step` is the fixed-step integrator;
:class:`Plant` couples them with the wind, the constraint projections (ground, brake,
drum stops, quaternion norm) and convenient read-outs.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import NamedTuple

import numpy as np

from sitl.tether import Tether, TetherForces
from sitl.wind import WindModel
from sitl.winder import WinderModel
from tuavdefs.airframe import ROTOR_LAYOUT, command_to_rotor_speed
from tuavdefs.frames import euler_to_quat, quat_to_euler
from tuavdefs.params import SystemParams

N_STATES = 19
POS, VEL, QUAT, RATES, ROTORS, DRUM_ANGLE, DRUM_RATE = (
    slice(0, 3), slice(3, 6), slice(6, 10), slice(10, 13), slice(13, 17), 17, 18)

#: Heights within this of the gear height count as touching the ground [m].
GROUND_EPS_M = 1e-6
#: Horizontal speeds below this count as stopped for static friction [m/s].
STICK_SPEED_M_S = 1e-3
#: Time constant with which the landing gear kills body rates on the ground [s].
GEAR_RATE_DAMPING_S = 0.02


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
    """Parameters digested for the state derivative, plus the tether solver (warm start)."""

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

    def rotor_setpoints(self, u: PlantInputs) -> tuple[float, ...]:
        """Rotor-speed set-points [rad/s] for the commands in ``u``."""
        veh = self.params.vehicle
        return tuple(command_to_rotor_speed(c, veh, u.armed) for c in u.rotor_commands)


def rhs(t: float, x: Sequence[float], u: PlantInputs, model: PlantModel,
        wind_m_s: Sequence[float] = (0.0, 0.0, 0.0),
        rotor_setpoints: Sequence[float] | None = None) -> list[float]:
    """dx/dt of the whole plant at time ``t`` [s] for state ``x`` and inputs ``u``.

    ``wind_m_s`` is the air velocity at the UAV (held over a step). ``rotor_setpoints``
    may pass the rotor-speed set-points precomputed from ``u`` (they do not change
    within a step). Pure apart from the tether solver's warm start, which changes only
    how fast it converges.
    """
    m = model
    (px, py, pz, vx, vy, vz, qw, qx, qy, qz, wx, wy, wz,
     o1, o2, o3, o4, theta, omega_d) = x
    # --- rotors: thrusts and torques in the body frame
    t1, t2, t3, t4 = m.kf * o1 * o1, m.kf * o2 * o2, m.kf * o3 * o3, m.kf * o4 * o4
    thrust = t1 + t2 + t3 + t4
    ts = (t1, t2, t3, t4)
    tau_x = tau_y = tau_z = 0.0
    ratio = m.km / m.kf
    for (sx, sy, spin), ti in zip(ROTOR_LAYOUT, ts, strict=True):
        tau_x += sy * m.d * ti
        tau_y -= sx * m.d * ti
        tau_z -= spin * ratio * ti
    # --- attitude: rotation matrix body -> inertial
    r00 = 1 - 2 * (qy * qy + qz * qz)
    r01 = 2 * (qx * qy - qw * qz)
    r02 = 2 * (qx * qz + qw * qy)
    r10 = 2 * (qx * qy + qw * qz)
    r11 = 1 - 2 * (qx * qx + qz * qz)
    r12 = 2 * (qy * qz - qw * qx)
    r20 = 2 * (qx * qz - qw * qy)
    r21 = 2 * (qy * qz + qw * qx)
    r22 = 1 - 2 * (qx * qx + qy * qy)
    # --- aerodynamic drag against the air-relative velocity, in body axes
    ax_, ay_, az_ = vx - wind_m_s[0], vy - wind_m_s[1], vz - wind_m_s[2]
    bx = r00 * ax_ + r10 * ay_ + r20 * az_
    by = r01 * ax_ + r11 * ay_ + r21 * az_
    bz = r02 * ax_ + r12 * ay_ + r22 * az_
    dbx, dby, dbz = -m.drag[0] * bx, -m.drag[1] * by, -m.drag[2] * bz
    # --- tether
    length = m.winder.length_m(theta)
    tf = m.tether.forces(px, py, pz, length)
    fu = tf.on_uav_n
    # --- net force, inertial frame
    fx = thrust * r02 + r00 * dbx + r01 * dby + r02 * dbz + fu[0]
    fy = thrust * r12 + r10 * dbx + r11 * dby + r12 * dbz + fu[1]
    fz = thrust * r22 + r20 * dbx + r21 * dby + r22 * dbz + fu[2] - m.m * m.g
    # --- ground contact: a constraint force, and friction on the gear
    landed = pz <= m.gear + GROUND_EPS_M and vz <= 0.0 and fz <= 0.0
    if landed:
        normal = -fz
        fz = 0.0
        fx, fy = _friction(fx, fy, vx, vy, m.mu * normal)
    # --- rotational dynamics
    if landed:
        dwx, dwy = -wx / GEAR_RATE_DAMPING_S, -wy / GEAR_RATE_DAMPING_S
        dwz = -wz / GEAR_RATE_DAMPING_S
    else:
        tx = tau_x - m.rot_damp * wx
        ty = tau_y - m.rot_damp * wy
        tz = tau_z - m.rot_damp * wz
        # J domega = tau - omega x (J omega)
        dwx = (tx - (wy * m.izz * wz - wz * m.iyy * wy)) / m.ixx
        dwy = (ty - (wz * m.ixx * wx - wx * m.izz * wz)) / m.iyy
        dwz = (tz - (wx * m.iyy * wy - wy * m.ixx * wx)) / m.izz
    # --- quaternion kinematics: dq/dt = q * (0, omega) / 2
    dqw = 0.5 * (-qx * wx - qy * wy - qz * wz)
    dqx = 0.5 * (qw * wx + qy * wz - qz * wy)
    dqy = 0.5 * (qw * wy + qz * wx - qx * wz)
    dqz = 0.5 * (qw * wz + qx * wy - qy * wx)
    # --- rotor lag
    sp = rotor_setpoints if rotor_setpoints is not None else m.rotor_setpoints(u)
    inv_tau = 1.0 / m.tau_m
    # --- winder
    wm = m.winder
    tau_motor = wm.motor_torque_n_m(u.winder_torque_n_m, omega_d, u.winder_enabled)
    domega_d = wm.acceleration(theta, omega_d, tau_motor, tf.drum_tension_n,
                               braked=not u.winder_enabled)
    dtheta = omega_d
    if (theta <= wm.theta_min and omega_d < 0.0) or (theta >= wm.theta_max and omega_d > 0.0):
        dtheta = 0.0
    inv_m = 1.0 / m.m
    return [vx, vy, vz, fx * inv_m, fy * inv_m, fz * inv_m,
            dqw, dqx, dqy, dqz, dwx, dwy, dwz,
            (sp[0] - o1) * inv_tau, (sp[1] - o2) * inv_tau,
            (sp[2] - o3) * inv_tau, (sp[3] - o4) * inv_tau,
            dtheta, domega_d]


def _friction(fx: float, fy: float, vx: float, vy: float, limit_n: float
              ) -> tuple[float, float]:
    """Horizontal force left after Coulomb friction of at most ``limit_n`` [N]."""
    speed = math.hypot(vx, vy)
    if speed < STICK_SPEED_M_S:
        f = math.hypot(fx, fy)
        if f <= limit_n:
            return 0.0, 0.0
        k = (f - limit_n) / f
        return fx * k, fy * k
    return fx - limit_n * vx / speed, fy - limit_n * vy / speed


def rk4_step(f: Callable[..., list[float]], t: float, x: np.ndarray, dt: float,
             *args: object) -> np.ndarray:
    """One classical Runge-Kutta step of dx/dt = f(t, x, *args) of size ``dt`` [s]."""
    h2 = 0.5 * dt
    k1 = np.asarray(f(t, x, *args))
    k2 = np.asarray(f(t + h2, x + h2 * k1, *args))
    k3 = np.asarray(f(t + h2, x + h2 * k2, *args))
    k4 = np.asarray(f(t + dt, x + dt * k3, *args))
    return x + (dt / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


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
        if self.x.shape != (N_STATES,) or not np.all(np.isfinite(self.x)):
            raise ValueError(f"state must be {N_STATES} finite floats")
        self.wind_m_s: tuple[float, float, float] = tuple(self.params.wind.steady_m_s)

    def step(self, u: PlantInputs) -> None:
        """Advance the plant by one step of ``dt_s`` with inputs ``u``."""
        x = self.x
        self.wind_m_s = self.wind.sample(self.t_s, float(x[2]), tuple(x[VEL]))
        setpoints = self.model.rotor_setpoints(u)
        omega_before = float(x[DRUM_RATE])
        x = rk4_step(rhs, self.t_s, x, self.dt_s, u, self.model, self.wind_m_s, setpoints)
        self._project(x, omega_before, braked=not u.winder_enabled)
        self.x = x
        self.t_s += self.dt_s

    def _project(self, x: np.ndarray, omega_before: float, braked: bool) -> None:
        q = x[QUAT]
        x[QUAT] = q / math.sqrt(float(q @ q))
        m = self.model
        if x[2] <= m.gear + GROUND_EPS_M:
            x[2] = max(x[2], m.gear)
            if x[5] < 0.0:
                x[5] = 0.0
            fz_up = self._vertical_force_n(x)
            if fz_up <= 0.0:
                # resting on the gear: level, no body rates, no creeping below stick speed
                _, _, yaw = quat_to_euler(tuple(x[QUAT]))
                x[QUAT] = euler_to_quat(0.0, 0.0, yaw)
                x[RATES] = 0.0
                if math.hypot(x[3], x[4]) < STICK_SPEED_M_S:
                    x[3] = x[4] = 0.0
        theta, omega = m.winder.project(float(x[DRUM_ANGLE]), float(x[DRUM_RATE]),
                                        omega_before, braked)
        x[DRUM_ANGLE], x[DRUM_RATE] = theta, omega

    def _vertical_force_n(self, x: np.ndarray) -> float:
        """Net upward force on the UAV from rotors, gravity and tether [N] (no drag)."""
        m = self.model
        o = x[ROTORS]
        thrust = m.kf * float(o @ o)
        qw, qx, qy, _ = x[QUAT]
        r22 = 1 - 2 * (qx * qx + qy * qy)
        tf = m.tether.forces(float(x[0]), float(x[1]), float(x[2]),
                             m.winder.length_m(float(x[DRUM_ANGLE])))
        return thrust * r22 + tf.on_uav_n[2] - m.m * m.g

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

    def tether_forces(self) -> TetherForces:
        """The tether's forces at the current state."""
        x = self.x
        return self.model.tether.forces(float(x[0]), float(x[1]), float(x[2]),
                                        self.tether_length_m)

    def energy_j(self) -> float:
        """Kinetic plus gravitational energy of the UAV (reference: ground) [J]."""
        m = self.model
        v = self.x[VEL]
        w = self.x[RATES]
        rot = 0.5 * (m.ixx * w[0] ** 2 + m.iyy * w[1] ** 2 + m.izz * w[2] ** 2)
        return 0.5 * m.m * float(v @ v) + rot + m.m * m.g * float(self.x[2])
