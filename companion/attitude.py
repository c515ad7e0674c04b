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
    tau   = omega x J omega + c omega + J d(alpha)/dt - T(eta)' e_eta_bar - K4 e_w
    V     = 1/2 e_eta_bar' e_eta_bar + 1/2 e_w_bar' J e_w_bar,
    dV/dt = -e_eta_bar' K3 e_eta_bar - e_w_bar' K4 e_w_bar
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from scipy.linalg import expm

from companion.gains import FlightControlParams
from tuavdefs.frames import wrap_pi

Vec3 = tuple[float, float, float]


class AttitudeOutput(NamedTuple):
    """Torques and diagnostics of one attitude step."""

    torque_n_m: Vec3
    attitude_cmd_rad: Vec3       # filtered command eta_c
    rate_cmd_rad_s: Vec3         # alpha, the desired body rate
    e_eta_rad: Vec3              # compensated errors e_eta_bar, e_w_bar
    e_omega_rad_s: Vec3
    lyapunov: float              # 1/2 |e_eta_bar|^2 + 1/2 e_w_bar' J e_w_bar
    lyapunov_raw: float          # the same with the uncompensated errors


class CommandFilter:
    """Second-order low-pass per axis, x'' = wn^2 (u - x) - 2 zeta wn x', discretised exactly
    for a fixed step; returns the filtered value and its first two derivatives."""

    def __init__(self, natural_hz: float, damping: float, dt_s: float, n: int = 3) -> None:
        wn = 2.0 * math.pi * natural_hz
        a = np.array([[0.0, 1.0], [-wn * wn, -2.0 * damping * wn]])
        b = np.array([[0.0], [wn * wn]])
        m = np.zeros((3, 3))
        m[:2, :2], m[:2, 2:] = a, b
        e = expm(m * dt_s)
        self._ad, self._bd = e[:2, :2], e[:2, 2]
        self._wn2, self._2zw = wn * wn, 2.0 * damping * wn
        self.state = np.zeros((n, 2))
        self.initialised = False

    def reset(self, value: np.ndarray) -> None:
        """Start at rest at ``value``."""
        self.state[:, 0] = value
        self.state[:, 1] = 0.0
        self.initialised = True

    def update(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(x, dx/dt, d2x/dt2) now, for input ``u`` held over the coming step; then advance
        the state by one step. The reference handed out is the filter's value at the time
        of the measurement it will be compared with, not one step ahead."""
        if not self.initialised:
            self.reset(u)
        s = self.state
        x, xd = s[:, 0].copy(), s[:, 1].copy()
        xdd = self._wn2 * (u - x) - self._2zw * xd
        self.state = s @ self._ad.T + np.outer(u, self._bd)
        return x, xd, xdd


def euler_rate_matrices(roll: float, pitch: float) -> tuple[np.ndarray, np.ndarray]:
    """W with omega = W d(eta)/dt, and its inverse T, for Z-Y-X angles (valid |pitch| < 90 deg)."""
    sr, cr = math.sin(roll), math.cos(roll)
    sp, cp = math.sin(pitch), math.cos(pitch)
    w = np.array([[1.0, 0.0, -sp], [0.0, cr, sr * cp], [0.0, -sr, cr * cp]])
    tp = sp / cp
    t = np.array([[1.0, sr * tp, cr * tp], [0.0, cr, -sr], [0.0, sr / cp, cr / cp]])
    return w, t


class AttitudeController:
    """Backstepping attitude controller with a command filter on the desired attitude."""

    def __init__(self, gains: FlightControlParams, inertia_diag: Vec3,
                 rate_damping_n_m_s: float, dt_s: float) -> None:
        self.gains = gains
        self.j = np.array(inertia_diag)
        self.c = rate_damping_n_m_s
        self.dt_s = dt_s
        self.k3 = np.array(gains.att_k3_1_s)
        self.k4 = np.array(gains.att_k4_n_m_s)
        self.filter = CommandFilter(gains.command_filter_hz, gains.command_filter_damping, dt_s)
        self.xi_eta = np.zeros(3)
        self.xi_w = np.zeros(3)
        self._decay_w = np.exp(-self.k4 / self.j * dt_s)

    def reset(self, attitude_rad: Vec3) -> None:
        """Start the command filter at rest at ``attitude_rad``; clear the compensation."""
        self.filter.reset(np.array(attitude_rad))
        self.xi_eta = np.zeros(3)
        self.xi_w = np.zeros(3)

    def update(self, attitude_rad: Vec3, body_rates_rad_s: Vec3, desired_rad: Vec3,
               achieved_torque_n_m: Vec3 | None = None) -> AttitudeOutput:
        """Torques [N m] for the measured attitude and rates and the desired attitude.

        ``achieved_torque_n_m`` is what the rotors produce now (from
        :class:`companion.actuators.ActuatorModel`); without it the command is taken as
        achieved and the compensation stays zero.
        """
        eta = np.array(attitude_rad)
        om = np.array(body_rates_rad_s)
        des = np.array(desired_rad, dtype=float)
        if self.filter.initialised:
            # follow yaw the short way round: unwrap the command next to the filter state
            des[2] = self.filter.state[2, 0] + wrap_pi(des[2] - self.filter.state[2, 0])
        eta_c, eta_c_d, eta_c_dd = self.filter.update(des)
        e_eta = eta - eta_c
        e_eta[2] = wrap_pi(e_eta[2])
        w, t = euler_rate_matrices(eta[0], eta[1])
        v = eta_c_d - self.k3 * e_eta
        alpha = w @ v
        eta_d = t @ om                                  # measured Euler rates
        w_dot = _w_dot(eta[0], eta[1], eta_d[0], eta_d[1])
        alpha_dot = w_dot @ v + w @ (eta_c_dd - self.k3 * (eta_d - eta_c_d))
        e_w = om - alpha
        e_eta_b = e_eta - self.xi_eta
        e_w_b = e_w - self.xi_w
        jw = self.j * om
        tau = (np.cross(om, jw) + self.c * om + self.j * alpha_dot - t.T @ e_eta_b
               - self.k4 * e_w)
        lyap = 0.5 * float(e_eta_b @ e_eta_b) + 0.5 * float(e_w_b @ (self.j * e_w_b))
        lyap_raw = 0.5 * float(e_eta @ e_eta) + 0.5 * float(e_w @ (self.j * e_w))
        if achieved_torque_n_m is not None:
            drive = (np.array(achieved_torque_n_m) - tau) / self.k4
            xi_w_new = drive + (self.xi_w - drive) * self._decay_w
            # xi_eta driven by T xi_w (trapezoid over the step), decaying at K3
            d3 = np.exp(-self.k3 * self.dt_s)
            u = 0.5 * (t @ self.xi_w + t @ xi_w_new)
            self.xi_eta = u / self.k3 + (self.xi_eta - u / self.k3) * d3
            self.xi_w = xi_w_new
        return AttitudeOutput(tuple(tau), tuple(eta_c), tuple(alpha), tuple(e_eta_b),
                              tuple(e_w_b), lyap, lyap_raw)


def _w_dot(roll: float, pitch: float, roll_d: float, pitch_d: float) -> np.ndarray:
    """Time derivative of W(roll, pitch)."""
    sr, cr = math.sin(roll), math.cos(roll)
    sp, cp = math.sin(pitch), math.cos(pitch)
    return np.array([
        [0.0, 0.0, -cp * pitch_d],
        [0.0, -sr * roll_d, cr * cp * roll_d - sr * sp * pitch_d],
        [0.0, -cr * roll_d, -sr * cp * roll_d - cr * sp * pitch_d],
    ])
