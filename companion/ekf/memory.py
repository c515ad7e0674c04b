"""The filter's arrays, laid out by :mod:`companion.ekf.layout`, with named views of them."""

from __future__ import annotations

import math

import numpy as np

from companion.ekf.layout import (
    AID_COLS,
    BUF_COLS,
    IDX_P,
    N_AID_SOURCES,
    N_ERR,
    N_PRM,
    NX,
    W_AID,
    W_DX,
    W_PRM,
    W_SIZE,
    W_X,
    X_Q,
)
from companion.ekf.params import EstimatorParams


class FilterMemory:
    """The work array ``w`` (nominal state, correction, delayed state, rates, output lag,
    kernel parameters, aid-source rows), the covariance ``P``, the ring buffer of past
    states ``buf`` and its ``meta`` (next slot, entries): what the kernels take."""

    __slots__ = ("w", "P", "buf", "meta", "x", "dx", "prm", "aid", "pos_var")

    def __init__(self, params: EstimatorParams) -> None:
        p = params
        self.w = np.zeros(W_SIZE)
        self.P = np.zeros((N_ERR, N_ERR))
        longest = max(p.gnss_delay_s, p.baro_delay_s,
                      p.tether_max_delay_s if p.tether_aid else 0.0)
        n_buf = int(math.ceil(longest * p.imu_rate_hz)) + 8
        self.buf = np.zeros((n_buf, BUF_COLS))
        self.meta = np.zeros(2, dtype=np.int64)
        #: the nominal state (a view)
        self.x = self.w[W_X:W_X + NX]
        self.x[X_Q] = 1.0
        self.dx = self.w[W_DX:W_DX + N_ERR]
        self.prm = self.w[W_PRM:W_PRM + N_PRM]
        #: one row per aid source (AidSourceKind)
        self.aid = self.w[W_AID:W_AID + N_AID_SOURCES * AID_COLS].reshape(
            N_AID_SOURCES, AID_COLS)
        #: the position variances [m^2] on P's diagonal (a view)
        self.pos_var = self.P.reshape(-1)[::N_ERR + 1][IDX_P:IDX_P + 3]

    def buffered(self) -> np.ndarray:
        """The ring buffer's filled rows (a view)."""
        return self.buf[:int(self.meta[1])]
