"""GNSS position and velocity: the fusion kernel against the delayed state, and its
control (the fix's usability, its noise, the reset to the fix after ``gnss_reset_s`` of
rejections). The receiver's position error can be a Gauss-Markov state (``b_p``,
``gnss_pos_tau_s`` > 0): the fix is then ``p + b_p``."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from companion.ekf.aid_source import AidSources
from companion.ekf.layout import (
    ACC_POS_H,
    ACC_POS_V,
    ACC_VEL,
    BUF_P,
    FUSED,
    IDX_BP,
    IDX_P,
    IDX_V,
    N_ERR,
    NUMERIC,
    NX,
    PRM_BP_VAR_H,
    PRM_BP_VAR_V,
    PRM_GNSS_FUSE_HGT,
    PRM_GNSS_GATE_POS,
    PRM_GNSS_GATE_VEL,
    PRM_GNSS_R_VEL,
    PRM_VAR_MIN,
    PRM_WANDER,
    REJECTED,
    W_DELAYED,
    W_DX,
    W_PRM,
    W_X,
    X_BP,
    AidSourceKind,
)
from companion.ekf.memory import FilterMemory
from companion.ekf.output import OutputPredictor, take_up
from companion.ekf.params import EstimatorParams
from companion.ekf.update import delayed_state, inject, scalar_update, set_aid_row
from tuavdefs.frames import Vec3
from tuavdefs.jit import entry_point, njit

_POS, _HGT, _VEL = (int(AidSourceKind.GNSS_POS), int(AidSourceKind.GNSS_HGT),
                    int(AidSourceKind.GNSS_VEL))


@njit
def _fuse_gnss(w: np.ndarray, P: np.ndarray, buf: np.ndarray, meta: np.ndarray,
               t_meas_s: float, px: float, py: float, pz: float, vx: float, vy: float,
               vz: float, r_h: float, r_v: float) -> int:
    x = w[W_X:W_X + NX]
    dx = w[W_DX:W_DX + N_ERR]
    delayed = w[W_DELAYED:W_DELAYED + 6]
    prm = w[W_PRM:]
    var_min = prm[PRM_VAR_MIN]
    wander = prm[PRM_WANDER] != 0.0
    gate_pos, gate_vel = prm[PRM_GNSS_GATE_POS], prm[PRM_GNSS_GATE_VEL]
    r_vel = prm[PRM_GNSS_R_VEL]
    delayed_state(buf, meta, x, t_meas_s, delayed)
    z = (px, py, pz, vx, vy, vz)
    rr = (r_h, r_h, r_v, r_vel, r_vel, r_vel)
    gates = (gate_pos, gate_pos, gate_pos, gate_vel, gate_vel, gate_vel)
    y = np.zeros(6)
    s = np.zeros(6)
    tr = np.zeros(6)
    for i in range(6):
        yi = z[i] - delayed[i]
        si = P[i, i] + rr[i]
        if wander and i < 3:
            yi -= x[X_BP + i]
            si += 2.0 * P[i, IDX_BP + i] + P[IDX_BP + i, IDX_BP + i]
        y[i] = yi
        s[i] = si
        tr[i] = yi * yi / (si * gates[i] * gates[i])
    tr_h = max(tr[0], tr[1])
    tr_vel = max(tr[3], max(tr[4], tr[5]))
    set_aid_row(w, _POS, y[0], y[1], 0.0, s[0], s[1], 0.0, tr_h)
    set_aid_row(w, _HGT, y[2], 0.0, 0.0, s[2], 0.0, 0.0, tr[2])
    set_aid_row(w, _VEL, y[3], y[4], y[5], s[3], s[4], s[5], tr_vel)
    result = 0
    ok = np.zeros(6, dtype=np.bool_)
    if tr_h <= 1.0:
        ok[0] = ok[1] = True
        result |= ACC_POS_H
    if tr[2] <= 1.0 and prm[PRM_GNSS_FUSE_HGT] != 0.0:
        ok[2] = True
        result |= ACC_POS_V
    if tr_vel <= 1.0:
        ok[3] = ok[4] = ok[5] = True
        result |= ACC_VEL
    for i in range(6):
        ib = IDX_BP + i if wander and i < 3 else -1
        if ok[i] and not scalar_update(P, dx, var_min, y[i], rr[i], i, 1.0, ib, 1.0,
                                       -1, 0.0):
            result |= NUMERIC
    inject(x, dx, buf, meta)
    return result


@njit
def fuse_gnss_kernel(w: np.ndarray, P: np.ndarray, buf: np.ndarray, meta: np.ndarray,
                     t_meas_s: float, px: float, py: float, pz: float, vx: float, vy: float,
                     vz: float, r_h: float, r_v: float) -> int:
    """A GNSS fix of the time ``t_meas_s`` [s]: position ``p*`` [m] and velocity ``v*``
    [m/s] (ENU), position noise variances ``r_h``, ``r_v`` [m^2] (the velocity's, the
    gates, whether the height is fused and whether the receiver's wander is modelled are
    in the work array's parameters). The innovations are taken against the state at
    ``t_meas_s``, gated (horizontal position, height and velocity each as one; their rows
    of the aid-source block written), the accepted axes fused one by one, the correction
    injected into the current state and taken up by the output. Returns the accepted
    groups as bits (ACC_POS_H, ACC_POS_V, ACC_VEL; NUMERIC: an axis refused
    numerically)."""
    before = w[W_X:W_X + 6].copy()
    res = _fuse_gnss(w, P, buf, meta, t_meas_s, px, py, pz, vx, vy, vz, r_h, r_v)
    take_up(w, before)
    return res


def usable_fix(p: EstimatorParams, pos_enu_m: Sequence[float], vel_enu_m_s: Sequence[float],
               eph_m: float, epv_m: float) -> tuple[Vec3, Vec3] | None:
    """The fix's position and velocity if it is usable (finite, its claimed horizontal
    accuracy within ``gnss_max_eph_m``), else None."""
    px, py, pz = pos_enu_m
    vx, vy, vz = vel_enu_m_s
    pos = (float(px), float(py), float(pz))
    vel = (float(vx), float(vy), float(vz))
    if not (math.isfinite(eph_m) and math.isfinite(epv_m) and eph_m <= p.gnss_max_eph_m
            and all(map(math.isfinite, pos + vel))):
        return None
    return pos, vel


def white_var(p: EstimatorParams, prm: np.ndarray, eph_m: float,
              epv_m: float) -> tuple[float, float]:
    """The white part of a fix's position variance [m^2] (horizontal, vertical) from its
    claimed accuracies [m]; with the receiver's wander modelled, its share of the claim
    goes to the wander state (its stationary variance, set here in ``prm``)."""
    floor = p.gnss_pos_noise_min_m ** 2
    var_h, var_v = max(eph_m, p.gnss_pos_noise_min_m) ** 2, max(
        epv_m, p.gnss_pos_noise_min_m) ** 2
    if not p.gnss_pos_tau_s > 0.0:
        return var_h, var_v
    c = p.gnss_pos_correlated_fraction
    prm[PRM_BP_VAR_H] = c * var_h
    prm[PRM_BP_VAR_V] = c * var_v
    return max((1.0 - c) * var_h, floor), max((1.0 - c) * var_v, floor)


def position_prior(p: EstimatorParams, mem: FilterMemory, eph_m: float,
                   epv_m: float) -> None:
    """The position's covariance (and the receiver wander's) when the position is set
    from a fix with claimed accuracies [m]: the position's error is the fix's, minus the
    wander's where it is modelled (the wander estimate then 0)."""
    P = mem.P
    white = white_var(p, mem.prm, eph_m, epv_m)
    claim = (max(eph_m, p.gnss_pos_noise_min_m) ** 2,
             max(epv_m, p.gnss_pos_noise_min_m) ** 2)
    mem.x[X_BP:X_BP + 3] = 0.0
    P[IDX_BP:IDX_BP + 3, :] = 0.0
    P[:, IDX_BP:IDX_BP + 3] = 0.0
    for i in range(3):
        k = 0 if i < 2 else 1
        if p.gnss_pos_tau_s > 0.0:
            wander = claim[k] - white[k] if claim[k] > white[k] else 0.0
            P[IDX_P + i, IDX_P + i] = white[k] + wander
            P[IDX_BP + i, IDX_BP + i] = wander
            P[IDX_P + i, IDX_BP + i] = P[IDX_BP + i, IDX_P + i] = -wander
        else:
            P[IDX_P + i, IDX_P + i] = claim[k]


class GnssControl:
    """Fuses the fixes of an aligned filter; resets position and velocity to a fix after
    ``gnss_reset_s`` of rejected positions (its sources' policy)."""

    __slots__ = ("_p", "_mem", "_src", "_out", "_leave_const_pos", "_k", "_wander")

    def __init__(self, params: EstimatorParams, mem: FilterMemory, sources: AidSources,
                 output: OutputPredictor, leave_const_pos: Callable[[], None]) -> None:
        self._p = params
        self._mem = mem
        self._src = sources
        self._out = output
        #: called when a fix is fused or reset to (constant-position mode ends)
        self._leave_const_pos = leave_const_pos
        self._wander = params.gnss_pos_tau_s > 0.0
        prm = mem.prm
        prm[PRM_GNSS_GATE_POS] = sources.gnss_pos.policy.gate_sigma
        prm[PRM_GNSS_GATE_VEL] = sources.gnss_vel.policy.gate_sigma
        prm[PRM_GNSS_R_VEL] = params.gnss_vel_noise_m_s ** 2
        prm[PRM_GNSS_FUSE_HGT] = 1.0 if params.gnss_fuse_height else 0.0
        prm[PRM_WANDER] = 1.0 if self._wander else 0.0
        self._k = entry_point(fuse_gnss_kernel, mem.w, mem.P, mem.buf, mem.meta, 0.0, 0.0,
                              0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)

    def fuse(self, t_s: float, pos_enu_m: Sequence[float], vel_enu_m_s: Sequence[float],
             eph_m: float, epv_m: float) -> bool:
        """A fix arriving at ``t_s`` [s] (``NavFilter.fuse_gnss``). Returns whether its
        position was fused (or reset to)."""
        p = self._p
        fix = usable_fix(p, pos_enu_m, vel_enu_m_s, eph_m, epv_m)
        if fix is None:
            return False
        pos, vel = fix
        src = self._src
        src.gnss_pos.time_last_attempt = t_s
        # the fix's age is known only to within gnss_delay_uncertainty_s: at speed v that is
        # a position error of up to v u, added to the receiver's claimed accuracy
        vx, vy, vz = vel
        u = p.gnss_delay_uncertainty_s
        var_h, var_v = white_var(p, self._mem.prm, eph_m, epv_m)
        r_h = var_h + (vx * vx + vy * vy) * u * u
        r_v = var_v + vz * vz * u * u
        m = self._mem
        res = self._k(m.w, m.P, m.buf, m.meta, t_s - p.gnss_delay_s, *pos, *vel, r_h, r_v)
        src.gnss_vel.record(t_s, FUSED if res & ACC_VEL else REJECTED)
        if p.gnss_fuse_height:
            src.gnss_hgt.record(t_s, FUSED if res & ACC_POS_V else REJECTED)
        accepted = bool(res & ACC_POS_H)
        reset_due = src.gnss_pos.record(t_s, FUSED if accepted else REJECTED,
                                        bool(res & NUMERIC))
        if accepted:
            self._leave_const_pos()
            return True
        if reset_due:
            self._reset(pos, vel, r_h, r_v)
            src.gnss_pos.reset_done(t_s)
            src.gnss_vel.reset_done(t_s)
            self._leave_const_pos()
            return True
        return False

    def _reset(self, pos: Vec3, vel: Vec3, r_h: float, r_v: float) -> None:
        """Position and velocity set to the fix (brought forward by its age), their
        covariance to the fix's noise (``r_h``, ``r_v`` [m^2], the white part where the
        receiver's wander is modelled: that is reset too), uncorrelated with the rest."""
        m, p = self._mem, self._p
        age = p.gnss_delay_s
        new = np.array([pos[i] + vel[i] * age for i in range(3)] + list(vel))
        x = m.x
        delta = new - x[0:6]
        x[0:6] = new
        m.buffered()[:, BUF_P:BUF_P + 6] += delta
        P = m.P
        P[IDX_P:IDX_V + 3, :] = 0.0
        P[:, IDX_P:IDX_V + 3] = 0.0
        for i, v in enumerate((r_h, r_h, r_v)):
            P[IDX_P + i, IDX_P + i] = v
            P[IDX_V + i, IDX_V + i] = p.gnss_vel_noise_m_s ** 2
        if self._wander:
            h, v = m.prm[PRM_BP_VAR_H], m.prm[PRM_BP_VAR_V]
            x[X_BP:X_BP + 3] = 0.0
            P[IDX_BP:IDX_BP + 3, :] = 0.0
            P[:, IDX_BP:IDX_BP + 3] = 0.0
            for i, w in enumerate((h, h, v)):
                P[IDX_P + i, IDX_P + i] += w
                P[IDX_BP + i, IDX_BP + i] = w
                P[IDX_P + i, IDX_BP + i] = P[IDX_BP + i, IDX_P + i] = -w
        self._out.reset()
