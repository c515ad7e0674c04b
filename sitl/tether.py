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

from sitl._jit import njit
from sitl.catenary import (
    REGIMES,
    CatenaryConvergenceError,
    CatenaryInfo,
    CatenaryInputError,
    _solve,
    catenary_profile,
)
from sitl.pymath import hypot2
from tuavdefs.jit import F64, Signature, entry_point
from tuavdefs.params import TetherParams

__all__ = ["Tether", "TetherForces", "tether_forces_kernel"]

Vec3 = tuple[float, float, float]
#: A record built as the tuple it is (tuple.__new__), without its Python-level constructor
_new = tuple.__new__


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
        # the solve's machine code, loaded now and called without numba's dispatch (its
        # arguments are always floats)
        self._solve = entry_point(tether_forces_kernel, SOLVE_SIGNATURE)

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
        if not (-math.inf < x_m < math.inf and -math.inf < y_m < math.inf
                and 0.0 <= z_m < math.inf and 0.0 < length_m < math.inf):
            self._geometry(x_m, y_m, z_m, length_m)   # raises, naming the bad argument
        r = self._solve(float(x_m), float(y_m), float(z_m), float(length_m), self.ea_n,
                        self.w_n_per_m, self._hf0, self._vf0)
        if not r[-1]:
            span = math.hypot(x_m, y_m)
            raise CatenaryConvergenceError(
                f"catenary did not converge: span_m={span!r}, height_m={z_m!r}, "
                f"length_m={length_m!r}, ea_n={self.ea_n!r}, w_n_per_m={self.w_n_per_m!r}, "
                f"hf0={self._hf0!r}, vf0={self._vf0!r}")
        return self.accept(r)

    def accept(self, r: tuple) -> TetherForces:
        """The :class:`TetherForces` of a converged :func:`tether_forces_kernel` result
        (computed from this tether's warm start), which becomes the next warm start."""
        (ux_n, uy_n, uz_n, ex_n, ey_n, ez_n, drum_n, top_n, H, V, HA, VA, lbot, reg, it,
         low, warm, _) = r
        # (the records built as the tuples they are, without their Python-level
        # constructors: this runs for every read-out)
        info = _new(CatenaryInfo, (H, V, HA, VA, lbot, REGIMES[reg], it, low, warm))
        self._hf0 = H
        self._vf0 = V
        self.last_info = info
        return _new(TetherForces, ((ux_n, uy_n, uz_n), (ex_n, ey_n, ez_n), drum_n, top_n,
                                   info))

    def shape(self, x_m: float, y_m: float, z_m: float, length_m: float,
              n_points: int = 50) -> np.ndarray:
        """Points along the stretched tether from the exit point to the UAV, for drawing: an
        (n_points, 3) array [m] in the inertial frame, including the part lying on the ground.
        Uses, but does not update, the warm start of :meth:`forces`."""
        span, ux, uy = self._geometry(x_m, y_m, z_m, length_m)
        s, z = catenary_profile(span, z_m, length_m, self.ea_n, self.w_n_per_m, n_points,
                                self._hf0, self._vf0)
        return np.column_stack((s * ux, s * uy, z))


#: Relative Newton step at which a solve stops (catenary_end_forces' default).
_TOL = 1e-8
#: :func:`tether_forces_kernel`'s arguments.
SOLVE_SIGNATURE = Signature(F64, F64, F64, F64, F64, F64, F64, F64)


@njit
def tether_forces_kernel(x_m: float, y_m: float, z_m: float, length_m: float, ea_n: float,
                   w_n_per_m: float, hf0: float, vf0: float) -> tuple:
    """:meth:`Tether.forces` on valid inputs, in one compiled call: the force on the UAV
    (x, y, z) and on the exit (x, y, z) [N], the drum and top tensions [N], then
    :func:`sitl.catenary._solve`'s results (H, V, HA, VA [N], length on the ground [m],
    regime, iterations, lowest point [m], warm started, converged). The same arithmetic as
    :func:`sitl.catenary.catenary_end_forces` and CPython's ``math.hypot``
    (:mod:`sitl.pymath`), so the same bits."""
    span = hypot2(x_m, y_m)
    if span > 0.0:
        ux = x_m / span
        uy = y_m / span
    else:
        span, ux, uy = 0.0, 0.0, 0.0
    H, V, HA, VA, lbot, reg, it, low, warm, ok = _solve(span, z_m, length_m, ea_n,
                                                        w_n_per_m, hf0, vf0, _TOL)
    fah, fav, fbh, fbv = HA, VA, -H, -V
    return (fbh * ux, fbh * uy, fbv, fah * ux, fah * uy, fav, hypot2(fah, fav),
            hypot2(fbh, fbv), H, V, HA, VA, lbot, reg, it, low, warm, ok)
