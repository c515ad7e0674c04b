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

The bisection's result is what the estimator commands, to its last bit (its 1e-10 relative
tolerance would otherwise show in dL-bar/dt, a difference quotient over 0.1 mm). To make it
cheap, Newton's method first finds the root of the smooth exit slope to near machine
precision; the bisection then runs unchanged, except that it compares its midpoints with
that root instead of evaluating the slope, wherever the comparison is certain (everywhere but
within a guard band around the root scaled by the slope's rounding error). The law is
compiled (``tuavdefs.jit``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from tuavdefs.jit import njit
from tuavdefs.paramspec import Params, quantity

# Named indices of the packed records L-bar's compiled steps take (LBarEstimator's
# trim_params, trim_state, packed, state), one name a field.
#: trim_params: the tension trim's, the weight estimate's, the stop lead's and the slack
#: floor's parameters, in LBarParams' units (TP_LEAD_TAN_MIN the tangent of its angle)
(TP_TRIM_RATE, TP_TRIM_MAX_RATE, TP_TRIM_MAX, TP_TRIM_BAND, TP_TRIM_FILTER,
 TP_WEIGHT_FILTER, TP_WEIGHT_RATIO, TP_WEIGHT_MIN_EL, TP_LEAD_TIME, TP_LEAD_ACC,
 TP_LEAD_MARGIN, TP_LEAD_FULL_SPEED, TP_LEAD_RATE, TP_LEAD_FILTER, TP_FLOOR, TP_FLOOR_RATE,
 TP_FLOOR_RELEASE, TP_FLOOR_FILTER, TP_LEAD_TAN_MIN, TP_FLOOR_TENSION_RATIO, TP_FLOOR_HOLD,
 TP_LEAD_MIN_SPEED, TP_LEAD_ONSET, TP_LEAD_RELEASE, TP_WEIGHT_MAX_GAIN,
 TP_LEAD_RISE) = range(26)
#: trim_state: the trim's offset [m] and rate [m/s], the low-passed drum tension [N], the
#: line weight [N/m], the stop lead [m], its rate [m/s], its filtered target [m], the slack
#: floor [m], its rate [m/s], its filtered needed length [m], the time without a fix [s],
#: the lead the need asks for before the ground's bound [m], the stop lead's room's
#: exit-angle root [m], the join's gap as the last period took it [m]
(TS_OFFSET, TS_OFFSET_RATE, TS_TENSION, TS_WEIGHT, TS_LEAD,
 TS_LEAD_RATE, TS_LEAD_TARGET, TS_FLOOR, TS_FLOOR_RATE, TS_FLOOR_NEED,
 TS_NO_FIX_S, TS_LEAD_NEED, TS_ROOM_ROOT, TS_JOIN_GAP) = range(14)
#: LBarEstimator.packed: the target catenary parameter a [m], the tangent of the least
#: exit angle, the least slack [m], the model's line weight [N/m]
LB_A_TARGET, LB_TAN_MIN, LB_MIN_SLACK, LB_W = range(4)
#: LBarEstimator.state: the last exit-angle root [m], where Newton starts next time
LS_ROOT = 0
N_LBAR_STATE = 1


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
    tension_trim_rate_m_s: float = quantity(
        2.0, "m/s", "tension trim: how fast extra tether is paid out (or taken back) per "
        "unit of ln(measured / expected drum tension) beyond the dead band, so the tether "
        "keeps its slack when the UAV's reported position is off (0: off)", ge=0)
    tension_trim_max_rate_m_s: float = quantity(
        0.2, "m/s", "tension trim: fastest change of the offset (it corrects a position "
        "error that grows over seconds; on a dynamic line, faster, it chased the load "
        "cell's snaps into a limit cycle)", gt=0)
    tension_trim_max_m: float = quantity(
        5.0, "m", "tension trim: largest offset either way", ge=0)
    tension_trim_band: float = quantity(
        0.1, "1", "tension trim: dead band of ln(measured / expected tension) within which "
        "the offset holds", ge=0)
    tension_trim_filter_s: float = quantity(
        0.5, "s", "tension trim: time constant of the low-pass on the measured drum tension "
        "it compares (0: none): the trim corrects a slow position error, not the tether's "
        "axial waves and snaps", ge=0)
    weight_filter_s: float = quantity(
        2.0, "s", "line weight estimate: time constant of its low-pass (docs/control.md §3)",
        gt=0)
    weight_ratio_max: float = quantity(
        3.0, "1", "line weight estimate: bounded to [1/ratio, ratio] times the model's "
        "weight per metre (1: the model's always)", ge=1)
    weight_min_exit_angle_rad: float = quantity(
        math.radians(2.0), "rad", "line weight estimate: held while the measured exit "
        "angle is below this (the line may lie on the ground)", ge=0, lt=math.pi / 2)
    weight_max_gain_1_m: float = quantity(
        0.5, "1/m", "line weight estimate: held where its sensitivity to the tension, "
        "2 z / (L^2 - z^2), exceeds this (near the vertical the estimate is ill-"
        "conditioned: a tenth of a newton reads as a fifth of the weight)", gt=0)
    stop_lead_time_s: float = quantity(
        0.6, "s", "stop lead: seconds of the UAV's speed it runs on before braking, when "
        "the drum stops (its reaction, the links' delays; docs/control.md §3)", ge=0)
    stop_lead_acc_m_s2: float = quantity(
        2.5, "m/s^2", "stop lead: the UAV's braking deceleration its stopping distance "
        "v^2/2a is allowed for (0: no stop lead; it works with the companion's tether "
        "governor, TUAV_TETH_GOV)", ge=0)
    stop_lead_margin_m: float = quantity(
        0.1, "m", "stop lead: slack kept beyond the stopping point's distance once the UAV "
        "moves outward at stop_lead_full_speed_m_s (in proportion below)", ge=0)
    stop_lead_full_speed_m_s: float = quantity(
        0.5, "m/s", "stop lead: outward speed from which the margin is kept in full",
        gt=0)
    stop_lead_min_speed_m_s: float = quantity(
        2.0, "m/s", "stop lead: once the UAV moves (in full from stop_lead_onset_m_s, in "
        "proportion below), its stop is allowed for at no less than this speed along its "
        "velocity: the lead pays out ahead of an acceleration, not only behind the speed "
        "(the vehicle's governor allows speed only with room; docs/control.md §3)", ge=0)
    stop_lead_onset_m_s: float = quantity(
        1.0, "m/s", "stop lead: speed from which stop_lead_min_speed_m_s holds in full",
        gt=0)
    stop_lead_rate_m_s: float = quantity(
        2.0, "m/s", "stop lead: fastest change of the lead (at 4 m/s the drum overshot a "
        "lead paid out to its bound by 0.2 m in 12-15 m/s winds, laying the line on the "
        "ground at the exit)", gt=0)
    stop_lead_release_m_s: float = quantity(
        0.3, "m/s", "stop lead: fastest taking back of the lead as the UAV slows (the "
        "ground's bound is followed at stop_lead_rate_m_s): the vehicle's governor counts "
        "on the reported length, and a lead wound in fast braked it as it slowed", gt=0)
    stop_lead_filter_s: float = quantity(
        0.05, "s", "stop lead: time constant of the low-pass on its target", ge=0)
    stop_lead_rise_m_s2: float = quantity(
        2.0, "m/s^2", "stop lead: its pay-out rate rises at most this fast from what it was "
        "(from 0 after a wind-in; it may fall, and a wind-in stop, at once; 0: at once). "
        "A step of its pay-out rate set the drum paying out faster than the line "
        "took it: on the dynamic (lumped) line the exit went slack and snapped taut when "
        "the slack ran out (circle-rtk: 69 N; the mission: 124 N, the rotors saturated "
        "3.9 % of the flight, 0.4 % with it)", ge=0)
    stop_lead_min_exit_angle_rad: float = quantity(
        math.radians(4.0), "rad", "stop lead: the lead is bounded so that the catenary at "
        "the reported position leaves the winder at least this far above the ground (the "
        "line off the ground); where that leaves less room than the stopping distance, "
        "the vehicle's tether governor slows it", ge=0, lt=math.pi / 2)
    slack_floor_m: float = quantity(
        0.03, "m", "slack floor: least slack (paid-out length less the distance to the "
        "UAV) as the winder measures it (its tether fix: length, tension, exit angles); "
        "below it (or tighter than slack_floor_tension_ratio), line is paid out whatever "
        "the UAV's reported position (0: off)", ge=0)
    slack_floor_tension_ratio: float = quantity(
        4.0, "1", "slack floor: the line is kept at least as long as the catenary through "
        "the fix's position whose horizontal tension is this many times "
        "target_horizontal_tension_n (a line much tighter than L-bar's pulls hard long "
        "before it is taut)", ge=1)
    slack_floor_rate_m_s: float = quantity(
        2.0, "m/s", "slack floor: fastest pay-out of the floor's extra length", gt=0)
    slack_floor_release_m_s: float = quantity(
        0.1, "m/s", "slack floor: fastest take-back of the floor's extra length, once the "
        "measured slack is above the floor again", gt=0)
    slack_floor_hold_s: float = quantity(
        0.5, "s", "slack floor: how long the last fix's need holds without a valid fix "
        "(the exit angle's frames late or lost) before the extra length is taken back",
        ge=0)
    slack_floor_filter_s: float = quantity(
        0.05, "s", "slack floor: time constant of the low-pass on the measured distance "
        "(the load cell's axial waves)", ge=0)


#: Width of the smooth maxima [m]: over this range the larger argument takes over.
SMOOTHING_A_M = 1.0
SMOOTHING_L_M = 0.02


@njit
def smooth_max(x: float, y: float, width: float) -> float:
    """A smooth maximum of ``x`` and ``y``: at least ``max(x, y)``, at most
    ``max(x, y) + width/2``, infinitely differentiable."""
    return 0.5 * (x + y + math.sqrt((x - y) ** 2 + width * width))


class LBar(NamedTuple):
    """Desired length, its rate and the catenary parameter used."""

    length_m: float
    rate_m_s: float
    a_m: float


@njit
def catenary_length_m(a_m: float, h_m: float, v_m: float) -> float:
    """Length of the catenary of parameter ``a_m`` spanning ``h_m`` across, ``v_m`` up [m]."""
    if h_m <= 0.0:
        return abs(v_m)
    x = h_m / (2.0 * a_m)
    if x > 350.0:  # sinh overflows; the tether would be impossibly long anyway
        return math.inf
    return math.hypot(v_m, 2.0 * a_m * math.sinh(x))


@njit
def exit_slope(a_m: float, h_m: float, v_m: float) -> float:
    """V_bottom / H: the tangent of the tether's angle above the ground at the exit."""
    x = h_m / (2.0 * a_m)
    length = catenary_length_m(a_m, h_m, v_m)
    return (v_m / math.tanh(x) - length) / (2.0 * a_m)


@njit
def _exit_slope_derivative(a_m: float, h_m: float, v_m: float) -> float:
    """d(exit_slope)/da: with x = h/2a, S = 2a sinh x, L = sqrt(v^2 + S^2),
    dS/da = 2 (sinh x - x cosh x), d(coth x)/da = x / (a sinh^2 x), and
    d/da [(v coth x - L) / 2a] = (d(v coth x - L)/da - 2 slope) / 2a."""
    x = h_m / (2.0 * a_m)
    sh = math.sinh(x)
    s_len = 2.0 * a_m * sh
    length = math.hypot(v_m, s_len)
    dl = s_len * 2.0 * (sh - x * math.cosh(x)) / length
    slope = (v_m / math.tanh(x) - length) / (2.0 * a_m)
    return (v_m * x / (a_m * sh * sh) - dl - 2.0 * slope) / (2.0 * a_m)


@njit
def _exit_slope_root(h: float, v: float, tan_min: float, lo: float, guess: float
                     ) -> tuple[float, float]:
    """(a, guard): the root of exit_slope(a) = tan_min above ``lo`` (where the slope is
    below it) by Newton's method from ``guess``, safeguarded by bisection, and the distance
    from it beyond which the sign of exit_slope - tan_min as computed is certain;
    (nan, inf) if it does not converge."""
    hi = math.inf
    a = guess if lo < guess < math.inf else 2.0 * lo
    for _ in range(100):
        f = exit_slope(a, h, v) - tan_min
        if not math.isfinite(f):
            if f > 0.0:
                break
            lo = a
            a = 2.0 * a if hi == math.inf else 0.5 * (lo + hi)
            continue
        if f < 0.0:
            lo = a
        else:
            hi = a
        df = _exit_slope_derivative(a, h, v)
        a_new = a - f / df
        if not lo < a_new < hi:
            a_new = 2.0 * a if hi == math.inf else 0.5 * (lo + hi)
        x = h / (2.0 * a_new)
        # rounding error of the computed slope near a_new, as a distance in a
        noise = (16.0 * 2.2e-16 * (abs(v / math.tanh(x)) + catenary_length_m(a_new, h, v))
                 / (2.0 * a_new) / df)
        if abs(a_new - a) <= 1e-14 * a_new + noise:
            guard = 1e-12 * a_new + 64.0 * noise
            if math.isfinite(guard) and guard > 0.0:
                return a_new, guard
            break
        a = a_new
    return math.nan, math.inf


@njit
def _below(a: float, h: float, v: float, tan_min: float, root: float, guard: float) -> bool:
    """exit_slope(a) < tan_min, decided by the side of ``root`` that ``a`` is on where it
    is at least ``guard`` away from it, and by evaluating the slope elsewhere."""
    if abs(a - root) > guard:
        return a < root
    return exit_slope(a, h, v) < tan_min


@njit
def _a_for_exit_slope(h: float, v: float, a_target: float, tan_min: float, root: float,
                      guard: float) -> float:
    """The least a >= a_target with exit_slope(a) >= tan_min, by bisection to 1e-10
    relative (``root``, ``guard`` from :func:`_exit_slope_root` spare evaluations)."""
    lo = a_target
    hi = max(2.0 * lo, h)
    while _below(hi, h, v, tan_min, root, guard) and hi < 1e9:
        hi *= 2.0
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        if _below(mid, h, v, tan_min, root, guard):
            lo = mid
        else:
            hi = mid
        if hi - lo <= 1e-10 * hi:
            break
    return hi


@njit
def _length(x: float, y: float, z: float, a_target: float, tan_min: float,
            min_slack: float, guess: float) -> tuple[float, float, float]:
    """:meth:`LBarEstimator.length` in scalars: (L-bar, a, the exit-angle root found or
    ``guess``), ``guess`` a starting point for that root's Newton iteration."""
    h = math.hypot(x, y)
    v = max(z, 0.0)
    chord = math.hypot(h, v)
    if h < 1e-6:
        return v + min_slack, math.inf, guess
    if v <= 0.0 or v / h <= tan_min:
        return chord + min_slack, math.inf, guess
    a = a_target
    if exit_slope(a, h, v) < tan_min:
        root, guard = _exit_slope_root(h, v, tan_min, a_target, guess)
        a = _a_for_exit_slope(h, v, a_target, tan_min, root, guard)
        if math.isfinite(root):
            guess = root
    # smooth maximum of the target and the exit-angle bound: never below either, and
    # no kink in L-bar where one takes over from the other (a kink is a step in
    # dL-bar/dt, i.e. a torque spike at the winder)
    a = smooth_max(a, a_target, SMOOTHING_A_M)
    length = catenary_length_m(a, h, v)
    return smooth_max(length, chord + min_slack, SMOOTHING_L_M), a, guess


@njit
def lbar_kernel(px: float, py: float, pz: float, vx: float, vy: float, vz: float,
              a_target: float, tan_min: float, min_slack: float, guess: float
              ) -> tuple[float, float, float, float]:
    """:meth:`LBarEstimator.estimate` in scalars: (L-bar, its rate, a, root guess)."""
    length, a, guess = _length(px, py, pz, a_target, tan_min, min_slack, guess)
    speed = math.sqrt(vx * vx + vy * vy + vz * vz)
    if speed == 0.0:
        return length, 0.0, a, guess
    step = 1e-4  # [m] along the velocity direction
    ux, uy, uz = vx / speed, vy / speed, vz / speed
    fwd, _, guess = _length(px + step * ux, py + step * uy, pz + step * uz, a_target,
                            tan_min, min_slack, guess)
    back, _, guess = _length(px - step * ux, py - step * uy, pz - step * uz, a_target,
                             tan_min, min_slack, guess)
    return length, speed * (fwd - back) / (2.0 * step), a, guess


@njit
def expected_drum_tension_n(a_m: float, h_m: float, v_m: float, w_n_m: float) -> float:
    """The tension [N] at the winder's exit of the inelastic catenary of parameter ``a_m``
    [m] spanning ``h_m`` across and ``v_m`` up [m], weighing ``w_n_m`` [N/m]:
    H sqrt(1 + s^2), H = w a, s the exit slope; NaN where the catenary is degenerate
    (vertical, or a infinite)."""
    if not (math.isfinite(a_m) and h_m > 1e-6):
        return math.nan
    slope = exit_slope(a_m, h_m, v_m)
    return w_n_m * a_m * math.sqrt(1.0 + slope * slope)


@njit
def line_weight_n_m(tension_n: float, elevation_rad: float, length_m: float,
                    height_m: float) -> float:
    """The weight per metre [N/m] of an inextensible line hanging clear of the ground from
    the exit (tension ``tension_n`` [N] leaving at ``elevation_rad`` above the horizontal)
    to a point ``height_m`` [m] up along ``length_m`` [m] of line; NaN where it does not
    say (a straight or vertical line, no tension). The top tension exceeds the exit's by
    w z, and the vertical tension grows by w per metre of line: with H = T cos(el),
    V = T sin(el), (T + w z)^2 = H^2 + (V + w L)^2 gives w = 2 (z T - V L) / (L^2 - z^2)."""
    den = length_m * length_m - height_m * height_m
    if not (tension_n > 0.0 and den > 1e-6 * length_m * length_m and height_m > 0.0):
        return math.nan
    return 2.0 * (height_m * tension_n - tension_n * math.sin(elevation_rad) * length_m) / den


@njit
def weight_estimate(trim_p: np.ndarray, trim_s: np.ndarray, dt_s: float, w_n_m: float,
                    tension_n: float, elevation_rad: float, length_m: float,
                    height_m: float) -> float:
    """One period of the line's weight estimate (docs/control.md §3): the low-passed
    (``trim_p[TP_WEIGHT_FILTER]`` [s]) :func:`line_weight_n_m` of the trim's filtered drum
    tension ``trim_s[TS_TENSION]`` (before its first sample: ``tension_n`` [N], the one
    measured now), the measured exit elevation, the paid-out length and the UAV's reported
    height, bounded to [1/r, r] times the model's ``w_n_m`` (r =
    ``trim_p[TP_WEIGHT_RATIO]``), held while the exit angle is below
    ``trim_p[TP_WEIGHT_MIN_EL]`` or unknown (NaN), or where the estimate's sensitivity to
    the tension 2 z / (L^2 - z^2) exceeds ``trim_p[TP_WEIGHT_MAX_GAIN]`` [1/m] (near the
    vertical). Its state is ``trim_s[TS_WEIGHT]`` (NaN: no estimate yet); returns the weight
    to use [N/m] (the model's until there is one)."""
    r, w_hat = trim_p[TP_WEIGHT_RATIO], trim_s[TS_WEIGHT]
    den = length_m * length_m - height_m * height_m
    if (elevation_rad >= trim_p[TP_WEIGHT_MIN_EL]          # (not NaN)
            and 2.0 * height_m <= trim_p[TP_WEIGHT_MAX_GAIN] * den):
        t = trim_s[TS_TENSION] if trim_s[TS_TENSION] == trim_s[TS_TENSION] else tension_n
        w = line_weight_n_m(t, elevation_rad, length_m, height_m)
        if w == w:
            w = min(max(w, w_n_m / r), w_n_m * r)
            if w_hat == w_hat:
                w_hat += (1.0 - math.exp(-dt_s / trim_p[TP_WEIGHT_FILTER])) * (w - w_hat)
            else:
                w_hat = w
            trim_s[TS_WEIGHT] = w_hat
    return w_hat if w_hat == w_hat else w_n_m


@njit
def tension_trim(trim_p: np.ndarray, trim_s: np.ndarray, dt_s: float, a_m: float, px: float,
                 py: float, pz: float, w_n_m: float, tension_n: float) -> None:
    """One period of the tension trim (docs/control.md §3): the extra length ``trim_s[TS_OFFSET]``
    [m] paid out beyond L-bar, and its rate ``trim_s[TS_OFFSET_RATE]`` [m/s].

    With e = ln(T / T_expected), T the drum tension measured and T_expected the model
    catenary's (parameter ``a_m`` [m]) for the reported position (``px``, ``py``, ``pz``
    [m]): beyond the dead band ``band`` the extra length
    grows at ``rate (e - band)`` (the tether is tighter than the model says: the UAV is
    farther than reported), and below ``-band`` shrinks at ``rate (e + band)``, never
    below 0 (never less tether than L-bar), at most ``offset_max``, at most ``rate_max``
    fast; held where the catenary is degenerate or the tension unknown. T is the measured
    tension low-passed (time constant ``filter`` [s], its state ``trim_s[TS_TENSION]`` [N], NaN
    before the first sample). ``trim_p`` = (rate [m/s], rate_max [m/s], offset_max [m],
    band, filter [s])."""
    gain, rate_max = trim_p[TP_TRIM_RATE], trim_p[TP_TRIM_MAX_RATE]
    offset_max, band = trim_p[TP_TRIM_MAX], trim_p[TP_TRIM_BAND]
    if tension_n >= 0.0:          # (not NaN)
        tau = trim_p[TP_TRIM_FILTER]
        if tau > 0.0 and trim_s[TS_TENSION] == trim_s[TS_TENSION]:
            trim_s[TS_TENSION] += (1.0 - math.exp(-dt_s / tau)) * (tension_n - trim_s[TS_TENSION])
        else:
            trim_s[TS_TENSION] = tension_n
    tension_n = trim_s[TS_TENSION]
    expected = expected_drum_tension_n(a_m, math.hypot(px, py), max(pz, 0.0), w_n_m)
    rate = 0.0
    if gain > 0.0 and expected > 0.0 and tension_n > 0.0:
        e = math.log(tension_n / expected)
        if e > band:
            rate = gain * (e - band)
        elif e < -band:
            rate = gain * (e + band)
        rate = min(max(rate, -rate_max), rate_max)
    offset = trim_s[TS_OFFSET] + rate * dt_s
    if offset < 0.0:
        offset, rate = 0.0, 0.0
    elif offset > offset_max:
        offset, rate = offset_max, 0.0
    trim_s[TS_OFFSET] = offset
    trim_s[TS_OFFSET_RATE] = rate


@njit
def stop_lead(trim_p: np.ndarray, trim_s: np.ndarray, dt_s: float, px: float, py: float,
              pz: float, vx: float, vy: float, vz: float, base_m: float, room_m: float,
              elevation_rad: float) -> None:
    """One period of the stop lead (docs/control.md §3): the extra length ``trim_s[TS_LEAD]``
    [m] paid out beyond the reference ``base_m`` [m] (L-bar and the trim) while the UAV
    moves, and its rate ``trim_s[TS_LEAD_RATE]`` [m/s].

    Should the drum stop (a snag, a brake, a lost bus) the UAV at (``px``, ``py``, ``pz``)
    [m] moving at (``vx``, ``vy``, ``vz``) [m/s] runs on ``s = v t + v^2 / 2a`` along its
    velocity before it is stopped, ``v`` here at least ``v_floor min(1, |v| / v_on)``
    (``trim_p[21:23]`` [m/s]: the lead pays out ahead of the vehicle's acceleration, not
    behind its speed). The lead is what the line lacks for that: the stopping point's
    distance from the winder, plus ``margin min(1, v_out / v_full)`` (v_out the outward
    speed), less ``base_m`` (the slack L-bar already has counts); never negative. That
    target is low-passed (time constant ``trim_p[TP_LEAD_FILTER]`` [s], into
    ``trim_s[TS_LEAD_TARGET]``) and followed (into ``trim_s[TS_LEAD_NEED]``) at most
    ``trim_p[TP_LEAD_RATE]`` [m/s] out and ``trim_p[TP_LEAD_RELEASE]``
    [m/s] back; the lead is that, at most ``room_m`` [m] (the longest line that stays off
    the ground, less ``base_m``: where the room is smaller than the stop, the vehicle's
    governor slows it), followed at most ``trim_p[TP_LEAD_RATE]`` [m/s] fast, its pay-out
    rate rising
    at most ``trim_p[TP_LEAD_RISE]`` [m/s^2] from what it was, from 0 after a wind-in (0: at once;
    it may fall at once), and not lengthened
    while the line's measured exit elevation ``elevation_rad`` [rad] (NaN: none) is below
    the bound's angle ``atan(trim_p[TP_LEAD_TAN_MIN])`` (the room is the reported
    position's; near the
    ground or the vertical a report centimetres off is the line on the ground).
    ``trim_p[8:12]`` = (t [s], a [m/s^2], margin [m], v_full [m/s]); a = 0 switches it
    off."""
    t_lead, acc = trim_p[TP_LEAD_TIME], trim_p[TP_LEAD_ACC]
    margin, v_full = trim_p[TP_LEAD_MARGIN], trim_p[TP_LEAD_FULL_SPEED]
    if not acc > 0.0:
        trim_s[TS_LEAD], trim_s[TS_LEAD_RATE], trim_s[TS_LEAD_NEED] = 0.0, 0.0, 0.0
        return
    d = math.sqrt(px * px + py * py + pz * pz)
    speed = math.sqrt(vx * vx + vy * vy + vz * vz)
    target = 0.0
    if speed > 0.0 and d > 0.0:
        # the speed the stop is allowed for: at least the floor once moving
        v_eff = max(speed, trim_p[TP_LEAD_MIN_SPEED] * min(1.0, speed / trim_p[TP_LEAD_ONSET]))
        run = (v_eff * t_lead + v_eff * v_eff / (2.0 * acc)) / speed
        sx, sy, sz = px + vx * run, py + vy * run, pz + vz * run
        v_out = (px * vx + py * vy + pz * vz) / d * v_eff / speed
        need = (max(math.sqrt(sx * sx + sy * sy + sz * sz), d)
                + margin * min(1.0, max(v_out, 0.0) / v_full) - base_m)
        target = max(need, 0.0)
    tau = trim_p[TP_LEAD_FILTER]
    if tau > 0.0:
        trim_s[TS_LEAD_TARGET] += (1.0 - math.exp(-dt_s / tau)) * (target - trim_s[TS_LEAD_TARGET])
    else:
        trim_s[TS_LEAD_TARGET] = target
    # the lead the need asks for (trim_s[TS_LEAD_NEED]): out at most trim_p[TP_LEAD_RATE],
    # back at most trim_p[TP_LEAD_RELEASE] [m/s]; then bounded by the ground's room
    # (followed at trim_p[TP_LEAD_RATE])
    step = trim_s[TS_LEAD_TARGET] - trim_s[TS_LEAD_NEED]
    step = min(max(step, -trim_p[TP_LEAD_RELEASE] * dt_s), trim_p[TP_LEAD_RATE] * dt_s)
    trim_s[TS_LEAD_NEED] += step
    bound = max(room_m, 0.0) if room_m == room_m else 0.0
    step = min(trim_s[TS_LEAD_NEED], bound) - trim_s[TS_LEAD]
    most = trim_p[TP_LEAD_RATE] * dt_s
    step = min(max(step, -most), most)
    if elevation_rad < math.atan(trim_p[TP_LEAD_TAN_MIN]):      # the winder's own reading (not NaN)
        step = min(step, 0.0)
    if trim_p[TP_LEAD_RISE] > 0.0:
        # (from a wind-in the pay-out starts at 0: stopping a wind-in is at once)
        step = min(step, (max(trim_s[TS_LEAD_RATE], 0.0) + trim_p[TP_LEAD_RISE] * dt_s) * dt_s)
    trim_s[TS_LEAD] += step
    trim_s[TS_LEAD_RATE] = step / dt_s


@njit
def slack_floor(trim_p: np.ndarray, trim_s: np.ndarray, dt_s: float, base_m: float,
                needed_m: float) -> None:
    """One period of the slack floor (docs/control.md §3): the extra length
    ``trim_s[TS_FLOOR]`` [m] paid out beyond the reference ``base_m`` [m] (L-bar, trim and
    lead) so that the line is never shorter than ``needed_m`` [m], the length the winder's
    own measurements ask for (:func:`floor_length_m` at its tether fix; NaN: no valid fix
    now: the last one holds for ``trim_p[TP_FLOOR_HOLD]`` [s], ``trim_s[TS_NO_FIX_S]``
    counting, then the floor is taken back), whatever the UAV's reported position; its rate
    ``trim_s[TS_FLOOR_RATE]`` [m/s]. The needed length is low-passed
    (``trim_p[TP_FLOOR_FILTER]`` [s], into ``trim_s[TS_FLOOR_NEED]``); the extra length
    grows at most ``trim_p[TP_FLOOR_RATE]`` and shrinks at most ``trim_p[TP_FLOOR_RELEASE]``
    [m/s], never below 0. ``trim_p[TP_FLOOR]`` (the least slack) 0 switches it off."""
    if not trim_p[TP_FLOOR] > 0.0:
        trim_s[TS_FLOOR], trim_s[TS_FLOOR_RATE] = 0.0, 0.0
        return
    if needed_m == needed_m:
        tau = trim_p[TP_FLOOR_FILTER]
        if tau > 0.0 and trim_s[TS_FLOOR_NEED] == trim_s[TS_FLOOR_NEED]:
            trim_s[TS_FLOOR_NEED] += ((1.0 - math.exp(-dt_s / tau))
                                      * (needed_m - trim_s[TS_FLOOR_NEED]))
        else:
            trim_s[TS_FLOOR_NEED] = needed_m
        trim_s[TS_NO_FIX_S] = 0.0
    else:
        trim_s[TS_NO_FIX_S] += dt_s
        if trim_s[TS_NO_FIX_S] > trim_p[TP_FLOOR_HOLD]:
            trim_s[TS_FLOOR_NEED] = math.nan
    need = trim_s[TS_FLOOR_NEED]
    target = max(need - base_m, 0.0) if need == need else 0.0
    step = min(max(target - trim_s[TS_FLOOR], -trim_p[TP_FLOOR_RELEASE] * dt_s),
               trim_p[TP_FLOOR_RATE] * dt_s)
    trim_s[TS_FLOOR] += step
    trim_s[TS_FLOOR_RATE] = step / dt_s


@njit
def floor_length_m(fx: float, fy: float, fz: float, a_floor: float, floor_m: float
                   ) -> float:
    """The least length [m] the slack floor keeps for the UAV at (``fx``, ``fy``, ``fz``)
    [m] as the winder's own tether fix places it: the distance plus ``floor_m`` [m], and
    at least the catenary of parameter ``a_floor`` [m] through it (the line no tighter
    than a horizontal tension ``a_floor`` w: a line much tighter than L-bar's pulls hard
    long before it is taut); NaN without a fix."""
    if not (fx == fx and fy == fy and fz == fz):
        return math.nan
    chord = math.sqrt(fx * fx + fy * fy + fz * fz)
    return max(chord + floor_m, catenary_length_m(a_floor, math.hypot(fx, fy), fz))


def initial_trim_state() -> np.ndarray:
    """The trim's, the lead's and the floor's state before the first period (see
    :attr:`LBarEstimator.trim_state`)."""
    return np.array([0.0, 0.0, math.nan, math.nan, 0.0, 0.0, 0.0, 0.0, 0.0, math.nan,
                     0.0, 0.0, math.nan, 0.0])


@njit
def lead_room_m(px: float, py: float, pz: float, tan_min: float, min_slack: float) -> float:
    """The longest line [m] from the winder to the UAV at (``px``, ``py``, ``pz``) [m]
    whose catenary still leaves the winder at least ``tan_min`` (tangent) above the ground:
    the most the stop lead may pay out to (``chord + min_slack`` where the chord itself is
    flatter, or vertical)."""
    return lead_room_from(px, py, pz, tan_min, min_slack, math.nan)[0]


@njit
def lead_room_from(px: float, py: float, pz: float, tan_min: float, min_slack: float,
                   guess: float) -> tuple[float, float]:
    """:func:`lead_room_m` with its exit-angle root's Newton iteration started at
    ``guess`` (NaN: none): (the room [m], the root, for the next call's guess). From the
    last period's root it converges in a few steps."""
    if math.isnan(guess):
        # not from 2 mm: Newton crawls up sinh's exponential flank from there and gives
        # up after its 100 steps (bisection then finds the bound, at about 8 us)
        guess = max(math.hypot(px, py), 2e-3)
    room, _, root = _length(px, py, pz, 1e-3, tan_min, min_slack, guess)
    return room, root


class LBarEstimator:
    """Desired tether length and its rate for a UAV position and velocity."""

    def __init__(self, params: LBarParams, w_n_m: float) -> None:
        self.p = params
        self.w = w_n_m
        self.a_target = params.target_horizontal_tension_n / w_n_m
        #: L-bar's parameters as the compiled steps take them (indices LB_*)
        self.packed = np.array([self.a_target, math.tan(params.min_exit_angle_rad),
                                params.min_slack_m, w_n_m])
        #: what one estimate leaves the next (indices LS_*): the exit-angle root
        self.state = np.full(N_LBAR_STATE, math.nan)
        #: the tension trim's parameters and state (:func:`tension_trim`)
        self.trim_params = np.array([params.tension_trim_rate_m_s,
                                     params.tension_trim_max_rate_m_s,
                                     params.tension_trim_max_m, params.tension_trim_band,
                                     params.tension_trim_filter_s,
                                     params.weight_filter_s, params.weight_ratio_max,
                                     params.weight_min_exit_angle_rad,
                                     params.stop_lead_time_s, params.stop_lead_acc_m_s2,
                                     params.stop_lead_margin_m,
                                     params.stop_lead_full_speed_m_s,
                                     params.stop_lead_rate_m_s, params.stop_lead_filter_s,
                                     params.slack_floor_m, params.slack_floor_rate_m_s,
                                     params.slack_floor_release_m_s,
                                     params.slack_floor_filter_s,
                                     math.tan(params.stop_lead_min_exit_angle_rad),
                                     params.slack_floor_tension_ratio,
                                     params.slack_floor_hold_s,
                                     params.stop_lead_min_speed_m_s,
                                     params.stop_lead_onset_m_s,
                                     params.stop_lead_release_m_s,
                                     params.weight_max_gain_1_m,
                                     params.stop_lead_rise_m_s2])
        #: (offset [m], its rate [m/s], filtered drum tension [N], line weight [N/m],
        #: stop lead [m], its rate [m/s], its filtered target [m], slack floor [m], its
        #: rate [m/s], its filtered needed length [m], the time without a fix [s], the
        #: lead the need asks for before the ground's bound [m], the stop lead's room's
        #: exit-angle root [m]: where its Newton iteration starts next period, the join's
        #: gap as the last period took it [m] (groundstation.winder_host.winder_step))
        self.trim_state = initial_trim_state()

    @property
    def join_gap_m(self) -> float:
        """The join's gap [m] as the last step took it (what a reference falling into it
        left of it; :func:`winder_step <groundstation.winder_host.winder_step>`)."""
        return float(self.trim_state[TS_JOIN_GAP])

    def weight_n_m(self) -> float:
        """The line's weight per metre [N/m]: the estimate (:func:`weight_estimate`) once
        there is one, else the model's."""
        w = float(self.trim_state[TS_WEIGHT])
        return w if math.isfinite(w) else self.w

    @property
    def estimated_weight_n_m(self) -> float:
        """The line's weight per metre [N/m] as :func:`weight_estimate` holds it, NaN before
        it has one (what the winch sends the vehicle with each raw reading)."""
        return float(self.trim_state[TS_WEIGHT])

    def drum_tension_n(self, measured_n: float) -> float:
        """The drum tension [N] as the tension trim low-passes it (:func:`tension_trim`),
        ``measured_n`` before its first sample."""
        t = float(self.trim_state[TS_TENSION])
        return t if math.isfinite(t) else measured_n

    def floor_need_m(self, fix_m: tuple[float, float, float] | None) -> float:
        """The least length [m] the slack floor asks at the winder's own fix ``fix_m``
        [m] (:func:`floor_length_m` on the parameters :func:`winder_step
        <groundstation.winder_host.winder_step>` gives it); NaN without a fix or with the
        floor off."""
        tp = self.trim_params
        if fix_m is None or not tp[TP_FLOOR] > 0.0:
            return math.nan
        return floor_length_m(fix_m[0], fix_m[1], fix_m[2],
                              tp[TP_FLOOR_TENSION_RATIO] * self.a_target, tp[TP_FLOOR])

    def length(self, pos_m: tuple[float, float, float]) -> tuple[float, float]:
        """(L-bar [m], a [m]) for the UAV at ``pos_m``."""
        x, y, z = pos_m
        lp, ls = self.packed, self.state
        length, a, ls[LS_ROOT] = _length(x, y, z, lp[LB_A_TARGET], lp[LB_TAN_MIN],
                                         lp[LB_MIN_SLACK], ls[LS_ROOT])
        return length, a

    def estimate(self, pos_m: tuple[float, float, float],
                 vel_m_s: tuple[float, float, float]) -> LBar:
        """L-bar, its time derivative along the UAV's velocity (central differences of the
        length along the velocity direction, exact to O(step^2)), and the parameter a."""
        x, y, z = pos_m
        vx, vy, vz = vel_m_s
        lp, ls = self.packed, self.state
        length, rate, a, ls[LS_ROOT] = lbar_kernel(x, y, z, vx, vy, vz, lp[LB_A_TARGET],
                                                   lp[LB_TAN_MIN], lp[LB_MIN_SLACK],
                                                   ls[LS_ROOT])
        return LBar(length, rate, a)
