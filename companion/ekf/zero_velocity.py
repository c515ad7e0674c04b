"""The stationary constraint: a vehicle at rest on its gear (landed and disarmed, as the
caller knows) has zero velocity, and the gear's height; fused ungated, as EKF2 and EKF3
do on the ground without GNSS, so that the estimate does not drift."""

from __future__ import annotations

import math

import numpy as np

from companion.ekf.aid_source import AidSourceStatus
from companion.ekf.layout import (
    FUSED,
    IDX_P,
    IDX_V,
    N_ERR,
    NUMERIC,
    NX,
    PRM_VAR_MIN,
    W_DX,
    W_PRM,
    W_X,
    X_P,
    X_V,
)
from companion.ekf.memory import FilterMemory
from companion.ekf.output import take_up
from companion.ekf.params import EstimatorParams
from companion.ekf.update import inject, scalar_update
from tuavdefs.jit import entry_point, njit


@njit
def fuse_zero_velocity_kernel(w: np.ndarray, P: np.ndarray, buf: np.ndarray,
                              meta: np.ndarray, r: float, height_m: float,
                              r_height: float) -> bool:
    """A zero velocity of now on each axis with noise variance ``r`` [m^2/s^2], and with
    ``r_height`` > 0 the height ``height_m`` [m] with that variance [m^2], ungated; the
    correction taken up by the output. Returns whether every update was applied."""
    x = w[W_X:W_X + NX]
    dx = w[W_DX:W_DX + N_ERR]
    var_min = w[W_PRM + PRM_VAR_MIN]
    before = w[W_X:W_X + 6].copy()
    ok = True
    for i in range(3):
        ok = scalar_update(P, dx, var_min, -x[X_V + i], r, IDX_V + i, 1.0, -1, 0.0, -1,
                           0.0) and ok
    if r_height > 0.0:
        ok = scalar_update(P, dx, var_min, height_m - x[X_P + 2], r_height, IDX_P + 2, 1.0,
                           -1, 0.0, -1, 0.0) and ok
    inject(x, dx, buf, meta)
    take_up(w, before)
    return ok


class ZeroVelocityControl:
    """Fuses the stationary constraint at most every ``stationary_interval_s``."""

    __slots__ = ("_p", "_mem", "_st", "_k")

    def __init__(self, params: EstimatorParams, mem: FilterMemory,
                 status: AidSourceStatus) -> None:
        self._p = params
        self._mem = mem
        self._st = status
        self._k = entry_point(fuse_zero_velocity_kernel, mem.w, mem.P, mem.buf, mem.meta,
                              0.0, 0.0, 0.0)

    def fuse(self, t_s: float, height_m: float | None) -> bool:
        """At rest at ``t_s`` [s], at the height ``height_m`` [m] (None: not known).
        Returns whether it was fused."""
        st = self._st
        if st.too_soon(t_s):
            return False
        st.time_last_attempt = t_s
        p, m = self._p, self._mem
        use_height = height_m is not None and math.isfinite(height_m)
        ok = self._k(m.w, m.P, m.buf, m.meta, p.stationary_vel_noise_m_s ** 2,
                     float(height_m) if use_height else 0.0,
                     p.ground_height_noise_m ** 2 if use_height else 0.0)
        st.record(t_s, FUSED if ok else NUMERIC)
        return bool(ok)
