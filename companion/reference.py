"""Reference primitives for the backstepping position controller: the trajectories
(:class:`Hold`, :class:`Transition`, :class:`Line`, :class:`Circle`, :class:`Sequence` and
its :class:`SequenceBuilder`) and the sample they give (:class:`RefSample`).

Every trajectory gives, at any time ``t`` [s], the reference position, velocity,
acceleration and jerk (inertial frame: z up, x east, y north, origin at the winder) and a
reference yaw and yaw rate (yaw from +x toward +y). References are at least C2 in
position (continuous acceleration) and respect the speed and acceleration limits they are
built with, so that a far waypoint never becomes a step that saturates the rotors.

:class:`Transition` (point to point, from rest or from a moving state, and its yaw) is
planned by :mod:`companion.planner`, whose docstring gives its profiles. The others
(``u = (t - t0) / T`` is normalised time, ``s(u) = 10u^3 - 15u^4 + 6u^5`` the quintic
smoothstep):

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
import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable
from typing import NamedTuple

import numpy as np
from scipy.optimize import minimize_scalar

from companion.planner import (
    LIMIT_RTOL,
    QUINTIC_PEAK_SPEED,
    T_FLOOR,
    Piece,
    Piecewise,
    pieces_peaks,
    piecewise1_kernel,
    plan_to_rest,
    smoothstep5,
)
from tuavdefs import jit
from tuavdefs.frames import wrap_pi
from tuavdefs.jit import entry_point, njit

Vec3 = tuple[float, float, float]
"""A point or vector in the inertial frame (x east, y north, z up)."""

DEFAULT_MAX_YAW_RATE_RAD_S = math.radians(45.0)
"""Default yaw-rate limit [rad/s] of a transition."""
DEFAULT_MAX_YAW_ACC_RAD_S2 = math.radians(90.0)
"""Default yaw-acceleration limit [rad/s^2] of a transition."""
DEFAULT_MIN_DURATION_S = 0.5
"""Shortest transition [s]; bounds the jerk of tiny moves (jerk <= 10.4 a_max / T)."""
DEFAULT_CIRCLE_MAX_ACC_M_S2 = 3.0
"""Default limit [m/s^2] on a circle's total (centripetal + tangential) acceleration."""

ZERO3: Vec3 = (0.0, 0.0, 0.0)
"""The zero vector (a start at rest) [m/s, m/s^2]."""


class RefSample(NamedTuple):
    """One reference sample; inertial frame, SI units."""

    pos_m: Vec3
    vel_m_s: Vec3
    acc_m_s2: Vec3
    jerk_m_s3: Vec3
    yaw_rad: float
    """Reference yaw in [-pi, pi), from +x toward +y."""
    yaw_rate_rad_s: float


#: A record built as the tuple it is (tuple.__new__), without its Python-level constructor
#: (the samplers run every control period).
_new = tuple.__new__


# --- argument checks ------------------------------------------------------------------------

def vec(v: Iterable[float], name: str, n: int = 3) -> tuple[float, ...]:
    """``v`` as a tuple of ``n`` finite floats (any unit), else ValueError naming ``name``."""
    out = tuple(float(x) for x in v)
    if len(out) != n or not all(math.isfinite(x) for x in out):
        raise ValueError(f"{name} must be {n} finite numbers, got {v!r}")
    return out


def vec3(v: Iterable[float], name: str) -> Vec3:
    """``v`` as three finite floats (any unit), else ValueError naming ``name``."""
    x, y, z = vec(v, name, 3)
    return (x, y, z)


def positive(x: float, name: str) -> float:
    """``x`` as a float if positive and finite (any unit), else ValueError naming ``name``."""
    x = float(x)
    if not (x > 0.0 and math.isfinite(x)):
        raise ValueError(f"{name} must be positive and finite, got {x!r}")
    return x


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
        pos = vec3(position, "position")
        if not duration_s >= 0.0:
            raise ValueError(f"duration_s must be >= 0, got {duration_s!r}")
        self.start_s = float(t0)
        self.end_s = self.start_s + duration_s
        self.final_pos_m = pos
        self.final_yaw_rad = wrap_pi(yaw)
        self.knots_s = (self.start_s,) if math.isinf(self.end_s) else (self.start_s, self.end_s)
        self._sample = RefSample(pos, ZERO3, ZERO3, ZERO3, self.final_yaw_rad, 0.0)

    def sample(self, t_s: float) -> RefSample:
        return self._sample


class Transition(Trajectory):
    """Smooth point-to-point move to rest at ``goal_pos`` [m] within the speed
    ``max_speed_m_s`` [m/s] and acceleration ``max_acc_m_s2`` [m/s^2] limits.

    From rest (``start_vel`` and ``start_acc`` zero) it is the straight-line minimum-jerk
    quintic of duration ``max(15/8 D / v_max, sqrt(10/sqrt(3) D / a_max), min_duration_s)``
    (0 if D = 0). From a moving state (retargeting) it matches ``start_pos``, ``start_vel``
    [m/s] and ``start_acc`` [m/s^2] and stops at the goal (see :mod:`companion.planner`).

    Yaw goes from ``yaw_start`` to ``yaw_goal`` (default: ``yaw_start``) [rad] the shortest
    way round on its own quintic profile within ``max_yaw_rate`` [rad/s] and
    ``max_yaw_acc_rad_s2``, starting from ``start_yaw_rate_rad_s`` and
    ``start_yaw_acc_rad_s2``. Position and yaw finish independently; ``end_s`` is the
    later. ``within_limits`` is False only when the start state itself made the limits
    impossible to keep.
    """

    def __init__(self, start_pos: Iterable[float], goal_pos: Iterable[float], t0: float,
                 max_speed_m_s: float, max_acc_m_s2: float,
                 start_vel: Iterable[float] = ZERO3, start_acc: Iterable[float] = ZERO3,
                 yaw_start: float = 0.0, yaw_goal: float | None = None,
                 max_yaw_rate: float = DEFAULT_MAX_YAW_RATE_RAD_S, *,
                 start_yaw_rate_rad_s: float = 0.0, start_yaw_acc_rad_s2: float = 0.0,
                 max_yaw_acc_rad_s2: float = DEFAULT_MAX_YAW_ACC_RAD_S2,
                 min_duration_s: float = DEFAULT_MIN_DURATION_S) -> None:
        p0 = vec(start_pos, "start_pos")
        goal = vec3(goal_pos, "goal_pos")
        v0 = vec(start_vel, "start_vel")
        a0 = vec(start_acc, "start_acc")
        self.max_speed_m_s = positive(max_speed_m_s, "max_speed_m_s")
        self.max_acc_m_s2 = positive(max_acc_m_s2, "max_acc_m_s2")
        self.max_yaw_rate = positive(max_yaw_rate, "max_yaw_rate")
        self.max_yaw_acc_rad_s2 = positive(max_yaw_acc_rad_s2, "max_yaw_acc_rad_s2")
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

        pos_pieces, pos_ok = plan_to_rest(p0, v0, a0, goal, self.max_speed_m_s,
                                           self.max_acc_m_s2, min_duration_s)
        yaw_end = yaw0 + wrap_pi(yaw_goal - yaw0)  # unwrapped, shortest way round
        yaw_pieces, yaw_ok = plan_to_rest((yaw0,), (float(start_yaw_rate_rad_s),),
                                           (float(start_yaw_acc_rad_s2),), (yaw_end,),
                                           self.max_yaw_rate, self.max_yaw_acc_rad_s2,
                                           min_duration_s)
        self._pos = Piecewise(t0, pos_pieces, goal, 3)
        self._yaw = Piecewise(t0, yaw_pieces, (yaw_end,), 1)
        self.start_s = t0
        self.end_s = max(self._pos.end, self._yaw.end)
        self.final_pos_m = goal
        self.final_yaw_rad = wrap_pi(yaw_end)
        self.pos_duration_s = self._pos.end - t0
        """Duration [s] of the position profile."""
        self.yaw_duration_s = self._yaw.end - t0
        """Duration [s] of the yaw profile."""
        self.peak_speed_m_s, self.peak_acc_m_s2 = pieces_peaks(pos_pieces)
        self.peak_yaw_rate_rad_s = pieces_peaks(yaw_pieces)[0]
        self.within_limits = pos_ok and yaw_ok
        self.knots_s = tuple(sorted(set(self._pos.knots()) | set(self._yaw.knots())))
        self._rest = self._sample(self.end_s)   # from the end on: at rest, the same sample

    def sample(self, t_s: float) -> RefSample:
        if t_s >= self.end_s:
            return self._rest
        return self._sample(t_s)

    def _sample(self, t_s: float) -> RefSample:
        p, v, a, j = self._pos.eval(t_s)
        y, yr, _, _ = self._yaw.eval1(t_s)
        return _new(RefSample, (p, v, a, j, wrap_pi(y), yr))

    def yaw_acc_rad_s2(self, t_s: float) -> float:
        return self._yaw.eval(t_s)[2][0]


def _ramp_pieces(V: float, Tr: float, sigma0: float, up: bool) -> Piece:
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
        p0 = np.array(vec(start, "start"))
        p1 = np.array(vec(end, "end"))
        V = positive(speed_m_s, "speed_m_s")
        a_max = positive(max_acc_m_s2, "max_acc_m_s2")
        min_ramp_s = max(float(min_ramp_s), T_FLOOR)
        D = math.hypot(*(p1 - p0))
        t0 = float(t0)
        pieces: list[Piece] = []
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
        self._pos = Piecewise(t0, pieces, tuple(p1), 3)
        self.start_s = t0
        self.end_s = self._pos.end
        self.final_pos_m = vec3(p1, "end")
        self.final_yaw_rad = wrap_pi(yaw)
        self.knots_s = tuple(self._pos.knots())

    def sample(self, t_s: float) -> RefSample:
        p, v, a, j = self._pos.eval(t_s)
        return _new(RefSample, (p, v, a, j, self.final_yaw_rad, 0.0))


#: A circle's geometry as :func:`circle_kernel` takes it (a tuple of floats), by index: the
#: start angle [rad], the turn per metre of arc (+-1 / radius) [rad/m], the radius [m],
#: the centre's x and y [m].
CG_THETA0, CG_K, CG_R, CG_CX, CG_CY, N_CG = range(6)
#: :func:`circle_kernel`'s arguments, declared once: the time [s], the arc's piecewise
#: polynomial (:data:`companion.planner.PIECEWISE1_SIGNATURE`'s arrays), the geometry
#: (CG_*).
CIRCLE_SIGNATURE = jit.Signature(jit.F64, jit.array(), jit.array(3), jit.vec(N_CG))


@njit
def circle_kernel(t_s: float, times: np.ndarray, cols: np.ndarray,
                  geometry: tuple[float, ...]) -> tuple[float, ...]:
    """:class:`Circle`'s sample at ``t_s`` [s] in the plane (module docstring): the
    position's, velocity's, acceleration's and jerk's x and y [m, m/s, m/s^2, m/s^3], the
    angle on the circle [rad] and its rate [rad/s]."""
    s, sd, sdd, sddd = piecewise1_kernel(t_s, times, cols)
    r, k = geometry[CG_R], geometry[CG_K]
    th = geometry[CG_THETA0] + k * s
    w, al, ze = k * sd, k * sdd, k * sddd
    c, sn = math.cos(th), math.sin(th)
    rw2 = r * w * w
    tj = r * (ze - w * w * w)
    rj = 3.0 * r * w * al
    return (geometry[CG_CX] + r * c, geometry[CG_CY] + r * sn,
            -r * w * sn, r * w * c,
            -r * al * sn - rw2 * c, r * al * c - rw2 * sn,
            -tj * sn - rj * c, tj * c - rj * sn, th, w)


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

    #: circle_kernel's entry point (on the class: an instance still pickles)
    _sample: Callable[..., tuple[float, ...]] | None = None

    def __init__(self, centre_xy: Iterable[float], radius_m: float, altitude_m: float,
                 speed_m_s: float, t0: float, lead_in_s: float = 5.0,
                 turns: float = math.inf, start_angle_rad: float = 0.0,
                 clockwise: bool = False, max_acc_m_s2: float = DEFAULT_CIRCLE_MAX_ACC_M_S2,
                 *, yaw: float = 0.0, face_travel: bool = False) -> None:
        self.centre_xy_m = vec(centre_xy, "centre_xy", 2)
        self.radius_m = r = positive(radius_m, "radius_m")
        self.altitude_m = float(vec((altitude_m,), "altitude_m", 1)[0])
        V = positive(speed_m_s, "speed_m_s")
        Tr = self.lead_in_s = positive(lead_in_s, "lead_in_s")
        if not turns > 0.0:
            raise ValueError(f"turns must be > 0, got {turns!r}")
        self.turns = float(turns)
        self.max_acc_m_s2 = a_max = positive(max_acc_m_s2, "max_acc_m_s2")
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
        if centripetal > a_max * (1.0 + LIMIT_RTOL):
            raise ValueError(
                f"centripetal acceleration speed^2/radius = {centripetal:.4g} m/s^2 exceeds "
                f"max_acc_m_s2 = {a_max:.4g} m/s^2 (speed must be <= "
                f"{math.sqrt(a_max * r):.4g} m/s on radius {r:.4g} m)")
        peak = self.peak_acc_m_s2(r, V, Tr)
        if peak > a_max * (1.0 + LIMIT_RTOL):
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
        self._arc = Piecewise(t0, pieces, final, 1)
        self._geometry = (self._theta0, self._sgn / r, r, *self.centre_xy_m)
        if Circle._sample is None:
            Circle._sample = staticmethod(  # type: ignore[assignment]
                entry_point(circle_kernel, CIRCLE_SIGNATURE))
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
            s = smoothstep5(x)
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
        arc = self._arc
        x, y, vx, vy, ax, ay, jx, jy, th, w = self._sample(t_s, arc.times1, arc.cols1,
                                                           self._geometry)
        if self.face_travel:
            yaw, yaw_rate = wrap_pi(th + self._sgn * 0.5 * math.pi), w
        else:
            yaw, yaw_rate = self._yaw, 0.0
        return _new(RefSample, ((x, y, self.altitude_m), (vx, vy, 0.0), (ax, ay, 0.0),
                                (jx, jy, 0.0), yaw, yaw_rate))

    def yaw_acc_rad_s2(self, t_s: float) -> float:
        if not self.face_travel:
            return 0.0
        return self._sgn * self._arc.eval(t_s)[2][0] / self.radius_m

    def arc_m(self, t_s: float) -> float:
        """The arc [m] flown from the start at ``t_s`` [s] (0 before it, the whole arc
        after its end)."""
        return float(self._arc.eval(t_s)[0][0])


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
        self.pos_m: Vec3 = vec3(start_pos, "start_pos")
        self.t_s = float(t0)
        self.yaw_rad = wrap_pi(yaw)
        self.max_speed_m_s = positive(max_speed_m_s, "max_speed_m_s")
        self.max_acc_m_s2 = positive(max_acc_m_s2, "max_acc_m_s2")
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
        cx, cy = vec(centre_xy, "centre_xy", 2)
        alt = self.pos_m[2] if altitude_m is None else float(altitude_m)
        theta0 = (nearest_angle((cx, cy), self.pos_m) if start_angle_rad is None
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


def nearest_angle(centre_xy: tuple[float, float], pos: Iterable[float]) -> float:
    """Angle [rad] from +x toward +y, about ``centre_xy`` [m], of the point of a circle
    nearest ``pos`` [m] (its x, y); 0 when ``pos`` is over the centre."""
    x, y = tuple(pos)[:2]
    dx, dy = x - centre_xy[0], y - centre_xy[1]
    return math.atan2(dy, dx) if math.hypot(dx, dy) > 1e-9 else 0.0


__all__ = [
    "DEFAULT_CIRCLE_MAX_ACC_M_S2", "DEFAULT_MAX_YAW_ACC_RAD_S2", "DEFAULT_MAX_YAW_RATE_RAD_S",
    "DEFAULT_MIN_DURATION_S", "ZERO3", "Circle", "Hold", "Line", "RefSample", "Sequence",
    "SequenceBuilder", "Trajectory", "Transition", "Vec3", "nearest_angle", "positive", "vec",
    "vec3",
]
