"""The tether between the winder's exit point and the UAV, in 3-D.

Wraps the 2-D elastic catenary of :mod:`sitl.catenary` (bottom end on flat frictionless ground)
into the z-up inertial frame whose origin is the winder's tether exit point. The catenary lies
in the vertical plane through the exit point and the UAV attach point; its horizontal direction
is the unit vector from the exit point to the attach point projected on the ground.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from sitl.catenary import (
    CatenaryInfo,
    CatenaryInputError,
    catenary_end_forces,
    catenary_profile,
)
from tuavdefs.params import TetherParams

__all__ = ["Tether", "TetherForces"]

Vec3 = tuple[float, float, float]


class TetherForces(NamedTuple):
    """Forces of the tether on its two ends, inertial z-up frame [N].

    ``on_uav_n`` is the force on the UAV attach point, ``on_exit_n`` the force on the winder's
    exit point, ``drum_tension_n`` the tension at the exit point (the magnitude of
    ``on_exit_n``: what pulls line off the drum), ``top_tension_n`` the tension at the UAV (the
    magnitude of ``on_uav_n``), ``info`` the catenary solution.
    """

    on_uav_n: Vec3
    on_exit_n: Vec3
    drum_tension_n: float
    top_tension_n: float
    info: CatenaryInfo


class Tether:
    """Quasi-static elastic tether from the winder exit point (origin) to the UAV.

    Built from the project's :class:`~tuavdefs.params.TetherParams` and gravity [m/s^2]. Each
    solve is warm-started from the previous one (kept in the object); if a warm-started
    Newton iteration fails, :func:`~sitl.catenary.catenary_end_forces` retries it from a cold
    start by itself.
    """

    def __init__(self, params: TetherParams, gravity_m_s2: float) -> None:
        if not (gravity_m_s2 > 0.0 and math.isfinite(gravity_m_s2)):
            raise ValueError(f"gravity_m_s2: must be finite and > 0, got {gravity_m_s2!r}")
        self.params = params
        self.ea_n = float(params.axial_stiffness_n)
        self.w_n_per_m = float(params.weight_per_length_n_m(gravity_m_s2))
        self._hf0 = 0.0
        self._vf0 = 0.0
        self.last_info: CatenaryInfo | None = None

    def reset_warm_start(self) -> None:
        """Forget the previous solution: the next solve starts cold."""
        self._hf0 = 0.0
        self._vf0 = 0.0

    @property
    def warm_start(self) -> tuple[float, float]:
        """The (H, V) top tensions [N] the next solve starts from ((0, 0): a cold start)."""
        return self._hf0, self._vf0

    def _geometry(self, x_m: float, y_m: float, z_m: float,
                  length_m: float) -> tuple[float, float, float]:
        """Validates a configuration; returns (span, unit x, unit y) of the horizontal
        direction from the exit point to the UAV ((0, 0) when the span is zero)."""
        if not (-math.inf < x_m < math.inf):
            raise CatenaryInputError(f"x_m: must be finite, got {x_m!r}")
        if not (-math.inf < y_m < math.inf):
            raise CatenaryInputError(f"y_m: must be finite, got {y_m!r}")
        if not (0.0 <= z_m < math.inf):
            raise CatenaryInputError(
                f"z_m: the UAV attach point must be finite and at or above the exit point "
                f"(z_m >= 0), got {z_m!r}")
        if not (0.0 < length_m < math.inf):
            raise CatenaryInputError(f"length_m: must be finite and > 0, got {length_m!r}")
        span = math.hypot(x_m, y_m)
        if span > 0.0:
            return span, x_m / span, y_m / span
        return 0.0, 0.0, 0.0

    def forces(self, x_m: float, y_m: float, z_m: float, length_m: float) -> TetherForces:
        """Tether forces for the UAV attach point at (x_m, y_m, z_m) [m] relative to the exit
        point (inertial, z up) with ``length_m`` [m] of unstretched tether paid out.

        Raises :class:`~sitl.catenary.CatenaryInputError` for non-finite coordinates, z_m < 0
        or length_m <= 0.
        """
        span, ux, uy = self._geometry(x_m, y_m, z_m, length_m)
        fah, fav, fbh, fbv, info = catenary_end_forces(
            span, z_m, length_m, self.ea_n, self.w_n_per_m, self._hf0, self._vf0)
        self._hf0 = info.hf_n
        self._vf0 = info.vf_n
        self.last_info = info
        return TetherForces(
            (fbh * ux, fbh * uy, fbv),
            (fah * ux, fah * uy, fav),
            math.hypot(fah, fav),
            math.hypot(fbh, fbv),
            info,
        )

    def shape(self, x_m: float, y_m: float, z_m: float, length_m: float,
              n_points: int = 50) -> np.ndarray:
        """Points along the stretched tether from the exit point to the UAV, for drawing: an
        (n_points, 3) array [m] in the inertial frame, including the part lying on the ground.
        Uses, but does not update, the warm start of :meth:`forces`."""
        span, ux, uy = self._geometry(x_m, y_m, z_m, length_m)
        s, z = catenary_profile(span, z_m, length_m, self.ea_n, self.w_n_per_m, n_points,
                                self._hf0, self._vf0)
        return np.column_stack((s * ux, s * uy, z))
