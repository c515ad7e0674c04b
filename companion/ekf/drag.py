"""The drag's specific force, and the wind states it makes observable (EKF3's drag
fusion; docs/estimation.md §11).

A multirotor's thrust is along its body z axis, so its accelerometer's body x and y read
only the other forces over the mass: the air's drag on the body and rotors and the
tether's pull. With the air-relative velocity ``v_r = R'(v - U)`` (body FLU, ``U`` the
horizontal wind states) the drag model is EKF3's, per body axis ``i`` (x, y):

    a_i = -(rho / (2 B_i)) |v_r| v_r,i - M_i v_r,i            (B: ballistic coefficient
                                                               [kg/m^2], M: momentum drag
                                                               coefficient [1/s])

and the tether's pull ``F`` [N] (inertial) adds ``(R' F / m)_i``. The measurement is the
bias-corrected specific force averaged over ``drag.interval_s`` (the prediction sums it),
against the current state; its Jacobian has the velocity, the attitude, the accelerometer
bias and the wind. The coefficients are the controllers' vehicle model's
(:meth:`DragModel.from_vehicle`: the quadratic drag area and linear drag the position
loop's feed-forward uses), never the plant's.

The wind states are inhibited (their covariance zero, no process noise: no other fusion
moves them) on the ground and until drag fusion starts, as EKF3's ``inhibitWindStates``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from companion.ekf.aid_source import AidSourceStatus
from companion.ekf.layout import (
    FUSED,
    IDX_BA,
    IDX_TH,
    IDX_V,
    IDX_W,
    N_ERR,
    NUMERIC,
    NX,
    PRM_DRAG_ALL,
    PRM_DRAG_GATE,
    PRM_DRAG_MODEL_FRAC,
    PRM_DRAG_MX,
    PRM_DRAG_MY,
    PRM_DRAG_PULL_FRAC,
    PRM_DRAG_QX,
    PRM_DRAG_QY,
    PRM_DRAG_R,
    PRM_DRAG_RESET,
    PRM_MASS_INV,
    PRM_VAR_MIN,
    PRM_WIND_HGT_SCALE,
    PRM_WIND_VAR0,
    PRM_WIND_WALK,
    REJECTED,
    W_DRAG_SUM,
    W_DX,
    W_PRM,
    W_X,
    X_Q,
    X_V,
    X_W,
    AidSourceKind,
)
from companion.ekf.memory import FilterMemory
from companion.ekf.output import take_up
from companion.ekf.params import EstimatorParams
from companion.ekf.update import dot, inject, mat_vec, row_update, row_update_only, set_aid_row
from tuavdefs.frames import Vec3, quat_to_matrix_kernel
from tuavdefs.jit import entry_point, njit
from tuavdefs.params import EnvironmentParams, VehicleParams

_DRAG = int(AidSourceKind.DRAG)


class DragModel(NamedTuple):
    """The vehicle's drag as the filter models it (EKF3's names)."""

    bcoef_x_kg_m2: float
    """Ballistic coefficient along body x, mass / (C_d A) [kg/m^2] (EK3_DRAG_BCOEF_X;
    inf: no quadratic drag)."""
    bcoef_y_kg_m2: float
    """The same along body y (EK3_DRAG_BCOEF_Y)."""
    mcoef_x_1_s: float
    """Momentum (rotor) drag along body x, linear drag / mass [1/s] (EK3_DRAG_MCOEF)."""
    mcoef_y_1_s: float
    """The same along body y."""
    mass_kg: float
    """The vehicle's mass [kg] (the tether's pull over it)."""
    air_density_kg_m3: float

    @classmethod
    def from_vehicle(cls, vehicle: object, air_density_kg_m3: float) -> DragModel:
        """From a vehicle model (``tuavdefs.params.VehicleParams``: ``mass_kg``,
        ``drag_area_m2`` C_d A per body axis, ``drag_coeff_n_s_m`` linear drag per body
        axis)."""
        m = float(vehicle.mass_kg)                       # type: ignore[attr-defined]
        area = vehicle.drag_area_m2                      # type: ignore[attr-defined]
        lin = vehicle.drag_coeff_n_s_m                   # type: ignore[attr-defined]
        return cls(m / area[0] if area[0] > 0 else math.inf,
                   m / area[1] if area[1] > 0 else math.inf,
                   float(lin[0]) / m, float(lin[1]) / m, m, float(air_density_kg_m3))

    @classmethod
    def default_vehicle(cls) -> DragModel:
        """The companion's default vehicle model (``VehicleParams()``) in its default air
        (``EnvironmentParams()``): what a companion built on default parameters gives its
        filter, for a filter built without a drag model."""
        return cls.from_vehicle(VehicleParams(), EnvironmentParams().air_density_kg_m3)


@njit
def drag_prediction(x: np.ndarray, prm: np.ndarray, tfx: float, tfy: float, tfz: float,
                    h: np.ndarray) -> tuple[float, float]:
    """The specific force's body x and y [m/s^2] the drag model predicts at the nominal
    state ``x`` (parameters ``prm``) with the tether pulling ``tf*`` [N] (inertial), and
    their Jacobian rows on the error state in ``h`` (2 x N_ERR, overwritten)."""
    qw, qx, qy, qz = x[X_Q], x[X_Q + 1], x[X_Q + 2], x[X_Q + 3]
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = quat_to_matrix_kernel(
        (qw, qx, qy, qz))
    # the air-relative velocity, inertial (w) and body (b = R' w)
    wx, wy, wz = x[X_V] - x[X_W], x[X_V + 1] - x[X_W + 1], x[X_V + 2]
    bx = r00 * wx + r10 * wy + r20 * wz
    by = r01 * wx + r11 * wy + r21 * wz
    bz = r02 * wx + r12 * wy + r22 * wz
    speed = math.sqrt(bx * bx + by * by + bz * bz)
    minv = prm[PRM_MASS_INV]
    # the pull in body axes over the mass
    px = (r00 * tfx + r10 * tfy + r20 * tfz) * minv
    py = (r01 * tfx + r11 * tfy + r21 * tfz) * minv
    for i in range(2):
        h[i, :] = 0.0
    pred = np.zeros(2)
    b = (bx, by, bz)
    # columns of R (rows of R'), and R' [u]x's rows: (R' [u]x)_i = (u x R[:, i])' ...
    rc = ((r00, r10, r20), (r01, r11, r21), (r02, r12, r22))
    for i in range(2):
        kq = prm[PRM_DRAG_QX + i]
        km = prm[PRM_DRAG_MX + i]
        pred[i] = -(kq * speed + km) * b[i] + (px if i == 0 else py)
        # d a_i / d b_j
        g = np.zeros(3)
        for j in range(3):
            g[j] = -kq * (b[i] * b[j] / speed if speed > 0.0 else 0.0)
        g[i] -= kq * speed + km
        # R g: the inertial direction of the row (on dv; -its horizontal part on dU)
        ex = r00 * g[0] + r01 * g[1] + r02 * g[2]
        ey = r10 * g[0] + r11 * g[1] + r12 * g[2]
        ez = r20 * g[0] + r21 * g[1] + r22 * g[2]
        h[i, IDX_V] = ex
        h[i, IDX_V + 1] = ey
        h[i, IDX_V + 2] = ez
        h[i, IDX_W] = -ex
        h[i, IDX_W + 1] = -ey
        # dtheta: b = R' w, d b = R' [w]x dtheta, so (g' R' [w]x) = (R g)' [w]x = -(w x (R g))'
        # ... = ((R g) x w)'; the pull likewise: e_i' R' [F]x / m = ((R e_i) x F)' / m
        cx, cy, cz = rc[i]
        fx_, fy_, fz_ = tfx * minv, tfy * minv, tfz * minv
        h[i, IDX_TH] = (ey * wz - ez * wy) + (cy * fz_ - cz * fy_)
        h[i, IDX_TH + 1] = (ez * wx - ex * wz) + (cz * fx_ - cx * fz_)
        h[i, IDX_TH + 2] = (ex * wy - ey * wx) + (cx * fy_ - cy * fx_)
        # the bias-corrected reading is the true specific force plus the bias's error
        h[i, IDX_BA + i] = 1.0
    return pred[0], pred[1]


@njit
def drag_noise_var(x: np.ndarray, prm: np.ndarray, tfx: float, tfy: float, tfz: float,
                   px: float, py: float) -> tuple[float, float]:
    """The variance [m^2/s^4] of the specific force's body x and y against the model whose
    prediction is ``p*`` with the tether pulling ``tf*`` [N] (inertial): the noise's, plus
    the drag's share times its model error (``PRM_DRAG_MODEL_FRAC``: the coefficients and
    the mass are the companion's vehicle's, not the air's) and the pull's times its own
    (``PRM_DRAG_PULL_FRAC``: the line's model, the mass), as standard deviations."""
    (r00, r01, _), (r10, r11, _), (r20, r21, _) = quat_to_matrix_kernel(
        (x[X_Q], x[X_Q + 1], x[X_Q + 2], x[X_Q + 3]))
    minv = prm[PRM_MASS_INV]
    ux = (r00 * tfx + r10 * tfy + r20 * tfz) * minv
    uy = (r01 * tfx + r11 * tfy + r21 * tfz) * minv
    fd, fp = prm[PRM_DRAG_MODEL_FRAC], prm[PRM_DRAG_PULL_FRAC]
    r = prm[PRM_DRAG_R]
    return (r + (fd * (px - ux)) ** 2 + (fp * ux) ** 2,
            r + (fd * (py - uy)) ** 2 + (fp * uy) ** 2)


@njit
def wind_reset(x: np.ndarray, prm: np.ndarray, tfx: float, tfy: float, tfz: float,
               fx: float, fy: float, P: np.ndarray) -> bool:
    """The wind states set to the wind under which the drag model with the tether pulling
    ``tf*`` [N] (inertial) predicts the specific force ``fx``, ``fy`` [m/s^2] (body x,
    y) at the current attitude and velocity (Newton's method on the model's wind columns,
    from the current wind), their covariance the prior's (``PRM_WIND_VAR0``, uncorrelated).
    Returns False (nothing changed) if it does not converge to a finite wind."""
    xx = x.copy()
    h = np.zeros((2, N_ERR))
    for _ in range(12):
        px, py = drag_prediction(xx, prm, tfx, tfy, tfz, h)
        e0, e1 = fx - px, fy - py
        a, b, c, d = h[0, IDX_W], h[0, IDX_W + 1], h[1, IDX_W], h[1, IDX_W + 1]
        det = a * d - b * c
        if not abs(det) > 1e-9:
            return False
        du0, du1 = (d * e0 - b * e1) / det, (a * e1 - c * e0) / det
        # a step at most 5 m/s: the model's curvature at low airspeed
        step = math.sqrt(du0 * du0 + du1 * du1)
        if step > 5.0:
            du0, du1 = du0 * 5.0 / step, du1 * 5.0 / step
        xx[X_W] += du0
        xx[X_W + 1] += du1
        if step < 1e-3:
            break
    px, py = drag_prediction(xx, prm, tfx, tfy, tfz, h)
    if not (math.isfinite(xx[X_W]) and math.isfinite(xx[X_W + 1])
            and abs(fx - px) < 0.05 and abs(fy - py) < 0.05):
        return False
    x[X_W], x[X_W + 1] = xx[X_W], xx[X_W + 1]
    P[IDX_W:IDX_W + 2, :] = 0.0
    P[:, IDX_W:IDX_W + 2] = 0.0
    P[IDX_W, IDX_W] = P[IDX_W + 1, IDX_W + 1] = prm[PRM_WIND_VAR0]
    return True


@njit
def fuse_drag_kernel(w: np.ndarray, P: np.ndarray, buf: np.ndarray, meta: np.ndarray,
                     tfx: float, tfy: float, tfz: float) -> int:
    """The specific force's body x and y averaged since the last call (the prediction's
    sums, reset here) against the drag model with the tether pulling ``tf*`` [N]
    (inertial), at the current state. Gated as one (the larger axis's test ratio);
    fused as two scalars into the wind states alone: every other state is considered
    (its uncertainty in the innovation's variance, its estimate and covariance left as
    they are), as EKF3 fuses drag into the wind only, so that where the model is off
    (the truth's mass, the line's pull) it moves the wind, never the attitude or the
    position. Returns FUSED, REJECTED or NUMERIC (no sample summed, or numerically)."""
    x = w[W_X:W_X + NX]
    prm = w[W_PRM:]
    sums = w[W_DRAG_SUM:W_DRAG_SUM + 3]
    n = sums[2]
    if not n > 0.0:
        return NUMERIC
    fx, fy = sums[0] / n, sums[1] / n
    sums[0] = sums[1] = sums[2] = 0.0
    h = np.zeros((2, N_ERR))
    px, py = drag_prediction(x, prm, tfx, tfy, tfz, h)
    r0, r1 = drag_noise_var(x, prm, tfx, tfy, tfz, px, py)
    gate = prm[PRM_DRAG_GATE]
    y0, y1 = fx - px, fy - py
    s0 = dot(h[0], mat_vec(P, h[0])) + r0
    s1 = dot(h[1], mat_vec(P, h[1])) + r1
    ratio = max(y0 * y0 / (gate * gate * s0), y1 * y1 / (gate * gate * s1))
    set_aid_row(w, _DRAG, y0, y1, 0.0, s0, s1, 0.0, ratio)
    if ratio > 1.0:
        if prm[PRM_DRAG_RESET] > 0.0 and wind_reset(x, prm, tfx, tfy, tfz, fx, fy, P):
            prm[PRM_DRAG_RESET] = 0.0        # done (the caller records the reset)
            set_aid_row(w, _DRAG, y0, y1, 0.0, s0, s1, 0.0, ratio)
            return FUSED
        return REJECTED
    dx = w[W_DX:W_DX + N_ERR]
    var_min = prm[PRM_VAR_MIN]
    res = FUSED
    if prm[PRM_DRAG_ALL] > 0.0:       # every state its Jacobian has (correct_navigation)
        before = w[W_X:W_X + 6].copy()
        for i, y, r in ((0, y0, r0), (1, y1, r1)):
            if not row_update(P, dx, var_min, y, r, h[i], 0, 0):
                res = NUMERIC
        inject(x, dx, buf, meta)
        take_up(w, before)
        return res
    # the second axis's innovation against the state before the batch: row_update_only
    # subtracts h dx (the first axis's correction)
    for i, y, r in ((0, y0, r0), (1, y1, r1)):
        if not row_update_only(P, dx, var_min, y, r, h[i], IDX_W, IDX_W + 2):
            res = NUMERIC
    # only the wind moved: the rest of the state (and the output) untouched, to the bit
    x[X_W] += dx[IDX_W]
    x[X_W + 1] += dx[IDX_W + 1]
    dx[IDX_W] = dx[IDX_W + 1] = 0.0
    return res


class DragControl:
    """Fuses the drag's specific force every ``drag.interval_s`` while the vehicle flies;
    the wind states inhibited on the ground and before the first fusion."""

    __slots__ = ("_p", "_mem", "_st", "_k", "active")

    def __init__(self, params: EstimatorParams, mem: FilterMemory, status: AidSourceStatus,
                 model: DragModel) -> None:
        self._p = params
        self._mem = mem
        self._st = status
        prm = mem.prm
        rho = model.air_density_kg_m3
        prm[PRM_DRAG_QX] = 0.5 * rho / model.bcoef_x_kg_m2
        prm[PRM_DRAG_QY] = 0.5 * rho / model.bcoef_y_kg_m2
        prm[PRM_DRAG_MX] = model.mcoef_x_1_s
        prm[PRM_DRAG_MY] = model.mcoef_y_1_s
        prm[PRM_MASS_INV] = 1.0 / model.mass_kg
        prm[PRM_DRAG_R] = params.drag.noise_m_s2 ** 2
        prm[PRM_DRAG_MODEL_FRAC] = params.drag.model_error_fraction
        prm[PRM_DRAG_PULL_FRAC] = params.drag.pull_error_fraction
        prm[PRM_DRAG_GATE] = status.policy.gate_sigma
        prm[PRM_WIND_HGT_SCALE] = params.drag.wind_walk_height_rate_scale
        prm[PRM_WIND_VAR0] = params.drag.wind_sigma_m_s ** 2
        prm[PRM_DRAG_RESET] = 0.0
        prm[PRM_DRAG_ALL] = 1.0 if params.drag.correct_navigation else 0.0
        #: whether the wind states are estimated (not inhibited)
        self.active = False
        self._k = entry_point(fuse_drag_kernel, mem.w, mem.P, mem.buf, mem.meta, 0.0, 0.0,
                              0.0)

    def fuse(self, t_s: float, in_air: bool, tether_pull_n: Sequence[float]) -> bool:
        """At ``t_s`` [s]: the vehicle in the air (``in_air``; else the wind states are
        inhibited), the tether's modelled pull on it [N] (inertial). Returns whether the
        drag was fused."""
        m, st = self._mem, self._st
        if not in_air:
            self._inhibit()
            return False
        if st.too_soon(t_s):
            return False
        if not self.active:
            self._start()
            st.time_last_attempt = t_s
            m.w[W_DRAG_SUM:W_DRAG_SUM + 3] = 0.0     # from now on
            return False
        st.time_last_attempt = t_s
        tx, ty, tz = tether_pull_n
        # rejected for reset_s: the kernel resets the wind to the measurement if this one
        # is rejected too
        due = t_s - st.fail_since >= st.policy.reset_s
        m.prm[PRM_DRAG_RESET] = 1.0 if due else 0.0
        res = self._k(m.w, m.P, m.buf, m.meta, float(tx), float(ty), float(tz))
        if due and m.prm[PRM_DRAG_RESET] == 0.0:      # the kernel reset the wind
            st.reset_done(t_s)
            return True
        st.record(t_s, res)
        return res == FUSED

    def _start(self) -> None:
        """The wind states estimated from now on: at 0, with their prior and walk."""
        m, p = self._mem, self._p
        m.x[X_W:X_W + 2] = 0.0
        m.P[IDX_W:IDX_W + 2, :] = 0.0
        m.P[:, IDX_W:IDX_W + 2] = 0.0
        m.P[IDX_W, IDX_W] = m.P[IDX_W + 1, IDX_W + 1] = p.drag.wind_sigma_m_s ** 2
        m.prm[PRM_WIND_WALK] = p.drag.wind_walk_m_s_sqrt_s
        self.active = True

    def _inhibit(self) -> None:
        """The wind states inhibited: kept, their covariance zeroed, no walk."""
        if not self.active:
            return
        m = self._mem
        m.P[IDX_W:IDX_W + 2, :] = 0.0
        m.P[:, IDX_W:IDX_W + 2] = 0.0
        m.prm[PRM_WIND_WALK] = 0.0
        self.active = False

    @property
    def wind_m_s(self) -> tuple[float, float]:
        """The wind states [m/s] (east, north)."""
        x = self._mem.x
        return (float(x[X_W]), float(x[X_W + 1]))


def wind_vec3(wind: tuple[float, float]) -> Vec3:
    """The horizontal wind as a 3-vector (vertical 0) [m/s]."""
    return (wind[0], wind[1], 0.0)
