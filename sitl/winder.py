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

from tuavdefs.params import TetherParams, WinderParams

#: Drum rates below this [rad/s] count as stopped for the brake and the hard stops.
STOPPED_RAD_S = 1e-6


class WinderModel:
    """Drum dynamics, motor torque limiting, brake and hard stops."""

    def __init__(self, winder: WinderParams, tether: TetherParams) -> None:
        self.p = winder
        self.r_w = winder.drum_radius_m
        self.theta_min = winder.min_paid_out_m / winder.drum_radius_m
        self.theta_max = tether.total_length_m / winder.drum_radius_m
        self._rho = tether.linear_density_kg_m
        self._lt = tether.total_length_m
        self._radii_sq = winder.drum_radius_m ** 2 + winder.drum_inner_radius_m ** 2

    def length_m(self, theta_rad: float) -> float:
        """Paid-out unstretched tether length for a drum angle [m]."""
        return self.r_w * theta_rad

    def theta_rad(self, length_m: float) -> float:
        """Drum angle that has paid out ``length_m`` [rad]."""
        return length_m / self.r_w

    def inertia_kg_m2(self, length_m: float) -> float:
        """Drum, spooled tether and motor rotor inertia for a paid-out length [kg m^2]."""
        m_w = self.p.drum_mass_kg + max(self._lt - length_m, 0.0) * self._rho
        return 0.5 * m_w * self._radii_sq + self.p.rotor_inertia_kg_m2

    def motor_torque_n_m(self, command_n_m: float, omega_rad_s: float, enabled: bool) -> float:
        """Torque the motor actually applies [N m]: zero when disabled, clamped to the torque
        limit, and cut back near the speed limit as a torque-mode motor controller does
        (|tau| <= k_v (omega_max -+ omega) in each direction). NaN commands give zero."""
        if not enabled or command_n_m != command_n_m:
            return 0.0
        lim = self.p.motor_torque_limit_n_m
        tau = min(max(command_n_m, -lim), lim)
        kv, wmax = self.p.speed_limit_gain_n_m_s_rad, self.p.motor_speed_limit_rad_s
        tau = min(tau, kv * (wmax - omega_rad_s))
        return max(tau, kv * (-wmax - omega_rad_s))

    def acceleration(self, theta: float, omega: float, motor_torque_n_m: float,
                     drum_tension_n: float, braked: bool) -> float:
        """d(omega)/dt [rad/s^2] for the drum state, applied motor torque and tension."""
        inertia = self.inertia_kg_m2(self.r_w * theta)
        driving = motor_torque_n_m + self.r_w * drum_tension_n
        tau = driving - self.p.viscous_friction_n_m_s_rad * omega
        if braked:
            hold = self.p.brake_torque_n_m
            if abs(omega) <= STOPPED_RAD_S:
                if abs(driving) <= hold:
                    return 0.0  # static friction of the brake holds the drum
                tau -= hold if driving > 0 else -hold
            else:
                tau -= hold if omega > 0 else -hold
        acc = tau / inertia
        # hard stops: the drum cannot turn past a full or an empty drum
        if theta <= self.theta_min and omega <= STOPPED_RAD_S and acc < 0.0:
            return 0.0
        if theta >= self.theta_max and omega >= -STOPPED_RAD_S and acc > 0.0:
            return 0.0
        return acc

    def project(self, theta: float, omega: float, omega_before: float, braked: bool
                ) -> tuple[float, float]:
        """Constraints applied after an integration step: hard stops, and the brake's
        sticking when the rate crossed zero during the step."""
        if braked and omega_before != 0.0 and (omega > 0.0) != (omega_before > 0.0):
            omega = 0.0
        if theta < self.theta_min:
            theta, omega = self.theta_min, max(omega, 0.0)
        elif theta > self.theta_max:
            theta, omega = self.theta_max, min(omega, 0.0)
        return theta, omega
