"""The L-bar estimator: the tether length the winder should pay out for the UAV's position.

A catenary of parameter ``a = H/w`` (H the horizontal tension, w the weight per metre)
between the winder exit (origin) and the UAV at horizontal distance ``h = sqrt(x^2+y^2)``
and height ``v`` has the length (docs/control.md §3; the paper drops the square)

    L(a; h, v) = sqrt(v^2 + (2 a sinh(h / 2a))^2).

The estimator commands the target horizontal tension ``H_target`` (the paper's
``a = T0/(rho g)``), raised where needed so that the tether leaves the winder *upward* by at
least ``min_exit_angle``: the lowest point of the sag is then the exit itself and no tether
lies on the ground. The exit slope of the catenary is

    V_bottom / H = (v coth(h/2a) - L) / (2a),

which grows with ``a`` toward the chord's slope v/h, so the smallest admissible ``a`` is
found by bisection. Where even the chord is flatter than the minimum angle (the UAV low and
far), the tether is kept at ``min_slack`` above the straight line instead.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

from tuavdefs.paramspec import Params, quantity


@dataclass(frozen=True)
class LBarParams(Params):
    """Settings of the L-bar estimator."""

    target_horizontal_tension_n: float = quantity(
        2.0, "N", "horizontal tension to keep in the tether, T0 of the paper", gt=0)
    min_exit_angle_rad: float = quantity(
        math.radians(8.0), "rad", "least angle above the ground at which the tether leaves "
        "the winder", ge=0, lt=math.pi / 2)
    min_slack_m: float = quantity(
        0.05, "m", "least length above the straight-line distance, always", gt=0)


#: Width of the smooth maxima [m]: over this range the larger argument takes over.
SMOOTHING_A_M = 1.0
SMOOTHING_L_M = 0.02


def smooth_max(x: float, y: float, width: float) -> float:
    """A smooth maximum of ``x`` and ``y``: at least ``max(x, y)``, at most
    ``max(x, y) + width/2``, infinitely differentiable."""
    return 0.5 * (x + y + math.sqrt((x - y) ** 2 + width * width))


class LBar(NamedTuple):
    """Desired length, its rate and the catenary parameter used."""

    length_m: float
    rate_m_s: float
    a_m: float


def catenary_length_m(a_m: float, h_m: float, v_m: float) -> float:
    """Length of the catenary of parameter ``a_m`` spanning ``h_m`` across, ``v_m`` up [m]."""
    if h_m <= 0.0:
        return abs(v_m)
    x = h_m / (2.0 * a_m)
    if x > 350.0:  # sinh overflows; the tether would be impossibly long anyway
        return math.inf
    return math.hypot(v_m, 2.0 * a_m * math.sinh(x))


def exit_slope(a_m: float, h_m: float, v_m: float) -> float:
    """V_bottom / H: the tangent of the tether's angle above the ground at the exit."""
    x = h_m / (2.0 * a_m)
    length = catenary_length_m(a_m, h_m, v_m)
    return (v_m / math.tanh(x) - length) / (2.0 * a_m)


class LBarEstimator:
    """Desired tether length and its rate for a UAV position and velocity."""

    def __init__(self, params: LBarParams, w_n_m: float) -> None:
        self.p = params
        self.w = w_n_m
        self.a_target = params.target_horizontal_tension_n / w_n_m
        self._tan_min = math.tan(params.min_exit_angle_rad)

    def length(self, pos_m: tuple[float, float, float]) -> tuple[float, float]:
        """(L-bar [m], a [m]) for the UAV at ``pos_m``."""
        h = math.hypot(pos_m[0], pos_m[1])
        v = max(pos_m[2], 0.0)
        chord = math.hypot(h, v)
        if h < 1e-6:
            return v + self.p.min_slack_m, math.inf
        if v <= 0.0 or v / h <= self._tan_min:
            return chord + self.p.min_slack_m, math.inf
        a = self.a_target
        if exit_slope(a, h, v) < self._tan_min:
            a = self._a_for_exit_slope(h, v)
        # smooth maximum of the target and the exit-angle bound: never below either, and
        # no kink in L-bar where one takes over from the other (a kink is a step in
        # dL-bar/dt, i.e. a torque spike at the winder)
        a = smooth_max(a, self.a_target, SMOOTHING_A_M)
        length = catenary_length_m(a, h, v)
        return smooth_max(length, chord + self.p.min_slack_m, SMOOTHING_L_M), a

    def _a_for_exit_slope(self, h: float, v: float) -> float:
        lo = self.a_target
        hi = max(2.0 * lo, h)
        while exit_slope(hi, h, v) < self._tan_min and hi < 1e9:
            hi *= 2.0
        for _ in range(100):
            mid = 0.5 * (lo + hi)
            if exit_slope(mid, h, v) < self._tan_min:
                lo = mid
            else:
                hi = mid
            if hi - lo <= 1e-10 * hi:
                break
        return hi

    def estimate(self, pos_m: tuple[float, float, float],
                 vel_m_s: tuple[float, float, float]) -> LBar:
        """L-bar, its time derivative along the UAV's velocity (central differences of the
        length along the velocity direction, exact to O(step^2)), and the parameter a."""
        length, a = self.length(pos_m)
        speed = math.sqrt(sum(c * c for c in vel_m_s))
        if speed == 0.0:
            return LBar(length, 0.0, a)
        step = 1e-4  # [m] along the velocity direction
        u = [c / speed for c in vel_m_s]
        fwd = self.length(tuple(pos_m[i] + step * u[i] for i in range(3)))[0]
        back = self.length(tuple(pos_m[i] - step * u[i] for i in range(3)))[0]
        return LBar(length, speed * (fwd - back) / (2.0 * step), a)
