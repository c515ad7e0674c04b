"""The X-quadrotor airframe: rotor order, geometry, and what a rotor command means.

This is the actuator *interface* shared by the plant and the companion: the order of the
four normalised commands (as in HIL_ACTUATOR_CONTROLS), where each rotor sits, which way it
spins, and how a command in [0, 1] maps to a rotor-speed set-point. The plant computes the
forces of the rotors it simulates from these definitions and its own rotor-speed states;
the companion uses :class:`Mixer` to turn a wrench into commands.

Rotor order is PX4's and ArduPilot's "quad X": 1 front-right (CCW), 2 back-left (CCW),
3 front-left (CW), 4 back-right (CW). In the body frame (x forward, y left, z up) rotor i
sits at (sx_i, sy_i) * arm / sqrt(2) and produces thrust T_i = k_f * Omega_i^2 along +z and a
reaction torque -spin_i * k_m * Omega_i^2 about +z (spin +1 = counter-clockwise from above).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from tuavdefs.params import VehicleParams

#: (x sign, y sign, spin) of rotors 1..4 in the body frame (x forward, y left, z up).
ROTOR_LAYOUT: tuple[tuple[float, float, float], ...] = (
    (1.0, -1.0, 1.0),    # 1 front-right, CCW
    (-1.0, 1.0, 1.0),    # 2 back-left, CCW
    (1.0, 1.0, -1.0),    # 3 front-left, CW
    (-1.0, -1.0, -1.0),  # 4 back-right, CW
)


def command_to_rotor_speed(command: float, vehicle: VehicleParams, armed: bool) -> float:
    """Rotor-speed set-point [rad/s] for a normalised command in [0, 1].

    Disarmed rotors stop. Armed rotors idle at the minimum speed for command 0 and reach the
    maximum for 1; the speed is linear in the command, as an ESC's is. Out-of-range and NaN
    commands are clamped (NaN to 0).
    """
    if not armed:
        return 0.0
    c = 0.0 if math.isnan(command) else min(max(command, 0.0), 1.0)  # NaN -> 0
    lo, hi = vehicle.rotor_speed_min_rad_s, vehicle.rotor_speed_max_rad_s
    return lo + c * (hi - lo)


def rotor_speed_to_command(speed_rad_s: float, vehicle: VehicleParams) -> float:
    """The command in [0, 1] whose set-point is ``speed_rad_s`` (clamped)."""
    lo, hi = vehicle.rotor_speed_min_rad_s, vehicle.rotor_speed_max_rad_s
    return min(max((speed_rad_s - lo) / (hi - lo), 0.0), 1.0)


def allocation_matrix(vehicle: VehicleParams) -> np.ndarray:
    """A (4x4) with [U, tau_x, tau_y, tau_z] = A @ [T_1..T_4]: rotor thrusts [N] to the
    collective thrust [N] and body torques [N m] (body x forward, y left, z up)."""
    d = vehicle.arm_length_m / math.sqrt(2.0)
    ratio = vehicle.rotor_torque_coeff / vehicle.rotor_thrust_coeff
    a = np.zeros((4, 4))
    for i, (sx, sy, spin) in enumerate(ROTOR_LAYOUT):
        a[0, i] = 1.0
        a[1, i] = sy * d          # r x F, F along +z: tau_x = y * T
        a[2, i] = -sx * d         # tau_y = -x * T
        a[3, i] = -spin * ratio   # reaction torque opposes the rotor's spin
    return a


class MixerOutput(NamedTuple):
    """Rotor commands in [0, 1] and whether the request had to be cut back."""

    commands: tuple[float, float, float, float]
    saturated: bool


class Mixer:
    """Collective thrust and body torques to the four normalised rotor commands.

    When the request is outside what the rotors can give, yaw torque is given up first,
    then roll/pitch torque is scaled down keeping the collective thrust, so attitude
    control keeps authority: the usual priority of multirotor mixers.
    """

    def __init__(self, vehicle: VehicleParams) -> None:
        self.vehicle = vehicle
        self._inv = np.linalg.inv(allocation_matrix(vehicle))
        self._t_min = vehicle.rotor_thrust_coeff * vehicle.rotor_speed_min_rad_s ** 2
        self._t_max = vehicle.rotor_thrust_coeff * vehicle.rotor_speed_max_rad_s ** 2

    def rotor_thrusts(self, thrust_n: float, torque_n_m: tuple[float, float, float]
                      ) -> np.ndarray:
        """Unconstrained per-rotor thrusts [N] that give exactly the requested wrench."""
        return self._inv @ np.array([thrust_n, torque_n_m[0], torque_n_m[1], torque_n_m[2]])

    def mix(self, thrust_n: float, torque_n_m: tuple[float, float, float]) -> MixerOutput:
        """Commands for collective thrust ``thrust_n`` [N] and body torques [N m]."""
        lo, hi = self._t_min, self._t_max
        u = min(max(thrust_n, 4 * lo), 4 * hi)
        saturated = u != thrust_n
        t = self.rotor_thrusts(u, torque_n_m)
        if t.min() < lo - 1e-9 or t.max() > hi + 1e-9:
            saturated = True
            t = self._fit(u, torque_n_m, lo, hi)
        speeds = np.sqrt(np.clip(t, lo, hi) / self.vehicle.rotor_thrust_coeff)
        cmds = tuple(rotor_speed_to_command(float(s), self.vehicle) for s in speeds)
        return MixerOutput(cmds, saturated)  # type: ignore[arg-type]

    def _fit(self, u: float, tau: tuple[float, float, float], lo: float, hi: float
             ) -> np.ndarray:
        base = self.rotor_thrusts(u, (0.0, 0.0, 0.0))
        rp = self.rotor_thrusts(0.0, (tau[0], tau[1], 0.0))
        yaw = self.rotor_thrusts(0.0, (0.0, 0.0, tau[2]))
        s_rp = _largest_scale(base, rp, lo, hi)
        with_rp = base + s_rp * rp
        s_yaw = _largest_scale(with_rp, yaw, lo, hi) if s_rp >= 1.0 else 0.0
        return with_rp + s_yaw * yaw


def _largest_scale(base: np.ndarray, delta: np.ndarray, lo: float, hi: float) -> float:
    """Largest s in [0, 1] with lo <= base + s * delta <= hi element-wise."""
    s = 1.0
    for b, d in zip(base, delta, strict=True):
        if d > 1e-12:
            s = min(s, (hi - b) / d)
        elif d < -1e-12:
            s = min(s, (lo - b) / d)
    return max(s, 0.0)
