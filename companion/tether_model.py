"""The companion's own model of the tether's pull, from what the vehicle knows.

Inputs are what a real vehicle has: its own position, the paid-out length the winder
reports, and (optionally) the tension the winder's load cell measures at the drum. The
model is deliberately simpler than the plant's: an **inextensible** catenary over a
frictionless flat ground (the plant's is elastic, and its solver is not shared).

For an inextensible line over a frictionless ground, the tension grows by exactly ``w``
per metre of height whatever the regime (suspended, touching down, slack), so the
measured drum tension gives the top tension magnitude directly: ``T_top = T_drum + w z``.
The length-based shape gives the direction of the pull. Without a measurement the
magnitude comes from the shape as well.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from tuavdefs.jit import njit, vec


class TetherEstimate(NamedTuple):
    """The modelled pull of the tether on the UAV (inertial z-up frame)."""

    force_n: tuple[float, float, float]
    horizontal_tension_n: float
    top_vertical_tension_n: float
    regime: str  # "suspended", "touchdown", "slack", "vertical", "taut"


#: Time constant of the low-pass on the reported tension [s]: the feed-forward is for the
#: tether's quasi-static pull; a dynamic tether's axial waves and snaps (0 to 20 N at
#: 20-25 Hz at the drum) fed forward as they come saturate the rotors.
TENSION_FILTER_S = 0.1


class WinchReport:
    """The latest report of the winch (length, line speed, tension), extrapolated to the
    control loop's time: reports arrive slower than the loop runs, and a stale length
    beside a fresh position makes the catenary estimate jump at every report. The tension
    is low-passed (``filter_s`` [s], over the time between reports)."""

    def __init__(self, filter_s: float = TENSION_FILTER_S) -> None:
        self.t_s: float | None = None
        self.length_m = 0.0
        self.speed_m_s = 0.0
        self.tension_n: float | None = None
        self.filter_s = filter_s

    def update(self, t_s: float, length_m: float, speed_m_s: float,
               tension_n: float | None) -> None:
        """A new report at ``t_s`` [s]: length [m], speed [m/s, + paying out], tension [N]."""
        last_t, last = self.t_s, self.tension_n
        if (tension_n is not None and last is not None and last_t is not None
                and t_s > last_t and self.filter_s > 0.0):
            tension_n = last + (1.0 - math.exp((last_t - t_s) / self.filter_s)) * (
                tension_n - last)
        self.t_s, self.length_m, self.speed_m_s, self.tension_n = (
            t_s, length_m, speed_m_s, tension_n)

    def length_at(self, t_s: float, max_age_s: float = 0.5) -> float:
        """Paid-out length at ``t_s`` [m], extrapolated at the reported speed (for at most
        ``max_age_s``: an old report is not extrapolated further)."""
        if self.t_s is None:
            return self.length_m
        # min(max(age, 0.0), max_age_s), without the calls: it runs at every period
        age = t_s - self.t_s
        if age < 0.0:
            age = 0.0
        if max_age_s < age:
            age = max_age_s
        return self.length_m + self.speed_m_s * age


class TetherModel:
    """Inextensible catenary of weight ``w_n_m`` [N/m] between the winder exit (origin) and
    the UAV, with a frictionless ground at the exit's level."""

    #: The type of :attr:`packed` (:class:`tuavdefs.jit.Signature` texts).
    RECORD = vec(2)

    def __init__(self, w_n_m: float, taut_stiffness_n: float = 1.0e5) -> None:
        if not w_n_m > 0:
            raise ValueError("w_n_m: must be > 0")
        self.w = w_n_m
        self.taut_stiffness_n = taut_stiffness_n  # EA used only if the line is taut

    @property
    def packed(self) -> tuple[float, float]:
        """This model for a compiled step (:attr:`RECORD`): the line's weight [N/m] and
        the stiffness used when it is taut [N]."""
        return self.w, self.taut_stiffness_n

    def estimate(self, pos_m: tuple[float, float, float], length_m: float,
                 drum_tension_n: float | None = None) -> TetherEstimate:
        """The pull on the UAV at ``pos_m`` with ``length_m`` paid out [N]."""
        x, y, z = pos_m
        measured = drum_tension_n is not None
        fx, fy, fz, hz, v_top, regime = estimate_kernel(
            self.w, self.taut_stiffness_n, x, y, z, length_m, measured,
            drum_tension_n if measured else 0.0)
        return TetherEstimate((fx, fy, fz), hz, v_top, _REGIMES[regime])


_REGIMES = ("slack", "taut", "vertical", "suspended", "touchdown")


@njit
def estimate_kernel(w: float, taut_stiffness_n: float, x: float, y: float, z: float,
              length_m: float, measured: bool, drum_tension_n: float
              ) -> tuple[float, float, float, float, float, int]:
    """:meth:`TetherModel.estimate` in scalars: (force, horizontal tension, top vertical
    tension, index into ``_REGIMES``); ``measured`` says whether ``drum_tension_n`` is."""
    z = max(z, 0.0)
    h = math.hypot(x, y)
    if not (length_m > 0 and math.isfinite(length_m)):
        return 0.0, 0.0, 0.0, 0.0, 0.0, 0                                  # slack
    chord = math.hypot(h, z)
    if length_m <= chord:
        # taut: a straight spring along the chord
        t = taut_stiffness_n * (chord - length_m) / length_m + w * z
        if measured:
            t = drum_tension_n + w * z
        if chord == 0.0:
            return 0.0, 0.0, 0.0, 0.0, 0.0, 1                              # taut
        return -t * x / chord, -t * y / chord, -t * z / chord, t * h / chord, t * z / chord, 1
    if length_m >= h + z or h < 1e-9:
        # slack (or vertical): hangs straight down from the UAV, the rest lies flat
        v_top = w * min(z, length_m)
        return 0.0, 0.0, -v_top, 0.0, v_top, 2 if h < 1e-9 else 0
    a = _suspended_parameter(h, z, length_m)
    v_top = 0.5 * w * (length_m + z / math.tanh(h / (2.0 * a)))
    regime = 3                                                              # suspended
    if v_top - w * length_m < 0.0:
        a = _touchdown_parameter(h, z, length_m)
        v_top = w * math.sqrt(z * z + 2.0 * a * z)
        regime = 4                                                          # touchdown
    hz = w * a
    if measured and drum_tension_n >= 0.0:
        t_model = math.hypot(hz, v_top)
        scale = (drum_tension_n + w * z) / t_model
        hz, v_top = hz * scale, v_top * scale
    return -hz * x / h, -hz * y / h, -v_top, hz, v_top, regime


@njit
def _suspended_parameter(h: float, v: float, length: float) -> float:
    """Catenary parameter a [m] with sqrt(v^2 + (2 a sinh(h/2a))^2) = length (Newton on
    u = h/(2a), solving sinh(u)/u = sqrt(length^2 - v^2)/h)."""
    r = math.sqrt(length * length - v * v) / h
    # initial guess from sinh(u)/u ~ 1 + u^2/6 for small u, log for large
    u = math.sqrt(6.0 * (r - 1.0)) if r < 3.0 else math.log(2.0 * r * math.log(2.0 * r) + 1.0)
    u = max(u, 1e-6)
    for _ in range(50):
        s, c = math.sinh(u), math.cosh(u)
        f = s / u - r
        df = (c * u - s) / (u * u)
        step = f / df
        u_new = u - step
        if u_new <= 0.0:
            u_new = 0.5 * u
        if abs(u_new - u) <= 1e-13 * u:
            u = u_new
            break
        u = u_new
    return h / (2.0 * u)


@njit
def _touchdown_residual(a: float, h: float, v: float, length: float) -> float:
    """length - sqrt(v^2 + 2 a v) + a acosh(1 + v/a) - h: zero at the touchdown parameter."""
    return length - math.sqrt(v * v + 2.0 * a * v) + a * math.acosh(1.0 + v / a) - h


@njit
def _touchdown_parameter(h: float, v: float, length: float) -> float:
    """Catenary parameter a [m] of a line lying on a frictionless ground from the exit and
    rising to the UAV: h = length - sqrt(v^2 + 2 a v) + a acosh(1 + v/a) (bisection)."""
    lo, hi = 1e-9, 1.0
    # the residual grows from (length - v) - h < 0 ... as a rises
    while _touchdown_residual(hi, h, v, length) < 0.0 and hi < 1e9:
        hi *= 2.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if _touchdown_residual(mid, h, v, length) < 0.0:
            lo = mid
        else:
            hi = mid
        if hi - lo <= 1e-12 * hi:
            break
    return 0.5 * (lo + hi)
