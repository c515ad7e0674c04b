"""Constant-position mode (EKF2's fake position, EKF3's constant position): no position
source fused for ``const_pos_after_s``, the position then held is fused with the large
noise ``const_pos_noise_m``, ungated, to keep the attitude and the velocity bounded."""

from __future__ import annotations

import numpy as np

from companion.ekf.aid_source import AidSources
from companion.ekf.layout import (
    FUSED,
    IDX_P,
    N_ERR,
    NUMERIC,
    NX,
    PRM_VAR_MIN,
    W_DX,
    W_PRM,
    W_X,
    X_P,
)
from companion.ekf.memory import FilterMemory
from companion.ekf.params import EstimatorParams
from companion.ekf.update import inject, scalar_update
from tuavdefs.jit import entry_point, njit


@njit
def fuse_position_kernel(w: np.ndarray, P: np.ndarray, buf: np.ndarray, meta: np.ndarray,
                         px: float, py: float, r: float) -> bool:
    """A horizontal position ``p*`` [m] of now with noise variance ``r`` [m^2], ungated
    (flown at once: the output does not take it up). Returns whether both updates were
    applied."""
    x = w[W_X:W_X + NX]
    dx = w[W_DX:W_DX + N_ERR]
    var_min = w[W_PRM + PRM_VAR_MIN]
    ok = scalar_update(P, dx, var_min, px - x[X_P], r, IDX_P, 1.0, -1, 0.0, -1, 0.0)
    ok = scalar_update(P, dx, var_min, py - x[X_P + 1], r, IDX_P + 1, 1.0, -1, 0.0, -1,
                       0.0) and ok
    inject(x, dx, buf, meta)
    return ok


class ConstPosControl:
    """Enters constant-position mode when no position source has been fused for
    ``const_pos_after_s``, fuses the held position meanwhile, leaves it when a position
    source is fused again (:meth:`leave`)."""

    __slots__ = ("_p", "_mem", "_src", "_k", "held")

    def __init__(self, params: EstimatorParams, mem: FilterMemory,
                 sources: AidSources) -> None:
        self._p = params
        self._mem = mem
        self._src = sources
        #: the held horizontal position [m] (None: not in constant-position mode)
        self.held: tuple[float, float] | None = None
        self._k = entry_point(fuse_position_kernel, mem.w, mem.P, mem.buf, mem.meta, 0.0,
                              0.0, 0.0)

    def step(self, t_s: float) -> None:
        """After the IMU step at ``t_s`` [s]: fuse the held position when due, or enter
        the mode."""
        held, src = self.held, self._src
        st = src.const_pos
        if held is not None:
            if not st.too_soon(t_s):
                st.time_last_attempt = t_s
                m = self._mem
                ok = self._k(m.w, m.P, m.buf, m.meta, held[0], held[1],
                             self._p.const_pos_noise_m ** 2)
                st.record(t_s, FUSED if ok else NUMERIC)
        elif (t_s - max(src.gnss_pos.time_last_fused, src.tether.time_last_fused)
              > self._p.const_pos_after_s):
            x = self._mem.x
            self.held = (float(x[X_P]), float(x[X_P + 1]))

    def leave(self) -> None:
        """A position source was fused: the mode ends."""
        self.held = None
