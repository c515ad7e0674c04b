"""The winch's tether-exit angle sensor: a guide arm at the fairlead with two encoders.

The arm follows the tether where it leaves the winder; one encoder reads its azimuth (the
tether's horizontal direction, counter-clockwise from the winder frame's x axis, east), the
other its elevation above the horizontal. The truth is the direction of the tether's pull
on the exit point (``sitl.tether.TetherForces.on_exit_n``: the catenary's exit slope, or the
lumped line's first segment). Each reading carries a turn-on bias per axis drawn once (the
arm's mounting and zero offsets), white noise (the arm's play, the line's flutter) and the
encoder's quantisation. The azimuth of a line standing straight up, or of a line with no
pull on it, is not defined: the reading is then marked invalid (the arm does not know).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from tuavdefs.frames import Vec3
from tuavdefs.paramspec import Params, quantity

_TWO_PI = 2.0 * math.pi
#: Readings whose noise is drawn at once.
_BLOCK = 256


@dataclass(frozen=True)
class ExitAngleSensorParams(Params):
    """The guide arm's encoders (a 14-bit magnetic encoder on each axis)."""

    resolution_rad: float = quantity(
        _TWO_PI / 16384, "rad", "one count of each encoder (14 bits per turn: 0.38 mrad)",
        ge=0)
    noise_rad: float = quantity(
        1.0e-3, "rad", "white noise of each angle (the arm's play, the line's flutter)", ge=0)
    bias_sigma_rad: float = quantity(
        2.0e-3, "rad", "standard deviation of each axis's turn-on bias (mounting, zero "
        "offset), drawn once", ge=0)
    min_tension_n: float = quantity(
        0.01, "N", "below this pull the arm does not follow the line: the reading is "
        "invalid", ge=0)
    seed: int = quantity(7, "", "seed of the bias and the noise", ge=0)


class ExitAngleSensor:
    """Azimuth and elevation [rad] of the tether at the exit, as the encoders read them."""

    def __init__(self, params: ExitAngleSensorParams | None = None) -> None:
        self.p = p = params or ExitAngleSensorParams()
        self._rng = np.random.default_rng(p.seed)
        self.azimuth_bias_rad = float(self._rng.normal(0.0, p.bias_sigma_rad))
        self.elevation_bias_rad = float(self._rng.normal(0.0, p.bias_sigma_rad))
        # the white noise drawn in blocks (the same stream as a pair a reading)
        self._noise: list[float] = []
        self._next = 0

    def read(self, on_exit_n: Vec3) -> tuple[float, float, bool]:
        """(azimuth [rad] in -pi..pi, elevation [rad], valid) for the tether's pull on the
        exit point ``on_exit_n`` [N] (inertial, z up)."""
        fx, fy, fz = on_exit_n
        horizontal = math.hypot(fx, fy)
        tension = math.hypot(horizontal, fz)
        p = self.p
        if p.noise_rad > 0:
            i = self._next
            if i >= len(self._noise):
                self._noise = self._rng.normal(0.0, p.noise_rad, 2 * _BLOCK).tolist()
                i = 0
            n_az, n_el = self._noise[i], self._noise[i + 1]
            self._next = i + 2
        else:
            n_az = n_el = 0.0
        if not (math.isfinite(tension) and tension >= max(p.min_tension_n, 1e-12)):
            return 0.0, 0.0, False
        elevation = math.atan2(fz, horizontal) + self.elevation_bias_rad + n_el
        # a line within a milliradian of the vertical leaves the azimuth undefined
        valid = horizontal > 1e-3 * tension
        azimuth = (math.atan2(fy, fx) if valid else 0.0) + self.azimuth_bias_rad + n_az
        q = p.resolution_rad
        if q > 0.0:
            azimuth, elevation = round(azimuth / q) * q, round(elevation / q) * q
        return math.remainder(azimuth, _TWO_PI), elevation, valid
