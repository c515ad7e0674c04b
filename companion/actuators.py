"""The companion's model of its own motors: what the rotors are producing right now.

Command-filtered backstepping compares what a loop asked for with what its actuators
achieved (docs/control.md §1.3). The rotors lag their commands; this model runs each
commanded rotor speed through the first-order lag the vehicle's parameters give (discretised
exactly for a command held over the control step) and turns the modelled speeds into the
collective thrust and body torques.
"""

from __future__ import annotations

import math

import numpy as np

from tuavdefs.airframe import allocation_matrix, command_to_rotor_speed
from tuavdefs.params import VehicleParams


class ActuatorModel:
    """Modelled rotor speeds and the wrench they make."""

    def __init__(self, vehicle: VehicleParams, dt_s: float,
                 initial_speed_rad_s: float = 0.0) -> None:
        self.vehicle = vehicle
        self._a = allocation_matrix(vehicle)
        self._decay = math.exp(-dt_s / vehicle.motor_time_constant_s)
        self.speeds = np.full(4, initial_speed_rad_s)
        self._setpoints = self.speeds.copy()

    def reset(self, speeds_rad_s: np.ndarray | tuple[float, ...]) -> None:
        """Start from known rotor speeds [rad/s] (e.g. hover trim)."""
        self.speeds = np.array(speeds_rad_s, dtype=float)
        self._setpoints = self.speeds.copy()

    def command(self, commands: tuple[float, ...], armed: bool = True) -> None:
        """The commands just sent; they hold until the next call to :meth:`advance`."""
        self._setpoints = np.array([command_to_rotor_speed(c, self.vehicle, armed)
                                    for c in commands])

    def advance(self) -> None:
        """Move the modelled speeds one control step toward the held set-points."""
        self.speeds = self._setpoints + (self.speeds - self._setpoints) * self._decay

    def wrench(self) -> tuple[float, tuple[float, float, float]]:
        """(collective thrust [N], body torques [N m]) of the modelled rotor speeds."""
        w = self._a @ (self.vehicle.rotor_thrust_coeff * self.speeds ** 2)
        return float(w[0]), (float(w[1]), float(w[2]), float(w[3]))
