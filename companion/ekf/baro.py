"""Barometric height: ``h = p_z + b_h`` above the reference taken at alignment (the
pressure altitude then minus the GNSS height), against the delayed state; its control."""

from __future__ import annotations

import math

import numpy as np

from companion.ekf.aid_source import AidSourceStatus
from companion.ekf.layout import (
    FUSED,
    IDX_BH,
    IDX_P,
    N_ERR,
    NUMERIC,
    NX,
    PRM_BARO_GATE,
    PRM_BARO_R,
    PRM_VAR_MIN,
    REJECTED,
    W_DELAYED,
    W_DX,
    W_PRM,
    W_X,
    X_BH,
    X_P,
    AidSourceKind,
)
from companion.ekf.memory import FilterMemory
from companion.ekf.output import take_up
from companion.ekf.params import EstimatorParams
from companion.ekf.update import delayed_state, inject, scalar_update, set_aid_row
from tuavdefs.jit import entry_point, njit

_BARO = int(AidSourceKind.BARO)
_Z, _IZ = X_P + 2, IDX_P + 2


@njit
def _fuse_baro(w: np.ndarray, P: np.ndarray, buf: np.ndarray, meta: np.ndarray,
               t_meas_s: float, height_m: float) -> int:
    x = w[W_X:W_X + NX]
    delayed = w[W_DELAYED:W_DELAYED + 6]
    r, gate = w[W_PRM + PRM_BARO_R], w[W_PRM + PRM_BARO_GATE]
    delayed_state(buf, meta, x, t_meas_s, delayed)
    y = height_m - (delayed[_Z] + x[X_BH])
    s = P[_IZ, _IZ] + 2.0 * P[_IZ, IDX_BH] + P[IDX_BH, IDX_BH] + r
    ratio = y * y / (s * gate * gate)
    set_aid_row(w, _BARO, y, 0.0, 0.0, s, 0.0, 0.0, ratio)
    if ratio > 1.0:
        return REJECTED
    dx = w[W_DX:W_DX + N_ERR]
    if not scalar_update(P, dx, w[W_PRM + PRM_VAR_MIN], y, r, _IZ, 1.0, IDX_BH, 1.0, -1,
                         0.0):
        return NUMERIC
    inject(x, dx, buf, meta)
    return FUSED


@njit
def fuse_baro_kernel(w: np.ndarray, P: np.ndarray, buf: np.ndarray, meta: np.ndarray,
                     t_meas_s: float, height_m: float) -> int:
    """A barometric height ``height_m`` [m] (above the alignment's reference) of the time
    ``t_meas_s`` [s], against the delayed state, gated (noise and gate in the work
    array's parameters); the correction taken up by the output. Returns FUSED, REJECTED
    or NUMERIC."""
    before = w[W_X:W_X + 6].copy()
    res = _fuse_baro(w, P, buf, meta, t_meas_s, height_m)
    take_up(w, before)
    return res


class BaroControl:
    """Fuses the barometer's samples of an aligned filter, at most one per
    ``baro_min_interval_s``."""

    __slots__ = ("_p", "_mem", "_st", "_k", "ref_m")

    def __init__(self, params: EstimatorParams, mem: FilterMemory,
                 status: AidSourceStatus) -> None:
        self._p = params
        self._mem = mem
        self._st = status
        mem.prm[PRM_BARO_R] = params.baro_noise_m ** 2
        mem.prm[PRM_BARO_GATE] = status.policy.gate_sigma
        #: the pressure altitude [m AMSL] at the filter's zero height (None: not set)
        self.ref_m: float | None = None
        self._k = entry_point(fuse_baro_kernel, mem.w, mem.P, mem.buf, mem.meta, 0.0, 0.0)

    def fuse(self, t_s: float, pressure_alt_m: float) -> bool:
        """A pressure altitude [m AMSL] arriving at ``t_s`` [s]. Returns whether it was
        fused."""
        st = self._st
        if st.too_soon(t_s) or not math.isfinite(pressure_alt_m):
            return False
        if self.ref_m is None:        # no baro at alignment: referenced now
            self.ref_m = pressure_alt_m - float(self._mem.x[X_P + 2])
        st.time_last_attempt = t_s
        m = self._mem
        res = self._k(m.w, m.P, m.buf, m.meta, t_s - self._p.baro_delay_s,
                      pressure_alt_m - self.ref_m)
        st.record(t_s, res)
        return res == FUSED
