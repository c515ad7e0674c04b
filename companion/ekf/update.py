"""The measurement update's kernels, shared by every fusion: the delayed state a
measurement is compared with, one scalar (sequential) update, one dense-row update (with
Schmidt's considered states), the injection of the correction into the nominal state,
a 3 x 3 Cholesky factor, and the one writer of an aid source's status row."""

from __future__ import annotations

import math

import numpy as np

from companion.ekf.layout import (
    AID_COLS,
    AID_INNOV,
    AID_INNOV_VAR,
    AID_TEST_RATIO,
    BUF_P,
    BUF_T,
    FUSED,
    IDX_BA,
    IDX_BG,
    IDX_BH,
    IDX_BM,
    IDX_BP,
    IDX_LINE,
    IDX_TH,
    IDX_W,
    N_LINE,
    NUMERIC,
    REJECTED,
    W_AID,
    X_BA,
    X_BG,
    X_BH,
    X_BM,
    X_BP,
    X_LINE,
    X_Q,
    X_W,
)
from companion.ekf.rotation import expq_mul
from tuavdefs.jit import njit


@njit
def set_aid_row(w: np.ndarray, kind: int, y0: float, y1: float, y2: float, s0: float,
                s1: float, s2: float, test_ratio: float) -> None:
    """Aid source ``kind``'s status row of the work array ``w``: its latest innovation
    ``y*``, their variances ``s*`` (unused axes 0) and its test ratio."""
    k = W_AID + kind * AID_COLS
    w[k + AID_INNOV], w[k + AID_INNOV + 1], w[k + AID_INNOV + 2] = y0, y1, y2
    w[k + AID_INNOV_VAR], w[k + AID_INNOV_VAR + 1], w[k + AID_INNOV_VAR + 2] = s0, s1, s2
    w[k + AID_TEST_RATIO] = test_ratio


@njit
def delayed_state(buf: np.ndarray, meta: np.ndarray, x: np.ndarray, t_s: float,
                  out: np.ndarray) -> None:
    """``out`` = (p, v) at time ``t_s`` [s]: interpolated in the ring buffer, the oldest
    entry if older, the current state if newer than the newest (or the buffer empty)."""
    n, count, size = meta[0], meta[1], buf.shape[0]
    newest = (n - 1) % size
    if count == 0 or t_s >= buf[newest, BUF_T]:
        for i in range(6):
            out[i] = x[i]
        return
    later = newest
    for m in range(1, count):
        k = (newest - m) % size
        if buf[k, BUF_T] <= t_s:
            t0, t1 = buf[k, BUF_T], buf[later, BUF_T]
            w = (t_s - t0) / (t1 - t0) if t1 > t0 else 1.0
            for i in range(6):
                out[i] = buf[k, BUF_P + i] + w * (buf[later, BUF_P + i] - buf[k, BUF_P + i])
            return
        later = k
    for i in range(6):       # older than the buffer: its oldest entry
        out[i] = buf[later, BUF_P + i]


@njit
def scalar_update(P: np.ndarray, dx: np.ndarray, var_min: float, y: float, r: float,
                  i0: int, h0: float, i1: int, h1: float, i2: int, h2: float,
                  i3: int = -1, h3: float = 0.0) -> bool:
    """One scalar measurement with up to four non-zero Jacobian entries ``h`` at error
    indices ``i`` (-1: unused), innovation ``y`` (against the state before this batch's
    corrections ``dx``, which it accumulates into) and noise variance ``r``. Updates ``P``
    (symmetric by construction; refused if a variance it changes would fall below
    ``var_min``). Returns whether it was applied."""
    n = P.shape[0]
    pht = np.zeros(n)
    yy = y
    for i, h in ((i0, h0), (i1, h1), (i2, h2), (i3, h3)):
        if i >= 0:
            yy -= h * dx[i]
            for k in range(n):
                pht[k] += P[k, i] * h
    s = r
    for i, h in ((i0, h0), (i1, h1), (i2, h2), (i3, h3)):
        if i >= 0:
            s += h * pht[i]
    if not (s > 0.0) or not math.isfinite(s):
        return False
    inv = 1.0 / s
    for k in range(n):
        if pht[k] != 0.0 and P[k, k] - pht[k] * pht[k] * inv < var_min:
            return False
    for k in range(n):
        dx[k] += pht[k] * inv * yy
    for a in range(n):
        ka = pht[a] * inv
        for b in range(n):
            P[a, b] -= ka * pht[b]
    return True


@njit
def mat_vec(P: np.ndarray, h: np.ndarray) -> np.ndarray:
    """``P h``: the block of the states before the wind's by one BLAS product of that
    square block, the rows and columns of the wind's and the line's states added by loops
    (so that every sum over the other states is that of a filter without them, to the bit:
    BLAS groups its rows by the matrix's size)."""
    n, c = h.shape[0], IDX_W
    out = np.empty(n)
    out[:c] = np.ascontiguousarray(P[:c, :c]) @ np.ascontiguousarray(h[:c])
    for j in range(c, n):
        if h[j] != 0.0:
            for k in range(c):
                out[k] += P[k, j] * h[j]
    for k in range(c, n):
        acc = 0.0
        for j in range(n):
            acc += P[k, j] * h[j]
        out[k] = acc
    return out


@njit
def dot(a: np.ndarray, b: np.ndarray) -> float:
    """``a . b``, summed as :func:`mat_vec` sums."""
    acc = float(np.ascontiguousarray(a[:IDX_W]) @ np.ascontiguousarray(b[:IDX_W]))
    for j in range(IDX_W, a.shape[0]):
        if a[j] != 0.0:
            acc += a[j] * b[j]
    return acc


@njit
def _row_innovation(P: np.ndarray, dx: np.ndarray, y: float, r: float, h: np.ndarray
                    ) -> tuple[np.ndarray, float, float]:
    """For a scalar reading ``y`` with noise variance ``r`` and Jacobian row ``h``: ``P h'``,
    the innovation ``y - h dx`` and ``1/s`` for its variance ``s = h P h' + r`` (0 where
    ``s`` is not positive and finite: the reading is not fused)."""
    pht = mat_vec(P, h)
    yy = y - dot(h, dx)
    s = dot(h, pht) + r
    if not (s > 0.0) or not math.isfinite(s):
        return pht, yy, 0.0
    return pht, yy, 1.0 / s


@njit
def row_update(P: np.ndarray, dx: np.ndarray, var_min: float, y: float, r: float,
               h: np.ndarray, c0: int, c1: int) -> bool:
    """:func:`scalar_update` with a dense Jacobian row ``h``; the error states ``c0`` to
    ``c1 - 1`` are *considered*, not estimated (Schmidt's update: their gain is zero, their
    uncertainty still enters the innovation's variance and their correlations are kept
    right)."""
    n = P.shape[0]
    pht, yy, inv = _row_innovation(P, dx, y, r, h)
    if inv == 0.0:
        return False
    for k in range(n):
        if (pht[k] != 0.0 and not c0 <= k < c1
                and P[k, k] - pht[k] * pht[k] * inv < var_min):
            return False
    for k in range(n):
        if not c0 <= k < c1:
            dx[k] += pht[k] * inv * yy
    for a in range(n):
        ka = pht[a] * inv
        ca = c0 <= a < c1
        for b in range(n):
            if not (ca and c0 <= b < c1):
                P[a, b] -= ka * pht[b]
    return True


@njit
def row_update_only(P: np.ndarray, dx: np.ndarray, var_min: float, y: float, r: float,
                    h: np.ndarray, e0: int, e1: int) -> bool:
    """:func:`row_update` with only the error states ``e0`` to ``e1 - 1`` estimated and
    every other *considered* (Schmidt's update: their gain is zero, their uncertainty
    enters the innovation's variance, their correlations with the estimated states are
    kept right; their own covariance block is left as it is, to the bit)."""
    n = P.shape[0]
    pht, yy, inv = _row_innovation(P, dx, y, r, h)
    if inv == 0.0:
        return False
    for k in range(e0, e1):
        if pht[k] != 0.0 and P[k, k] - pht[k] * pht[k] * inv < var_min:
            return False
    for k in range(e0, e1):
        dx[k] += pht[k] * inv * yy
    for a in range(n):
        ka = pht[a] * inv
        ea = e0 <= a < e1
        for b in range(n):
            if ea or e0 <= b < e1:
                P[a, b] -= ka * pht[b]
    return True


@njit
def inject(x: np.ndarray, dx: np.ndarray, buf: np.ndarray, meta: np.ndarray) -> None:
    """Add the error-state correction ``dx`` to the nominal state (the attitude as
    ``q <- Exp(dtheta) q``), and its position and velocity to the buffered past states;
    ``dx`` is zeroed. The covariance's reset Jacobian is taken as the identity."""
    for i in range(6):
        x[i] += dx[i]
    q = X_Q
    x[q], x[q + 1], x[q + 2], x[q + 3] = expq_mul(dx[IDX_TH], dx[IDX_TH + 1],
                                                  dx[IDX_TH + 2], x[q], x[q + 1],
                                                  x[q + 2], x[q + 3])
    for i in range(3):
        x[X_BG + i] += dx[IDX_BG + i]
        x[X_BA + i] += dx[IDX_BA + i]
    x[X_BH] += dx[IDX_BH]
    for i in range(3):
        x[X_BM + i] += dx[IDX_BM + i]
        x[X_BP + i] += dx[IDX_BP + i]
    x[X_W] += dx[IDX_W]
    x[X_W + 1] += dx[IDX_W + 1]
    for i in range(N_LINE):
        x[X_LINE + i] += dx[IDX_LINE + i]
    for m in range(meta[1]):
        for i in range(6):
            buf[m, BUF_P + i] += dx[i]
    for i in range(dx.shape[0]):
        dx[i] = 0.0



@njit
def cholesky3(s00: float, s01: float, s02: float, s11: float, s12: float, s22: float
               ) -> tuple[bool, float, float, float, float, float, float]:
    """The lower Cholesky factor of the symmetric 3 x 3 matrix of upper triangle ``s``:
    (positive definite, l00, l10, l20, l11, l21, l22); False (and zeros) as soon as a
    leading minor is not positive."""
    if not s00 > 0.0:
        return False, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    l00 = math.sqrt(s00)
    l10, l20 = s01 / l00, s02 / l00
    d11 = s11 - l10 * l10
    if not d11 > 0.0:
        return False, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    l11 = math.sqrt(d11)
    l21 = (s12 - l20 * l10) / l11
    d22 = s22 - l20 * l20 - l21 * l21
    if not d22 > 0.0:
        return False, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    return True, l00, l10, l20, l11, l21, math.sqrt(d22)



@njit
def gate3(w: np.ndarray, kind: int, y0: float, y1: float, y2: float, s00: float,
          s01: float, s02: float, s11: float, s12: float, s22: float, gate: float) -> int:
    """One gate for a three-axis innovation ``y`` with covariance ``S`` (upper triangle
    ``s``): its test ratio ``y' S^-1 y / gate^2`` through ``S``'s Cholesky factor, written
    with the innovation into aid source ``kind``'s row of ``w``. FUSED when it passes (the
    caller fuses), REJECTED beyond the gate, NUMERIC when ``S`` is not positive definite
    (the innovation kept, the test ratio the last one's)."""
    ok, a00, a10, a20, a11, a21, a22 = cholesky3(s00, s01, s02, s11, s12, s22)
    if not ok:
        set_aid_row(w, kind, y0, y1, y2, s00, s11, s22,
                    w[W_AID + kind * AID_COLS + AID_TEST_RATIO])
        return NUMERIC
    v0 = y0 / a00
    v1 = (y1 - a10 * v0) / a11
    v2 = (y2 - a20 * v0 - a21 * v1) / a22
    ratio = (v0 * v0 + v1 * v1 + v2 * v2) / (gate * gate)
    set_aid_row(w, kind, y0, y1, y2, s00, s11, s22, ratio)
    return REJECTED if ratio > 1.0 else FUSED


@njit
def whitening3(c00: float, c01: float, c02: float, c11: float, c12: float, c22: float
               ) -> tuple[bool, float, float, float, float, float, float]:
    """The rows of ``L^-1`` for the measurement noise ``C = L L'`` (upper triangle ``c``):
    (positive definite, m00, m10, m11, m20, m21, m22), so that ``L^-1 z`` has the noise I
    and its three rows fuse one at a time."""
    ok, l00, l10, l20, l11, l21, l22 = cholesky3(c00, c01, c02, c11, c12, c22)
    if not ok:
        return False, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    return (True, 1.0 / l00, -l10 / (l00 * l11), 1.0 / l11,
            (l10 * l21 - l11 * l20) / (l00 * l11 * l22), -l21 / (l11 * l22), 1.0 / l22)

