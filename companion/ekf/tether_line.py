"""The winch's raw tether reading fused tightly: the line's model in the filter's own wind
and line states (docs/estimation.md §11).

A reading ``m = (L, T0, psi, eps)`` (the paid-out length, the load cell's tension, the guide
arm's azimuth and elevation as read) at the time ``t`` says that the tether's attachment
point is the end of the line the model integrates from the exit
(:mod:`tuavdefs.line_shape`) under the line's weight ``k_w w_b`` and the drag ``k_c c_b``
of the wind states ``U`` (taken at the vehicle's height, sheared below it), the angles less
the arm's biases ``b_psi``, ``b_eps``:

    h(x) = p(t) + R r_a - f(m; U, k_w, k_c, b_psi, b_eps) = 0 + noise

Against the delayed state (§4) the innovation is ``y = f - p(t) - R r_a`` and the Jacobian

    H = [ I (dp) | -[R r_a]x (dtheta) | -J_U (dU) | -J_c c_b, -J_w w_b, +J_psi, +J_eps ]

(``J = df/dinputs``, :func:`tuavdefs.line_shape.end_slopes`). The readings' noises enter
through ``R = sum_k (J_k sigma_k)(J_k sigma_k)' + sigma_model^2 I`` (the length, the tension,
the two angles, and the gusts: the wind the line feels less the wind states). The three
axes are gated as one on ``y' S^-1 y`` and fused as three scalar
updates whitened by ``R``'s Cholesky factor. The line's states (``k_c``, ``k_w``, ``b_psi``,
``b_eps``: random constants) are learnt only while a GNSS position is fused in the air (and
``k_c`` only with ``learn_drag``, in a wind the drag can be told in); otherwise they are
*considered* (Schmidt: no gain, their uncertainty in ``S``).
"""

from __future__ import annotations

import math

import numpy as np

from companion.ekf.aid_source import AidSources
from companion.ekf.layout import (
    BUF_P,
    FUSED,
    IDX_LINE,
    IDX_P,
    IDX_TH,
    IDX_W,
    LINE_BEPS,
    LINE_BPSI,
    LINE_KC,
    LINE_KW,
    N_ERR,
    N_LINE,
    NUMERIC,
    NX,
    PRM_ATTACH_X,
    PRM_LINE_C,
    PRM_LINE_EA,
    PRM_LINE_GATE,
    PRM_LINE_SHEAR,
    PRM_LINE_SIG_ANG,
    PRM_LINE_SIG_GUST,
    PRM_LINE_SIG_L,
    PRM_LINE_SIG_MIN,
    PRM_LINE_SIG_T,
    PRM_LINE_SIG_T_FRAC,
    PRM_LINE_STEPS,
    PRM_LINE_W,
    PRM_VAR_MIN,
    REJECTED,
    W_DELAYED,
    W_DX,
    W_PRM,
    W_X,
    X_LINE,
    X_Q,
    X_W,
    AidSourceKind,
)
from companion.ekf.memory import FilterMemory
from companion.ekf.output import OutputPredictor, take_up
from companion.ekf.params import EstimatorParams
from companion.ekf.update import (
    delayed_state,
    gate3,
    inject,
    row_update,
    whitening3,
)
from tuavdefs.frames import quat_to_matrix_kernel
from tuavdefs.jit import entry_point, njit
from tuavdefs.line_shape import N_COLUMNS, LineModel, end_slopes

_LINE = int(AidSourceKind.TETHER_LINE)
#: The range the line's weight and drag factors are kept in.
FACTOR_BOUNDS = (0.2, 5.0)
#: The wind profile's floor [m] (the ground station's and the drag fusion's).
_MIN_HEIGHT_M = 1.0
#: The error states a reading's Jacobian rows can be non-zero in (:func:`line_rows`).
_COLS = np.array([IDX_P, IDX_P + 1, IDX_P + 2, IDX_TH, IDX_TH + 1, IDX_TH + 2, IDX_W,
                  IDX_W + 1, IDX_LINE + LINE_KC, IDX_LINE + LINE_KW, IDX_LINE + LINE_BPSI,
                  IDX_LINE + LINE_BEPS], dtype=np.int64)


@njit
def line_rows(x: np.ndarray, prm: np.ndarray, height_m: float, length_m: float,
              tension_n: float, azimuth_rad: float, elevation_rad: float, h: np.ndarray,
              r: np.ndarray) -> tuple[float, float, float]:
    """The innovation ``f - p - R r_a`` [m] of a reading (``length_m`` [m], ``tension_n``
    [N], the angles as read [rad]) against the state ``x`` with the vehicle's position
    ``x[0:3]`` (the caller puts the delayed one there) at the height ``height_m`` [m]
    (the wind states' reference), its Jacobian rows on the error state in ``h`` (3 x
    N_ERR, overwritten) and the reading's noise covariance in ``r`` (3 x 3) [m^2]."""
    J = np.zeros((3, N_COLUMNS))
    inp = np.empty(N_COLUMNS)
    kc, kw = x[X_LINE + LINE_KC], x[X_LINE + LINE_KW]
    w_b, c_b = prm[PRM_LINE_W], prm[PRM_LINE_C]
    inp[0], inp[1], inp[2], inp[3] = length_m, tension_n, azimuth_rad, elevation_rad
    inp[4], inp[5] = x[X_W], x[X_W + 1]
    inp[6], inp[7] = kw * w_b, kc * c_b
    inp[8], inp[9] = x[X_LINE + LINE_BPSI], x[X_LINE + LINE_BEPS]
    e = end_slopes(inp, prm[PRM_LINE_EA], max(height_m, _MIN_HEIGHT_M), prm[PRM_LINE_SHEAR],
                   _MIN_HEIGHT_M, int(prm[PRM_LINE_STEPS]), J)
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = quat_to_matrix_kernel(
        (x[X_Q], x[X_Q + 1], x[X_Q + 2], x[X_Q + 3]))
    ax, ay, az = prm[PRM_ATTACH_X], prm[PRM_ATTACH_X + 1], prm[PRM_ATTACH_X + 2]
    a0 = r00 * ax + r01 * ay + r02 * az
    a1 = r10 * ax + r11 * ay + r12 * az
    a2 = r20 * ax + r21 * ay + r22 * az
    for i in range(3):
        h[i, :] = 0.0
        h[i, IDX_P + i] = 1.0
    # R_true r_a = Exp(dtheta) R r_a ~ R r_a - [R r_a]x dtheta
    h[0, IDX_TH + 1], h[0, IDX_TH + 2] = a2, -a1
    h[1, IDX_TH], h[1, IDX_TH + 2] = -a2, a0
    h[2, IDX_TH], h[2, IDX_TH + 1] = a1, -a0
    for i in range(3):
        h[i, IDX_W] = -J[i, 4]
        h[i, IDX_W + 1] = -J[i, 5]
        h[i, IDX_LINE + LINE_KC] = -J[i, 7] * c_b
        h[i, IDX_LINE + LINE_KW] = -J[i, 6] * w_b
        h[i, IDX_LINE + LINE_BPSI] = -J[i, 8]
        h[i, IDX_LINE + LINE_BEPS] = -J[i, 9]
    sig_t = math.hypot(prm[PRM_LINE_SIG_T], prm[PRM_LINE_SIG_T_FRAC] * tension_n)
    sig_a, sig_m, sig_g = prm[PRM_LINE_SIG_ANG], prm[PRM_LINE_SIG_MIN], prm[PRM_LINE_SIG_GUST]
    sig = (prm[PRM_LINE_SIG_L], sig_t, sig_a, sig_a, sig_g, sig_g)
    for i in range(3):
        for j in range(3):
            acc = sig_m * sig_m if i == j else 0.0
            for k in range(6):
                acc += J[i, k] * J[j, k] * sig[k] * sig[k]
            r[i, j] = acc
    return (e[0] - x[0] - a0, e[1] - x[1] - a1, e[2] - x[2] - a2)


@njit
def _fuse_line(w: np.ndarray, P: np.ndarray, buf: np.ndarray, meta: np.ndarray,
               t_meas_s: float, length_m: float, tension_n: float, azimuth_rad: float,
               elevation_rad: float, c0: int, c1: int) -> int:
    x = w[W_X:W_X + NX]
    prm = w[W_PRM:]
    delayed = w[W_DELAYED:W_DELAYED + 6]
    delayed_state(buf, meta, x, t_meas_s, delayed)
    xd = x.copy()
    for i in range(3):
        xd[i] = delayed[i]
    h = np.zeros((3, N_ERR))
    r = np.zeros((3, 3))
    y0, y1, y2 = line_rows(xd, prm, delayed[2], length_m, tension_n, azimuth_rad,
                           elevation_rad, h, r)
    if not (math.isfinite(y0) and math.isfinite(y1) and math.isfinite(y2)):
        return NUMERIC
    # S = H P H' + R over the columns H can be non-zero in
    s00, s01, s02 = r[0, 0], r[0, 1], r[0, 2]
    s11, s12, s22 = r[1, 1], r[1, 2], r[2, 2]
    for a in _COLS:
        q0 = q1 = q2 = 0.0
        for b in _COLS:
            pab = P[a, b]
            q0 += pab * h[0, b]
            q1 += pab * h[1, b]
            q2 += pab * h[2, b]
        h0, h1, h2 = h[0, a], h[1, a], h[2, a]
        s00 += h0 * q0
        s01 += h0 * q1
        s02 += h0 * q2
        s11 += h1 * q1
        s12 += h1 * q2
        s22 += h2 * q2
    res = gate3(w, _LINE, y0, y1, y2, s00, s01, s02, s11, s12, s22, prm[PRM_LINE_GATE])
    if res != FUSED:
        return res
    # whitened by the reading's own noise R = L L': L^-1 y has the noise I
    ok, m00, m10, m11, m20, m21, m22 = whitening3(r[0, 0], r[0, 1], r[0, 2], r[1, 1],
                                                  r[1, 2], r[2, 2])
    if not ok:
        return NUMERIC
    dx = w[W_DX:W_DX + N_ERR]
    var_min = prm[PRM_VAR_MIN]
    res = FUSED
    if not row_update(P, dx, var_min, m00 * y0, 1.0, m00 * h[0], c0, c1):
        res = NUMERIC
    if not row_update(P, dx, var_min, m10 * y0 + m11 * y1, 1.0, m10 * h[0] + m11 * h[1],
                      c0, c1):
        res = NUMERIC
    if not row_update(P, dx, var_min, m20 * y0 + m21 * y1 + m22 * y2, 1.0,
                      m20 * h[0] + m21 * h[1] + m22 * h[2], c0, c1):
        res = NUMERIC
    inject(x, dx, buf, meta)
    return res


@njit
def fuse_tether_line_kernel(w: np.ndarray, P: np.ndarray, buf: np.ndarray, meta: np.ndarray,
                            t_meas_s: float, length_m: float, tension_n: float,
                            azimuth_rad: float, elevation_rad: float, c0: int, c1: int
                            ) -> int:
    """A raw tether reading of the time ``t_meas_s`` [s] (length [m], tension [N], the
    exit angles as read [rad]) against the state at that time: gated as one on the
    innovation's Mahalanobis distance (the row: the innovation, the diagonal of its
    covariance, d^2 / gate^2), fused as three scalars whitened by the reading's noise, the
    error states ``c0`` to ``c1 - 1`` considered (not learnt), the correction injected and
    taken up by the output. Returns FUSED, REJECTED or NUMERIC."""
    before = w[W_X:W_X + 6].copy()
    res = _fuse_line(w, P, buf, meta, t_meas_s, length_m, tension_n, azimuth_rad,
                     elevation_rad, c0, c1)
    take_up(w, before)
    return res


class TetherLineControl:
    """Fuses the raw readings of a line hanging clear of the ground; learns the line's
    states while a GNSS position is fused in the air and the wind states are known to
    ``wind_sigma_max_m_s``, keeps them considered otherwise;
    without GNSS fuses only once they have been learnt for ``learn_time_s`` (before that
    the ground station's fix is the tether's position); resets the position to the line's
    end after ``tether_reset_s`` of rejections without GNSS."""

    __slots__ = ("_p", "_lp", "_mem", "_src", "_out", "_leave_const_pos", "_k",
                 "learnt_s", "_learn_t", "refused", "_w_param", "weight_from_winder")

    def __init__(self, params: EstimatorParams, mem: FilterMemory, sources: AidSources,
                 output: OutputPredictor, leave_const_pos, line: LineModel,
                 attachment_m: tuple[float, float, float]) -> None:
        self._p = params
        self._lp = lp = params.drag.tether_line
        self._mem = mem
        self._src = sources
        self._out = output
        self._leave_const_pos = leave_const_pos
        prm = mem.prm
        prm[PRM_LINE_GATE] = sources.tether_line.policy.gate_sigma
        prm[PRM_LINE_W] = self._w_param = line.weight_n_m
        #: whether the weight belief w_b is the winder's estimate (else the parameter's)
        self.weight_from_winder = False
        prm[PRM_LINE_C] = line.drag_n_s2_m3
        prm[PRM_LINE_EA] = line.ea_n
        prm[PRM_LINE_SHEAR] = params.drag.tether_wind_shear
        prm[PRM_LINE_STEPS] = lp.steps
        prm[PRM_ATTACH_X:PRM_ATTACH_X + 3] = attachment_m
        prm[PRM_LINE_SIG_L] = lp.length_noise_m
        prm[PRM_LINE_SIG_T] = lp.tension_noise_n
        prm[PRM_LINE_SIG_T_FRAC] = lp.tension_noise_fraction
        prm[PRM_LINE_SIG_ANG] = lp.angle_noise_rad
        prm[PRM_LINE_SIG_MIN] = lp.model_sigma_m
        prm[PRM_LINE_SIG_GUST] = lp.gust_sigma_m_s
        #: how long the line's states have been learnt with GNSS in the air [s]
        self.learnt_s = 0.0
        self._learn_t = -math.inf
        #: readings refused as too old, not finite, slack or of a line on the ground
        self.refused = 0
        self._k = entry_point(fuse_tether_line_kernel, mem.w, mem.P, mem.buf, mem.meta, 0.0,
                              0.0, 0.0, 0.0, 0.0, 0, 0)

    def start(self) -> None:
        """At the alignment: the line as believed (factors 1, no biases), the priors."""
        m, lp = self._mem, self._lp
        m.x[X_LINE + LINE_KC] = m.x[X_LINE + LINE_KW] = 1.0
        m.x[X_LINE + LINE_BPSI] = m.x[X_LINE + LINE_BEPS] = 0.0
        i = IDX_LINE
        m.P[i:i + N_LINE, :] = 0.0
        m.P[:, i:i + N_LINE] = 0.0
        m.P[i + LINE_KC, i + LINE_KC] = lp.drag_sigma_fraction ** 2
        m.P[i + LINE_KW, i + LINE_KW] = lp.weight_sigma_fraction ** 2
        m.P[i + LINE_BPSI, i + LINE_BPSI] = lp.angle_bias_sigma_rad ** 2
        m.P[i + LINE_BEPS, i + LINE_BEPS] = lp.angle_bias_sigma_rad ** 2
        self.learnt_s = 0.0
        self._learn_t = -math.inf

    def take_weight(self, t_s: float, weight_n_m: float, aligned: bool) -> None:
        """With ``winder_weight``, the line's weight belief ``w_b`` [N/m] from the
        ``weight_n_m`` of a reading arriving at ``t_s`` [s] (the winder's estimate; NaN:
        none): the first within :data:`FACTOR_BOUNDS` of the parameter file's is taken,
        later ones while a GNSS position is fused (the winder's estimate is made with the
        vehicle's reported height, which without GNSS is partly this line's model: a
        loop); otherwise the belief stays (the parameter file's before the first). ``k_w``
        stays a factor on the belief (docs/estimation.md §11): at the first estimate (the
        filter ``aligned``) it starts again at 1 with its prior, uncorrelated; at a later
        move of the estimate its standard deviation grows by the move's fraction of the
        belief, up to the prior's."""
        lo, hi = FACTOR_BOUNDS
        w0 = self._w_param
        if not (self._lp.winder_weight and lo * w0 <= weight_n_m <= hi * w0):  # NaN: False
            return
        first = not self.weight_from_winder
        if not (first or self._src.gnss_pos.in_use(t_s)):
            return
        prm, m, i = self._mem.prm, self._mem, IDX_LINE + LINE_KW
        before = float(prm[PRM_LINE_W])
        prm[PRM_LINE_W] = weight_n_m
        sig_prior = self._lp.weight_sigma_fraction
        if first:
            self.weight_from_winder = True
            if aligned:
                m.x[X_LINE + LINE_KW] = 1.0
                m.P[i, :] = 0.0
                m.P[:, i] = 0.0
                m.P[i, i] = sig_prior ** 2
            return
        sig = math.sqrt(max(float(m.P[i, i]), 0.0))
        grown = min(sig + abs(weight_n_m - before) / weight_n_m, max(sig, sig_prior))
        m.P[i, i] = grown * grown

    def suspended(self, t_s: float, t_meas_s: float, length_m: float, tension_n: float,
                  azimuth_rad: float, elevation_rad: float) -> bool:
        """Whether a reading arriving at ``t_s`` [s] is of a line hanging clear of the
        ground at the exit, pulling, fresh and finite (else counted refused)."""
        lp = self._lp
        ok = (t_s - t_meas_s <= lp.max_age_s and length_m > 0.0
              and tension_n >= max(lp.min_tension_n, 1e-9)
              and elevation_rad >= lp.ground_elevation_rad
              and abs(length_m) + abs(tension_n) + abs(azimuth_rad) + abs(elevation_rad)
              < math.inf)
        if not ok:
            self.refused += 1
        return ok

    def fuse(self, t_s: float, t_meas_s: float, length_m: float, tension_n: float,
             azimuth_rad: float, elevation_rad: float, in_air: bool) -> bool | None:
        """A reading arriving at ``t_s`` [s] (its sample time ``t_meas_s`` [s]; the
        vehicle in the air or not). Returns None when it is not this source's to fuse (a
        line on the ground or slack, stale, or no GNSS and the line's states not learnt:
        the ground station's fix stands), else whether it was fused (or reset to)."""
        if not self.suspended(t_s, t_meas_s, length_m, tension_n, azimuth_rad,
                              elevation_rad):
            return None
        src, lp = self._src, self._lp
        P = self._mem.P
        wind_var = max(P[IDX_W, IDX_W], P[IDX_W + 1, IDX_W + 1])
        if not wind_var > 0.0:         # the wind states inhibited: no drag fusion yet
            return None
        gnss = src.gnss_pos.in_use(t_s)
        # the line's states learnt only with GNSS in the air, in a wind already learnt
        learn = gnss and in_air and wind_var <= lp.wind_sigma_max_m_s ** 2
        if not (learn or self.learnt_s >= lp.learn_time_s):
            return None
        i = IDX_LINE
        if not learn:
            c0, c1 = i, i + N_LINE
        else:
            u = self._mem.x[X_W:X_W + 2]
            windy = (lp.learn_drag
                     and math.hypot(float(u[0]), float(u[1])) >= lp.drag_learn_wind_m_s)
            c0, c1 = (0, 0) if windy else (i + LINE_KC, i + LINE_KC + 1)
        m = self._mem
        res = self._k(m.w, m.P, m.buf, m.meta, min(t_meas_s, t_s), float(length_m),
                      float(tension_n), float(azimuth_rad), float(elevation_rad), c0, c1)
        st = src.tether_line
        st.time_last_attempt = t_s
        reset_due = st.record(t_s, res)
        if learn:
            self._bound()
        if res == FUSED:
            if learn:
                self.learnt_s += min(max(t_s - self._learn_t, 0.0), 1.0)
                self._learn_t = t_s
            self._leave_const_pos()
            return True
        if res == REJECTED and reset_due and not gnss:
            self._reset()
            st.reset_done(t_s)
            self._leave_const_pos()
            return True
        return False

    def _bound(self) -> None:
        """The weight and drag factors kept within :data:`FACTOR_BOUNDS` (a line's weight
        and drag per metre are positive; the model is integrated with them)."""
        x = self._mem.x
        lo, hi = FACTOR_BOUNDS
        for k in (LINE_KC, LINE_KW):
            x[X_LINE + k] = min(max(float(x[X_LINE + k]), lo), hi)

    def _reset(self) -> None:
        """Position set to the line's end (the latest innovation added), its covariance to
        the innovation's (uncorrelated with the rest); the velocity kept."""
        m = self._mem
        st = self._src.tether_line
        y, s = st.innovation, st.innovation_variance
        m.x[0:3] += y
        m.buffered()[:, BUF_P:BUF_P + 3] += y
        P = m.P
        P[IDX_P:IDX_P + 3, :] = 0.0
        P[:, IDX_P:IDX_P + 3] = 0.0
        for k in range(3):
            P[IDX_P + k, IDX_P + k] = s[k]
        self._out.reset(velocity=False)

    @property
    def weight_belief_n_m(self) -> float:
        """The line's weight per metre ``w_b`` [N/m] that ``k_w`` multiplies: the winder's
        estimate once a reading carried one, the parameter file's before."""
        return float(self._mem.prm[PRM_LINE_W])

    @property
    def states(self) -> tuple[float, float, float, float]:
        """The line's states: (k_w, k_c, b_psi [rad], b_eps [rad])."""
        x = self._mem.x
        return (float(x[X_LINE + LINE_KW]), float(x[X_LINE + LINE_KC]),
                float(x[X_LINE + LINE_BPSI]), float(x[X_LINE + LINE_BEPS]))
