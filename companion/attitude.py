"""Command-filtered backstepping attitude control: desired attitude -> body torques.

States (docs/control.md §2): Euler angles eta = (roll, pitch, yaw), Z-Y-X, and body rates
omega, with the kinematics  d(eta)/dt = T(eta) omega  (T = W^-1, omega = W(eta) d(eta)/dt)
and Euler's equations  J d(omega)/dt = tau - c omega - omega x J omega.

The desired attitude from the position loop passes through a second-order command filter
that yields eta_c and its first two derivatives (command-filtered backstepping: the
reference derivatives come from the filter, not from differentiating the position loop).

    e_eta = eta - eta_c                         (yaw wrapped)
    alpha = W(eta) (d(eta_c)/dt - K3 e_eta)     desired body rate
    e_w   = omega - alpha
    compensation, tau_a the torque achieved:
        d(xi_eta)/dt = -K3 xi_eta + T(eta) xi_w,   J d(xi_w)/dt = -K4 xi_w + (tau_a - tau)
    e_eta_bar = e_eta - xi_eta,  e_w_bar = e_w - xi_w
    tau   = omega x J omega + c omega + J d(alpha)/dt - T(eta)' e_eta_bar - K4 e_w - tau_hat
    d(tau_hat)/dt = Gamma_tau e_w_bar   (projected onto |tau_hat| <= tau_max)
    V     = 1/2 e_eta_bar' e_eta_bar + 1/2 e_w_bar' J e_w_bar
            + 1/2 tau_tilde' Gamma_tau^-1 tau_tilde,
    dV/dt = -e_eta_bar' K3 e_eta_bar - e_w_bar' K4 e_w_bar
for a constant disturbance torque tau_d (J d(omega)/dt = tau + tau_d - ...; a tether
attached off the centre of mass), tau_tilde = tau_d - tau_hat: integral action that
leaves no steady attitude error (docs/control.md §2).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
from scipy.linalg import expm

from companion.gains import FlightControlParams
from tuavdefs.frames import wrap_pi
from tuavdefs.jit import array, njit, record

Vec3 = tuple[float, float, float]
Mat3 = tuple[float, float, float, float, float, float, float, float, float]  # row-major


class AttitudeOutput(NamedTuple):
    """Torques and diagnostics of one attitude step."""

    torque_n_m: Vec3
    attitude_cmd_rad: Vec3       # filtered command eta_c
    rate_cmd_rad_s: Vec3         # alpha, the desired body rate
    e_eta_rad: Vec3              # compensated errors e_eta_bar, e_w_bar
    e_omega_rad_s: Vec3
    lyapunov: float              # 1/2 |e_eta_bar|^2 + 1/2 e_w_bar' J e_w_bar
    lyapunov_raw: float          # the same with the uncompensated errors
    disturbance_n_m: Vec3        # the disturbance-torque estimate tau_hat


class CommandFilter:
    """Third-order low-pass per axis: the second-order x'' = wn^2 (u_f - x) - 2 zeta wn x'
    behind a first-order lag u_f' = wp (u - u_f), in the phase variables (x, x', x''):
    x''' = wn^2 wp (u - x) - (wn^2 + 2 zeta wn wp) x' - (2 zeta wn + wp) x'', discretised
    exactly for a fixed step; returns the filtered value and its first two derivatives.
    x'' is a state, not a gain on the input: a noisy command reaches it integrated once
    (docs/control.md §2.2), where the second-order filter alone passes the command's noise
    into x'' with the gain wn^2 (``pole_hz`` = 0 gives that filter)."""

    def __init__(self, natural_hz: float, damping: float, dt_s: float, n: int = 3,
                 pole_hz: float = 0.0) -> None:
        wn = 2.0 * math.pi * natural_hz
        wp = 2.0 * math.pi * pole_hz
        second = wp <= 0.0
        if second:   # x'' from the input, the third column unused
            a = np.array([[0.0, 1.0, 0.0], [-wn * wn, -2.0 * damping * wn, 0.0],
                          [0.0, 0.0, 0.0]])
            b = np.array([[0.0], [wn * wn], [0.0]])
        else:
            a = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0],
                          [-wn * wn * wp, -(wn * wn + 2.0 * damping * wn * wp),
                           -(2.0 * damping * wn + wp)]])
            b = np.array([[0.0], [0.0], [wn * wn * wp]])
        m = np.zeros((4, 4))
        m[:3, :3], m[:3, 3:] = a, b
        e = expm(m * dt_s)
        # the same numbers packed for the compiled step (_filter_step): Ad row-major, Bd,
        # wn^2, 2 zeta wn and whether x'' comes from the input (the second-order form)
        self.coeffs = np.concatenate([e[:3, :3].ravel(), e[:3, 3],
                                      [wn * wn, 2.0 * damping * wn, float(second)]])
        self.state = np.zeros((n, 3))
        self.initialised = False

    def reset(self, value: np.ndarray | Vec3) -> None:
        """Start at rest at ``value``."""
        self.state[:, 0] = value
        self.state[:, 1:] = 0.0
        self.initialised = True

    def update(self, u: np.ndarray | Vec3) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(x, dx/dt, d2x/dt2) now, for input ``u`` held over the coming step; then advance
        the state by one step. The reference handed out is the filter's value at the time
        of the measurement it will be compared with, not one step ahead."""
        if not self.initialised:
            self.reset(u)
        s = self.state
        n = s.shape[0]
        x, xd, xdd = np.empty(n), np.empty(n), np.empty(n)
        for i in range(n):
            x[i], xd[i], xdd[i] = _filter_step(self.coeffs, s, i, float(u[i]))
        return x, xd, xdd


@njit
def _filter_step(c: np.ndarray, s: np.ndarray, i: int, u: float
                 ) -> tuple[float, float, float]:
    """One axis of :class:`CommandFilter`: (x, x', x'') of row ``i`` of the state ``s``,
    then the row advanced in place by the exact discretisation ``c`` (Ad row-major, Bd,
    wn^2, 2 zeta wn, the second-order flag) for ``u`` held over the step."""
    x, xd, xdd = s[i, 0], s[i, 1], s[i, 2]
    if c[14] != 0.0:
        xdd = c[12] * (u - x) - c[13] * xd
    s[i, 0] = c[0] * x + c[1] * xd + c[2] * xdd + c[9] * u
    s[i, 1] = c[3] * x + c[4] * xd + c[5] * xdd + c[10] * u
    s[i, 2] = c[6] * x + c[7] * xd + c[8] * xdd + c[11] * u
    return x, xd, xdd


@njit
def _euler_rate_entries(roll: float, pitch: float) -> tuple[Mat3, Mat3]:
    """Entries (row-major) of W and T = W^-1 (see :func:`euler_rate_matrices`)."""
    sr, cr = math.sin(roll), math.cos(roll)
    sp, cp = math.sin(pitch), math.cos(pitch)
    w = (1.0, 0.0, -sp, 0.0, cr, sr * cp, 0.0, -sr, cr * cp)
    tp = sp / cp
    t = (1.0, sr * tp, cr * tp, 0.0, cr, -sr, 0.0, sr / cp, cr / cp)
    return w, t


def euler_rate_matrices(roll: float, pitch: float) -> tuple[np.ndarray, np.ndarray]:
    """W with omega = W d(eta)/dt, and its inverse T, for Z-Y-X angles (valid |pitch| < 90 deg)."""
    w, t = _euler_rate_entries(float(roll), float(pitch))
    return np.array(w).reshape(3, 3), np.array(t).reshape(3, 3)


@njit
def _mv(m: Mat3, x0: float, x1: float, x2: float) -> tuple[float, float, float]:
    """m @ x for a row-major 3x3 ``m``."""
    return (m[0] * x0 + m[1] * x1 + m[2] * x2,
            m[3] * x0 + m[4] * x1 + m[5] * x2,
            m[6] * x0 + m[7] * x1 + m[8] * x2)


@njit
def _mtv(m: Mat3, x0: float, x1: float, x2: float) -> tuple[float, float, float]:
    """m' @ x for a row-major 3x3 ``m``."""
    return (m[0] * x0 + m[3] * x1 + m[6] * x2,
            m[1] * x0 + m[4] * x1 + m[7] * x2,
            m[2] * x0 + m[5] * x1 + m[8] * x2)


class AttitudeController:
    """Backstepping attitude controller with a command filter on the desired attitude."""

    #: The type of :attr:`packed` (:class:`tuavdefs.jit.Signature` texts).
    RECORD = record(array(), array(), array(2), array(), array(), array())

    def __init__(self, gains: FlightControlParams, inertia_diag: Vec3,
                 rate_damping_n_m_s: float, dt_s: float) -> None:
        self.gains = gains
        self.j = np.array(inertia_diag)
        self.c = rate_damping_n_m_s
        self.dt_s = dt_s
        self.k3 = np.array(gains.att_k3_1_s)
        self.k4 = np.array(gains.att_k4_n_m_s)
        self.filter = CommandFilter(gains.command_filter_hz, gains.command_filter_damping, dt_s,
                                    pole_hz=gains.command_filter_pole_hz)
        self.xi_eta = np.zeros(3)
        self.xi_w = np.zeros(3)
        self.tau_hat = np.zeros(3)
        """The disturbance-torque estimate [N m] (body axes)."""
        self._decay_w = np.exp(-self.k4 / self.j * dt_s)
        self._pack()

    def _pack(self) -> None:
        """J, c, K3, K4, the decays of xi_w and xi_eta over a step, the step, Gamma_tau and
        the estimate's bound, packed for the compiled law (:func:`attitude_law`)."""
        decay_eta = np.exp(-self.k3 * self.dt_s)
        gn = self.gains
        p = np.concatenate([self.j, [float(self.c)], self.k3, self.k4, self._decay_w,
                            decay_eta, [self.dt_s], gn.att_disturbance_gain_n_m_rad,
                            [gn.att_disturbance_limit_n_m]]).astype(float)
        old = getattr(self, "_p", None)
        if old is not None and old.shape == p.shape:
            old[:] = p     # in place: a packed record holding it stays good
        else:
            self._p = p
        self._packed_from = (self.j, self.c, self.k3, self.k4, self._decay_w, self.dt_s,
                             self.gains)

    def params(self) -> np.ndarray:
        """The packed parameters, packed again if an attribute they come from was
        replaced."""
        f = self._packed_from
        if (self.j is not f[0] or self.c is not f[1] or self.k3 is not f[2]
                or self.k4 is not f[3] or self._decay_w is not f[4] or self.dt_s is not f[5]
                or self.gains is not f[6]):
            self._pack()
        return self._p

    def set_gains(self, gains: FlightControlParams) -> None:
        """Use ``gains`` (K3, K4, the command filter's frequency and damping) from the next
        step on, keeping the command filter's state and the compensation."""
        self.gains = gains
        self.k3 = np.array(gains.att_k3_1_s)
        self.k4 = np.array(gains.att_k4_n_m_s)
        self._decay_w = np.exp(-self.k4 / self.j * self.dt_s)
        old = self.filter
        new = CommandFilter(gains.command_filter_hz, gains.command_filter_damping, self.dt_s,
                            old.state.shape[0], gains.command_filter_pole_hz)
        new.state = old.state
        new.initialised = old.initialised
        self.filter = new
        self._pack()

    def reset(self, attitude_rad: Vec3) -> None:
        """Start the command filter at rest at ``attitude_rad``; clear the compensation and
        the disturbance-torque estimate."""
        self.filter.reset(np.array(attitude_rad))
        self.xi_eta[:] = 0.0      # (in place: a packed record holding them stays good)
        self.xi_w[:] = 0.0
        self.tau_hat[:] = 0.0

    def update(self, attitude_rad: Vec3, body_rates_rad_s: Vec3, desired_rad: Vec3,
               achieved_torque_n_m: Vec3 | None = None) -> AttitudeOutput:
        """Torques [N m] for the measured attitude and rates and the desired attitude.

        ``achieved_torque_n_m`` is what the rotors produce now (from
        :class:`companion.actuators.ActuatorModel`); without it the command is taken as
        achieved and the compensation stays zero.
        """
        f = self.filter
        achieved = achieved_torque_n_m is not None
        r = attitude_law(self.packed, _vec3(attitude_rad), _vec3(body_rates_rad_s),
                         _vec3(desired_rad), f.initialised, achieved,
                         _vec3(achieved_torque_n_m) if achieved else (0.0, 0.0, 0.0))
        f.initialised = True
        return attitude_output(r)

    @property
    def packed(self) -> tuple[np.ndarray, ...]:
        """What :func:`attitude_law` takes of this controller (:attr:`RECORD`): the packed
        parameters (:meth:`params`), the command filter's coefficients and state, and
        xi_eta, xi_w, tau_hat (the states updated in place)."""
        f = self.filter
        return self.params(), f.coeffs, f.state, self.xi_eta, self.xi_w, self.tau_hat


def attitude_output(r: tuple[Any, ...]) -> AttitudeOutput:
    """The :class:`AttitudeOutput` of :func:`attitude_law`'s result."""
    return AttitudeOutput._make(r)


def _vec3(v: Any) -> Vec3:
    """Three floats as a tuple (a compiled law's vector)."""
    return (float(v[0]), float(v[1]), float(v[2]))


@njit
def attitude_law(controller: tuple[np.ndarray, ...], eta: Vec3, omega: Vec3,
                 desired: Vec3, initialised: bool, achieved: bool, tau_achieved: Vec3
                 ) -> tuple[Any, ...]:
    """One step of :class:`AttitudeController` (the law of the module docstring) for the
    attitude ``eta`` (Z-Y-X Euler angles) [rad], body rates ``omega`` [rad/s] and the
    desired attitude [rad]; ``controller`` is its :attr:`~AttitudeController.packed`
    record: ``p`` = (J, c, K3, K4, decay of xi_w, decay of xi_eta over one step, the step
    [s], Gamma_tau, the bound on tau_hat), the command filter's coefficients ``fc`` and
    state ``fs`` (started at rest at the desired attitude unless ``initialised``), the
    compensation ``xi_eta``, ``xi_w`` and the disturbance-torque estimate ``tau_hat``,
    the states advanced in place. ``tau_achieved`` [N m] is the torque the rotors give
    (when ``achieved``). Returns the fields of an :class:`AttitudeOutput`."""
    p, fc, fs, xi_eta, xi_w, tau_hat = controller
    eta0, eta1, eta2 = eta
    om0, om1, om2 = omega
    des0, des1, des2 = desired
    ta0, ta1, ta2 = tau_achieved
    j0, j1, j2, c = p[0], p[1], p[2], p[3]
    k30, k31, k32, k40, k41, k42 = p[4], p[5], p[6], p[7], p[8], p[9]
    if initialised:
        # follow yaw the short way round: unwrap the command next to the filter state
        des2 = fs[2, 0] + wrap_pi(des2 - fs[2, 0])
    else:
        fs[0, 0], fs[1, 0], fs[2, 0] = des0, des1, des2
        fs[0, 1] = fs[1, 1] = fs[2, 1] = 0.0
        fs[0, 2] = fs[1, 2] = fs[2, 2] = 0.0
    c0, cd0, cdd0 = _filter_step(fc, fs, 0, des0)     # eta_c and its derivatives
    c1, cd1, cdd1 = _filter_step(fc, fs, 1, des1)
    c2, cd2, cdd2 = _filter_step(fc, fs, 2, des2)
    e0, e1, e2 = eta0 - c0, eta1 - c1, wrap_pi(eta2 - c2)
    w, t = _euler_rate_entries(eta0, eta1)
    v0, v1, v2 = cd0 - k30 * e0, cd1 - k31 * e1, cd2 - k32 * e2
    a0, a1, a2 = _mv(w, v0, v1, v2)                   # alpha
    ed0, ed1, ed2 = _mv(t, om0, om1, om2)             # measured Euler rates
    w_dot = _w_dot(eta0, eta1, ed0, ed1)
    p0, p1, p2 = _mv(w_dot, v0, v1, v2)
    q0, q1, q2 = _mv(w, cdd0 - k30 * (ed0 - cd0), cdd1 - k31 * (ed1 - cd1),
                     cdd2 - k32 * (ed2 - cd2))
    ad0, ad1, ad2 = p0 + q0, p1 + q1, p2 + q2         # d(alpha)/dt
    ew0, ew1, ew2 = om0 - a0, om1 - a1, om2 - a2
    eb0, eb1, eb2 = e0 - xi_eta[0], e1 - xi_eta[1], e2 - xi_eta[2]
    wb0, wb1, wb2 = ew0 - xi_w[0], ew1 - xi_w[1], ew2 - xi_w[2]
    jw0, jw1, jw2 = j0 * om0, j1 * om1, j2 * om2
    g0, g1, g2 = _mtv(t, eb0, eb1, eb2)               # T' e_eta_bar
    th0, th1, th2 = tau_hat[0], tau_hat[1], tau_hat[2]
    tau0 = (om1 * jw2 - om2 * jw1) + c * om0 + j0 * ad0 - g0 - k40 * ew0 - th0
    tau1 = (om2 * jw0 - om0 * jw2) + c * om1 + j1 * ad1 - g1 - k41 * ew1 - th1
    tau2 = (om0 * jw1 - om1 * jw0) + c * om2 + j2 * ad2 - g2 - k42 * ew2 - th2
    # the disturbance torque's adaptation on the compensated rate error, projected onto
    # its bound (the projection only removes the outward part: V still falls)
    dt = p[16]
    n0, n1, n2 = th0 + dt * p[17] * wb0, th1 + dt * p[18] * wb1, th2 + dt * p[19] * wb2
    norm = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
    if norm > p[20]:
        n0, n1, n2 = n0 * p[20] / norm, n1 * p[20] / norm, n2 * p[20] / norm
    tau_hat[0], tau_hat[1], tau_hat[2] = n0, n1, n2
    lyap = (0.5 * (eb0 * eb0 + eb1 * eb1 + eb2 * eb2)
            + 0.5 * (wb0 * (j0 * wb0) + wb1 * (j1 * wb1) + wb2 * (j2 * wb2)))
    lyap_raw = (0.5 * (e0 * e0 + e1 * e1 + e2 * e2)
                + 0.5 * (ew0 * (j0 * ew0) + ew1 * (j1 * ew1) + ew2 * (j2 * ew2)))
    if achieved:
        dr0, dr1, dr2 = (ta0 - tau0) / k40, (ta1 - tau1) / k41, (ta2 - tau2) / k42
        n0 = dr0 + (xi_w[0] - dr0) * p[10]
        n1 = dr1 + (xi_w[1] - dr1) * p[11]
        n2 = dr2 + (xi_w[2] - dr2) * p[12]
        # xi_eta driven by T xi_w (trapezoid over the step), decaying at K3
        o0, o1, o2 = _mv(t, xi_w[0], xi_w[1], xi_w[2])
        m0, m1, m2 = _mv(t, n0, n1, n2)
        u0, u1, u2 = 0.5 * (o0 + m0), 0.5 * (o1 + m1), 0.5 * (o2 + m2)
        xi_eta[0] = u0 / k30 + (xi_eta[0] - u0 / k30) * p[13]
        xi_eta[1] = u1 / k31 + (xi_eta[1] - u1 / k31) * p[14]
        xi_eta[2] = u2 / k32 + (xi_eta[2] - u2 / k32) * p[15]
        xi_w[0], xi_w[1], xi_w[2] = n0, n1, n2
    return ((tau0, tau1, tau2), (c0, c1, c2), (a0, a1, a2), (eb0, eb1, eb2), (wb0, wb1, wb2),
            lyap, lyap_raw, (th0, th1, th2))


@njit
def _w_dot(roll: float, pitch: float, roll_d: float, pitch_d: float) -> Mat3:
    """Time derivative of W(roll, pitch), row-major."""
    sr, cr = math.sin(roll), math.cos(roll)
    sp, cp = math.sin(pitch), math.cos(pitch)
    return (0.0, 0.0, -cp * pitch_d,
            0.0, -sr * roll_d, cr * cp * roll_d - sr * sp * pitch_d,
            0.0, -cr * roll_d, -sr * cp * roll_d - cr * sp * pitch_d)
