"""Parameters of the onboard flight controller: gains, limits, rates.

Loaded from TOML like every parameter group (``tuavdefs.paramspec``); these are also the
values a ground station reads and changes through the MAVLink parameter protocol.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from tuavdefs.paramspec import Params, quantity


@dataclass(frozen=True)
class FlightControlParams(Params):
    """Backstepping position and attitude control of the UAV (docs/control.md)."""

    rate_hz: float = quantity(250.0, "Hz", "control-loop rate", gt=0, le=2000)
    pos_k1_1_s: tuple[float, ...] = quantity(
        (1.6, 1.6, 2.0), "1/s", "position error gain K1 (x, y, z): alpha1 = v_ref - K1 e1",
        gt=0, length=3)
    pos_k2_1_s: tuple[float, ...] = quantity(
        (2.6, 2.6, 3.0), "1/s", "velocity error gain K2 (x, y, z)", gt=0, length=3)
    disturbance_gain_1_s2: tuple[float, ...] = quantity(
        (3.0, 3.0, 1.0), "1/s^2", "adaptation gain Gamma of the disturbance estimate",
        ge=0, length=3)
    disturbance_limit_m_s2: float = quantity(
        8.0, "m/s^2", "bound on the disturbance estimate (projection, anti-windup)", gt=0)
    max_tilt_rad: float = quantity(
        math.radians(35.0), "rad", "largest tilt of the thrust from vertical", gt=0,
        lt=math.pi / 2)
    max_thrust_fraction: float = quantity(
        0.9, "1", "share of the rotors' maximum thrust the position loop may ask for",
        gt=0, le=1)
    att_k3_1_s: tuple[float, ...] = quantity(
        (7.0, 7.0, 3.0), "1/s", "attitude error gain K3 (roll, pitch, yaw)", gt=0, length=3)
    att_k4_n_m_s: tuple[float, ...] = quantity(
        (7.0, 7.0, 0.6), "N*m*s/rad", "body-rate error gain K4 (x, y, z)", gt=0, length=3)
    att_disturbance_gain_n_m_rad: tuple[float, ...] = quantity(
        (5.0, 5.0, 0.5), "N*m/rad", "adaptation gain Gamma_tau of the disturbance-torque "
        "estimate (x, y, z): d(tau_hat)/dt = Gamma_tau e_w_bar (integral action); 0 turns "
        "it off", ge=0, length=3)
    att_disturbance_limit_n_m: float = quantity(
        2.0, "N*m", "bound on the disturbance-torque estimate (projection, anti-windup)",
        gt=0)
    command_filter_hz: float = quantity(
        6.0, "Hz", "natural frequency of the attitude command filter", gt=0)
    command_filter_damping: float = quantity(
        1.0, "1", "damping ratio of the attitude command filter", gt=0)
    command_filter_pole_hz: float = quantity(
        12.0, "Hz", "the attitude command filter's first-order pole ahead of its second-"
        "order part: the command's second derivative becomes a state, not a gain of wn^2 "
        "on a noisy command (0: the second-order filter alone)", ge=0)
    use_tether_model: bool = quantity(
        True, "", "compensate the tether's pull with the onboard catenary model")
    use_measured_tension: bool = quantity(
        True, "", "scale the modelled pull by the tension the winder reports")
