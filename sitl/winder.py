"""The ground winder: a drum with the tether wound on it, driven by a torque-controlled motor.

Sign convention: the drum angle ``theta`` [rad] and rate ``omega`` [rad/s] are positive in
the direction that pays tether out, so the paid-out (unstretched) length is
``L = r_w * theta`` and ``dL/dt = r_w * omega``; ``theta = 0`` is a full drum. A positive
motor torque pays out; the tether's tension at the drum pulls line off it, i.e. also acts
in the positive direction:

    I_w(L) * d(omega)/dt = tau_motor + r_w * T_drum - beta_w * omega (+ brake, hard stops)

with the paper's mass and inertia that shrink as tether leaves the drum:
``m_w = m_w_bar + (L_T - L) * rho`` and ``I_w = m_w (r_w^2 + r_i^2) / 2`` (plus the motor
rotor's inertia). The drum is treated as a control volume: line leaves it tangentially at
the drum's own surface speed, so it carries no net thrust and ``I_w * d(omega)/dt`` (not
``d(I_w omega)/dt``) is the right left-hand side.
"""

from __future__ import annotations

from sitl.kernel import (
    P_THETA_MAX,
    P_THETA_MIN,
    STOPPED_RAD_S,
    drum_acceleration,
    drum_inertia,
    drum_projection,
    motor_torque,
    pack_params,
)
from tuavdefs.params import SystemParams, TetherParams, WinderParams

__all__ = ["WinderModel", "STOPPED_RAD_S"]


class WinderModel:
    """Drum dynamics, motor torque limiting, brake and hard stops (the kernel's functions,
    callable one at a time)."""

    def __init__(self, winder: WinderParams, tether: TetherParams) -> None:
        self.p = winder
        self.r_w = winder.drum_radius_m
        self._packed = pack_params(SystemParams(winder=winder, tether=tether))
        #: The drum's own hard stops [rad] (full, empty).
        self.theta_min = float(self._packed[P_THETA_MIN])
        self.theta_max = float(self._packed[P_THETA_MAX])

    def set_stops(self, theta_min: float, theta_max: float) -> None:
        """The stops acting from now on [rad] (a snagged tether closes them on the drum's
        angle: sitl.faults); :attr:`theta_min` and :attr:`theta_max` stay the drum's own."""
        self._packed[P_THETA_MIN] = theta_min
        self._packed[P_THETA_MAX] = theta_max

    def length_m(self, theta_rad: float) -> float:
        """Paid-out unstretched tether length for a drum angle [m]."""
        return self.r_w * theta_rad

    def theta_rad(self, length_m: float) -> float:
        """Drum angle that has paid out ``length_m`` [rad]."""
        return length_m / self.r_w

    def inertia_kg_m2(self, length_m: float) -> float:
        """Drum, spooled tether and motor rotor inertia for a paid-out length [kg m^2]."""
        return float(drum_inertia(self._packed, float(length_m)))

    def motor_torque_n_m(self, command_n_m: float, omega_rad_s: float, enabled: bool) -> float:
        """Torque the motor actually applies [N m]: zero when disabled, clamped to the torque
        limit, and cut back near the speed limit as a torque-mode motor controller does
        (|tau| <= k_v (omega_max -+ omega) in each direction). NaN commands give zero."""
        return float(motor_torque(self._packed, float(command_n_m), float(omega_rad_s),
                                  bool(enabled)))

    def acceleration(self, theta: float, omega: float, motor_torque_n_m: float,
                     drum_tension_n: float, braked: bool) -> float:
        """d(omega)/dt [rad/s^2] for the drum state, applied motor torque and tension."""
        return float(drum_acceleration(self._packed, float(theta), float(omega),
                                       float(motor_torque_n_m), float(drum_tension_n),
                                       bool(braked)))

    def project(self, theta: float, omega: float, omega_before: float, braked: bool
                ) -> tuple[float, float]:
        """Constraints applied after an integration step: hard stops, and the brake's
        sticking when the rate crossed zero during the step."""
        return drum_projection(self._packed, float(theta), float(omega), float(omega_before),
                               bool(braked))


