"""The magnetometer: its heading (the yaw error, with or without the tilt's effect through
the field's inclination) or its three axes against the Earth field with a bias state per
axis (EKF2's 3-axis fusion, EKF3's MAG_CAL) while the vehicle manoeuvres; its control."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from companion.ekf.aid_source import AidSourceStatus
from companion.ekf.layout import (
    FUSED,
    IDX_BM,
    IDX_TH,
    N_ERR,
    NUMERIC,
    NX,
    PRM_EARTH_X,
    PRM_EARTH_Y,
    PRM_EARTH_Z,
    PRM_HEADING_EARTH,
    PRM_MAG_COUPLE_X,
    PRM_MAG_COUPLE_Y,
    PRM_MAG_GATE,
    PRM_MAG_R_3D,
    PRM_MAG_R_HEADING,
    PRM_MAG_TILT,
    PRM_MAG_WITH_BIAS,
    PRM_VAR_MIN,
    REJECTED,
    W_DX,
    W_HEADING_INNOV,
    W_PRM,
    W_RATES,
    W_X,
    X_BM,
    X_Q,
    AidSourceKind,
)
from companion.ekf.memory import FilterMemory
from companion.ekf.params import EstimatorParams, MagFusion
from companion.ekf.update import dot, inject, mat_vec, row_update, scalar_update, set_aid_row
from tuavdefs.frames import quat_to_matrix_kernel, wrap_pi
from tuavdefs.jit import entry_point, njit

_MAG = int(AidSourceKind.MAG)


@njit
def fuse_mag_kernel(w: np.ndarray, P: np.ndarray, buf: np.ndarray, meta: np.ndarray,
                    mx: float, my: float, mz: float) -> int:
    """A magnetometer sample ``m*`` [gauss] (body FLU) as a heading: the field rotated
    into the inertial frame with the estimated attitude, the innovation the Earth field's
    heading minus its heading (the yaw error, the tilt taken from the estimate). Its
    Jacobian: that of the yaw, and with the tilt flag also the heading's dependence on the
    tilt error through the field's inclination (couple_* = E_z E_x / |E_h|^2,
    E_z E_y / |E_h|^2). The bias estimate ``b_m`` is taken off the sample first; with the
    bias flag (3-axis mode's still phases, where a heading cannot tell the bias from the
    yaw) the Jacobian has the heading's dependence on the bias error too, the bias
    considered, not estimated: the yaw's variance stays honest, the bias waits for a
    manoeuvre. Noise, gate, flags and field in the work array's parameters. Returns
    FUSED, REJECTED or NUMERIC (also: no horizontal field)."""
    x = w[W_X:W_X + NX]
    prm = w[W_PRM:]
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = quat_to_matrix_kernel(
        (x[X_Q], x[X_Q + 1], x[X_Q + 2], x[X_Q + 3]))
    mx, my, mz = mx - x[X_BM], my - x[X_BM + 1], mz - x[X_BM + 2]
    ex = r00 * mx + r01 * my + r02 * mz
    ey = r10 * mx + r11 * my + r12 * mz
    if ex * ex + ey * ey < 1e-12:
        return NUMERIC
    y = wrap_pi(prm[PRM_HEADING_EARTH] - math.atan2(ey, ex))
    # yaw = atan2(R10, R00); d yaw / d dtheta for R <- (I + [dtheta]x) R
    d = r00 * r00 + r10 * r10
    if d < 1e-9:
        return NUMERIC
    h0, h1 = -r20 * r00 / d, -r20 * r10 / d
    if prm[PRM_MAG_TILT] != 0.0:
        # the heading of the field rotated with the estimate depends on its tilt error
        # too, through the field's inclination
        h0, h1 = -prm[PRM_MAG_COUPLE_X], -prm[PRM_MAG_COUPLE_Y]
    n = P.shape[0]
    h = np.zeros(n)
    h[IDX_TH], h[IDX_TH + 1], h[IDX_TH + 2] = h0, h1, 1.0
    with_bias = prm[PRM_MAG_WITH_BIAS] != 0.0
    if with_bias:
        # the heading of R (m - b_m - db_m): d/d db_m = (e_y R_0j - e_x R_1j) / |e_h|^2
        eh2 = ex * ex + ey * ey
        for j, (a0, a1) in enumerate(((r00, r10), (r01, r11), (r02, r12))):
            h[IDX_BM + j] = (ey * a0 - ex * a1) / eh2
    r, gate = prm[PRM_MAG_R_HEADING], prm[PRM_MAG_GATE]
    ph = mat_vec(P, h)
    s = dot(h, ph) + r
    ratio = y * y / (s * gate * gate)
    w[W_HEADING_INNOV] = y
    set_aid_row(w, _MAG, y, 0.0, 0.0, s, 0.0, 0.0, ratio)
    if ratio > 1.0:
        return REJECTED
    c0, c1 = (IDX_BM, IDX_BM + 3) if with_bias else (0, 0)
    dx = w[W_DX:W_DX + N_ERR]
    if not row_update(P, dx, prm[PRM_VAR_MIN], y, r, h, c0, c1):
        return NUMERIC
    inject(x, dx, buf, meta)
    return FUSED


@njit
def fuse_mag3d_kernel(w: np.ndarray, P: np.ndarray, buf: np.ndarray, meta: np.ndarray,
                      mx: float, my: float, mz: float) -> int:
    """A magnetometer sample ``m*`` [gauss] (body FLU) fused on its three axes: the model
    ``m = R' E + b_m`` with the Earth field ``E`` [gauss] (inertial), Jacobians ``R' [E]x``
    on the attitude error and the identity on the bias, the 3-axis noise per axis. Gated
    as one: any axis's test ratio above 1 rejects the sample (the row: the axes'
    innovations and variances, the largest ratio). The heading innovation of the
    bias-corrected sample is kept for the status. Returns FUSED, REJECTED or NUMERIC."""
    x = w[W_X:W_X + NX]
    prm = w[W_PRM:]
    ex, ey, ez = prm[PRM_EARTH_X], prm[PRM_EARTH_Y], prm[PRM_EARTH_Z]
    r, gate = prm[PRM_MAG_R_3D], prm[PRM_MAG_GATE]
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = quat_to_matrix_kernel(
        (x[X_Q], x[X_Q + 1], x[X_Q + 2], x[X_Q + 3]))
    cols = ((r00, r10, r20), (r01, r11, r21), (r02, r12, r22))   # rows of R'
    m = (mx, my, mz)
    y = np.zeros(3)
    s = np.zeros(3)
    h = np.zeros((3, 3))
    worst = 0.0
    for k in range(3):
        a0, a1, a2 = cols[k]
        y[k] = m[k] - (a0 * ex + a1 * ey + a2 * ez + x[X_BM + k])
        h0, h1, h2 = a1 * ez - a2 * ey, a2 * ex - a0 * ez, a0 * ey - a1 * ex
        h[k, 0], h[k, 1], h[k, 2] = h0, h1, h2
        b = IDX_BM + k
        t0, t1, t2 = IDX_TH, IDX_TH + 1, IDX_TH + 2
        s[k] = (h0 * h0 * P[t0, t0] + h1 * h1 * P[t1, t1] + h2 * h2 * P[t2, t2]
                + 2.0 * (h0 * h1 * P[t0, t1] + h0 * h2 * P[t0, t2] + h1 * h2 * P[t1, t2])
                + 2.0 * (h0 * P[t0, b] + h1 * P[t1, b] + h2 * P[t2, b]) + P[b, b] + r)
        worst = max(worst, y[k] * y[k] / (s[k] * gate * gate))
    # the heading innovation, for the status
    cx, cy, cz = mx - x[X_BM], my - x[X_BM + 1], mz - x[X_BM + 2]
    hx = r00 * cx + r01 * cy + r02 * cz
    hy = r10 * cx + r11 * cy + r12 * cz
    w[W_HEADING_INNOV] = wrap_pi(prm[PRM_HEADING_EARTH] - math.atan2(hy, hx))
    set_aid_row(w, _MAG, y[0], y[1], y[2], s[0], s[1], s[2], worst)
    if worst > 1.0:
        return REJECTED
    res = FUSED
    dx = w[W_DX:W_DX + N_ERR]
    var_min = prm[PRM_VAR_MIN]
    for k in range(3):
        if not scalar_update(P, dx, var_min, y[k], r, IDX_TH, h[k, 0], IDX_TH + 1, h[k, 1],
                             IDX_TH + 2, h[k, 2], IDX_BM + k, 1.0):
            res = NUMERIC
    inject(x, dx, buf, meta)
    return res


def finite_sample(mag_flu_gauss: Sequence[float]) -> tuple[float, float, float] | None:
    """The sample's three axes [gauss] if all are finite, else None."""
    mx, my, mz = float(mag_flu_gauss[0]), float(mag_flu_gauss[1]), float(mag_flu_gauss[2])
    if math.isfinite(mx) and math.isfinite(my) and math.isfinite(mz):
        return mx, my, mz
    return None


class MagControl:
    """Fuses the magnetometer's samples of an aligned filter: the three axes while the
    vehicle manoeuvres (3-axis mode), else the heading; at most one per
    ``mag_min_interval_s`` after the last fused."""

    __slots__ = ("_p", "_mem", "_st", "_mag3d", "_rates", "_t_manoeuvre", "_k_heading",
                 "_k_3d")

    def __init__(self, params: EstimatorParams, mem: FilterMemory, status: AidSourceStatus,
                 earth_field_enu_gauss: tuple[float, float, float]) -> None:
        self._p = p = params
        self._mem = mem
        self._st = status
        self._mag3d = MagFusion(p.mag_fusion) is MagFusion.AXES_3D
        ex, ey, ez = earth_field_enu_gauss
        prm = mem.prm
        prm[PRM_EARTH_X], prm[PRM_EARTH_Y], prm[PRM_EARTH_Z] = ex, ey, ez
        prm[PRM_HEADING_EARTH] = math.atan2(ey, ex)
        prm[PRM_MAG_COUPLE_X] = ez * ex / (ex * ex + ey * ey)
        prm[PRM_MAG_COUPLE_Y] = ez * ey / (ex * ex + ey * ey)
        prm[PRM_MAG_R_HEADING] = p.mag_yaw_noise_rad ** 2
        prm[PRM_MAG_R_3D] = p.mag_noise_gauss ** 2
        prm[PRM_MAG_GATE] = status.policy.gate_sigma
        prm[PRM_MAG_TILT] = 0.0 if p.mag_yaw_only else 1.0
        prm[PRM_MAG_WITH_BIAS] = 1.0 if self._mag3d else 0.0
        self._rates = mem.w[W_RATES:W_RATES + 7]
        self._t_manoeuvre = -math.inf
        self._k_heading = entry_point(fuse_mag_kernel, mem.w, mem.P, mem.buf, mem.meta,
                                      0.0, 0.0, 0.0)
        self._k_3d = entry_point(fuse_mag3d_kernel, mem.w, mem.P, mem.buf, mem.meta, 0.0,
                                 0.0, 0.0)

    def fuse(self, t_s: float, mag_flu_gauss: Sequence[float]) -> bool:
        """A sample [gauss], body FLU, at ``t_s`` [s]. Returns whether it was fused."""
        st = self._st
        if st.too_soon(t_s):
            return False
        sample = finite_sample(mag_flu_gauss)
        if sample is None:
            return False
        st.time_last_attempt = t_s
        m = self._mem
        k: Callable[..., int] = (self._k_3d if self._mag3d and self._manoeuvring(t_s)
                                 else self._k_heading)
        res = k(m.w, m.P, m.buf, m.meta, *sample)
        st.record(t_s, res)
        return res == FUSED

    def _manoeuvring(self, t_s: float) -> bool:
        """Whether the magnetometer's bias is observable now (EKF2's rule for its 3-axis
        fusion): the low-passed horizontal acceleration or yaw rate above its threshold,
        or was within ``mag_3d_hold_s``. Still, the bias and the heading cannot be told
        apart, and the heading alone is fused (with the bias learnt so far taken off)."""
        p, r = self._p, self._rates
        if (math.hypot(r[3], r[4]) >= p.mag_3d_accel_m_s2
                or abs(r[6]) >= p.mag_3d_yaw_rate_rad_s):
            self._t_manoeuvre = t_s
        return t_s - self._t_manoeuvre <= p.mag_3d_hold_s
