"""The ground station's winder control step: from the winch's measurements and the UAV's
telemetry to the motor's torque request.

What the ground-station process runs for every encoder frame it receives, and what the
offline runner runs in-process: L-bar and its rate from the UAV's position and velocity
(`groundstation.lbar`), then the backstepping torque law (`groundstation.winder_control`).
"""

from __future__ import annotations

from typing import NamedTuple

from groundstation.lbar import LBarEstimator, LBarParams
from groundstation.winder_control import WinderCommand, WinderController, WinderControlParams
from tuavdefs.params import TetherParams, WinderParams


class WinderStep(NamedTuple):
    """One winder control step's output."""

    torque_n_m: float
    lbar_m: float
    lbar_rate_m_s: float
    command: WinderCommand


class WinderHost:
    """L-bar estimator + winder torque law, at ``gains.rate_hz``."""

    def __init__(self, gains: WinderControlParams, lbar: LBarParams, winder: WinderParams,
                 tether: TetherParams, gravity_m_s2: float) -> None:
        self.dt_s = 1.0 / gains.rate_hz
        self.lbar = LBarEstimator(lbar, tether.weight_per_length_n_m(gravity_m_s2))
        self.controller = WinderController(gains, winder, tether)

    def update(self, length_m: float, omega_rad_s: float, drum_tension_n: float,
               uav_pos_m: tuple[float, float, float],
               uav_vel_m_s: tuple[float, float, float]) -> WinderStep:
        """Torque request [N m] for the measured length [m], drum rate [rad/s] and drum
        tension [N], and the UAV's position [m] and velocity [m/s]."""
        lb = self.lbar.estimate(uav_pos_m, uav_vel_m_s)
        cmd = self.controller.update(self.dt_s, length_m, omega_rad_s, drum_tension_n,
                                     lb.length_m, lb.rate_m_s)
        return WinderStep(cmd.torque_n_m, lb.length_m, lb.rate_m_s, cmd)
