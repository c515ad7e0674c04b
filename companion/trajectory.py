"""Reference trajectories for the backstepping position controller, and the waypoint logic.

Every trajectory gives, at any time ``t`` [s], the reference position, velocity,
acceleration and jerk (inertial frame: z up, x east, y north, origin at the winder) and a
reference yaw and yaw rate (yaw from +x toward +y). References are at least C2 in
position (continuous acceleration) and respect the speed and acceleration limits they are
built with, so that a far waypoint never becomes a step that saturates the rotors.

Profiles (``u = (t - t0) / T`` is normalised time):

- Minimum-jerk (quintic) smoothstep ``s(u) = 10u^3 - 15u^4 + 6u^5``: ``s(0) = 0``,
  ``s(1) = 1``, first and second derivatives zero at both ends. Peak of ``s'`` is 15/8 (at
  u = 1/2) and peak of ``|s''|`` is ``10/sqrt(3)`` (at ``u = 1/2 -+ sqrt(3)/6``).
- :class:`Transition` from rest: ``p(t) = p0 + (g - p0) s(u)`` along the straight line,
  ``T = max(15/8 D / v_max, sqrt(10/sqrt(3) D / a_max), T_min)`` with ``D = |g - p0|``
  (``T = 0`` when ``D = 0``; ``T_min`` defaults to 0.5 s and is at least 1 ms). Peak
  speed is ``15/8 D / T``, peak acceleration ``10/sqrt(3) D / T^2``, jerk at the ends
  ``60 D / T^3``.
- :class:`Transition` from a moving state (retargeting): per axis the quintic with
  ``p(0) = p0, p'(0) = v0, p''(0) = a0, p(T) = g, p'(T) = p''(T) = 0``, i.e. in local
  time ``tau`` the coefficients ``c0 = p0, c1 = v0, c2 = a0/2,
  c3 = (20D - 12 v0 T - 3 a0 T^2) / (2T^3), c4 = (-30D + 16 v0 T + 3 a0 T^2) / (2T^4),
  c5 = (12D - 6 v0 T - a0 T^2) / (2T^5)`` with ``D = g - p0``. ``T`` is the shortest
  duration found (geometric scan, then a bracketed regula falsi) whose exact peak speed
  and acceleration (maxima of the squared-norm polynomials over the segment, from the
  roots of their derivatives) are within the limits. A single quintic cannot always do that when
  ``a0 != 0`` (its velocity picks up ``a0 T h'(u)``, up to ``~ a0 T / 15``), so a two-phase
  plan is also tried: first the acceleration is brought to zero over ``tau1`` (0.5 s,
  halved as needed) as ``a = (1 - x)(a0 + x d)``, ``x = tau / tau1``, where
  ``d = -beta v0/|v0|`` (``beta`` in {0, 1/4, 1/2, 1} ``a_max``) brakes just enough to keep
  the speed within the limit (needed when starting at the speed limit with a sideways
  acceleration, as on a circle); ``|a| <= a_max`` holds for ``beta <= a_max``. Then a
  quintic from that zero-acceleration state, for which a long enough T always works. The
  shorter feasible plan wins. If the start state itself violates the limits, the
  least-violating single quintic is used and ``within_limits`` is False.
- Yaw: the same planner in one dimension on the unwrapped angle, going the shortest way
  round (``wrap_pi(yaw_goal - yaw_start)``), limited by the yaw rate and yaw acceleration.
- :class:`Line`: speed ``V s(tau / Ta)`` up, cruise at ``V``, ``V (1 - s(tau / Ta))``
  down, with ``Ta = max(15/8 V / a_max, min_ramp_s)`` (peak acceleration
  ``15/8 V / Ta``); each ramp covers ``V Ta / 2``, so the duration is ``D / V + Ta``. When
  ``V Ta > D`` the cruise speed drops to ``V = sqrt(8 a_max D / 15)`` (or ``D / min_ramp_s``
  if that ramp would be shorter than ``min_ramp_s``) and there is no cruise. The position
  is C3 (jerk continuous).
- :class:`Circle`: arc length ``sigma(t)`` with the same ramps over ``lead_in_s``;
  ``theta = theta0 +- sigma / r``; with ``w = theta'``, ``al = theta''``,
  ``ze = theta'''``: ``p = c + r e_r``, ``v = r w e_t``, ``a = r al e_t - r w^2 e_r``,
  ``j = r (ze - w^3) e_t - 3 r w al e_r`` (``e_r = (cos, sin)``, ``e_t = (-sin, cos)``).
  Acceleration norm in the ramp is ``sqrt((V s'(x) / Tl)^2 + (V^2 s(x)^2 / r)^2)``,
  ``V^2 / r`` at cruise.
"""

from __future__ import annotations

import bisect
import functools
import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.polynomial import polynomial as npoly
from scipy.linalg.lapack import dgeev as _dgeev
from scipy.optimize import minimize_scalar

from tuavdefs.frames import wrap_pi

Vec3 = tuple[float, float, float]

QUINTIC_PEAK_SPEED = 15.0 / 8.0
"""Peak of ds/du for the quintic smoothstep s(u) = 10u^3 - 15u^4 + 6u^5."""
QUINTIC_PEAK_ACC = 10.0 / math.sqrt(3.0)
"""Peak of |d2s/du2| for the quintic smoothstep."""

DEFAULT_MAX_YAW_RATE_RAD_S = math.radians(45.0)
DEFAULT_MAX_YAW_ACC_RAD_S2 = math.radians(90.0)
DEFAULT_MIN_DURATION_S = 0.5
"""Shortest transition [s]; bounds the jerk of tiny moves (jerk <= 10.4 a_max / T)."""
DEFAULT_CIRCLE_MAX_ACC_M_S2 = 3.0

_ZERO3: Vec3 = (0.0, 0.0, 0.0)
_LIMIT_RTOL = 1e-12  # float slack on the limit checks
_T_FLOOR = 1e-3  # shortest planned duration [s]; keeps 1/T^5 coefficients finite
_ACC_RAMP_S = 0.5  # nominal duration of the acceleration ramp-down of a two-phase retarget
_SCAN_RATIO = 1.25
_SCAN_STEPS = 42  # 1.25**42 ~ 1.2e4: the scan covers four decades above the lower bound
_BISECT_RTOL = 1e-7
_PEAK_GRID = np.linspace(0.0, 1.0, 33)
# The quintic to rest with D = 0 and unit v0 (g) or unit a0 (h), and the smoothstep s, have
# velocities g'(u) = 1 - 18u^2 + 32u^3 - 15u^4, T h'(u) with h'(u) = u (1-u)^2 (2 - 5u) / 2,
# and D s'(u) / T with s'(u) = 30 u^2 (1-u)^2; their values at u* = 0.155, where h' peaks
# (~1/15), bound the quintic's speed from below (see _search_quintic).
_U_STAR = 0.155
_H1 = _U_STAR * (1.0 - _U_STAR) ** 2 * (2.0 - 5.0 * _U_STAR) / 2.0
_G1 = abs(1.0 - 18.0 * _U_STAR**2 + 32.0 * _U_STAR**3 - 15.0 * _U_STAR**4)
_S1 = 30.0 * _U_STAR**2 * (1.0 - _U_STAR) ** 2


class RefSample(NamedTuple):
    """One reference sample; inertial frame, SI units."""

    pos_m: Vec3
    vel_m_s: Vec3
    acc_m_s2: Vec3
    jerk_m_s3: Vec3
    yaw_rad: float
    """Reference yaw in [-pi, pi), from +x toward +y."""
    yaw_rate_rad_s: float


# --- polynomial machinery -----------------------------------------------------------------

def _vec(v: Iterable[float], name: str, n: int = 3) -> tuple[float, ...]:
    out = tuple(float(x) for x in v)
    if len(out) != n or not all(math.isfinite(x) for x in out):
        raise ValueError(f"{name} must be {n} finite numbers, got {v!r}")
    return out


def _vec3(v: Iterable[float], name: str) -> Vec3:
    x, y, z = _vec(v, name, 3)
    return (x, y, z)


def _positive(x: float, name: str) -> float:
    x = float(x)
    if not (x > 0.0 and math.isfinite(x)):
        raise ValueError(f"{name} must be positive and finite, got {x!r}")
    return x


def _horner(rev_coefs: list[float], x: float) -> float:
    acc = 0.0
    for c in rev_coefs:
        acc = acc * x + c
    return acc


def _horner3(cols: list[tuple[float, float, float]], x: float) -> tuple[float, float, float]:
    """Three polynomials at ``x`` by :func:`_horner`'s steps (so to the bit), at once:
    ``cols[k]`` holds their k-th coefficients, highest power first."""
    a = b = c = 0.0
    for p, q, r in cols:
        a = a * x + p
        b = b * x + q
        c = c * x + r
    return (a, b, c)


def _smoothstep5(x: float) -> float:
    return x * x * x * (10.0 + x * (-15.0 + 6.0 * x))


_Piece = tuple[float, np.ndarray]  # (duration [s], coefficients (ndim, degree + 1) in local time)


class _Piecewise:
    """A piecewise polynomial in absolute time, any dimension; clamped before its start and
    held (at rest) after its end."""

    __slots__ = ("t0", "end", "ndim", "_starts", "_durs", "_p", "_v", "_a", "_j", "_cols3",
                 "_first", "_final")

    def __init__(self, t0: float, pieces: list[_Piece], final_pos: tuple[float, ...] | None,
                 ndim: int) -> None:
        self.t0 = t0
        self.ndim = ndim
        self._starts: list[float] = []
        self._durs: list[float] = []
        self._p: list[list[list[float]]] = []
        self._v: list[list[list[float]]] = []
        self._a: list[list[list[float]]] = []
        self._j: list[list[list[float]]] = []
        t = t0
        for dur, c in pieces:
            self._starts.append(t)
            self._durs.append(dur)
            t += dur
            derivs = [c]
            for _ in range(3):
                prev = derivs[-1]
                derivs.append(npoly.polyder(prev, axis=1) if prev.shape[1] > 1
                              else np.zeros((ndim, 1)))
            for store, d in zip((self._p, self._v, self._a, self._j), derivs, strict=True):
                store.append([[float(x) for x in row[::-1]] for row in d])
        # in three dimensions, the same coefficients by power for _horner3
        self._cols3 = [tuple([list(zip(*store[i], strict=True)) for store in
                              (self._p, self._v, self._a, self._j)])
                       for i in range(len(self._starts))] if ndim == 3 else []
        self.end = t
        zeros = (0.0,) * ndim
        if final_pos is None:
            final_pos = self._eval_piece(len(pieces) - 1, self._durs[-1])[0] if pieces else zeros
        self._final = (tuple(final_pos), zeros, zeros, zeros)
        self._first = self._eval_piece(0, 0.0) if pieces else self._final

    def _eval_piece(self, i: int, tau: float) -> tuple[tuple[float, ...], ...]:
        if self.ndim == 1:  # the common scalar case (arc length), without the loops
            return ((_horner(self._p[i][0], tau),), (_horner(self._v[i][0], tau),),
                    (_horner(self._a[i][0], tau),), (_horner(self._j[i][0], tau),))
        if self.ndim == 3:  # positions: the three axes together
            p, v, a, j = self._cols3[i]
            return (_horner3(p, tau), _horner3(v, tau), _horner3(a, tau), _horner3(j, tau))
        return (tuple([_horner(r, tau) for r in self._p[i]]),
                tuple([_horner(r, tau) for r in self._v[i]]),
                tuple([_horner(r, tau) for r in self._a[i]]),
                tuple([_horner(r, tau) for r in self._j[i]]))

    def eval(self, t: float) -> tuple[tuple[float, ...], ...]:
        """(position, velocity, acceleration, jerk) at absolute time t."""
        if t >= self.end:
            return self._final
        if t <= self.t0:
            return self._first
        i = bisect.bisect_right(self._starts, t) - 1
        return self._eval_piece(i, t - self._starts[i])

    def knots(self) -> list[float]:
        return [*self._starts, self.end] if self._starts else [self.t0]


def _peak_norm(c: np.ndarray) -> float:
    """Max over u in [0, 1] of the norm of the vector polynomial with ascending coefficient
    rows ``c`` (ndim, m): candidates are the ends, a grid and the real parts of the roots of
    the derivative of the squared norm (extra candidates can never over-estimate)."""
    scale = float(np.abs(c).max())
    if scale == 0.0 or not math.isfinite(scale):
        return scale
    c = c / scale  # so that squaring neither underflows nor overflows
    n = 2 * c.shape[1] - 1
    # The squared norm's coefficients: the anti-diagonal sums of the Gram matrix of c's
    # columns (np.polyval's Python loop would cost more than the whole rest).
    sq = np.bincount(_antidiagonals(c.shape[1]), weights=(c.T @ c).ravel(), minlength=n)
    best = float((_grid_powers(n) @ sq).max())
    d = sq[1:] * np.arange(1, n)  # ascending derivative
    m = len(d)
    while m > 1 and abs(d[m - 1]) < 1e-300:
        m -= 1
    if m > 1:
        comp = np.eye(m - 1, k=-1)  # companion matrix of the monic derivative
        comp[0, :] = -d[m - 2::-1] / d[m - 1]
        roots = None
        if np.isfinite(comp).all():
            # LAPACK's geev without numpy.linalg's wrapper, which costs twice the solve
            wr, _, _, _, info = _dgeev(comp, compute_vl=0, compute_vr=0)
            if info == 0:
                roots = wr
        if roots is None:  # pathological leading coefficient: fall back to a dense grid
            roots = np.linspace(0.0, 1.0, 4097)
        roots = roots[(roots >= 0.0) & (roots <= 1.0)]
        if roots.size:
            best = max(best, float((roots[:, None] ** np.arange(n) @ sq).max()))
    return scale * math.sqrt(max(best, 0.0))


@functools.cache
def _antidiagonals(m: int) -> np.ndarray:
    """Flat index i + j of each element (i, j) of an m x m matrix."""
    k = np.arange(m)
    return (k[:, None] + k[None, :]).ravel()


@functools.cache
def _grid_powers(n: int) -> np.ndarray:
    """The peak grid's powers 0 .. n-1, (grid, n): times ascending coefficients, values."""
    return _PEAK_GRID[:, None] ** np.arange(n)


def _piece_peaks(dur: float, c: np.ndarray) -> tuple[float, float]:
    """(peak speed, peak acceleration norm) of one piece over its duration."""
    if dur <= 0.0:
        return 0.0, 0.0
    m = c.shape[1]
    if m < 2:
        return 0.0, 0.0
    k = np.arange(m)
    b = c * dur**k  # coefficients in normalised time u = tau / dur
    vb = b[:, 1:] * (k[1:] / dur)
    if m < 3:
        return _peak_norm(vb), 0.0
    return _peak_norm(vb), _peak_norm(vb[:, 1:] * (k[1:-1] / dur))


def _pieces_peaks(pieces: list[_Piece]) -> tuple[float, float]:
    peaks = [_piece_peaks(d, c) for d, c in pieces]
    return (max((p[0] for p in peaks), default=0.0), max((p[1] for p in peaks), default=0.0))


def _quintic_to_rest(p0: np.ndarray, v0: np.ndarray, a0: np.ndarray, goal: np.ndarray,
                     T: float) -> np.ndarray:
    """Local-time coefficients (ndim, 6) of the quintic from (p0, v0, a0) to rest at goal."""
    D = goal - p0
    c = np.empty((p0.size, 6))
    c[:, 0] = p0
    c[:, 1] = v0
    c[:, 2] = 0.5 * a0
    c[:, 3] = (20.0 * D - 12.0 * v0 * T - 3.0 * a0 * T * T) / (2.0 * T**3)
    c[:, 4] = (-30.0 * D + 16.0 * v0 * T + 3.0 * a0 * T * T) / (2.0 * T**4)
    c[:, 5] = (12.0 * D - 6.0 * v0 * T - a0 * T * T) / (2.0 * T**5)
    return c


def _limit_ratio(pieces: list[_Piece], v_max: float, a_max: float) -> float:
    ps, pa = _pieces_peaks(pieces)
    return max(ps / v_max, pa / a_max)


def _search_quintic(p0: np.ndarray, v0: np.ndarray, a0: np.ndarray, goal: np.ndarray,
                    v_max: float, a_max: float, t_min: float) -> tuple[float | None, float]:
    """(shortest feasible duration or None, least-violating duration seen)."""

    limit = 1.0 + _LIMIT_RTOL

    def excess(T: float) -> float:
        """Largest of peak speed / v_max and peak acceleration / a_max, less the limit."""
        return _limit_ratio([(T, _quintic_to_rest(p0, v0, a0, goal, T))], v_max,
                            a_max) - limit

    dist = math.hypot(*(goal - p0))  # hypot, not np.linalg.norm: no underflow of tiny moves
    vn, an = math.hypot(*v0), math.hypot(*a0)
    # Necessary conditions: cover the distance at v_max; stop from v0 at a_max.
    T = max(t_min, dist / v_max, vn / a_max, 1e-3)
    prev, f_prev = None, math.inf
    best_f, best_T = math.inf, T
    for _ in range(_SCAN_STEPS):
        # At u*, |v| >= |a0| T h'(u*) - |v0| |g'(u*)| - D s'(u*) / T, which only grows with T:
        # once it exceeds v_max, no longer duration can work either.
        if an * T * _H1 - vn * _G1 - dist * _S1 / T > v_max * limit:
            break
        f = excess(T)
        if f <= 0.0:
            if prev is None:
                return T, T
            hi = _bracket_boundary(excess, prev, f_prev, T, f)
            return hi, hi
        if f < best_f:
            best_f, best_T = f, T
        prev, f_prev = T, f
        T *= _SCAN_RATIO
    return None, best_T


def _bracket_boundary(excess: Callable[[float], float], lo: float, f_lo: float, hi: float,
                      f_hi: float) -> float:
    """A duration ``hi`` [s] with ``excess(hi) <= 0`` and, within ``_BISECT_RTOL`` below
    it, a duration ``lo`` with ``excess(lo) > 0``; from such a bracket (lo, hi) with
    ``f_lo = excess(lo) > 0 >= f_hi = excess(hi)``.

    Feasibility need not be monotone in T, so the bracket keeps lo infeasible and hi
    feasible rather than assume it. Steps are regula falsi in log T with the
    Anderson-Bjoerck weighting, aimed a third of the tolerance past the root estimate
    toward the end that did not move last, so that once the estimate is that good the
    other end closes in too (about six evaluations where bisection takes twenty). A
    bisection follows whenever the bracket has not halved in the last four steps, so that
    the worst case stays within a few times bisection's.
    """
    bias = math.log1p(_BISECT_RTOL / 3.0)
    widths = [math.inf] * 4
    side = 0  # which end the last step moved: -1 lo, +1 hi
    while hi / lo - 1.0 > _BISECT_RTOL:
        a, b = math.log(lo), math.log(hi)
        if b - a > 0.5 * widths[-4] or f_lo == f_hi:
            x = 0.5 * (a + b)
        else:
            x = b - f_hi * (b - a) / (f_hi - f_lo) - side * bias
        T = math.exp(x)
        if not lo < T < hi:  # rounding, or the aim left the bracket: bisect
            T = math.sqrt(lo * hi)
            if not lo < T < hi:
                break
        widths.append(b - a)
        f = excess(T)
        if f <= 0.0:
            if side == 1:  # hi moved twice: weigh lo down (Anderson-Bjoerck)
                m = 1.0 - f / f_hi if f_hi < 0.0 else 0.0
                f_lo *= m if m > 0.0 else 0.5
            hi, f_hi, side = T, f, 1
        else:
            if side == -1:
                m = 1.0 - f / f_lo
                f_hi *= m if m > 0.0 else 0.5
            lo, f_lo, side = T, f, -1
    return hi


def _acc_ramp_down(p0: np.ndarray, v0: np.ndarray, a0: np.ndarray, v_max: float,
                   a_max: float) -> _Piece | None:
    """First phase of a two-phase plan: acceleration a0 (1 - x) + d x (1 - x), x = tau/tau1,
    brought to zero within the limits, with d = -beta v0/|v0| a braking term that keeps the
    speed down when the start is at the speed limit with a sideways acceleration (a
    circle). |a| <= (1 - x)|a0| + x (1 - x) beta <= a_max for beta <= a_max. The longest
    ramp (smallest jerk), then the least braking, that keeps both limits wins."""
    vn = math.hypot(*v0)
    brake = -v0 / vn if vn > 0.0 else np.zeros_like(v0)
    betas = (0.0, 0.25, 0.5, 1.0) if vn > 0.0 else (0.0,)
    for halvings in range(10):
        tau1 = _ACC_RAMP_S * 0.5**halvings
        for beta in betas:
            d = brake * (beta * a_max)
            c = np.zeros((p0.size, 5))
            c[:, 0] = p0
            c[:, 1] = v0
            c[:, 2] = 0.5 * a0
            c[:, 3] = (d - a0) / (6.0 * tau1)
            c[:, 4] = -d / (12.0 * tau1 * tau1)
            if _limit_ratio([(tau1, c)], v_max, a_max) <= 1.0 + _LIMIT_RTOL:
                return tau1, c
    return None


def _plan_to_rest(p0: tuple[float, ...], v0: tuple[float, ...], a0: tuple[float, ...],
                  goal: tuple[float, ...], v_max: float, a_max: float,
                  t_min: float) -> tuple[list[_Piece], bool]:
    """Pieces taking the state (p0, v0, a0) to rest at goal within the limits, and whether
    the limits hold (False only when no plan could keep them)."""
    P0, V0, A0, G = (np.array(x, dtype=float) for x in (p0, v0, a0, goal))
    t_min = max(t_min, _T_FLOOR)
    if not V0.any() and not A0.any():
        dist = math.hypot(*(G - P0))
        if dist == 0.0:
            return [], True
        T = max(QUINTIC_PEAK_SPEED * dist / v_max, math.sqrt(QUINTIC_PEAK_ACC * dist / a_max),
                t_min)
        return [(T, _quintic_to_rest(P0, V0, A0, G, T))], True

    plans: list[tuple[float, list[_Piece]]] = []
    T_direct, T_best = _search_quintic(P0, V0, A0, G, v_max, a_max, t_min)
    if T_direct is not None:
        plans.append((T_direct, [(T_direct, _quintic_to_rest(P0, V0, A0, G, T_direct))]))
    if A0.any():
        ramp = _acc_ramp_down(P0, V0, A0, v_max, a_max)
        if ramp is not None:
            tau1, c1 = ramp
            k = np.arange(c1.shape[1])
            P1 = c1 @ tau1**k
            V1 = c1[:, 1:] @ (k[1:] * tau1 ** (k[1:] - 1))
            zero = np.zeros_like(A0)
            T2, _ = _search_quintic(P1, V1, zero, G, v_max, a_max, t_min)
            if T2 is not None:
                plans.append((tau1 + T2, [ramp, (T2, _quintic_to_rest(P1, V1, zero, G, T2))]))
    if plans:
        return min(plans, key=lambda p: p[0])[1], True
    return [(T_best, _quintic_to_rest(P0, V0, A0, G, T_best))], False


# --- trajectories ---------------------------------------------------------------------------

class Trajectory(ABC):
    """A reference trajectory: ``sample(t)`` for any t; before ``start_s`` the start state
    is returned, after ``end_s`` the final state (at rest) is held."""

    start_s: float
    """Start time [s]."""
    end_s: float
    """Time [s] at which the trajectory comes to rest for good; ``math.inf`` if never."""
    final_pos_m: Vec3 | None
    """Where it ends at rest [m]; None for an endless motion (endless circle)."""
    final_yaw_rad: float
    """Yaw at the end [rad] (the constant yaw for an endless one with constant yaw)."""
    knots_s: tuple[float, ...]
    """Times [s] at which polynomial pieces join (start and end included); the jerk may jump
    there, position, velocity and acceleration do not."""

    @abstractmethod
    def sample(self, t_s: float) -> RefSample:
        """The reference at time ``t_s`` [s]."""

    def yaw_acc_rad_s2(self, t_s: float) -> float:
        """Reference yaw acceleration [rad/s^2] at ``t_s``; used to chain yaw profiles C2."""
        return 0.0

    @property
    def duration_s(self) -> float:
        """end_s - start_s [s]."""
        return self.end_s - self.start_s


class Hold(Trajectory):
    """Stay at ``position`` [m] with ``yaw`` [rad] from ``t0`` [s], for ``duration_s`` [s]
    (endless by default)."""

    def __init__(self, position: Iterable[float], yaw: float = 0.0, t0: float = 0.0, *,
                 duration_s: float = math.inf) -> None:
        pos = _vec3(position, "position")
        if not duration_s >= 0.0:
            raise ValueError(f"duration_s must be >= 0, got {duration_s!r}")
        self.start_s = float(t0)
        self.end_s = self.start_s + duration_s
        self.final_pos_m = pos
        self.final_yaw_rad = wrap_pi(yaw)
        self.knots_s = (self.start_s,) if math.isinf(self.end_s) else (self.start_s, self.end_s)
        self._sample = RefSample(pos, _ZERO3, _ZERO3, _ZERO3, self.final_yaw_rad, 0.0)

    def sample(self, t_s: float) -> RefSample:
        return self._sample


class Transition(Trajectory):
    """Smooth point-to-point move to rest at ``goal_pos`` [m] within the speed
    ``max_speed_m_s`` [m/s] and acceleration ``max_acc_m_s2`` [m/s^2] limits.

    From rest (``start_vel`` and ``start_acc`` zero) it is the straight-line minimum-jerk
    quintic of duration ``max(15/8 D / v_max, sqrt(10/sqrt(3) D / a_max), min_duration_s)``
    (0 if D = 0). From a moving state (retargeting) it matches ``start_pos``, ``start_vel``
    [m/s] and ``start_acc`` [m/s^2] and stops at the goal (see the module docstring).

    Yaw goes from ``yaw_start`` to ``yaw_goal`` (default: ``yaw_start``) [rad] the shortest
    way round on its own quintic profile within ``max_yaw_rate`` [rad/s] and
    ``max_yaw_acc_rad_s2``, starting from ``start_yaw_rate_rad_s`` and
    ``start_yaw_acc_rad_s2``. Position and yaw finish independently; ``end_s`` is the
    later. ``within_limits`` is False only when the start state itself made the limits
    impossible to keep.
    """

    def __init__(self, start_pos: Iterable[float], goal_pos: Iterable[float], t0: float,
                 max_speed_m_s: float, max_acc_m_s2: float,
                 start_vel: Iterable[float] = _ZERO3, start_acc: Iterable[float] = _ZERO3,
                 yaw_start: float = 0.0, yaw_goal: float | None = None,
                 max_yaw_rate: float = DEFAULT_MAX_YAW_RATE_RAD_S, *,
                 start_yaw_rate_rad_s: float = 0.0, start_yaw_acc_rad_s2: float = 0.0,
                 max_yaw_acc_rad_s2: float = DEFAULT_MAX_YAW_ACC_RAD_S2,
                 min_duration_s: float = DEFAULT_MIN_DURATION_S) -> None:
        p0 = _vec(start_pos, "start_pos")
        goal = _vec3(goal_pos, "goal_pos")
        v0 = _vec(start_vel, "start_vel")
        a0 = _vec(start_acc, "start_acc")
        self.max_speed_m_s = _positive(max_speed_m_s, "max_speed_m_s")
        self.max_acc_m_s2 = _positive(max_acc_m_s2, "max_acc_m_s2")
        self.max_yaw_rate = _positive(max_yaw_rate, "max_yaw_rate")
        self.max_yaw_acc_rad_s2 = _positive(max_yaw_acc_rad_s2, "max_yaw_acc_rad_s2")
        if not min_duration_s >= 0.0:
            raise ValueError(f"min_duration_s must be >= 0, got {min_duration_s!r}")
        yaw0 = float(yaw_start)
        yaw_goal = yaw0 if yaw_goal is None else float(yaw_goal)
        for name, x in (("yaw_start", yaw0), ("yaw_goal", yaw_goal),
                        ("start_yaw_rate_rad_s", start_yaw_rate_rad_s),
                        ("start_yaw_acc_rad_s2", start_yaw_acc_rad_s2)):
            if not math.isfinite(x):
                raise ValueError(f"{name} must be finite, got {x!r}")
        t0 = float(t0)

        pos_pieces, pos_ok = _plan_to_rest(p0, v0, a0, goal, self.max_speed_m_s,
                                           self.max_acc_m_s2, min_duration_s)
        yaw_end = yaw0 + wrap_pi(yaw_goal - yaw0)  # unwrapped, shortest way round
        yaw_pieces, yaw_ok = _plan_to_rest((yaw0,), (float(start_yaw_rate_rad_s),),
                                           (float(start_yaw_acc_rad_s2),), (yaw_end,),
                                           self.max_yaw_rate, self.max_yaw_acc_rad_s2,
                                           min_duration_s)
        self._pos = _Piecewise(t0, pos_pieces, goal, 3)
        self._yaw = _Piecewise(t0, yaw_pieces, (yaw_end,), 1)
        self.start_s = t0
        self.end_s = max(self._pos.end, self._yaw.end)
        self.final_pos_m = goal
        self.final_yaw_rad = wrap_pi(yaw_end)
        self.pos_duration_s = self._pos.end - t0
        """Duration [s] of the position profile."""
        self.yaw_duration_s = self._yaw.end - t0
        """Duration [s] of the yaw profile."""
        self.peak_speed_m_s, self.peak_acc_m_s2 = _pieces_peaks(pos_pieces)
        self.peak_yaw_rate_rad_s = _pieces_peaks(yaw_pieces)[0]
        self.within_limits = pos_ok and yaw_ok
        self.knots_s = tuple(sorted(set(self._pos.knots()) | set(self._yaw.knots())))
        self._rest = self._sample(self.end_s)   # from the end on: at rest, the same sample

    def sample(self, t_s: float) -> RefSample:
        if t_s >= self.end_s:
            return self._rest
        return self._sample(t_s)

    def _sample(self, t_s: float) -> RefSample:
        p, v, a, j = self._pos.eval(t_s)
        y, yr, _, _ = self._yaw.eval(t_s)
        return RefSample(p, v, a, j, wrap_pi(y[0]), yr[0])  # type: ignore[arg-type]

    def yaw_acc_rad_s2(self, t_s: float) -> float:
        return self._yaw.eval(t_s)[2][0]


def _ramp_pieces(V: float, Tr: float, sigma0: float, up: bool) -> _Piece:
    """Arc-length piece whose rate goes 0 -> V (``up``) or V -> 0 along the quintic
    smoothstep over Tr: sigma = sigma0 + V Tr (2.5 x^4 - 3 x^5 + x^6), x = tau / Tr, or
    sigma0 + V tau minus that."""
    c = np.zeros((1, 7))
    sgn = 1.0 if up else -1.0
    c[0, 0] = sigma0
    c[0, 1] = 0.0 if up else V
    c[0, 4] = sgn * 2.5 * V / Tr**3
    c[0, 5] = -sgn * 3.0 * V / Tr**4
    c[0, 6] = sgn * V / Tr**5
    return Tr, c


class Line(Trajectory):
    """The "linear trajectory": a straight segment from ``start`` to ``end`` [m] flown at
    the cruise speed ``speed_m_s`` [m/s], with quintic-smoothstep speed ramps up and down of
    duration ``ramp_s = max(15/8 V / a_max, min_ramp_s)`` (peak acceleration
    ``15/8 V / ramp_s <= max_acc_m_s2`` [m/s^2]), ending at rest at ``end``. Segments
    shorter than ``V ramp_s`` get a lower cruise speed ``cruise_speed_m_s``:
    ``sqrt(8 a_max D / 15)``, or ``D / min_ramp_s`` if that ramp would be shorter than
    ``min_ramp_s`` [s]. Constant ``yaw`` [rad]."""

    def __init__(self, start: Iterable[float], end: Iterable[float], t0: float,
                 speed_m_s: float, max_acc_m_s2: float, *, yaw: float = 0.0,
                 min_ramp_s: float = 0.5 * DEFAULT_MIN_DURATION_S) -> None:
        p0 = np.array(_vec(start, "start"))
        p1 = np.array(_vec(end, "end"))
        V = _positive(speed_m_s, "speed_m_s")
        a_max = _positive(max_acc_m_s2, "max_acc_m_s2")
        min_ramp_s = max(float(min_ramp_s), _T_FLOOR)
        D = math.hypot(*(p1 - p0))
        t0 = float(t0)
        pieces: list[_Piece] = []
        Ta = 0.0
        if D > 0.0:
            Ta = max(QUINTIC_PEAK_SPEED * V / a_max, min_ramp_s)
            if V * Ta > D:
                V = math.sqrt(8.0 * a_max * D / 15.0)
                Ta = QUINTIC_PEAK_SPEED * V / a_max
                if Ta < min_ramp_s:
                    Ta = min_ramp_s
                    V = D / Ta
            cruise_s = (D - V * Ta) / V
            arc = [_ramp_pieces(V, Ta, 0.0, up=True)]
            if cruise_s > 0.0:
                arc.append((cruise_s, np.array([[0.5 * V * Ta, V]])))
            arc.append(_ramp_pieces(V, Ta, D - 0.5 * V * Ta, up=False))
            unit = (p1 - p0) / D
            for dur, c in arc:
                c3 = np.outer(unit, c[0])
                c3[:, 0] += p0
                pieces.append((dur, c3))
        else:
            V = 0.0
        self.cruise_speed_m_s = V
        """Speed [m/s] of the constant-speed part (lower than asked on short segments)."""
        self.ramp_s = Ta
        """Duration [s] of each speed ramp."""
        self._pos = _Piecewise(t0, pieces, tuple(p1), 3)
        self.start_s = t0
        self.end_s = self._pos.end
        self.final_pos_m = _vec3(p1, "end")
        self.final_yaw_rad = wrap_pi(yaw)
        self.knots_s = tuple(self._pos.knots())

    def sample(self, t_s: float) -> RefSample:
        p, v, a, j = self._pos.eval(t_s)
        return RefSample(p, v, a, j, self.final_yaw_rad, 0.0)  # type: ignore[arg-type]


class Circle(Trajectory):
    """The circular trajectory: radius ``radius_m`` [m] about ``centre_xy`` [m] at
    ``altitude_m`` [m], starting at rest at ``start_angle_rad`` (from +x toward +y) at
    ``t0`` [s], counter-clockwise seen from above unless ``clockwise``.

    The tangential speed ramps from 0 to ``speed_m_s`` [m/s] over ``lead_in_s`` [s] along
    the quintic smoothstep (continuous acceleration and jerk), then stays constant. With
    finite ``turns`` it ramps down over ``lead_in_s`` and stops after ``turns`` full turns
    of arc counting both ramps (short circles get a lower top speed ``turns 2 pi r /
    lead_in_s``). Yaw is the constant ``yaw`` [rad], or faces the direction of travel when
    ``face_travel``.

    Raises ValueError if the acceleration (centripetal + tangential) would exceed
    ``max_acc_m_s2`` [m/s^2]: either ``speed^2 / radius`` itself, or its sum with the
    lead-in's tangential acceleration (the message gives the shortest lead-in that works).
    """

    def __init__(self, centre_xy: Iterable[float], radius_m: float, altitude_m: float,
                 speed_m_s: float, t0: float, lead_in_s: float = 5.0,
                 turns: float = math.inf, start_angle_rad: float = 0.0,
                 clockwise: bool = False, max_acc_m_s2: float = DEFAULT_CIRCLE_MAX_ACC_M_S2,
                 *, yaw: float = 0.0, face_travel: bool = False) -> None:
        self.centre_xy_m = _vec(centre_xy, "centre_xy", 2)
        self.radius_m = r = _positive(radius_m, "radius_m")
        self.altitude_m = float(_vec((altitude_m,), "altitude_m", 1)[0])
        V = _positive(speed_m_s, "speed_m_s")
        Tr = self.lead_in_s = _positive(lead_in_s, "lead_in_s")
        if not turns > 0.0:
            raise ValueError(f"turns must be > 0, got {turns!r}")
        self.turns = float(turns)
        self.max_acc_m_s2 = a_max = _positive(max_acc_m_s2, "max_acc_m_s2")
        self.clockwise = bool(clockwise)
        self.face_travel = bool(face_travel)
        self._theta0 = float(start_angle_rad)
        self._sgn = -1.0 if clockwise else 1.0
        self._yaw = wrap_pi(yaw)

        arc_len = self.turns * 2.0 * math.pi * r
        if arc_len < V * Tr:  # finite and too short to reach the speed: ramp up then down
            V = arc_len / Tr
        self.cruise_speed_m_s = V
        """Top tangential speed [m/s] actually flown."""
        centripetal = V * V / r
        if centripetal > a_max * (1.0 + _LIMIT_RTOL):
            raise ValueError(
                f"centripetal acceleration speed^2/radius = {centripetal:.4g} m/s^2 exceeds "
                f"max_acc_m_s2 = {a_max:.4g} m/s^2 (speed must be <= "
                f"{math.sqrt(a_max * r):.4g} m/s on radius {r:.4g} m)")
        peak = self.peak_acc_m_s2(r, V, Tr)
        if peak > a_max * (1.0 + _LIMIT_RTOL):
            raise ValueError(
                f"lead_in_s = {Tr:.4g} s is too short: centripetal + tangential acceleration "
                f"peaks at {peak:.4g} m/s^2 > max_acc_m_s2 = {a_max:.4g} m/s^2 (needs "
                f"lead_in_s >= {self.min_lead_in_s(r, V, a_max):.4g} s)")
        self.peak_total_acc_m_s2 = peak

        t0 = float(t0)
        pieces = [_ramp_pieces(V, Tr, 0.0, up=True)]
        if math.isinf(arc_len):
            pieces.append((math.inf, np.array([[0.5 * V * Tr, V]])))
            final: tuple[float, ...] | None = (0.0,)  # never reached
        else:
            cruise_s = (arc_len - V * Tr) / V
            if cruise_s > 0.0:
                pieces.append((cruise_s, np.array([[0.5 * V * Tr, V]])))
            pieces.append(_ramp_pieces(V, Tr, arc_len - 0.5 * V * Tr, up=False))
            final = (arc_len,)
        self._arc = _Piecewise(t0, pieces, final, 1)
        self.start_s = t0
        self.end_s = self._arc.end
        self.knots_s = tuple(k for k in self._arc.knots() if math.isfinite(k))
        if math.isinf(arc_len):
            self.final_pos_m = None
            self.final_yaw_rad = self._yaw
        else:
            last = self.sample(self.end_s)
            self.final_pos_m = last.pos_m
            self.final_yaw_rad = last.yaw_rad

    @property
    def start_pos_m(self) -> Vec3:
        """The point [m] on the circle where it starts at rest."""
        return self.point_at(self._theta0)

    def point_at(self, angle_rad: float) -> Vec3:
        """The point [m] of the circle at ``angle_rad`` from +x toward +y."""
        cx, cy = self.centre_xy_m
        return (cx + self.radius_m * math.cos(angle_rad),
                cy + self.radius_m * math.sin(angle_rad), self.altitude_m)

    @staticmethod
    def peak_acc_m_s2(radius_m: float, speed_m_s: float, lead_in_s: float) -> float:
        """Peak total acceleration [m/s^2] over the lead-in ramp (and cruise):
        max over x of sqrt((V s'(x) / T)^2 + (V^2 s(x)^2 / r)^2)."""
        V, r, T = speed_m_s, radius_m, lead_in_s

        def f(x: float) -> float:
            s = _smoothstep5(x)
            ds = 30.0 * x * x * (1.0 - x) ** 2
            return math.hypot(V * ds / T, V * V * s * s / r)

        xs = np.linspace(0.0, 1.0, 2001)
        s = xs**3 * (10.0 + xs * (-15.0 + 6.0 * xs))
        vals = np.hypot(V * 30.0 * xs**2 * (1.0 - xs) ** 2 / T, V * V * s * s / r)
        k = int(np.argmax(vals))
        lo, hi = xs[max(k - 1, 0)], xs[min(k + 1, len(xs) - 1)]
        res = minimize_scalar(lambda x: -f(x), bounds=(lo, hi), method="bounded",
                              options={"xatol": 1e-13})
        return max(float(vals[k]), -float(res.fun), V * V / r)

    @classmethod
    def min_lead_in_s(cls, radius_m: float, speed_m_s: float, max_acc_m_s2: float) -> float:
        """Shortest lead-in [s] keeping the total acceleration within ``max_acc_m_s2``
        (``math.inf`` if speed^2 / radius alone exceeds it)."""
        if speed_m_s**2 / radius_m > max_acc_m_s2:
            return math.inf
        hi = QUINTIC_PEAK_SPEED * speed_m_s / max_acc_m_s2  # tangential part alone
        while cls.peak_acc_m_s2(radius_m, speed_m_s, hi) > max_acc_m_s2:
            hi *= 2.0
            if hi > 1e7:
                return math.inf
        lo = hi / 2.0
        while hi - lo > 1e-9 * hi:
            mid = 0.5 * (lo + hi)
            if cls.peak_acc_m_s2(radius_m, speed_m_s, mid) > max_acc_m_s2:
                lo = mid
            else:
                hi = mid
        return hi

    def sample(self, t_s: float) -> RefSample:
        (s,), (sd,), (sdd,), (sddd,) = self._arc.eval(t_s)
        r, k = self.radius_m, self._sgn / self.radius_m
        th = self._theta0 + k * s
        w, al, ze = k * sd, k * sdd, k * sddd
        c, sn = math.cos(th), math.sin(th)
        cx, cy = self.centre_xy_m
        rw2 = r * w * w
        tj = r * (ze - w * w * w)
        rj = 3.0 * r * w * al
        if self.face_travel:
            yaw, yaw_rate = wrap_pi(th + self._sgn * 0.5 * math.pi), w
        else:
            yaw, yaw_rate = self._yaw, 0.0
        return RefSample((cx + r * c, cy + r * sn, self.altitude_m),
                         (-r * w * sn, r * w * c, 0.0),
                         (-r * al * sn - rw2 * c, r * al * c - rw2 * sn, 0.0),
                         (-tj * sn - rj * c, tj * c - rj * sn, 0.0),
                         yaw, yaw_rate)

    def yaw_acc_rad_s2(self, t_s: float) -> float:
        if not self.face_travel:
            return 0.0
        return self._sgn * self._arc.eval(t_s)[2][0] / self.radius_m


class Sequence(Trajectory):
    """Trajectories flown one after the other; each must start when and where (position,
    velocity, acceleration, yaw) the previous one ends, else ValueError. Usually built with
    :class:`SequenceBuilder`."""

    def __init__(self, segments: Iterable[Trajectory], *, tol: float = 1e-6) -> None:
        self.segments: tuple[Trajectory, ...] = tuple(segments)
        if not self.segments:
            raise ValueError("a Sequence needs at least one segment")
        for i, (prev, nxt) in enumerate(zip(self.segments, self.segments[1:], strict=False)):
            if math.isinf(prev.end_s):
                raise ValueError(f"segment {i} never ends, so segment {i + 1} cannot follow")
            if abs(nxt.start_s - prev.end_s) > 1e-9 * max(1.0, abs(prev.end_s)):
                raise ValueError(f"segment {i + 1} starts at {nxt.start_s} s, "
                                 f"segment {i} ends at {prev.end_s} s")
            a, b = prev.sample(prev.end_s), nxt.sample(nxt.start_s)
            for name, x, y in (("position", a.pos_m, b.pos_m), ("velocity", a.vel_m_s, b.vel_m_s),
                               ("acceleration", a.acc_m_s2, b.acc_m_s2)):
                if math.dist(x, y) > tol:
                    raise ValueError(f"{name} jumps between segments {i} and {i + 1}: "
                                     f"{x} -> {y}")
            if abs(wrap_pi(a.yaw_rad - b.yaw_rad)) > tol or abs(a.yaw_rate_rad_s
                                                                  - b.yaw_rate_rad_s) > tol:
                raise ValueError(f"yaw jumps between segments {i} and {i + 1}")
        self._starts = [s.start_s for s in self.segments]
        self.start_s = self.segments[0].start_s
        self.end_s = self.segments[-1].end_s
        self.final_pos_m = self.segments[-1].final_pos_m
        self.final_yaw_rad = self.segments[-1].final_yaw_rad
        self.knots_s = tuple(sorted({k for s in self.segments for k in s.knots_s}))

    def _active(self, t_s: float) -> Trajectory:
        i = bisect.bisect_right(self._starts, t_s) - 1
        return self.segments[min(max(i, 0), len(self.segments) - 1)]

    def sample(self, t_s: float) -> RefSample:
        return self._active(t_s).sample(t_s)

    def yaw_acc_rad_s2(self, t_s: float) -> float:
        return self._active(t_s).yaw_acc_rad_s2(t_s)


class SequenceBuilder:
    """Builds a :class:`Sequence` step by step from ``start_pos`` [m], ``t0`` [s] and
    ``yaw`` [rad] at rest; each step starts where and when the previous one ends. Goto
    moves are :class:`Transition` within ``max_speed_m_s`` / ``max_acc_m_s2``.

    ``SequenceBuilder(p, 0, 5, 2).goto(a).hold(3).line_to(b).circle(c, 10, 3, 2).build()``
    """

    def __init__(self, start_pos: Iterable[float], t0: float, max_speed_m_s: float,
                 max_acc_m_s2: float, *, yaw: float = 0.0,
                 max_yaw_rate: float = DEFAULT_MAX_YAW_RATE_RAD_S,
                 max_yaw_acc_rad_s2: float = DEFAULT_MAX_YAW_ACC_RAD_S2,
                 min_duration_s: float = DEFAULT_MIN_DURATION_S) -> None:
        self.pos_m: Vec3 = _vec3(start_pos, "start_pos")
        self.t_s = float(t0)
        self.yaw_rad = wrap_pi(yaw)
        self.max_speed_m_s = _positive(max_speed_m_s, "max_speed_m_s")
        self.max_acc_m_s2 = _positive(max_acc_m_s2, "max_acc_m_s2")
        self._yaw_limits = dict(max_yaw_rate=max_yaw_rate, max_yaw_acc_rad_s2=max_yaw_acc_rad_s2,
                                min_duration_s=min_duration_s)
        self._segments: list[Trajectory] = []

    def append(self, traj: Trajectory) -> SequenceBuilder:
        """Append any trajectory (it must start at the current time, position and yaw)."""
        if math.isinf(self.t_s):
            raise ValueError("the sequence already ends with an endless trajectory")
        self._segments.append(traj)
        self.t_s = traj.end_s
        if traj.final_pos_m is not None:
            self.pos_m = traj.final_pos_m
        self.yaw_rad = traj.final_yaw_rad
        return self

    def goto(self, goal: Iterable[float], yaw: float | None = None) -> SequenceBuilder:
        """Transition to ``goal`` [m] (and ``yaw`` [rad], default unchanged)."""
        return self.append(Transition(self.pos_m, goal, self.t_s, self.max_speed_m_s,
                                      self.max_acc_m_s2, yaw_start=self.yaw_rad,
                                      yaw_goal=yaw, **self._yaw_limits))

    def hold(self, duration_s: float) -> SequenceBuilder:
        """Stay for ``duration_s`` [s]."""
        return self.append(Hold(self.pos_m, self.yaw_rad, self.t_s, duration_s=duration_s))

    def line_to(self, end: Iterable[float], speed_m_s: float | None = None) -> SequenceBuilder:
        """Straight line at cruise ``speed_m_s`` [m/s] (default ``max_speed_m_s``)."""
        speed = self.max_speed_m_s if speed_m_s is None else min(speed_m_s, self.max_speed_m_s)
        return self.append(Line(self.pos_m, end, self.t_s, speed, self.max_acc_m_s2,
                                yaw=self.yaw_rad))

    def circle(self, centre_xy: Iterable[float], radius_m: float, speed_m_s: float,
               turns: float = math.inf, *, altitude_m: float | None = None,
               lead_in_s: float = 5.0, clockwise: bool = False,
               start_angle_rad: float | None = None,
               face_travel: bool = False) -> SequenceBuilder:
        """Fly to the circle's start point (default: the point nearest the current
        position, at ``altitude_m``, default the current altitude), then the circle."""
        cx, cy = _vec(centre_xy, "centre_xy", 2)
        alt = self.pos_m[2] if altitude_m is None else float(altitude_m)
        theta0 = (_nearest_angle((cx, cy), self.pos_m) if start_angle_rad is None
                  else float(start_angle_rad))
        sgn = -1.0 if clockwise else 1.0
        yaw = wrap_pi(theta0 + sgn * 0.5 * math.pi) if face_travel else self.yaw_rad
        speed = min(speed_m_s, self.max_speed_m_s)
        circle = Circle((cx, cy), radius_m, alt, speed, 0.0, lead_in_s, turns, theta0,
                        clockwise, self.max_acc_m_s2, yaw=yaw, face_travel=face_travel)
        self.goto(circle.start_pos_m, yaw=yaw)
        return self.append(Circle((cx, cy), radius_m, alt, speed, self.t_s, lead_in_s, turns,
                                  theta0, clockwise, self.max_acc_m_s2, yaw=yaw,
                                  face_travel=face_travel))

    def build(self) -> Sequence:
        """The Sequence (a Hold at the start if nothing was added)."""
        if not self._segments:
            return Sequence([Hold(self.pos_m, self.yaw_rad, self.t_s)])
        return Sequence(self._segments)


def _nearest_angle(centre_xy: tuple[float, float], pos: Iterable[float]) -> float:
    x, y = tuple(pos)[:2]
    dx, dy = x - centre_xy[0], y - centre_xy[1]
    return math.atan2(dy, dx) if math.hypot(dx, dy) > 1e-9 else 0.0


# --- mission logic --------------------------------------------------------------------------

@dataclass(frozen=True)
class GotoItem:
    """Fly to ``pos_m`` [m]; ``yaw_rad`` [rad] there, or keep the current yaw if None."""

    pos_m: Vec3
    yaw_rad: float | None = None


@dataclass(frozen=True)
class CircleItem:
    """Circle ``turns`` times (NAV_LOITER_TURNS) about ``centre_xy_m`` [m] at radius
    ``radius_m`` [m], altitude ``altitude_m`` [m], tangential speed ``speed_m_s`` [m/s]
    (clamped to the follower's max speed), starting at ``start_angle_rad`` (None: the point
    nearest the vehicle). ``turns`` may be ``math.inf`` (loiter until retargeted)."""

    centre_xy_m: tuple[float, float]
    radius_m: float
    altitude_m: float
    speed_m_s: float
    turns: float = 1.0
    clockwise: bool = False
    start_angle_rad: float | None = None
    lead_in_s: float = 5.0
    yaw_rad: float | None = None
    face_travel: bool = False


MissionItem = GotoItem | CircleItem

EVENT_CURRENT = "current"
"""An item became the one being flown (MISSION_CURRENT)."""
EVENT_REACHED = "reached"
"""An item was reached (MISSION_ITEM_REACHED)."""


class MissionEvent(NamedTuple):
    """Something the companion reports: ``kind`` is EVENT_CURRENT or EVENT_REACHED."""

    kind: str
    index: int
    t_s: float


def as_mission_item(item: MissionItem | Iterable[float]) -> MissionItem:
    """A GotoItem or CircleItem from an item or an (x, y, z) / (x, y, z, yaw) tuple."""
    if isinstance(item, GotoItem | CircleItem):
        return item
    vals = tuple(float(x) for x in item)
    if len(vals) == 3:
        return GotoItem(_vec3(vals, "waypoint"))
    if len(vals) == 4:
        return GotoItem(_vec3(vals[:3], "waypoint"), vals[3])
    raise ValueError(f"a waypoint is (x, y, z) or (x, y, z, yaw), got {item!r}")


_TRANSIT, _CIRCLE, _HOLD, _DONE = "transit", "circle", "hold", "done"


class WaypointFollower:
    """Mission logic shared by the companion's AUTO/GUIDED modes and the offline runner.

    Flies a :class:`Transition` (within ``max_speed_m_s`` [m/s], ``max_acc_m_s2``
    [m/s^2]) to each item in turn. A goto item is reached when its transition has finished
    and the vehicle is within ``acceptance_radius_m`` [m] of it; a circle item is flown as
    a transition to the circle's start point (entered when reached the same way), then the
    :class:`Circle`, and is reached when the circle has stopped and the vehicle is within
    the radius of its end point. After ``hold_s`` [s] at a reached item the next one starts.
    Until then the reference holds (at rest) at the item, whatever the vehicle does.

    Events (EVENT_CURRENT, EVENT_REACHED) go to ``on_event`` if given and are queued for
    :meth:`pop_events`; ``reached`` lists (index, time) pairs.
    """

    def __init__(self, max_speed_m_s: float, max_acc_m_s2: float, acceptance_radius_m: float,
                 hold_s: float = 0.0, *, max_yaw_rate: float = DEFAULT_MAX_YAW_RATE_RAD_S,
                 max_yaw_acc_rad_s2: float = DEFAULT_MAX_YAW_ACC_RAD_S2,
                 min_duration_s: float = DEFAULT_MIN_DURATION_S,
                 on_event: Callable[[MissionEvent], None] | None = None) -> None:
        self.max_speed_m_s = _positive(max_speed_m_s, "max_speed_m_s")
        self.max_acc_m_s2 = _positive(max_acc_m_s2, "max_acc_m_s2")
        self.acceptance_radius_m = _positive(acceptance_radius_m, "acceptance_radius_m")
        if not (hold_s >= 0.0 and math.isfinite(hold_s)):
            raise ValueError(f"hold_s must be >= 0 and finite, got {hold_s!r}")
        self.hold_s = float(hold_s)
        self._transition_kw = dict(max_yaw_rate=max_yaw_rate,
                                   max_yaw_acc_rad_s2=max_yaw_acc_rad_s2,
                                   min_duration_s=min_duration_s)
        self.on_event = on_event
        self.reached: list[tuple[int, float]] = []
        """(item index, time [s]) of each item reached, in order."""
        self._events: list[MissionEvent] = []
        self._items: list[MissionItem] = []
        self._index = 0
        self._phase = _DONE
        self._traj: Trajectory | None = None
        self._target: Vec3 | None = None
        self._hold_until = 0.0
        self._circle_kw: dict | None = None

    # -- state --

    @property
    def items(self) -> tuple[MissionItem, ...]:
        """The mission items (retargets replace or insert items)."""
        return tuple(self._items)

    @property
    def current_index(self) -> int:
        """Index of the item being flown or held at; len(items) when done."""
        return self._index

    @property
    def done(self) -> bool:
        """True when every item has been reached and its hold is over."""
        return self._phase == _DONE

    @property
    def phase(self) -> str:
        """"transit", "circle", "hold" or "done"."""
        return self._phase

    @property
    def trajectory(self) -> Trajectory:
        """The trajectory being flown."""
        if self._traj is None:
            raise RuntimeError("WaypointFollower.start() has not been called")
        return self._traj

    @property
    def target_m(self) -> Vec3 | None:
        """Point [m] the acceptance test currently uses (None while on an endless circle)."""
        return self._target

    @property
    def has_events(self) -> bool:
        """Whether :meth:`pop_events` has events to hand out."""
        return bool(self._events)

    def pop_events(self) -> list[MissionEvent]:
        """Events since the last call, oldest first."""
        out, self._events = self._events, []
        return out

    # -- control --

    def start(self, t: float, current_pos: Iterable[float],
              current_vel: Iterable[float] = _ZERO3,
              waypoints: Iterable[MissionItem | Iterable[float]] = (), *,
              current_yaw: float = 0.0, current_acc: Iterable[float] = _ZERO3) -> None:
        """Start the mission at time ``t`` [s] from the vehicle state (position [m],
        velocity [m/s], yaw [rad], acceleration [m/s^2]). With no items the reference just
        comes to rest at ``current_pos``. Raises ValueError on an impossible circle item."""
        items = [as_mission_item(w) for w in waypoints]
        for it in items:
            if isinstance(it, CircleItem):
                self._check_circle(it)
        pos = _vec3(current_pos, "current_pos")
        state = RefSample(pos, _vec3(current_vel, "current_vel"),
                          _vec3(current_acc, "current_acc"), _ZERO3, wrap_pi(current_yaw), 0.0)
        self._items = items
        self.reached = []
        self._events = []
        self._index = 0
        if items:
            self._begin_item(float(t), state, 0.0)
        else:
            self._traj = Transition(pos, pos, t, self.max_speed_m_s, self.max_acc_m_s2,
                                    state.vel_m_s, state.acc_m_s2, state.yaw_rad,
                                    **self._transition_kw)
            self._phase, self._target = _DONE, pos

    def update(self, t: float, current_pos: Iterable[float]) -> RefSample:
        """Advance the mission with the vehicle at ``current_pos`` [m] at time ``t`` [s]
        (non-decreasing) and return the reference at ``t``."""
        traj = self.trajectory
        phase = self._phase
        if (t < traj.end_s and phase in (_TRANSIT, _CIRCLE)
                or phase == _HOLD and t < self._hold_until or phase == _DONE):
            return traj.sample(t)   # nothing to decide (most calls)
        pos = tuple(current_pos)
        for _ in range(2 * len(self._items) + 4):  # each pass changes phase or stops
            traj = self.trajectory
            if self._phase in (_TRANSIT, _CIRCLE):
                if not (t >= traj.end_s and self._target is not None
                        and math.dist(pos, self._target) <= self.acceptance_radius_m):
                    break
                if self._phase == _TRANSIT and self._circle_kw is not None:
                    circle = Circle(t0=t, **self._circle_kw)
                    self._circle_kw = None
                    self._traj, self._phase, self._target = circle, _CIRCLE, circle.final_pos_m
                    continue
                self.reached.append((self._index, t))
                self._emit(EVENT_REACHED, self._index, t)
                self._phase, self._hold_until = _HOLD, t + self.hold_s
            elif self._phase == _HOLD:
                if t < self._hold_until:
                    break
                self._index += 1
                if self._index >= len(self._items):
                    self._phase = _DONE
                    break
                self._begin_item(t, traj.sample(t), traj.yaw_acc_rad_s2(t))
            else:
                break
        return self.trajectory.sample(t)

    def retarget(self, t: float, new_goal: MissionItem | Iterable[float]) -> RefSample:
        """Fly to ``new_goal`` from the current reference state at ``t`` [s] (position,
        velocity, acceleration, yaw and its rates), so the reference stays C2. It replaces
        the item being flown; if that was already reached (holding, or done), it is inserted
        after it. Later items are kept. Returns the reference at ``t``."""
        traj = self.trajectory
        item = as_mission_item(new_goal)
        if isinstance(item, CircleItem):
            self._check_circle(item)
        if self._phase in (_HOLD, _DONE):
            self._index = min(self._index + 1, len(self._items)) if self._phase == _HOLD \
                else len(self._items)
            self._items.insert(self._index, item)
        else:
            self._items[self._index] = item
        self._begin_item(float(t), traj.sample(t), traj.yaw_acc_rad_s2(t))
        return self.trajectory.sample(t)

    # -- internals --

    def _emit(self, kind: str, index: int, t: float) -> None:
        ev = MissionEvent(kind, index, t)
        self._events.append(ev)
        if self.on_event is not None:
            self.on_event(ev)

    def _circle_args(self, item: CircleItem, pos: Iterable[float], yaw: float) -> dict:
        theta0 = (_nearest_angle(item.centre_xy_m, pos) if item.start_angle_rad is None
                  else float(item.start_angle_rad))
        sgn = -1.0 if item.clockwise else 1.0
        if item.face_travel:
            yaw = wrap_pi(theta0 + sgn * 0.5 * math.pi)
        elif item.yaw_rad is not None:
            yaw = item.yaw_rad
        return dict(centre_xy=item.centre_xy_m, radius_m=item.radius_m,
                    altitude_m=item.altitude_m,
                    speed_m_s=min(item.speed_m_s, self.max_speed_m_s),
                    lead_in_s=item.lead_in_s, turns=item.turns, start_angle_rad=theta0,
                    clockwise=item.clockwise, max_acc_m_s2=self.max_acc_m_s2, yaw=yaw,
                    face_travel=item.face_travel)

    def _check_circle(self, item: CircleItem) -> None:
        Circle(t0=0.0, **self._circle_args(item, (item.centre_xy_m[0] + 1.0,
                                                  item.centre_xy_m[1]), 0.0))

    def _begin_item(self, t: float, state: RefSample, yaw_acc: float) -> None:
        item = self._items[self._index]
        if isinstance(item, CircleItem):
            self._circle_kw = self._circle_args(item, state.pos_m, state.yaw_rad)
            kw = self._circle_kw
            cx, cy = kw["centre_xy"]
            th = kw["start_angle_rad"]
            goal: Vec3 = (cx + kw["radius_m"] * math.cos(th), cy + kw["radius_m"] * math.sin(th),
                          kw["altitude_m"])
            yaw_goal = kw["yaw"]
        else:
            self._circle_kw = None
            goal = item.pos_m
            yaw_goal = state.yaw_rad if item.yaw_rad is None else item.yaw_rad
        self._traj = Transition(state.pos_m, goal, t, self.max_speed_m_s, self.max_acc_m_s2,
                                state.vel_m_s, state.acc_m_s2, state.yaw_rad, yaw_goal,
                                start_yaw_rate_rad_s=state.yaw_rate_rad_s,
                                start_yaw_acc_rad_s2=yaw_acc, **self._transition_kw)
        self._phase, self._target = _TRANSIT, goal
        self._emit(EVENT_CURRENT, self._index, t)


__all__ = [
    "DEFAULT_CIRCLE_MAX_ACC_M_S2", "DEFAULT_MAX_YAW_ACC_RAD_S2", "DEFAULT_MAX_YAW_RATE_RAD_S",
    "DEFAULT_MIN_DURATION_S", "EVENT_CURRENT", "EVENT_REACHED", "QUINTIC_PEAK_ACC",
    "QUINTIC_PEAK_SPEED", "Circle", "CircleItem", "GotoItem", "Hold", "Line", "MissionEvent",
    "MissionItem", "RefSample", "Sequence", "SequenceBuilder", "Trajectory", "Transition",
    "WaypointFollower", "as_mission_item",
]
