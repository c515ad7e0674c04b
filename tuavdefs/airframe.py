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

from tuavdefs.jit import array, njit, record
from tuavdefs.params import VehicleParams

Vec4 = tuple[float, float, float, float]

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
    return rotor_speed_setpoint(command, vehicle.rotor_speed_min_rad_s,
                                vehicle.rotor_speed_max_rad_s)


@njit
def rotor_speed_setpoint(command: float, lo: float, hi: float) -> float:
    """:func:`command_to_rotor_speed` of an armed rotor idling at ``lo``, full at ``hi``."""
    c = 0.0 if math.isnan(command) else min(max(command, 0.0), 1.0)  # NaN -> 0
    return lo + c * (hi - lo)


@njit
def rotor_speed_setpoints(out: np.ndarray, c0: float, c1: float, c2: float, c3: float,
                          armed: bool, lo: float, hi: float) -> None:
    """The set-points of four commands (:func:`command_to_rotor_speed`), into ``out``."""
    if not armed:
        out[:] = 0.0
        return
    out[0] = rotor_speed_setpoint(c0, lo, hi)
    out[1] = rotor_speed_setpoint(c1, lo, hi)
    out[2] = rotor_speed_setpoint(c2, lo, hi)
    out[3] = rotor_speed_setpoint(c3, lo, hi)


def rotor_speed_to_command(speed_rad_s: float, vehicle: VehicleParams) -> float:
    """The command in [0, 1] whose set-point is ``speed_rad_s`` (clamped)."""
    return _speed_to_command(speed_rad_s, vehicle.rotor_speed_min_rad_s,
                             vehicle.rotor_speed_max_rad_s)


@njit
def _speed_to_command(speed_rad_s: float, lo: float, hi: float) -> float:
    """:func:`rotor_speed_to_command` for the speed range [``lo``, ``hi``]."""
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
        self._pack()

    def _pack(self) -> None:
        """Thrust limits, k_f and the speed range, packed for the compiled mixer."""
        v = self.vehicle
        self._p = np.array([self._t_min, self._t_max, v.rotor_thrust_coeff,
                            v.rotor_speed_min_rad_s, v.rotor_speed_max_rad_s], dtype=float)
        self._packed_from = (self._t_min, self._t_max, v)

    def params(self) -> np.ndarray:
        """The packed parameters of :func:`mix_kernel`, packed again if an attribute they
        come from was replaced."""
        f = self._packed_from
        if self._t_min is not f[0] or self._t_max is not f[1] or self.vehicle is not f[2]:
            self._pack()
        return self._p

    #: The type of :attr:`packed` (:class:`tuavdefs.jit.Signature` texts).
    RECORD = record(array(2), array())

    @property
    def packed(self) -> tuple[np.ndarray, np.ndarray]:
        """What :func:`mix_kernel` takes of this mixer (:attr:`RECORD`): the allocation
        matrix's inverse and the packed parameters (:meth:`params`)."""
        return self._inv, self.params()

    def rotor_thrusts(self, thrust_n: float, torque_n_m: tuple[float, float, float]
                      ) -> np.ndarray:
        """Unconstrained per-rotor thrusts [N] that give exactly the requested wrench."""
        return np.array(_rotor_thrusts(self._inv, thrust_n, torque_n_m[0], torque_n_m[1],
                                       torque_n_m[2]))

    def mix(self, thrust_n: float, torque_n_m: tuple[float, float, float]) -> MixerOutput:
        """Commands for collective thrust ``thrust_n`` [N] and body torques [N m]."""
        c0, c1, c2, c3, saturated = mix_kernel(self._inv, self.params(), thrust_n,
                                               torque_n_m[0], torque_n_m[1], torque_n_m[2])
        return MixerOutput((c0, c1, c2, c3), saturated)


@njit
def _rotor_thrusts(inv: np.ndarray, u: float, tx: float, ty: float, tz: float) -> Vec4:
    """inv @ (u, tx, ty, tz): the rotor thrusts of a wrench (``inv`` the allocation
    matrix's inverse)."""
    return (inv[0, 0] * u + inv[0, 1] * tx + inv[0, 2] * ty + inv[0, 3] * tz,
            inv[1, 0] * u + inv[1, 1] * tx + inv[1, 2] * ty + inv[1, 3] * tz,
            inv[2, 0] * u + inv[2, 1] * tx + inv[2, 2] * ty + inv[2, 3] * tz,
            inv[3, 0] * u + inv[3, 1] * tx + inv[3, 2] * ty + inv[3, 3] * tz)


@njit
def mix_kernel(inv: np.ndarray, p: np.ndarray, thrust_n: float, tx: float, ty: float, tz: float
         ) -> tuple[float, float, float, float, bool]:
    """:meth:`Mixer.mix` in scalars: the four commands and whether the request was cut
    back. ``p`` = (least and greatest rotor thrust, k_f, least and greatest rotor speed)."""
    lo, hi, kf = p[0], p[1], p[2]
    u = min(max(thrust_n, 4 * lo), 4 * hi)
    saturated = u != thrust_n
    t = _rotor_thrusts(inv, u, tx, ty, tz)
    if (t[0] < lo - 1e-9 or t[1] < lo - 1e-9 or t[2] < lo - 1e-9 or t[3] < lo - 1e-9
            or t[0] > hi + 1e-9 or t[1] > hi + 1e-9 or t[2] > hi + 1e-9
            or t[3] > hi + 1e-9):
        saturated = True
        t = _fit(inv, u, tx, ty, tz, lo, hi)
    return (_speed_to_command(math.sqrt(min(max(t[0], lo), hi) / kf), p[3], p[4]),
            _speed_to_command(math.sqrt(min(max(t[1], lo), hi) / kf), p[3], p[4]),
            _speed_to_command(math.sqrt(min(max(t[2], lo), hi) / kf), p[3], p[4]),
            _speed_to_command(math.sqrt(min(max(t[3], lo), hi) / kf), p[3], p[4]),
            saturated)


@njit
def _fit(inv: np.ndarray, u: float, tx: float, ty: float, tz: float, lo: float, hi: float
         ) -> Vec4:
    """Rotor thrusts within [lo, hi] keeping the collective thrust: roll/pitch torque
    scaled down first, yaw torque only with what is left."""
    base = _rotor_thrusts(inv, u, 0.0, 0.0, 0.0)
    rp = _rotor_thrusts(inv, 0.0, tx, ty, 0.0)
    yaw = _rotor_thrusts(inv, 0.0, 0.0, 0.0, tz)
    s_rp = _largest_scale(base, rp, lo, hi)
    with_rp = (base[0] + s_rp * rp[0], base[1] + s_rp * rp[1], base[2] + s_rp * rp[2],
               base[3] + s_rp * rp[3])
    s_yaw = _largest_scale(with_rp, yaw, lo, hi) if s_rp >= 1.0 else 0.0
    return (with_rp[0] + s_yaw * yaw[0], with_rp[1] + s_yaw * yaw[1],
            with_rp[2] + s_yaw * yaw[2], with_rp[3] + s_yaw * yaw[3])


@njit
def _largest_scale(base: Vec4, delta: Vec4, lo: float, hi: float) -> float:
    """Largest s in [0, 1] with lo <= base + s * delta <= hi element-wise."""
    s = 1.0
    for i in range(4):
        b, d = base[i], delta[i]
        if d > 1e-12:
            s = min(s, (hi - b) / d)
        elif d < -1e-12:
            s = min(s, (lo - b) / d)
    return max(s, 0.0)
