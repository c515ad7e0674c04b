"""Backstepping position control: desired acceleration -> one thrust and a desired attitude.

Model the controller uses (inertial z-up frame, derivation in docs/control.md §1):

    m dv/dt = f + F_t - m g e3 - R D R' v + m d,     f = U R e3 (the thrust vector)

with ``F_t`` the tether's pull from :class:`companion.tether_model.TetherModel`, ``D`` the
vehicle's linear drag per body axis (still air), and ``d`` a slowly varying disturbance
acceleration (wind, model error) that is estimated.

Errors and virtual control:  e1 = p - p_r,  alpha1 = v_r - K1 e1,  e2 = v - alpha1.
Compensation signals (command-filtered backstepping), f_a the thrust vector achieved:
                              d(xi1)/dt = -K1 xi1 + xi2
                              d(xi2)/dt = -K2 xi2 + (f_a - f_d) / m
Compensated errors:           e1_bar = e1 - xi1,  e2_bar = e2 - xi2.
Desired thrust vector:        f_d = m (a_r - K1 (v - v_r) - e1_bar - K2 e2 + g e3 - d_hat)
                                    - F_t + R D R' v
Disturbance adaptation:       d(d_hat)/dt = Gamma e2_bar   (projected onto |d_hat| <= d_max)
Lyapunov function:            V = 1/2 |e1_bar|^2 + 1/2 |e2_bar|^2 + 1/2 d_tilde' Gamma^-1 d_tilde
                              dV/dt = -e1_bar' K1 e1_bar - e2_bar' K2 e2_bar <= 0,
whatever the attitude loop, the limits and the motors do to the thrust (that difference
drives xi, which decays once the thrust catches up).

The thrust vector is then limited in tilt and magnitude, split into the collective thrust
U = f_d . (R e3) and the desired attitude whose body z axis is along f_d at the reference
yaw.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np

from companion.gains import FlightControlParams
from tuavdefs.jit import array, njit, record

Vec3 = tuple[float, float, float]

# indices of the packed parameters (PositionController._pack) and state
(P_M, P_G, P_U_MAX, P_U_MIN, P_FZ_MIN, P_TAN_TILT, P_D_MAX, P_K1, P_K2, P_GAM,
 P_DRAG) = (0, 1, 2, 3, 4, 5, 6, 7, 10, 13, 16)
N_PARAMS = 19
S_D_HAT, S_XI1, S_XI2 = 0, 3, 6


class PositionOutput(NamedTuple):
    """What the position loop hands to the attitude loop and the mixer."""

    thrust_n: float
    attitude_rad: Vec3           # desired (roll, pitch, yaw), Z-Y-X, z-up convention
    thrust_vector_n: Vec3        # limited desired thrust vector f_d [N]
    e1_m: Vec3                   # compensated errors e1_bar, e2_bar
    e2_m_s: Vec3
    disturbance_m_s2: Vec3       # current estimate d_hat
    saturated: bool
    lyapunov: float              # 1/2 |e1_bar|^2 + 1/2 |e2_bar|^2
    lyapunov_raw: float          # 1/2 |e1|^2 + 1/2 |e2|^2 (uncompensated errors)


class PositionController:
    """Backstepping position controller with an adaptive disturbance estimate.

    The gains and limits are packed for the compiled law (:func:`position_law`), again
    whenever one of the attributes they come from is replaced.
    """

    #: The type of :attr:`packed` (:class:`tuavdefs.jit.Signature` texts).
    RECORD = record(array(), array())

    def __init__(self, gains: FlightControlParams, mass_kg: float, gravity_m_s2: float,
                 max_total_thrust_n: float, min_total_thrust_n: float = 0.0,
                 drag_coeff_n_s_m: Vec3 = (0.0, 0.0, 0.0)) -> None:
        self.gains = gains
        self.drag = drag_coeff_n_s_m
        self.m = mass_kg
        self.g = gravity_m_s2
        self.max_total_thrust_n = max_total_thrust_n
        self.u_max = gains.max_thrust_fraction * max_total_thrust_n
        self.u_min = min_total_thrust_n
        self._state = np.zeros(9)     # d_hat, xi1, xi2
        self._p = np.zeros(N_PARAMS)
        self._pack()

    def _pack(self) -> None:
        """The gains and limits into the packed array (in place: a packed record holding
        it stays good)."""
        gn = self.gains
        p = self._p
        p[P_M], p[P_G], p[P_U_MAX], p[P_U_MIN] = self.m, self.g, self.u_max, self.u_min
        p[P_FZ_MIN] = self.u_min if self.u_min > 0 else 1e-3 * self.m * self.g
        p[P_TAN_TILT] = math.tan(gn.max_tilt_rad)
        p[P_D_MAX] = gn.disturbance_limit_m_s2
        p[P_K1:P_K1 + 3] = gn.pos_k1_1_s
        p[P_K2:P_K2 + 3] = gn.pos_k2_1_s
        p[P_GAM:P_GAM + 3] = gn.disturbance_gain_1_s2
        p[P_DRAG:P_DRAG + 3] = self.drag
        self._packed_from = (self.gains, self.m, self.g, self.u_max, self.u_min, self.drag)

    @property
    def d_hat(self) -> list[float]:
        """The disturbance estimate [m/s^2]."""
        return self._state[S_D_HAT:S_D_HAT + 3].tolist()

    @property
    def xi1(self) -> list[float]:
        """The position compensation signal [m]."""
        return self._state[S_XI1:S_XI1 + 3].tolist()

    @property
    def xi2(self) -> list[float]:
        """The velocity compensation signal [m/s]."""
        return self._state[S_XI2:S_XI2 + 3].tolist()

    def set_gains(self, gains: FlightControlParams) -> None:
        """Use ``gains`` (K1, K2, Gamma, the disturbance bound, the tilt and thrust limits)
        from the next step on, keeping the disturbance estimate and the compensation."""
        self.gains = gains
        self.u_max = gains.max_thrust_fraction * self.max_total_thrust_n
        self._pack()

    def reset(self, disturbance_m_s2: Vec3 = (0.0, 0.0, 0.0)) -> None:
        """Forget the disturbance estimate (or start from a given one) and the compensation."""
        self._state[:] = 0.0
        self._state[S_D_HAT:S_D_HAT + 3] = disturbance_m_s2

    def update(self, dt_s: float, pos: Vec3, vel: Vec3, ref_pos: Vec3, ref_vel: Vec3,
               ref_acc: Vec3, ref_yaw_rad: float,
               rotation: tuple[Vec3, Vec3, Vec3] = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0),
                                                    (0.0, 0.0, 1.0)),
               tether_force_n: Vec3 = (0.0, 0.0, 0.0),
               achieved_thrust_n: float | None = None) -> PositionOutput:
        """One control step of ``dt_s`` [s].

        ``rotation`` is the attitude's rotation matrix (rows; body -> inertial);
        ``tether_force_n`` the modelled pull of the tether on the UAV;
        ``achieved_thrust_n`` the collective thrust the rotors produce now (from
        :class:`companion.actuators.ActuatorModel`); without it the limited command is
        taken as achieved.
        """
        achieved = achieved_thrust_n is not None
        r = position_law(self.packed, float(dt_s), _vec3(pos), _vec3(vel), _vec3(ref_pos),
                         _vec3(ref_vel), _vec3(ref_acc), float(ref_yaw_rad),
                         (_vec3(rotation[0]), _vec3(rotation[1]), _vec3(rotation[2])),
                         _vec3(tether_force_n), achieved,
                         float(achieved_thrust_n) if achieved else 0.0)
        return position_output(r)

    @property
    def packed(self) -> tuple[np.ndarray, np.ndarray]:
        """What :func:`position_law` takes of this controller (:attr:`RECORD`): the packed
        gains and limits (:meth:`params`) and the state (d_hat, xi1, xi2; updated in
        place)."""
        return self.params(), self._state

    def params(self) -> np.ndarray:
        """The gains and limits packed for :func:`position_law`."""
        f = self._packed_from
        if (self.gains is not f[0] or self.m is not f[1] or self.g is not f[2]
                or self.u_max is not f[3] or self.u_min is not f[4] or self.drag is not f[5]):
            self._pack()
        return self._p


def position_output(r: tuple[Any, ...]) -> PositionOutput:
    """The :class:`PositionOutput` of :func:`position_law`'s result."""
    return PositionOutput._make(r)


def _vec3(v: Any) -> Vec3:
    """Three floats as a tuple (a compiled law's vector)."""
    return (float(v[0]), float(v[1]), float(v[2]))


@njit
def position_law(controller: tuple[np.ndarray, np.ndarray], dt_s: float, pos: Vec3,
                 vel: Vec3, ref_pos: Vec3, ref_vel: Vec3, ref_acc: Vec3, yaw: float,
                 rotation: tuple[Vec3, Vec3, Vec3], tether_force: Vec3, achieved: bool,
                 u_ach: float) -> tuple[Any, ...]:
    """One step of :class:`PositionController` (the law of the module docstring) of
    ``dt_s`` [s]: ``controller`` its :attr:`~PositionController.packed` record (the
    packed parameters; d_hat, xi1, xi2, updated in place); position [m], velocity [m/s],
    the reference's position, velocity, acceleration and yaw [rad], the rotation matrix's
    rows (body -> inertial), the modelled tether pull [N], and whether the collective
    thrust the rotors achieve, ``u_ach`` [N], is known. Returns the fields of a
    :class:`PositionOutput`."""
    p, s = controller
    px, py, pz = pos
    vx, vy, vz = vel
    rpx, rpy, rpz = ref_pos
    rvx, rvy, rvz = ref_vel
    rax, ray, raz = ref_acc
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = rotation
    ftx, fty, ftz = tether_force
    m = p[P_M]
    k1x, k1y, k1z = p[P_K1], p[P_K1 + 1], p[P_K1 + 2]
    k2x, k2y, k2z = p[P_K2], p[P_K2 + 1], p[P_K2 + 2]
    e1x, e1y, e1z = px - rpx, py - rpy, pz - rpz
    evx, evy, evz = vx - rvx, vy - rvy, vz - rvz
    e2x, e2y, e2z = evx + k1x * e1x, evy + k1y * e1y, evz + k1z * e1z
    e1bx, e1by, e1bz = e1x - s[S_XI1], e1y - s[S_XI1 + 1], e1z - s[S_XI1 + 2]
    e2bx, e2by, e2bz = e2x - s[S_XI2], e2y - s[S_XI2 + 1], e2z - s[S_XI2 + 2]
    adx = rax - k1x * evx - e1bx - k2x * e2x - s[S_D_HAT]
    ady = ray - k1y * evy - e1by - k2y * e2y - s[S_D_HAT + 1]
    adz = raz - k1z * evz - e1bz - k2z * e2z - s[S_D_HAT + 2]
    adz += p[P_G]
    dgx, dgy, dgz = _drag_force(r00, r01, r02, r10, r11, r12, r20, r21, r22,
                                p[P_DRAG], p[P_DRAG + 1], p[P_DRAG + 2], vx, vy, vz)
    fdx, fdy, fdz = m * adx - ftx - dgx, m * ady - fty - dgy, m * adz - ftz - dgz
    fx, fy, fz, saturated = _limit(p, fdx, fdy, fdz)
    thrust = fx * r02 + fy * r12 + fz * r22
    thrust = min(max(thrust, p[P_U_MIN]), p[P_U_MAX])
    roll, pitch, yaw = _attitude_from_thrust(fx, fy, fz, yaw)
    # without actuator information the limited command is taken as achieved
    if achieved:
        fax, fay, faz = u_ach * r02, u_ach * r12, u_ach * r22
    else:
        fax, fay, faz = fx, fy, fz
    lyap = 0.5 * (e1bx * e1bx + e1by * e1by + e1bz * e1bz) + 0.5 * (
        e2bx * e2bx + e2by * e2by + e2bz * e2bz)
    lyap_raw = 0.5 * (e1x * e1x + e1y * e1y + e1z * e1z) + 0.5 * (
        e2x * e2x + e2y * e2y + e2z * e2z)
    # no conditional integration: the compensated error already leaves out what the
    # limits took away, and freezing would break dV/dt <= 0 (docs/control.md)
    _adapt(p, s, dt_s, e2bx, e2by, e2bz)
    # compensation signals, exact for one step with the input held
    s[S_XI1], s[S_XI2] = _compensate(s[S_XI1], s[S_XI2], k1x, k2x, (fax - fdx) / m, dt_s)
    s[S_XI1 + 1], s[S_XI2 + 1] = _compensate(s[S_XI1 + 1], s[S_XI2 + 1], k1y, k2y,
                                             (fay - fdy) / m, dt_s)
    s[S_XI1 + 2], s[S_XI2 + 2] = _compensate(s[S_XI1 + 2], s[S_XI2 + 2], k1z, k2z,
                                             (faz - fdz) / m, dt_s)
    return (thrust, (roll, pitch, yaw), (fx, fy, fz), (e1bx, e1by, e1bz), (e2bx, e2by, e2bz),
            (s[S_D_HAT], s[S_D_HAT + 1], s[S_D_HAT + 2]), saturated, lyap, lyap_raw)


@njit
def _adapt(p: np.ndarray, s: np.ndarray, dt_s: float, e2x: float, e2y: float,
           e2z: float) -> None:
    """d(d_hat)/dt = Gamma e2_bar over one step, projected onto |d_hat| <= d_max."""
    nx = s[S_D_HAT] + p[P_GAM] * e2x * dt_s
    ny = s[S_D_HAT + 1] + p[P_GAM + 1] * e2y * dt_s
    nz = s[S_D_HAT + 2] + p[P_GAM + 2] * e2z * dt_s
    lim = p[P_D_MAX]
    norm = math.sqrt(nx * nx + ny * ny + nz * nz)
    if norm > lim:  # projection onto the ball: keep the estimate bounded (anti-windup)
        nx, ny, nz = nx * lim / norm, ny * lim / norm, nz * lim / norm
    s[S_D_HAT], s[S_D_HAT + 1], s[S_D_HAT + 2] = nx, ny, nz


@njit
def _limit(p: np.ndarray, fx: float, fy: float, fz0: float
           ) -> tuple[float, float, float, bool]:
    """Limit the thrust vector's tilt and magnitude, keeping its vertical part first."""
    sat = False
    u_max = p[P_U_MAX]
    fz = fz0
    if fz < p[P_FZ_MIN]:
        fz, sat = p[P_FZ_MIN], True
    fz = min(fz, u_max)
    if fz != fz0:
        sat = True
    fh = math.hypot(fx, fy)
    fh_max = min(fz * p[P_TAN_TILT], math.sqrt(max(u_max * u_max - fz * fz, 0.0)))
    if fh > fh_max:
        sc = fh_max / fh
        fx, fy, sat = fx * sc, fy * sc, True
    return fx, fy, fz, sat


@njit
def _compensate(x1: float, x2: float, k1: float, k2: float, u: float, dt: float
                ) -> tuple[float, float]:
    """One step of dx1/dt = -k1 x1 + x2, dx2/dt = -k2 x2 + u with u held: exact (the
    system is triangular, so the matrix exponential has a closed form)."""
    e1, e2 = math.exp(-k1 * dt), math.exp(-k2 * dt)
    x2_new = e2 * x2 + (1.0 - e2) / k2 * u
    if abs(k1 - k2) > 1e-9:
        g = (e2 - e1) / (k1 - k2)              # integral of e^{-k1(dt-s)} e^{-k2 s} ds
        h = ((1.0 - e1) / k1 - g) / k2          # response of x1 to a unit step of u
    else:
        g = dt * e1
        h = ((1.0 - e1) / k1 - g) / k1
    x1_new = e1 * x1 + g * x2 + h * u
    return x1_new, x2_new


@njit
def _drag_force(r00: float, r01: float, r02: float, r10: float, r11: float, r12: float,
                r20: float, r21: float, r22: float, dx: float, dy: float, dz: float,
                vx: float, vy: float, vz: float) -> tuple[float, float, float]:
    """Linear drag in still air, R diag(d) R' v, as the inertial force on the UAV [N]
    (``r`` the rotation matrix's entries, row-major)."""
    bx = -(r00 * vx + r10 * vy + r20 * vz) * dx
    by = -(r01 * vx + r11 * vy + r21 * vz) * dy
    bz = -(r02 * vx + r12 * vy + r22 * vz) * dz
    return (r00 * bx + r01 * by + r02 * bz,
            r10 * bx + r11 * by + r12 * bz,
            r20 * bx + r21 * by + r22 * bz)


@njit
def _attitude_from_thrust(fx: float, fy: float, fz: float, yaw_rad: float
                          ) -> tuple[float, float, float]:
    """:func:`attitude_from_thrust_vector` in scalars."""
    n = math.sqrt(fx * fx + fy * fy + fz * fz)
    zx, zy, zz = fx / n, fy / n, fz / n
    cy, sy = math.cos(yaw_rad), math.sin(yaw_rad)
    # R = Rz(yaw) Ry(pitch) Rx(roll) has third column
    # (cy sp cr + sy sr, sy sp cr - cy sr, cp cr): rotate z_d back by -yaw about z
    bx = cy * zx + sy * zy        # = sp cr
    by = -sy * zx + cy * zy       # = -sr
    roll = math.asin(max(-1.0, min(1.0, -by)))
    pitch = math.atan2(bx, zz)
    return (roll, pitch, yaw_rad)


def attitude_from_thrust_vector(f: list[float] | Vec3, yaw_rad: float) -> Vec3:
    """Z-Y-X Euler angles (roll, pitch, yaw) [rad] of the attitude whose body z axis is along
    ``f`` and whose heading is ``yaw_rad`` (z-up convention: body x forward, y left)."""
    return _attitude_from_thrust(float(f[0]), float(f[1]), float(f[2]), float(yaw_rad))
