"""The winch's tether fix (ODOMETRY from the ground station): a 3-axis position with its
covariance, against the delayed state, gated on its Mahalanobis distance and fused as
three whitened scalars (ArduPilot's ExternalNav); its control, with the reset to the fix
after ``tether_reset_s`` of rejections without GNSS (docs/estimation.md §10)."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from companion.ekf.aid_source import AidSources
from companion.ekf.layout import (
    BUF_P,
    FUSED,
    IDX_P,
    N_ERR,
    NUMERIC,
    NX,
    PRM_TETHER_GATE,
    PRM_VAR_MIN,
    REJECTED,
    W_DELAYED,
    W_DX,
    W_PRM,
    W_X,
    X_P,
    AidSourceKind,
)
from companion.ekf.memory import FilterMemory
from companion.ekf.output import OutputPredictor, take_up
from companion.ekf.params import EstimatorParams
from companion.ekf.update import delayed_state, gate3, inject, scalar_update, whitening3
from tuavdefs.frames import Vec3
from tuavdefs.jit import entry_point, njit

_TETHER = int(AidSourceKind.TETHER)

#: A usable tether fix: its measurement time [s], position [m], covariance's upper
#: triangle (c00, c01, c02, c11, c12, c22) [m^2] with the floor added.
TetherFix = tuple[float, Vec3, tuple[float, float, float, float, float, float]]


@njit
def _fuse_tether(w: np.ndarray, P: np.ndarray, buf: np.ndarray, meta: np.ndarray,
                 t_meas_s: float, px: float, py: float, pz: float, c00: float, c01: float,
                 c02: float, c11: float, c12: float, c22: float) -> int:
    x = w[W_X:W_X + NX]
    delayed = w[W_DELAYED:W_DELAYED + 6]
    gate = w[W_PRM + PRM_TETHER_GATE]
    delayed_state(buf, meta, x, t_meas_s, delayed)
    y0, y1, y2 = px - delayed[0], py - delayed[1], pz - delayed[2]
    # S = P_pp + C, its Cholesky factor, and d^2 = y' S^-1 y
    s00, s01, s02 = P[0, 0] + c00, P[0, 1] + c01, P[0, 2] + c02
    s11, s12, s22 = P[1, 1] + c11, P[1, 2] + c12, P[2, 2] + c22
    res = gate3(w, _TETHER, y0, y1, y2, s00, s01, s02, s11, s12, s22, gate)
    if res != FUSED:
        return res
    # rows of L^-1 for the measurement's own C = L L': L^-1 z has the noise I
    ok, m00, m10, m11, m20, m21, m22 = whitening3(c00, c01, c02, c11, c12, c22)
    if not ok:
        return NUMERIC
    dx = w[W_DX:W_DX + N_ERR]
    var_min = w[W_PRM + PRM_VAR_MIN]
    res = FUSED
    if not scalar_update(P, dx, var_min, m00 * y0, 1.0, 0, m00, -1, 0.0, -1, 0.0):
        res = NUMERIC
    if not scalar_update(P, dx, var_min, m10 * y0 + m11 * y1, 1.0, 0, m10, 1, m11, -1, 0.0):
        res = NUMERIC
    if not scalar_update(P, dx, var_min, m20 * y0 + m21 * y1 + m22 * y2, 1.0, 0, m20, 1,
                         m21, 2, m22):
        res = NUMERIC
    inject(x, dx, buf, meta)
    return res


@njit
def fuse_tether_kernel(w: np.ndarray, P: np.ndarray, buf: np.ndarray, meta: np.ndarray,
                       t_meas_s: float, px: float, py: float, pz: float, c00: float,
                       c01: float, c02: float, c11: float, c12: float, c22: float) -> int:
    """A tether fix of the time ``t_meas_s`` [s]: position ``p*`` [m] with the covariance
    ``c`` [m^2] (its upper triangle), against the state at that time. Gated as one on the
    innovation's Mahalanobis distance (the row: the innovation, the diagonal of its
    covariance, d^2 / gate^2); fused as three whitened scalar measurements (``L^-1 z``
    with ``C = L L'``: unit, independent noises), the correction injected into the
    current state and taken up by the output. Returns FUSED, REJECTED or NUMERIC
    (numerically, or a covariance not positive definite)."""
    before = w[W_X:W_X + 6].copy()
    res = _fuse_tether(w, P, buf, meta, t_meas_s, px, py, pz, c00, c01, c02, c11, c12, c22)
    take_up(w, before)
    return res


class TetherControl:
    """Checks the tether fixes, fuses them into an aligned filter, resets the position to
    a fix after ``tether_reset_s`` of rejections while no GNSS position is fused."""

    __slots__ = ("_p", "_mem", "_src", "_out", "_leave_const_pos", "_k", "refused")

    def __init__(self, params: EstimatorParams, mem: FilterMemory, sources: AidSources,
                 output: OutputPredictor, leave_const_pos: Callable[[], None]) -> None:
        self._p = params
        self._mem = mem
        self._src = sources
        self._out = output
        self._leave_const_pos = leave_const_pos
        mem.prm[PRM_TETHER_GATE] = sources.tether.policy.gate_sigma
        #: Tether fixes refused as too old, not finite or not positive definite.
        self.refused = 0
        self._k = entry_point(fuse_tether_kernel, mem.w, mem.P, mem.buf, mem.meta, 0.0, 0.0,
                              0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)

    def check(self, t_s: float, t_meas_s: float, pos_m: Sequence[float],
              cov_m2: Sequence[Sequence[float]]) -> TetherFix | None:
        """The fix arriving at ``t_s`` [s] if usable (finite, fresh, its covariance with
        ``tether_noise_min_m`` added positive definite), else None (counted refused)."""
        p = self._p
        x0, x1, x2 = pos_m
        px, py, pz = pos = (float(x0), float(x1), float(x2))
        (a, b, c), (_, d, e), (_, _, f) = cov_m2
        floor = p.tether_noise_min_m ** 2
        a, d, f = float(a) + floor, float(d) + floor, float(f) + floor
        b = 0.5 * (float(b) + float(cov_m2[1][0]))
        c = 0.5 * (float(c) + float(cov_m2[2][0]))
        e = 0.5 * (float(e) + float(cov_m2[2][1]))
        age = t_s - t_meas_s
        # finite (NaN fails every comparison), fresh, positive definite (leading minors)
        if not (age <= p.tether_max_delay_s and abs(px) + abs(py) + abs(pz) < math.inf
                and abs(b) + abs(c) + abs(e) < math.inf and a > 0.0 and d < math.inf
                and f < math.inf and a * d - b * b > 0.0
                and a * (d * f - e * e) - b * (b * f - e * c) + c * (b * e - d * c) > 0.0):
            self.refused += 1
            return None
        # a stamp from the future is taken as now
        return min(t_meas_s, t_s), pos, (a, b, c, d, e, f)

    def fuse(self, t_s: float, fix: TetherFix) -> bool:
        """A checked fix arriving at ``t_s`` [s]. Returns whether it was fused (or reset
        to)."""
        t_meas, pos, cov = fix
        m = self._mem
        res = self._k(m.w, m.P, m.buf, m.meta, t_meas, *pos, *cov)
        st = self._src.tether
        st.time_last_attempt = t_s
        reset_due = st.record(t_s, res)
        if res == FUSED:
            self._leave_const_pos()
            return True
        if (res == REJECTED and reset_due
                and t_s - self._src.gnss_pos.time_last_fused > self._p.gnss_timeout_s):
            self._reset(pos, cov_matrix(cov))
            st.reset_done(t_s)
            self._leave_const_pos()
            return True
        return False

    def _reset(self, pos: Vec3, c: np.ndarray) -> None:
        """Position set to the fix ``pos`` [m], its covariance to the fix's ``c`` [m^2]
        (3 x 3, with the floor; uncorrelated with the rest); the velocity kept."""
        m = self._mem
        delta = np.array(pos) - m.x[X_P:X_P + 3]
        m.x[X_P:X_P + 3] = pos
        m.buffered()[:, BUF_P:BUF_P + 3] += delta
        P = m.P
        P[IDX_P:IDX_P + 3, :] = 0.0
        P[:, IDX_P:IDX_P + 3] = 0.0
        P[IDX_P:IDX_P + 3, IDX_P:IDX_P + 3] = c
        self._out.reset(velocity=False)


def cov_matrix(c: tuple[float, float, float, float, float, float]) -> np.ndarray:
    """The symmetric 3 x 3 matrix of the upper triangle ``c`` (c00, c01, c02, c11, c12,
    c22)."""
    a, b, cc, d, e, f = c
    return np.array(((a, b, cc), (b, d, e), (cc, e, f)))
