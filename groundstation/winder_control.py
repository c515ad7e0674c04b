"""Backstepping winder-torque control: track the desired tether length L-bar.

Model (docs/control.md §4), drum angle positive paying out, L = r_w theta:

    dL/dt = r_w omega
    I_w(L) d(omega)/dt = tau + r_w T_drum - beta_w omega
    I_w(L) = 1/2 (m_w_bar + (L_T - L) rho)(r_w^2 + r_i^2) + I_rotor

Errors and virtual control:  e_L = L - L_c,  alpha = (dL_c/dt - k_L e_L) / r_w,
                             e_w = omega - alpha.
Law:  tau = -r_w T_drum + beta_w omega + I_w d(alpha)/dt - 1/2 dI_w/dt e_w
            - k_w e_w - c r_w e_L
Lyapunov function:  V = 1/2 c e_L^2 + 1/2 I_w e_w^2,  dV/dt = -c k_L e_L^2 - k_w e_w^2.

``T_drum`` is the tension the winch's load cell measures (feed-forward); ``L_c`` follows
L-bar with the analytic rate from the UAV's velocity, and its second derivative comes
from a first-order filter on that rate (command-filtered backstepping). The torque is
limited to the motor's, and alpha to the speed limit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

from tuavdefs.params import TetherParams, WinderParams
from tuavdefs.paramspec import Params, quantity


@dataclass(frozen=True)
class WinderControlParams(Params):
    """Gains and limits of the winder torque law."""

    rate_hz: float = quantity(100.0, "Hz", "control rate (the encoder frames' rate)", gt=0)
    k_length_1_s: float = quantity(6.0, "1/s", "length error gain k_L", gt=0)
    k_rate_n_m_s: float = quantity(0.6, "N*m*s/rad", "drum-rate error gain k_w", gt=0)
    length_stiffness_n_m: float = quantity(
        20.0, "N/m", "weight c of the length error in the Lyapunov function", gt=0)
    rate_filter_s: float = quantity(
        0.05, "s", "time constant of the filter that differentiates dL-bar/dt", gt=0)
    speed_margin: float = quantity(
        0.9, "1", "share of the motor's speed limit the law may ask for", gt=0, le=1)
    torque_margin: float = quantity(
        1.0, "1", "share of the motor's torque limit the law may ask for", gt=0, le=1)


class WinderCommand(NamedTuple):
    """Output of one winder control step."""

    torque_n_m: float
    e_length_m: float
    e_rate_rad_s: float
    rate_cmd_rad_s: float
    lyapunov: float
    saturated: bool


class WinderController:
    """The winder's backstepping torque law (a controller-side model of the drum)."""

    def __init__(self, gains: WinderControlParams, winder: WinderParams,
                 tether: TetherParams) -> None:
        self.g = gains
        self.r_w = winder.drum_radius_m
        self.beta = winder.viscous_friction_n_m_s_rad
        self.tau_max = gains.torque_margin * winder.motor_torque_limit_n_m
        self.omega_max = gains.speed_margin * winder.motor_speed_limit_rad_s
        self._m_bar = winder.drum_mass_kg
        self._rho = tether.linear_density_kg_m
        self._lt = tether.total_length_m
        self._r2 = winder.drum_radius_m ** 2 + winder.drum_inner_radius_m ** 2
        self._i_rotor = winder.rotor_inertia_kg_m2
        self._rate_f: float | None = None     # filtered dL_c/dt
        self._acc_f = 0.0                     # its derivative, d2L_c/dt2

    def inertia_kg_m2(self, length_m: float) -> float:
        """The law's model of the drum inertia at a paid-out length [kg m^2]."""
        m_w = self._m_bar + max(self._lt - length_m, 0.0) * self._rho
        return 0.5 * m_w * self._r2 + self._i_rotor

    def reset(self) -> None:
        """Forget the reference filter."""
        self._rate_f = None
        self._acc_f = 0.0

    def update(self, dt_s: float, length_m: float, omega_rad_s: float, drum_tension_n: float,
               ref_length_m: float, ref_rate_m_s: float) -> WinderCommand:
        """Torque request [N m] for the measured length, drum rate and tension."""
        g = self.g
        # second derivative of the reference from a first-order filter on its rate
        if self._rate_f is None:
            self._rate_f = ref_rate_m_s
        k = 1.0 - math.exp(-dt_s / g.rate_filter_s)
        new_rate = self._rate_f + k * (ref_rate_m_s - self._rate_f)
        self._acc_f = (new_rate - self._rate_f) / dt_s
        self._rate_f = new_rate
        ref_acc = self._acc_f

        r = self.r_w
        e_l = length_m - ref_length_m
        alpha = (ref_rate_m_s - g.k_length_1_s * e_l) / r
        alpha_limited = min(max(alpha, -self.omega_max), self.omega_max)
        l_dot = r * omega_rad_s
        alpha_dot = (ref_acc - g.k_length_1_s * (l_dot - ref_rate_m_s)) / r
        if alpha_limited != alpha:
            alpha_dot = 0.0
        e_w = omega_rad_s - alpha_limited
        inertia = self.inertia_kg_m2(length_m)
        inertia_dot = -0.5 * self._rho * self._r2 * l_dot
        tau = (-r * drum_tension_n + self.beta * omega_rad_s + inertia * alpha_dot
               - 0.5 * inertia_dot * e_w - g.k_rate_n_m_s * e_w
               - g.length_stiffness_n_m * r * e_l)
        tau_limited = min(max(tau, -self.tau_max), self.tau_max)
        lyap = 0.5 * g.length_stiffness_n_m * e_l * e_l + 0.5 * inertia * e_w * e_w
        return WinderCommand(tau_limited, e_l, e_w, alpha_limited, lyap,
                             tau_limited != tau or alpha_limited != alpha)
