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

from tuavdefs.airframe import allocation_matrix, rotor_speed_setpoints
from tuavdefs.jit import F64, array, njit, record, vec
from tuavdefs.params import VehicleParams


class ActuatorModel:
    """Modelled rotor speeds and the wrench they make."""

    #: The type of :attr:`packed` (:class:`tuavdefs.jit.Signature` texts).
    RECORD = record(vec(4, F64), array(2), array(), array())

    def __init__(self, vehicle: VehicleParams, dt_s: float,
                 initial_speed_rad_s: float = 0.0) -> None:
        self.vehicle = vehicle
        self._a = allocation_matrix(vehicle)
        self._decay = math.exp(-dt_s / vehicle.motor_time_constant_s)
        self.speeds = np.full(4, initial_speed_rad_s)
        self._setpoints = self.speeds.copy()

    def reset(self, speeds_rad_s: np.ndarray | tuple[float, ...]) -> None:
        """Start from known rotor speeds [rad/s] (e.g. hover trim)."""
        self.speeds[:] = speeds_rad_s      # (in place: a packed record holding them stays
        self._setpoints[:] = self.speeds   # good)

    def command(self, commands: tuple[float, ...], armed: bool = True) -> None:
        """The commands just sent; they hold until the next call to :meth:`advance`."""
        c0, c1, c2, c3 = commands
        v = self.vehicle
        rotor_speed_setpoints(self._setpoints, c0, c1, c2, c3, bool(armed),
                              v.rotor_speed_min_rad_s, v.rotor_speed_max_rad_s)

    def advance(self) -> None:
        """Move the modelled speeds one control step toward the held set-points."""
        advance_kernel(self.speeds, self._setpoints, self._decay)

    @property
    def packed(self) -> tuple[tuple[float, float, float, float], np.ndarray, np.ndarray,
                              np.ndarray]:
        """This model for a compiled step (:attr:`RECORD`): (k_f, the lag's decay over a
        step, the least and greatest rotor speed [rad/s]), the allocation matrix, the
        modelled speeds and the held set-points [rad/s] (updated in place)."""
        v = self.vehicle
        return ((v.rotor_thrust_coeff, self._decay, v.rotor_speed_min_rad_s,
                 v.rotor_speed_max_rad_s), self._a, self.speeds, self._setpoints)

    def wrench(self) -> tuple[float, tuple[float, float, float]]:
        """(collective thrust [N], body torques [N m]) of the modelled rotor speeds."""
        u, tx, ty, tz = wrench_kernel(self._a, self.vehicle.rotor_thrust_coeff, self.speeds)
        return u, (tx, ty, tz)


@njit
def advance_kernel(speeds: np.ndarray, setpoints: np.ndarray, decay: float) -> None:
    """First-order lag over one step with the set-points held (exact), in place."""
    for i in range(4):
        speeds[i] = setpoints[i] + (speeds[i] - setpoints[i]) * decay


@njit
def wrench_kernel(a: np.ndarray, kf: float, speeds: np.ndarray
            ) -> tuple[float, float, float, float]:
    """a @ (k_f speeds^2): collective thrust and body torques."""
    t0, t1 = kf * speeds[0] ** 2, kf * speeds[1] ** 2
    t2, t3 = kf * speeds[2] ** 2, kf * speeds[3] ** 2
    return (a[0, 0] * t0 + a[0, 1] * t1 + a[0, 2] * t2 + a[0, 3] * t3,
            a[1, 0] * t0 + a[1, 1] * t1 + a[1, 2] * t2 + a[1, 3] * t3,
            a[2, 0] * t0 + a[2, 1] * t1 + a[2, 2] * t2 + a[2, 3] * t3,
            a[3, 0] * t0 + a[3, 1] * t1 + a[3, 2] * t2 + a[3, 3] * t3)
