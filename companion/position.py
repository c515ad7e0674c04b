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
from typing import NamedTuple

from companion.gains import FlightControlParams

Vec3 = tuple[float, float, float]


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
    """Backstepping position controller with an adaptive disturbance estimate."""

    def __init__(self, gains: FlightControlParams, mass_kg: float, gravity_m_s2: float,
                 max_total_thrust_n: float, min_total_thrust_n: float = 0.0,
                 drag_coeff_n_s_m: Vec3 = (0.0, 0.0, 0.0)) -> None:
        self.gains = gains
        self.drag = drag_coeff_n_s_m
        self.m = mass_kg
        self.g = gravity_m_s2
        self.u_max = gains.max_thrust_fraction * max_total_thrust_n
        self.u_min = min_total_thrust_n
        self.d_hat = [0.0, 0.0, 0.0]
        self.xi1 = [0.0, 0.0, 0.0]
        self.xi2 = [0.0, 0.0, 0.0]

    def reset(self, disturbance_m_s2: Vec3 = (0.0, 0.0, 0.0)) -> None:
        """Forget the disturbance estimate (or start from a given one) and the compensation."""
        self.d_hat = list(disturbance_m_s2)
        self.xi1 = [0.0, 0.0, 0.0]
        self.xi2 = [0.0, 0.0, 0.0]

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
        r = rotation
        body_z = (r[0][2], r[1][2], r[2][2])
        gn = self.gains
        k1, k2, gam = gn.pos_k1_1_s, gn.pos_k2_1_s, gn.disturbance_gain_1_s2
        e1 = [pos[i] - ref_pos[i] for i in range(3)]
        ev = [vel[i] - ref_vel[i] for i in range(3)]
        e2 = [ev[i] + k1[i] * e1[i] for i in range(3)]
        xi1, xi2 = self.xi1, self.xi2
        e1b = [e1[i] - xi1[i] for i in range(3)]
        e2b = [e2[i] - xi2[i] for i in range(3)]
        a_d = [ref_acc[i] - k1[i] * ev[i] - e1b[i] - k2[i] * e2[i] - self.d_hat[i]
               for i in range(3)]
        a_d[2] += self.g
        drag = _drag_force(r, self.drag, vel)
        f_d = [self.m * a_d[i] - tether_force_n[i] - drag[i] for i in range(3)]
        f, saturated = self._limit(f_d)
        thrust = f[0] * body_z[0] + f[1] * body_z[1] + f[2] * body_z[2]
        thrust = min(max(thrust, self.u_min), self.u_max)
        attitude = attitude_from_thrust_vector(f, ref_yaw_rad)
        # without actuator information the limited command is taken as achieved
        f_a = f if achieved_thrust_n is None else [achieved_thrust_n * b for b in body_z]
        lyap = 0.5 * sum(e * e for e in e1b) + 0.5 * sum(e * e for e in e2b)
        lyap_raw = 0.5 * sum(e * e for e in e1) + 0.5 * sum(e * e for e in e2)
        # no conditional integration: the compensated error already leaves out what the
        # limits took away, and freezing would break dV/dt <= 0 (docs/control.md)
        self._adapt(dt_s, e2b, gam)
        # compensation signals, exact for one step with the input held
        for i in range(3):
            drive = (f_a[i] - f_d[i]) / self.m
            xi1[i], xi2[i] = _compensate(xi1[i], xi2[i], k1[i], k2[i], drive, dt_s)
        return PositionOutput(thrust, attitude, tuple(f), tuple(e1b), tuple(e2b),
                              tuple(self.d_hat), saturated, lyap, lyap_raw)

    def _adapt(self, dt_s: float, e2: list[float], gam: tuple[float, ...]) -> None:
        step = [gam[i] * e2[i] * dt_s for i in range(3)]
        new = [self.d_hat[i] + step[i] for i in range(3)]
        lim = self.gains.disturbance_limit_m_s2
        norm = math.sqrt(sum(v * v for v in new))
        if norm > lim:  # projection onto the ball: keep the estimate bounded (anti-windup)
            new = [v * lim / norm for v in new]
        self.d_hat = new

    def _limit(self, f: list[float]) -> tuple[list[float], bool]:
        """Limit the thrust vector's tilt and magnitude, keeping its vertical part first."""
        sat = False
        fz = f[2]
        fz_min = self.u_min if self.u_min > 0 else 1e-3 * self.m * self.g
        if fz < fz_min:
            fz, sat = fz_min, True
        fz = min(fz, self.u_max)
        if fz != f[2]:
            sat = True
        fh = math.hypot(f[0], f[1])
        fh_max = min(fz * math.tan(self.gains.max_tilt_rad),
                     math.sqrt(max(self.u_max * self.u_max - fz * fz, 0.0)))
        fx, fy = f[0], f[1]
        if fh > fh_max:
            s = fh_max / fh
            fx, fy, sat = fx * s, fy * s, True
        return [fx, fy, fz], sat


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


def _drag_force(r: tuple[Vec3, Vec3, Vec3], d: Vec3, v: Vec3) -> Vec3:
    """Linear drag in still air, R diag(d) R' v, as the inertial force on the UAV [N]."""
    b = [-(r[0][i] * v[0] + r[1][i] * v[1] + r[2][i] * v[2]) * d[i] for i in range(3)]
    return tuple(r[j][0] * b[0] + r[j][1] * b[1] + r[j][2] * b[2]  # type: ignore[return-value]
                 for j in range(3))


def attitude_from_thrust_vector(f: list[float] | Vec3, yaw_rad: float) -> Vec3:
    """Z-Y-X Euler angles (roll, pitch, yaw) [rad] of the attitude whose body z axis is along
    ``f`` and whose heading is ``yaw_rad`` (z-up convention: body x forward, y left)."""
    n = math.sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2])
    zx, zy, zz = f[0] / n, f[1] / n, f[2] / n
    cy, sy = math.cos(yaw_rad), math.sin(yaw_rad)
    # R = Rz(yaw) Ry(pitch) Rx(roll) has third column
    # (cy sp cr + sy sr, sy sp cr - cy sr, cp cr): rotate z_d back by -yaw about z
    bx = cy * zx + sy * zy        # = sp cr
    by = -sy * zx + cy * zy       # = -sr
    roll = math.asin(max(-1.0, min(1.0, -by)))
    pitch = math.atan2(bx, zz)
    return (roll, pitch, yaw_rad)
