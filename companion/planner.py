"""Planner maths of the reference trajectories: piecewise polynomials in time, their exact
peak speed and acceleration, and the minimum-jerk plans that take a state to rest within a
speed and an acceleration limit (what :mod:`companion.reference` builds its trajectories
from). Times in s; positions, velocities and accelerations in any one unit system (m, m/s,
m/s^2 for positions; rad, rad/s, rad/s^2 for yaw), per axis of any dimension.

Profiles (``u = (t - t0) / T`` is normalised time):

- Minimum-jerk (quintic) smoothstep ``s(u) = 10u^3 - 15u^4 + 6u^5``: ``s(0) = 0``,
  ``s(1) = 1``, first and second derivatives zero at both ends. Peak of ``s'`` is 15/8 (at
  u = 1/2) and peak of ``|s''|`` is ``10/sqrt(3)`` (at ``u = 1/2 -+ sqrt(3)/6``).
- From rest (:func:`plan_to_rest`, as :class:`companion.reference.Transition` uses it):
  ``p(t) = p0 + (g - p0) s(u)`` along the straight line,
  ``T = max(15/8 D / v_max, sqrt(10/sqrt(3) D / a_max), T_min)`` with ``D = |g - p0|``
  (``T = 0`` when ``D = 0``; ``T_min`` defaults to 0.5 s and is at least 1 ms). Peak
  speed is ``15/8 D / T``, peak acceleration ``10/sqrt(3) D / T^2``, jerk at the ends
  ``60 D / T^3``.
- From a moving state (retargeting, :func:`plan_to_rest` again): per axis the quintic with
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
  least-violating single quintic is used and the limits are reported as not held
  (``Transition.within_limits`` False).
- Yaw (``Transition``'s): the same planner in one dimension on the unwrapped angle [rad],
  going the shortest way round (``wrap_pi(yaw_goal - yaw_start)``), limited by the yaw rate
  and yaw acceleration.
"""

from __future__ import annotations

import bisect
import functools
import math
from collections.abc import Callable

import numpy as np
from numpy.polynomial import polynomial as npoly
from scipy.linalg.lapack import dgeev as _dgeev

from tuavdefs.jit import F64, Signature, array, entry_point, njit

QUINTIC_PEAK_SPEED = 15.0 / 8.0
"""Peak of ds/du for the quintic smoothstep s(u) = 10u^3 - 15u^4 + 6u^5."""
QUINTIC_PEAK_ACC = 10.0 / math.sqrt(3.0)
"""Peak of |d2s/du2| for the quintic smoothstep."""
LIMIT_RTOL = 1e-12
"""Relative float slack on the limit checks (a peak may exceed its limit by this much)."""
T_FLOOR = 1e-3
"""Shortest planned duration [s]; keeps the 1/T^5 coefficients finite."""
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


# --- polynomial machinery -----------------------------------------------------------------

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


def _lead_zeros(rev_coefs: list[float], n: int) -> list[float]:
    """``rev_coefs`` (highest power first) led by zeros to ``n`` coefficients: the same
    polynomial for :func:`_horner` (its steps through the zeros leave the sum at +0.0 for
    any finite ``x``, and a non-finite ``x`` gives NaN either way)."""
    return [0.0] * (n - len(rev_coefs)) + list(rev_coefs)


def smoothstep5(x: float) -> float:
    """The quintic smoothstep s(x) = 10x^3 - 15x^4 + 6x^5 (x normalised time, unitless)."""
    return x * x * x * (10.0 + x * (-15.0 + 6.0 * x))


#: A one-dimensional piecewise polynomial's times and ends, as :func:`piecewise1_kernel`
#: takes them (one float array), by index: its start and end [s], its value and three
#: derivatives before the start, and after the end, then from PB_STARTS on the pieces'
#: start times [s].
PB_T0, PB_END, PB_FIRST, PB_FINAL, PB_STARTS = 0, 1, 2, 6, 10
#: :func:`piecewise1_kernel`'s arguments, declared once: the time [s], the times and ends
#: (PB_*), the pieces' coefficients by power, highest first (n, m, 4: the value's and its
#: three derivatives', led by zeros to one length).
PIECEWISE1_SIGNATURE = Signature(F64, array(), array(3))


@njit
def piece1_kernel(cols: np.ndarray, i: int, tau: float) -> tuple[float, float, float, float]:
    """Piece ``i`` of a one-dimensional piecewise polynomial (coefficients ``cols`` as
    :data:`PIECEWISE1_SIGNATURE` says) ``tau`` [s] after its start: the value and its
    three derivatives, by Horner's steps (the zeros leading a shorter piece's leave the sum
    at +0.0 for any finite ``tau``)."""
    p = v = a = j = 0.0
    for k in range(cols.shape[1]):
        p = p * tau + cols[i, k, 0]
        v = v * tau + cols[i, k, 1]
        a = a * tau + cols[i, k, 2]
        j = j * tau + cols[i, k, 3]
    return p, v, a, j


@njit
def piecewise1_kernel(t: float, times: np.ndarray, cols: np.ndarray
                      ) -> tuple[float, float, float, float]:
    """A one-dimensional :class:`Piecewise` at absolute time ``t`` [s] (its arrays as
    :data:`PIECEWISE1_SIGNATURE` says): the value and its three derivatives; held at the
    final ones from the end on, the first ones up to the start."""
    if t >= times[PB_END]:
        return (times[PB_FINAL], times[PB_FINAL + 1], times[PB_FINAL + 2],
                times[PB_FINAL + 3])
    if t <= times[PB_T0]:
        return (times[PB_FIRST], times[PB_FIRST + 1], times[PB_FIRST + 2],
                times[PB_FIRST + 3])
    starts = times[PB_STARTS:]
    i = np.searchsorted(starts, t, side="right") - 1
    return piece1_kernel(cols, i, t - starts[i])


Piece = tuple[float, np.ndarray]
"""One polynomial piece: (duration [s], ascending coefficients (ndim, degree + 1) in local
time [s] from the piece's start)."""


class Piecewise:
    """A piecewise polynomial in absolute time [s], any dimension ``ndim``: the ``pieces``
    one after the other from ``t0``; clamped before its start and held (at rest) at
    ``final_pos`` (default: where the last piece ends) after its end ``end`` [s]."""

    __slots__ = ("t0", "end", "ndim", "_starts", "_durs", "_p", "_v", "_a", "_j", "_cols3",
                 "_first", "_final", "times1", "cols1")
    #: piecewise1_kernel's entry point (on the class: an instance still pickles)
    _eval1: Callable[..., tuple[float, float, float, float]] | None = None

    def __init__(self, t0: float, pieces: list[Piece], final_pos: tuple[float, ...] | None,
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
        # in one dimension, the four derivatives' coefficients by power (the shorter ones
        # led by zeros, whose steps leave the sum at +0.0, as it starts) for
        # piecewise1_kernel: (n, m, 4), the pieces led by zeros to the longest's length
        self.times1 = self.cols1 = None
        if ndim == 1 and self._starts:
            m = max(len(self._p[i][0]) for i in range(len(self._starts)))
            self.cols1 = np.ascontiguousarray(np.array(
                [list(zip(*(_lead_zeros(store[i][0], m)
                            for store in (self._p, self._v, self._a, self._j)), strict=True))
                 for i in range(len(self._starts))], dtype=float).reshape(-1, m, 4))
            if Piecewise._eval1 is None:
                Piecewise._eval1 = staticmethod(  # type: ignore[assignment]
                    entry_point(piecewise1_kernel, PIECEWISE1_SIGNATURE))
        self.end = t
        zeros = (0.0,) * ndim
        if final_pos is None:
            final_pos = self._eval_piece(len(pieces) - 1, self._durs[-1])[0] if pieces else zeros
        self._final = (tuple(final_pos), zeros, zeros, zeros)
        self._first = self._eval_piece(0, 0.0) if pieces else self._final
        if self.cols1 is not None:
            #: the times and ends as piecewise1_kernel takes them (PB_*), in one dimension
            self.times1 = np.array([self.t0, self.end, *(x for (x,) in self._first),
                                    *(x for (x,) in self._final), *self._starts], dtype=float)

    def _eval_piece(self, i: int, tau: float) -> tuple[tuple[float, ...], ...]:
        if self.ndim == 1:  # the common scalar case (arc length): _horner's steps, at once
            p, v, a, j = piece1_kernel(self.cols1, i, tau)
            return ((p,), (v,), (a,), (j,))
        if self.ndim == 3:  # positions: the three axes together
            p, v, a, j = self._cols3[i]
            return (_horner3(p, tau), _horner3(v, tau), _horner3(a, tau), _horner3(j, tau))
        return (tuple([_horner(r, tau) for r in self._p[i]]),
                tuple([_horner(r, tau) for r in self._v[i]]),
                tuple([_horner(r, tau) for r in self._a[i]]),
                tuple([_horner(r, tau) for r in self._j[i]]))

    def eval(self, t: float) -> tuple[tuple[float, ...], ...]:
        """(position, velocity, acceleration, jerk) at absolute time t."""
        if self.cols1 is not None:
            p, v, a, j = self._eval1(t, self.times1, self.cols1)
            return ((p,), (v,), (a,), (j,))
        if t >= self.end:
            return self._final
        if t <= self.t0:
            return self._first
        i = bisect.bisect_right(self._starts, t) - 1
        return self._eval_piece(i, t - self._starts[i])

    def eval1(self, t: float) -> tuple[float, float, float, float]:
        """In one dimension: (value, its first, second and third derivative) at absolute
        time t, flat."""
        if self.cols1 is None:
            (p,), (v,), (a,), (j,) = self._final
            return p, v, a, j
        return self._eval1(t, self.times1, self.cols1)

    def knots(self) -> list[float]:
        """Absolute times [s] at which the pieces join, start and end included."""
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


def pieces_peaks(pieces: list[Piece]) -> tuple[float, float]:
    """(peak speed, peak acceleration norm) over all ``pieces``, in their units per s and
    per s^2."""
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


def _limit_ratio(pieces: list[Piece], v_max: float, a_max: float) -> float:
    ps, pa = pieces_peaks(pieces)
    return max(ps / v_max, pa / a_max)


def _search_quintic(p0: np.ndarray, v0: np.ndarray, a0: np.ndarray, goal: np.ndarray,
                    v_max: float, a_max: float, t_min: float) -> tuple[float | None, float]:
    """(shortest feasible duration or None, least-violating duration seen)."""

    limit = 1.0 + LIMIT_RTOL

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
                   a_max: float) -> Piece | None:
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
            if _limit_ratio([(tau1, c)], v_max, a_max) <= 1.0 + LIMIT_RTOL:
                return tau1, c
    return None


def plan_to_rest(p0: tuple[float, ...], v0: tuple[float, ...], a0: tuple[float, ...],
                  goal: tuple[float, ...], v_max: float, a_max: float,
                  t_min: float) -> tuple[list[Piece], bool]:
    """Pieces taking the state (p0, v0, a0) to rest at goal within the speed limit
    ``v_max`` and acceleration limit ``a_max`` (the state's units per s and per s^2) in no
    less than ``t_min`` [s] (at least :data:`T_FLOOR`), and whether the limits hold (False
    only when no plan could keep them). No pieces when already at rest at the goal."""
    P0, V0, A0, G = (np.array(x, dtype=float) for x in (p0, v0, a0, goal))
    t_min = max(t_min, T_FLOOR)
    if not V0.any() and not A0.any():
        dist = math.hypot(*(G - P0))
        if dist == 0.0:
            return [], True
        T = max(QUINTIC_PEAK_SPEED * dist / v_max, math.sqrt(QUINTIC_PEAK_ACC * dist / a_max),
                t_min)
        return [(T, _quintic_to_rest(P0, V0, A0, G, T))], True

    plans: list[tuple[float, list[Piece]]] = []
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


__all__ = [
    "LIMIT_RTOL", "QUINTIC_PEAK_ACC", "QUINTIC_PEAK_SPEED", "T_FLOOR", "Piece", "Piecewise",
    "pieces_peaks", "plan_to_rest", "smoothstep5",
]
