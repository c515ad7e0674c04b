"""Tests of companion.planner, companion.reference and companion.legs: reference trajectories
and the waypoint follower.

Derivatives are checked independently by central finite differences of the returned
position, velocity and acceleration; continuity by sampling either side of every knot;
limits over fine time grids. The checkers themselves are shown to fail on faulty input.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from companion.legs import (
    CircleItem,
    GotoItem,
    LegFollower,
    LegPhase,
)
from companion.planner import (
    _BISECT_RTOL,
    QUINTIC_PEAK_ACC,
    QUINTIC_PEAK_SPEED,
    _bracket_boundary,
    _peak_norm,
)
from companion.reference import (
    DEFAULT_MAX_YAW_ACC_RAD_S2,
    DEFAULT_MAX_YAW_RATE_RAD_S,
    DEFAULT_MIN_DURATION_S,
    Circle,
    Hold,
    Line,
    RefSample,
    Sequence,
    SequenceBuilder,
    Trajectory,
    Transition,
)
from tuavdefs.frames import wrap_pi

LIMIT_RTOL = 1e-9
FD_RTOL = 1e-5

SETTINGS = settings(max_examples=30, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow])

coord = st.floats(-1000.0, 1000.0, allow_nan=False, allow_infinity=False)
points = st.tuples(coord, coord, st.floats(0.0, 1000.0))
speeds = st.floats(0.5, 20.0)
accs = st.floats(0.3, 10.0)
yaws = st.floats(-math.pi, math.pi)


@st.composite
def goals(draw, start):
    """Far points, or points near ``start`` (down to sub-millimetre moves)."""
    if draw(st.booleans()):
        return draw(points)
    scale = draw(st.sampled_from([1e-4, 0.1, 1.0, 30.0]))
    d = draw(st.tuples(*[st.floats(-1.0, 1.0)] * 3))
    return tuple(s + scale * x for s, x in zip(start, d, strict=True))


# --- checkers -------------------------------------------------------------------------------

def arrays(traj: Trajectory, ts: np.ndarray) -> dict[str, np.ndarray]:
    samples = [traj.sample(float(t)) for t in ts]
    return {
        "pos": np.array([s.pos_m for s in samples]),
        "vel": np.array([s.vel_m_s for s in samples]),
        "acc": np.array([s.acc_m_s2 for s in samples]),
        "jerk": np.array([s.jerk_m_s3 for s in samples]),
        "yaw": np.array([s.yaw_rad for s in samples]),
        "yaw_rate": np.array([s.yaw_rate_rad_s for s in samples]),
    }


def span(traj: Trajectory, endless_s: float = 60.0) -> tuple[float, float]:
    end = traj.end_s if math.isfinite(traj.end_s) else traj.start_s + endless_s
    return traj.start_s, end


def knot_grid(traj: Trajectory, a: float, b: float, n: int, per_piece: int) -> np.ndarray:
    """n points over [a, b] plus ``per_piece`` points in every piece between knots, so short
    pieces (a brief yaw move within a long position move) are sampled too."""
    knots = sorted({a, b, *(k for k in traj.knots_s if a <= k <= b)})
    parts = [np.linspace(a, b, n)]
    parts += [np.linspace(k0, k1, per_piece) for k0, k1 in zip(knots[:-1], knots[1:],
                                                                 strict=True)]
    return np.unique(np.concatenate(parts))


def fine_grid(traj: Trajectory, n: int = 4001, endless_s: float = 60.0) -> np.ndarray:
    a, b = span(traj, endless_s)
    return knot_grid(traj, a, b, n, 201)


def assert_limits(traj: Trajectory, max_speed: float, max_acc: float,
                  max_yaw_rate: float = math.inf, endless_s: float = 60.0) -> None:
    d = arrays(traj, fine_grid(traj, endless_s=endless_s))
    speed = np.linalg.norm(d["vel"], axis=1)
    acc = np.linalg.norm(d["acc"], axis=1)
    assert speed.max() <= max_speed * (1 + LIMIT_RTOL), f"speed {speed.max()} > {max_speed}"
    assert acc.max() <= max_acc * (1 + LIMIT_RTOL), f"acc {acc.max()} > {max_acc}"
    assert np.abs(d["yaw_rate"]).max() <= max_yaw_rate * (1 + LIMIT_RTOL)


def assert_derivatives(traj: Trajectory, n: int = 300, endless_s: float = 60.0) -> None:
    """Central differences of pos / vel / acc / yaw agree with vel / acc / jerk / yaw rate."""
    a, b = span(traj, endless_s)
    knots = np.array(sorted({a, b, *(k for k in traj.knots_s if a <= k <= b)}))
    gaps = np.diff(knots)
    gaps = gaps[gaps > 0]
    h = min(max(1e-5 * (b - a), 1e-4), 1e-4 * gaps.min()) if gaps.size else 1e-4
    if b - a < 10 * h:
        return
    ts = knot_grid(traj, a, b, n, 30)
    ts = ts[(ts > a + 3 * h) & (ts < b - 3 * h)]
    mid, plus, minus = arrays(traj, ts), arrays(traj, ts + h), arrays(traj, ts - h)
    near_knot = np.min(np.abs(ts[:, None] - knots[None, :]), axis=1) < 3 * h
    # Across a knot the jerk may jump, which biases central differences of vel by O(h jump):
    # only pos -> vel is checked there (the knots themselves are assert_continuous's job).
    for x, dx, mask in (("pos", "vel", None), ("vel", "acc", ~near_knot),
                        ("acc", "jerk", ~near_knot)):
        fd = (plus[x] - minus[x]) / (2 * h)
        want = mid[dx]
        if mask is not None:
            fd, want = fd[mask], want[mask]
        scale = np.abs(mid[dx]).max()
        roundoff = 8 * np.finfo(float).eps * np.abs(mid[x]).max() / h
        err = np.abs(fd - want).max(initial=0.0)
        assert err <= FD_RTOL * scale + roundoff + 1e-12, \
            f"d{x}/dt differs from {dx} by {err} (scale {scale})"
    fd_yaw = np.array([wrap_pi(p - m) for p, m in zip(plus["yaw"], minus["yaw"], strict=True)])
    fd_yaw /= 2 * h
    err = np.abs(fd_yaw - mid["yaw_rate"]).max()
    roundoff = 8 * np.finfo(float).eps * math.pi / h
    assert err <= FD_RTOL * np.abs(mid["yaw_rate"]).max() + roundoff + 1e-12, \
        f"yaw rate off by {err}"


def assert_continuous(traj: Trajectory, endless_s: float = 60.0) -> None:
    """Position, velocity, acceleration, yaw and yaw rate do not jump at the knots."""
    a, b = span(traj, endless_s)
    d = arrays(traj, fine_grid(traj, n=501, endless_s=endless_s))
    bound = {k: np.linalg.norm(d[k], axis=1).max() for k in ("vel", "acc", "jerk")}
    yaw_rate_max = np.abs(d["yaw_rate"]).max()
    yaw_acc_max = max(abs(traj.yaw_acc_rad_s2(float(t))) for t in fine_grid(traj, 501, endless_s))
    for k in traj.knots_s:
        if not a < k < b:
            continue
        eps = 1e-9 * max(1.0, abs(k))
        lo, hi = traj.sample(k - eps), traj.sample(k + eps)
        jmax = max(bound["jerk"], np.linalg.norm(lo.jerk_m_s3), np.linalg.norm(hi.jerk_m_s3))
        for x, y, rate, tol0 in ((lo.pos_m, hi.pos_m, bound["vel"], 1e-9 * (1 + max(
                map(abs, lo.pos_m)))), (lo.vel_m_s, hi.vel_m_s, bound["acc"], 1e-9),
                (lo.acc_m_s2, hi.acc_m_s2, jmax, 1e-9)):
            assert math.dist(x, y) <= 3 * eps * rate + tol0, f"jump at t = {k}: {x} -> {y}"
        assert abs(wrap_pi(hi.yaw_rad - lo.yaw_rad)) <= 3 * eps * yaw_rate_max + 1e-12
        assert abs(hi.yaw_rate_rad_s - lo.yaw_rate_rad_s) <= 3 * eps * yaw_acc_max + 1e-12


def assert_all(traj: Trajectory, max_speed: float, max_acc: float,
               max_yaw_rate: float = math.inf, endless_s: float = 60.0) -> None:
    assert_limits(traj, max_speed, max_acc, max_yaw_rate, endless_s)
    assert_derivatives(traj, endless_s=endless_s)
    assert_continuous(traj, endless_s=endless_s)


def close(a, b, tol=1e-9) -> bool:
    return math.dist(a, b) <= tol * (1.0 + max(map(abs, b), default=0.0))


def quintic_duration(dist: float, v: float, a: float, t_min: float) -> float:
    if dist == 0.0:
        return 0.0
    return max(15 / 8 * dist / v, math.sqrt(10 / math.sqrt(3) * dist / a), t_min)


# --- the checkers can fail --------------------------------------------------------------------

class _Faulty(Trajectory):
    """A Transition with one defect injected."""

    def __init__(self, inner: Transition, defect: str) -> None:
        self.inner, self.defect = inner, defect
        self.start_s, self.end_s = inner.start_s, inner.end_s
        self.final_pos_m, self.final_yaw_rad = inner.final_pos_m, inner.final_yaw_rad
        self.knots_s = inner.knots_s + ((inner.start_s + inner.end_s) / 2,)

    def sample(self, t_s: float) -> RefSample:
        s = self.inner.sample(t_s)
        if self.defect == "jerk":
            return s._replace(jerk_m_s3=tuple(1.01 * j for j in s.jerk_m_s3))
        if self.defect == "acc_jump" and t_s > (self.start_s + self.end_s) / 2:
            return s._replace(acc_m_s2=(s.acc_m_s2[0] + 0.01, *s.acc_m_s2[1:]))
        return s


def test_checkers_catch_faults():
    tr = Transition((0, 0, 10), (40, -10, 20), 0.0, 5.0, 2.0)
    assert_all(tr, 5.0, 2.0)
    with pytest.raises(AssertionError):
        assert_derivatives(_Faulty(tr, "jerk"))
    with pytest.raises(AssertionError):
        assert_continuous(_Faulty(tr, "acc_jump"))
    with pytest.raises(AssertionError):
        assert_limits(tr, 5.0 * 0.999, 2.0)  # the profile really reaches its limit
    with pytest.raises(AssertionError):
        assert_limits(Transition((0, 0, 0), (1, 0, 0), 0.0, 5.0, 2.0), 5.0, 2.0 * 0.999)


# --- Transition -----------------------------------------------------------------------------

@SETTINGS
@given(start=points, data=st.data(), v_max=speeds, a_max=accs, yaw0=yaws, yaw1=yaws,
       t0=st.floats(-100.0, 1e4))
def test_transition_from_rest(start, data, v_max, a_max, yaw0, yaw1, t0):
    goal = data.draw(goals(start))
    tr = Transition(start, goal, t0, v_max, a_max, yaw_start=yaw0, yaw_goal=yaw1)
    assert tr.within_limits
    dist = math.dist(start, goal)
    assert tr.pos_duration_s == pytest.approx(
        quintic_duration(dist, v_max, a_max, DEFAULT_MIN_DURATION_S), rel=1e-12)
    s0, s1 = tr.sample(t0), tr.sample(tr.end_s)
    assert s0.pos_m == tuple(start) and s1.pos_m == tuple(goal)
    for s in (s0, s1):
        assert s.vel_m_s == (0.0, 0.0, 0.0) and s.acc_m_s2 == (0.0, 0.0, 0.0)
        assert s.yaw_rate_rad_s == 0.0
    assert s0.yaw_rad == pytest.approx(wrap_pi(yaw0), abs=1e-12)
    assert abs(wrap_pi(s1.yaw_rad - yaw1)) < 1e-12
    assert tr.sample(t0 - 5.0) == s0 and tr.sample(tr.end_s + 100.0) == s1
    assert_all(tr, v_max, a_max, DEFAULT_MAX_YAW_RATE_RAD_S)
    # the straight line: every point is on the segment
    if dist > 1e-3:
        d = arrays(tr, np.linspace(t0, tr.end_s, 50))
        u = (np.array(goal) - np.array(start)) / dist
        off = d["pos"] - np.array(start)
        perp = off - np.outer(off @ u, u)
        assert np.abs(perp).max() <= 1e-9 * (1 + max(map(abs, start)) + dist)


@pytest.mark.parametrize(("dist", "v", "a", "limited"), [
    (1000.0, 5.0, 2.0, "speed"), (2.0, 5.0, 2.0, "acc"), (0.001, 5.0, 2.0, "time")])
def test_transition_duration_formula_is_tight(dist, v, a, limited):
    tr = Transition((0, 0, 5), (0, dist, 5), 0.0, v, a)
    T = tr.duration_s
    expect = max(15 / 8 * dist / v, math.sqrt(10 / math.sqrt(3) * dist / a),
                 DEFAULT_MIN_DURATION_S)
    assert abs(T - expect) <= 1e-12 * expect
    d = arrays(tr, np.linspace(0, T, 20001))
    speed = np.linalg.norm(d["vel"], axis=1).max()
    acc = np.linalg.norm(d["acc"], axis=1).max()
    assert speed == pytest.approx(QUINTIC_PEAK_SPEED * dist / T, rel=1e-6)
    assert acc == pytest.approx(QUINTIC_PEAK_ACC * dist / T**2, rel=1e-6)
    if limited == "speed":
        assert speed == pytest.approx(v, rel=1e-6)
    elif limited == "acc":
        assert acc == pytest.approx(a, rel=1e-6)
    else:
        assert T == DEFAULT_MIN_DURATION_S


def test_transition_min_duration_and_zero_move():
    tr = Transition((1, 2, 3), (1, 2, 3.001), 0.0, 5.0, 2.0, min_duration_s=0.0)
    assert tr.duration_s == pytest.approx(math.sqrt(10 / math.sqrt(3) * 0.001 / 2.0))
    still = Transition((1, 2, 3), (1, 2, 3), 7.0, 5.0, 2.0)
    assert still.duration_s == 0.0 and still.end_s == 7.0
    assert still.sample(7.0).pos_m == (1.0, 2.0, 3.0)


def test_transition_rejects_bad_limits():
    with pytest.raises(ValueError, match="max_speed"):
        Transition((0, 0, 0), (1, 0, 0), 0.0, 0.0, 1.0)
    with pytest.raises(ValueError, match="max_acc"):
        Transition((0, 0, 0), (1, 0, 0), 0.0, 1.0, -1.0)
    with pytest.raises(ValueError, match="goal_pos"):
        Transition((0, 0, 0), (1, 0, math.nan), 0.0, 1.0, 1.0)


def test_yaw_goes_the_short_way():
    tr = Transition((0, 0, 5), (0, 0, 5), 0.0, 5.0, 2.0, yaw_start=3.0, yaw_goal=-3.0)
    d = arrays(tr, np.linspace(0, tr.end_s, 2001))
    assert (d["yaw_rate"] >= -1e-12).all()  # through +pi, not back through 0
    swept = np.sum([wrap_pi(b - a) for a, b in zip(d["yaw"][:-1], d["yaw"][1:], strict=True)])
    assert swept == pytest.approx(2 * math.pi - 6.0, rel=1e-9)
    dpsi = 2 * math.pi - 6.0
    assert tr.yaw_duration_s == pytest.approx(quintic_duration(
        dpsi, DEFAULT_MAX_YAW_RATE_RAD_S, DEFAULT_MAX_YAW_ACC_RAD_S2, DEFAULT_MIN_DURATION_S))
    assert_all(tr, 1e-9, 1e-9, DEFAULT_MAX_YAW_RATE_RAD_S)
    big = Transition((0, 0, 5), (1, 0, 5), 0.0, 5.0, 2.0, yaw_start=0.0, yaw_goal=3.0,
                     max_yaw_rate=0.5)
    assert big.end_s == big.yaw_duration_s > big.pos_duration_s  # yaw finishes later
    assert big.yaw_duration_s == pytest.approx(15 / 8 * 3.0 / 0.5)
    assert_all(big, 5.0, 2.0, 0.5)


@SETTINGS
@given(start=points, goal1=points, data=st.data(), v_max=speeds, a_max=accs,
       frac=st.floats(0.0, 1.0), yaw0=yaws, yaw1=yaws, yaw2=yaws)
def test_transition_retarget_mid_flight(start, goal1, data, v_max, a_max, frac, yaw0, yaw1,
                                        yaw2):
    goal2 = data.draw(goals(goal1))
    first = Transition(start, goal1, 0.0, v_max, a_max, yaw_start=yaw0, yaw_goal=yaw1)
    t_r = frac * first.end_s
    s = first.sample(t_r)
    second = Transition(s.pos_m, goal2, t_r, v_max, a_max, s.vel_m_s, s.acc_m_s2, s.yaw_rad,
                        yaw2, start_yaw_rate_rad_s=s.yaw_rate_rad_s,
                        start_yaw_acc_rad_s2=first.yaw_acc_rad_s2(t_r))
    assert second.within_limits
    s2 = second.sample(t_r)
    for x, y in ((s.pos_m, s2.pos_m), (s.vel_m_s, s2.vel_m_s), (s.acc_m_s2, s2.acc_m_s2)):
        assert close(x, y, 1e-12)
    assert abs(wrap_pi(s.yaw_rad - s2.yaw_rad)) < 1e-12
    assert s.yaw_rate_rad_s == pytest.approx(s2.yaw_rate_rad_s, abs=1e-12)
    end = second.sample(second.end_s)
    assert end.pos_m == tuple(goal2) and end.vel_m_s == (0.0, 0.0, 0.0)
    assert abs(wrap_pi(end.yaw_rad - yaw2)) < 1e-12
    assert_all(second, v_max, a_max, DEFAULT_MAX_YAW_RATE_RAD_S)
    # stitched together: first until t_r, then second
    stitched = Sequence([_Cut(first, t_r), second]) if t_r > 0 else second
    assert_continuous(stitched)


class _Cut(Trajectory):
    """``inner`` up to ``end_s`` (for stitching a retarget into a Sequence)."""

    def __init__(self, inner: Trajectory, end_s: float) -> None:
        self.inner = inner
        self.start_s, self.end_s = inner.start_s, end_s
        self.final_pos_m, self.final_yaw_rad = None, inner.final_yaw_rad
        self.knots_s = tuple(k for k in inner.knots_s if k < end_s) + (end_s,)

    def sample(self, t_s: float) -> RefSample:
        return self.inner.sample(min(t_s, self.end_s))


@pytest.mark.parametrize("frac", [0.1, 0.2113, 0.5, 0.7887, 0.95])
@pytest.mark.parametrize("goal2", [(2000.0, 0.0, 10.0), (0.0, 500.0, 10.0), (-50.0, 0.0, 10.0),
                                   (300.0, 1.0, 10.0)])
def test_retarget_from_peak_states(frac, goal2):
    """Retargets at the acceleration peaks and at the speed peak of a limit-bound move,
    ahead, sideways and back: the far-ahead case needs the two-phase plan."""
    first = Transition((0, 0, 10), (1000, 0, 10), 0.0, 5.0, 2.0)
    short = Transition((0, 0, 10), (6, 0, 10), 0.0, 5.0, 2.0)  # acceleration-bound
    for src in (first, short):
        t_r = frac * src.end_s
        s = src.sample(t_r)
        tr = Transition(s.pos_m, goal2, t_r, 5.0, 2.0, s.vel_m_s, s.acc_m_s2)
        assert tr.within_limits
        assert close(tr.sample(t_r).acc_m_s2, s.acc_m_s2, 1e-12)
        assert tr.sample(tr.end_s).pos_m == goal2
        assert_all(tr, 5.0, 2.0)


def test_retarget_from_circle_state():
    c = Circle((0, 0), 20.0, 30.0, 5.0, 0.0, max_acc_m_s2=2.0)
    s = c.sample(40.0)
    tr = Transition(s.pos_m, (100, 100, 40), 40.0, 5.0, 2.0, s.vel_m_s, s.acc_m_s2)
    assert tr.within_limits
    assert_all(tr, 5.0, 2.0)


@SETTINGS
@given(radius=st.floats(2.0, 100.0), speed=st.floats(0.5, 10.0), a_max=accs,
       t_frac=st.floats(0.0, 1.0), goal=points, clockwise=st.booleans())
def test_retarget_from_any_circle_state(radius, speed, a_max, t_frac, goal, clockwise):
    """From anywhere on a circle flown at the follower's speed limit (the hardest start:
    at the speed limit with a sideways acceleration) the retarget keeps the limits."""
    assume(speed**2 / radius < 0.9 * a_max)
    lead_in = Circle.min_lead_in_s(radius, speed, a_max)
    c = Circle((0, 0), radius, 30.0, speed, 0.0, lead_in, 1.0, 0.0, clockwise, a_max)
    t_r = t_frac * c.end_s
    s = c.sample(t_r)
    tr = Transition(s.pos_m, goal, t_r, speed, a_max, s.vel_m_s, s.acc_m_s2)
    assert tr.within_limits
    assert close(tr.sample(t_r).acc_m_s2, s.acc_m_s2, 1e-12)
    assert tr.sample(tr.end_s).pos_m == tuple(goal)
    assert_all(tr, speed, a_max)


def test_retarget_from_infeasible_state_is_flagged():
    tr = Transition((0, 0, 0), (100, 0, 0), 0.0, 5.0, 2.0, start_vel=(8.0, 0.0, 0.0))
    assert not tr.within_limits
    assert tr.sample(0.0).vel_m_s == (8.0, 0.0, 0.0)
    assert tr.sample(tr.end_s).pos_m == (100.0, 0.0, 0.0)
    assert_derivatives(tr)
    assert_continuous(tr)


# --- the planner's numerics -----------------------------------------------------------------

@SETTINGS
@given(ndim=st.integers(1, 3), m=st.integers(1, 6), scale_exp=st.floats(-6.0, 6.0),
       seed=st.integers(0, 2**32 - 1))
def test_peak_norm_matches_a_dense_sampling(ndim, m, scale_exp, seed):
    """The exact peak of a vector polynomial's norm over [0, 1] is at least every sampled
    value and at most the densest sampling's peak plus what that sampling can miss."""
    c = np.random.default_rng(seed).normal(size=(ndim, m)) * 10.0**scale_exp
    u = np.linspace(0.0, 1.0, 200_001)
    norms = np.sqrt(sum(np.polynomial.polynomial.polyval(u, row) ** 2 for row in c))
    dense = float(norms.max())
    peak = _peak_norm(c)
    assert peak >= dense * (1.0 - 1e-12)
    assert peak <= dense * (1.0 + 1e-8)


def _counting(f):
    calls: list[tuple[float, float]] = []

    def wrapped(x: float) -> float:
        calls.append((x, f(x)))
        return calls[-1][1]
    return wrapped, calls


def _check_bracket(f, lo, hi, result, calls):
    """The contract: result feasible, and an infeasible point (evaluated or the initial lo)
    within the tolerance below it."""
    assert f(result) <= 0.0 and lo < result <= hi
    below = [x for x, fx in [(lo, f(lo)), *calls] if fx > 0.0 and x < result]
    assert result / max(below) - 1.0 <= _BISECT_RTOL


def test_bracket_boundary_smooth_root_in_a_few_evaluations():
    """Peak-ratio-like excess 2/T^2 - 1 (root sqrt 2): the regula falsi brackets it to the
    tolerance in a handful of evaluations, where bisection from (1, 2) needs
    log2(ln 2 / 1e-7) ~ 23."""
    f = lambda T: 2.0 / T**2 - 1.0  # noqa: E731
    g, calls = _counting(f)
    hi = _bracket_boundary(g, 1.0, f(1.0), 2.0, f(2.0))
    _check_bracket(f, 1.0, 2.0, hi, calls)
    assert hi >= math.sqrt(2.0) and hi / math.sqrt(2.0) - 1.0 <= _BISECT_RTOL
    assert len(calls) <= 8


@pytest.mark.parametrize("case", ["step", "wiggle", "zero_at_hi", "flat_then_drop"])
def test_bracket_boundary_keeps_its_invariant_on_awkward_excesses(case):
    """Discontinuous, non-monotone (several sign changes), a root exactly at hi, and a
    plateau: the result is always feasible with an infeasible point within the tolerance
    below it, in at most about four bisections' worth of evaluations."""
    f = {"step": lambda T: 1.0 if T < 1.3 else -1.0,
         "wiggle": lambda T: math.cos(60.0 * (T - 1.0)) - 0.2 * (T - 1.0),
         "zero_at_hi": lambda T: 2.0 - T,
         "flat_then_drop": lambda T: 1e-3 if T < 1.9 else (1.95 - T)}[case]
    lo, hi = 1.0, 2.0
    assert f(lo) > 0.0 >= f(hi)
    g, calls = _counting(f)
    result = _bracket_boundary(g, lo, f(lo), hi, f(hi))
    _check_bracket(f, lo, hi, result, calls)
    assert len(calls) <= 4 * math.ceil(math.log2(math.log(2.0) / _BISECT_RTOL)) + 4


# --- Hold, Line -----------------------------------------------------------------------------

def test_hold():
    h = Hold((1, 2, 3), 4.0, 10.0)
    assert h.end_s == math.inf and h.final_pos_m == (1.0, 2.0, 3.0)
    s = h.sample(1e6)
    assert s.pos_m == (1.0, 2.0, 3.0) and s.vel_m_s == (0.0, 0.0, 0.0)
    assert s.yaw_rad == pytest.approx(4.0 - 2 * math.pi)
    assert Hold((0, 0, 0), 0.0, 1.0, duration_s=2.0).end_s == 3.0


@SETTINGS
@given(start=points, data=st.data(), speed=speeds, a_max=accs, t0=st.floats(0.0, 100.0))
def test_line(start, data, speed, a_max, t0):
    end = data.draw(goals(start))
    ln = Line(start, end, t0, speed, a_max, yaw=1.0)
    dist = math.dist(start, end)
    V, Ta = ln.cruise_speed_m_s, ln.ramp_s
    if dist > 0:
        # V is the asked speed, or as fast as the ramps (>= 0.25 s, <= a_max) allow
        short = min(math.sqrt(8 * a_max * dist / 15), dist / 0.25)
        assert abs(V - min(speed, short)) <= 1e-12 * V
        assert abs(Ta - max(15 / 8 * V / a_max, 0.25)) <= 1e-12 * Ta
        assert ln.duration_s == pytest.approx(dist / V + Ta, rel=1e-9)
    assert ln.sample(t0).pos_m == tuple(start) and ln.sample(ln.end_s).pos_m == tuple(end)
    assert ln.sample(ln.end_s).vel_m_s == (0.0, 0.0, 0.0)
    assert_all(ln, speed, a_max)
    if dist > 0 and V * Ta < dist * 0.99:  # cruise: constant speed, zero acceleration
        d = arrays(ln, np.linspace(t0 + Ta, ln.end_s - Ta, 101))
        assert np.linalg.norm(d["vel"], axis=1) == pytest.approx(speed, rel=1e-9)
        assert np.abs(d["acc"]).max() <= 1e-9 * a_max
        assert np.linalg.norm(d["vel"], axis=1).max() == pytest.approx(speed, rel=1e-12)


# --- Circle ---------------------------------------------------------------------------------

@SETTINGS
@given(cx=coord, cy=coord, radius=st.floats(1.0, 200.0), alt=st.floats(1.0, 500.0),
       speed=st.floats(0.5, 15.0), a_max=accs, slack=st.floats(1.0, 3.0),
       angle=st.floats(-math.pi, math.pi), clockwise=st.booleans(), turns=st.floats(0.2, 3.0),
       face=st.booleans())
def test_circle(cx, cy, radius, alt, speed, a_max, slack, angle, clockwise, turns, face):
    assume(speed**2 / radius < 0.95 * a_max)
    lead_in = slack * Circle.min_lead_in_s(radius, speed, a_max)
    c = Circle((cx, cy), radius, alt, speed, 5.0, lead_in, turns, angle, clockwise, a_max,
               yaw=0.3, face_travel=face)
    V = c.cruise_speed_m_s
    length = turns * 2 * math.pi * radius
    assert abs(V - min(speed, length / lead_in)) <= 1e-12 * V
    assert c.duration_s == pytest.approx(length / V + lead_in, rel=1e-9)
    s0 = c.sample(5.0)
    assert close(s0.pos_m, (cx + radius * math.cos(angle), cy + radius * math.sin(angle), alt))
    assert s0.vel_m_s == (0.0, 0.0, 0.0)
    assert close(c.final_pos_m, (cx + radius * math.cos(angle + (-1 if clockwise else 1)
                                                       * turns * 2 * math.pi),
                                 cy + radius * math.sin(angle + (-1 if clockwise else 1)
                                                        * turns * 2 * math.pi), alt), 1e-9)
    assert c.sample(c.end_s + 10).vel_m_s == (0.0, 0.0, 0.0)
    assert_all(c, speed, a_max, math.inf if face else 0.0)
    d = arrays(c, np.linspace(5.0, c.end_s, 4001))
    rel = d["pos"][:, :2] - np.array([cx, cy])
    assert np.linalg.norm(rel, axis=1) == pytest.approx(radius, rel=1e-9)
    assert (d["pos"][:, 2] == alt).all()
    th = np.arctan2(rel[:, 1], rel[:, 0])
    swept = np.sum(np.array([wrap_pi(b - a) for a, b in zip(th[:-1], th[1:], strict=True)]))
    assert swept == pytest.approx((-1 if clockwise else 1) * turns * 2 * math.pi, rel=1e-6)
    if face:
        moving = np.linalg.norm(d["vel"], axis=1) > 1e-3
        heading = np.arctan2(d["vel"][moving, 1], d["vel"][moving, 0])
        assert np.abs([wrap_pi(x) for x in heading - d["yaw"][moving]]).max() < 1e-9
    else:
        assert np.abs(d["yaw"] - 0.3).max() < 1e-15


@pytest.mark.parametrize("clockwise", [False, True])
def test_endless_circle_after_lead_in(clockwise):
    r, V, a = 15.0, 4.0, 2.0
    c = Circle((10, -20), r, 40.0, V, 0.0, lead_in_s=6.0, start_angle_rad=1.0,
               clockwise=clockwise, max_acc_m_s2=a)
    assert c.end_s == math.inf and c.final_pos_m is None
    for t in np.linspace(6.0, 3000.0, 997):
        s = c.sample(float(t))
        rel = np.array(s.pos_m) - np.array([10.0, -20.0, 40.0])
        assert np.linalg.norm(rel) == pytest.approx(r, rel=1e-9) and rel[2] == 0.0
        assert np.linalg.norm(s.vel_m_s) == pytest.approx(V, rel=1e-9)
        # centripetal: V^2/r toward the centre
        assert np.array(s.acc_m_s2) == pytest.approx(-V**2 / r * rel / r, abs=1e-9)
        turn = np.cross(rel, s.vel_m_s)[2]
        assert (turn < 0) if clockwise else (turn > 0)
        assert np.dot(rel, s.vel_m_s) == pytest.approx(0.0, abs=1e-9)
    assert_all(c, V, a, endless_s=200.0)


def test_circle_rejects_impossible_limits():
    with pytest.raises(ValueError, match=r"speed\^2/radius"):
        Circle((0, 0), 10.0, 20.0, 6.0, 0.0, max_acc_m_s2=3.0)
    t_min = Circle.min_lead_in_s(10.0, 5.0, 3.0)
    assert 0 < t_min < math.inf
    with pytest.raises(ValueError, match="lead_in_s"):
        Circle((0, 0), 10.0, 20.0, 5.0, 0.0, lead_in_s=0.99 * t_min, max_acc_m_s2=3.0)
    c = Circle((0, 0), 10.0, 20.0, 5.0, 0.0, lead_in_s=t_min, max_acc_m_s2=3.0)
    assert c.peak_total_acc_m_s2 <= 3.0 * (1 + 1e-12)
    assert_limits(c, 5.0, 3.0)
    with pytest.raises(ValueError, match="turns"):
        Circle((0, 0), 10.0, 20.0, 1.0, 0.0, turns=0.0)


# --- Sequence -------------------------------------------------------------------------------

def test_sequence_builder():
    seq = (SequenceBuilder((0, 0, 0), 2.0, 5.0, 2.0, yaw=0.5)
           .goto((0, 0, 20)).hold(3.0).goto((30, 10, 25), yaw=-1.0)
           .line_to((80, 10, 25), speed_m_s=4.0)
           .circle((80, 40), 20.0, 4.0, turns=1.5, face_travel=True)
           .goto((0, 0, 5), yaw=2.5).build())
    assert len(seq.segments) == 7  # the circle adds a goto to its start point
    assert seq.start_s == 2.0 and seq.final_pos_m == (0.0, 0.0, 5.0)
    for a, b in zip(seq.segments, seq.segments[1:], strict=False):
        assert b.start_s == a.end_s
    assert isinstance(seq.segments[4], Transition) and isinstance(seq.segments[5], Circle)
    assert seq.segments[5].sample(seq.segments[5].start_s).pos_m == pytest.approx((80, 20, 25))
    assert_all(seq, 5.0, 2.0, DEFAULT_MAX_YAW_RATE_RAD_S + 4.0 / 20.0)
    assert abs(wrap_pi(seq.sample(seq.end_s).yaw_rad - 2.5)) < 1e-12
    # the hold really holds
    hold = seq.segments[1]
    for t in np.linspace(hold.start_s, hold.end_s, 7):
        assert seq.sample(float(t)).pos_m == (0.0, 0.0, 20.0)


def test_sequence_rejects_gaps():
    a = Transition((0, 0, 0), (10, 0, 0), 0.0, 5.0, 2.0)
    with pytest.raises(ValueError, match="position"):
        Sequence([a, Transition((11, 0, 0), (20, 0, 0), a.end_s, 5.0, 2.0)])
    with pytest.raises(ValueError, match="starts at"):
        Sequence([a, Transition((10, 0, 0), (20, 0, 0), a.end_s + 1.0, 5.0, 2.0)])
    with pytest.raises(ValueError, match="never ends"):
        Sequence([Hold((0, 0, 0)), a])


# --- LegFollower ----------------------------------------------------------------------------

DT = 0.02


class Chain:
    """Legs flown one after the other, each started from the previous one's reference when
    it is done, as a sequencer (the navigator) does; ``reached`` lists (index, time)."""

    def __init__(self, v_max: float, a_max: float, accept: float, items, hold_s: float = 0.0,
                 t0: float = 0.0, pos=(0.0, 0.0, 10.0), vel=(0.0, 0.0, 0.0)) -> None:
        self.items = list(items)
        self.make = lambda: LegFollower(v_max, a_max, accept, hold_s)
        self.index = 0
        self.reached: list[tuple[int, float]] = []
        self.leg = self.make()
        self.leg.start(t0, pos, vel, self.items[0])

    @property
    def done(self) -> bool:
        return self.index >= len(self.items)

    @property
    def phase(self) -> LegPhase:
        return self.leg.phase

    def update(self, t: float, pos) -> RefSample:
        ref = self.leg.update(t, pos)
        if self.leg.reached_t_s is not None and not self.done and (
                not self.reached or self.reached[-1][0] != self.index):
            self.reached.append((self.index, self.leg.reached_t_s))
        if self.leg.done and not self.done:
            self.index += 1
            if not self.done:
                traj = self.leg.trajectory
                state = traj.sample(t)
                self.leg = self.make()
                self.leg.start(t, state.pos_m, state.vel_m_s, self.items[self.index],
                               current_yaw=state.yaw_rad, current_acc=state.acc_m_s2,
                               current_yaw_rate=state.yaw_rate_rad_s,
                               current_yaw_acc=traj.yaw_acc_rad_s2(t))
                ref = self.leg.update(t, pos)
        return ref


def fly(f, t0: float, t1: float, pos, tracker=None, phases=None):
    """Run the leg (or chain) from t0 to t1; the perfect tracker is one step behind the
    reference. Returns (times, references); appends the phase at each step to ``phases``."""
    ts, refs = [], []
    for k in range(int(round((t1 - t0) / DT)) + 1):
        t = t0 + k * DT
        ref = f.update(t, pos)
        ts.append(t)
        refs.append(ref)
        if phases is not None:
            phases.append(f.phase)
        pos = ref.pos_m if tracker is None else tracker(t, ref)
    return ts, refs


def assert_run_smooth(ts: list[float], refs: list[RefSample], v_max: float,
                      a_max: float) -> None:
    """Limits, and no jumps: each step of pos / vel / acc is within its rate bound."""
    dt = np.diff(ts)
    assert (dt > 0).all()
    pos = np.array([r.pos_m for r in refs])
    vel = np.array([r.vel_m_s for r in refs])
    acc = np.array([r.acc_m_s2 for r in refs])
    jerk = np.array([r.jerk_m_s3 for r in refs])
    assert np.linalg.norm(vel, axis=1).max() <= v_max * (1 + LIMIT_RTOL)
    assert np.linalg.norm(acc, axis=1).max() <= a_max * (1 + LIMIT_RTOL)
    # v_max and a_max bound the rates of pos and vel; the sampled jerk may miss the jerk's
    # peak at the end of a quintic (the sample after the end is at rest), hence the 2.
    jmax = 2.0 * np.linalg.norm(jerk, axis=1).max()
    for x, rate in ((pos, v_max), (vel, a_max), (acc, jmax)):
        steps = np.linalg.norm(np.diff(x, axis=0), axis=1)
        assert (steps <= 1.01 * rate * dt + 1e-9).all()


WAYPOINTS = [(20.0, 0.0, 10.0), (20.0, 30.0, 15.0, 1.0), (-10.0, 5.0, 5.0),
             GotoItem((0.0, 0.0, 10.0), yaw_rad=-2.0)]


def leg_duration(a, b, yaw_a, yaw_b, v=5.0, acc=2.0) -> float:
    dpsi = abs(wrap_pi(yaw_b - yaw_a))
    return max(quintic_duration(math.dist(a, b), v, acc, DEFAULT_MIN_DURATION_S),
               quintic_duration(dpsi, DEFAULT_MAX_YAW_RATE_RAD_S, DEFAULT_MAX_YAW_ACC_RAD_S2,
                                DEFAULT_MIN_DURATION_S))


def test_legs_perfect_tracker_reaches_all_in_order():
    f = Chain(5.0, 2.0, 0.05, WAYPOINTS, t0=1.0)
    assert not f.leg.done and f.leg.reached_t_s is None
    ts, refs = fly(f, 1.0, 200.0, (0.0, 0.0, 10.0))
    assert f.done
    assert [i for i, _ in f.reached] == [0, 1, 2, 3]
    # each leg starts when the previous item is reached and lasts the quintic duration
    pts = [(0.0, 0.0, 10.0), (20.0, 0.0, 10.0), (20.0, 30.0, 15.0), (-10.0, 5.0, 5.0),
           (0.0, 0.0, 10.0)]
    yaw = [0.0, 0.0, 1.0, 1.0, -2.0]
    t_prev = 1.0
    for k, (_, t_k) in enumerate(f.reached):
        expect = t_prev + leg_duration(pts[k], pts[k + 1], yaw[k], yaw[k + 1])
        assert expect <= t_k <= expect + 2 * DT + 1e-9
        t_prev = t_k
    assert_run_smooth(ts, refs, 5.0, 2.0)
    final = refs[-1]
    assert final.pos_m == (0.0, 0.0, 10.0) and abs(wrap_pi(final.yaw_rad + 2.0)) < 1e-12


def test_leg_waits_for_a_lagging_vehicle():
    f = LegFollower(5.0, 2.0, 0.5)
    f.start(0.0, (0, 0, 10), (0, 0, 0), WAYPOINTS[0])
    stuck = (0.0, 0.0, 10.0)
    ts, refs = fly(f, 0.0, 100.0, stuck, tracker=lambda t, ref: stuck)
    assert f.reached_t_s is None and f.phase is LegPhase.TRANSIT and not f.done
    assert refs[-1].pos_m == (20.0, 0.0, 10.0) and refs[-1].vel_m_s == (0.0, 0.0, 0.0)
    near = (20.3, 0.2, 10.1)  # within 0.5 m
    f.update(100.0 + DT, near)
    assert f.reached_t_s == 100.0 + DT and f.done


def test_legs_hold():
    hold = 3.0
    f = Chain(5.0, 2.0, 0.05, WAYPOINTS[:3], hold_s=hold)
    ts, refs = fly(f, 0.0, 150.0, (0.0, 0.0, 10.0))
    assert [i for i, _ in f.reached] == [0, 1, 2] and f.done
    pts = [(0.0, 0.0, 10.0), (20.0, 0.0, 10.0), (20.0, 30.0, 15.0), (-10.0, 5.0, 5.0)]
    yaw = [0.0, 0.0, 1.0, 1.0]
    (_, t0), (_, t1), (_, t2) = f.reached
    assert t1 == pytest.approx(t0 + hold + leg_duration(pts[1], pts[2], yaw[1], yaw[2]),
                               abs=2 * DT)
    assert t2 == pytest.approx(t1 + hold + leg_duration(pts[2], pts[3], yaw[2], yaw[3]),
                               abs=2 * DT)
    for t, r in zip(ts, refs, strict=True):
        if t0 <= t < t0 + hold - 1e-9:
            assert r.pos_m == pts[1] and r.vel_m_s == (0.0, 0.0, 0.0)
    assert_run_smooth(ts, refs, 5.0, 2.0)


def test_legs_circle_item():
    circle = CircleItem((0.0, 0.0), 10.0, 10.0, 3.0, turns=1.0)
    f = Chain(5.0, 2.0, 0.05, [(30.0, 0.0, 10.0), circle, (0.0, 0.0, 20.0)])
    phases = []
    ts, refs = fly(f, 0.0, 150.0, (0.0, 0.0, 10.0), phases=phases)
    assert [i for i, _ in f.reached] == [0, 1, 2] and f.done
    circ_t = [t for t, p in zip(ts, phases, strict=True) if p is LegPhase.CIRCLE]
    on = [r for t, r in zip(ts, refs, strict=True) if circ_t[0] <= t <= circ_t[-1]]
    # after the transit from (30, 0) to the nearest point (10, 0), one turn round the centre
    assert on[0].pos_m == (10.0, 0.0, 10.0) and on[0].vel_m_s == (0.0, 0.0, 0.0)
    assert f.reached[1][1] == pytest.approx(circ_t[-1] + DT)
    rel = np.array([r.pos_m for r in on])
    assert np.linalg.norm(rel[:, :2], axis=1) == pytest.approx(10.0, rel=1e-9)
    assert (rel[:, 2] == 10.0).all()
    th = np.arctan2(rel[:, 1], rel[:, 0])
    assert np.sum([wrap_pi(b - a) for a, b in zip(th[:-1], th[1:], strict=True)]) == \
        pytest.approx(2 * math.pi, abs=0.02)
    expect = 2 * math.pi * 10.0 / 3.0 + 5.0  # arc / speed + lead-in
    assert circ_t[-1] - circ_t[0] == pytest.approx(expect, abs=3 * DT)
    assert_run_smooth(ts, refs, 5.0, 2.0)


def test_leg_rejects_impossible_circle():
    f = LegFollower(5.0, 1.0, 0.1)
    with pytest.raises(ValueError, match="radius"):
        f.start(0.0, (0, 0, 10), (0, 0, 0), CircleItem((0.0, 0.0), 5.0, 10.0, 4.0))


@pytest.mark.parametrize("t_r", [3.0, 6.5, 10.0])
def test_leg_retarget_keeps_continuity(t_r):
    f = LegFollower(5.0, 2.0, 0.05)
    f.start(0.0, (0, 0, 10), (0, 0, 0), (60.0, 0.0, 10.0))
    ts, refs = fly(f, 0.0, t_r - DT, (0.0, 0.0, 10.0))
    before = f.trajectory.sample(t_r)
    assert np.linalg.norm(before.vel_m_s) > 0.5  # really mid-flight
    after = f.retarget(t_r, (-20.0, 30.0, 25.0, 1.5))
    assert close(before.pos_m, after.pos_m, 1e-12) and close(before.vel_m_s, after.vel_m_s,
                                                             1e-12)
    assert close(before.acc_m_s2, after.acc_m_s2, 1e-12)
    assert f.trajectory.within_limits and f.reached_t_s is None
    ts2, refs2 = fly(f, t_r, 200.0, refs[-1].pos_m)
    assert f.done and f.item == GotoItem((-20.0, 30.0, 25.0), 1.5)
    assert_run_smooth(ts + ts2, refs + refs2, 5.0, 2.0)
    assert refs2[-1].pos_m == (-20.0, 30.0, 25.0)


def test_leg_retarget_from_circle_and_after_done():
    f = LegFollower(4.0, 2.0, 0.05)
    f.start(0.0, (0, 0, 10), (0, 0, 0),
            CircleItem((0.0, 10.0), 10.0, 10.0, 4.0, turns=math.inf,
                       start_angle_rad=-math.pi / 2))
    ts, refs = fly(f, 0.0, 40.0, (0.0, 0.0, 10.0))
    assert f.phase is LegPhase.CIRCLE and not f.done
    after = f.retarget(40.0 + DT, (30.0, 30.0, 20.0))
    assert f.trajectory.within_limits
    ts2, refs2 = fly(f, 40.0 + DT, 100.0, refs[-1].pos_m)
    assert f.done and f.reached_t_s is not None
    assert after == refs2[0]
    f.retarget(100.0 + DT, (0.0, 0.0, 10.0))  # a new goal after the leg ended
    assert not f.done and f.reached_t_s is None
    ts3, refs3 = fly(f, 100.0 + DT, 150.0, refs2[-1].pos_m)
    assert f.done
    assert_run_smooth(ts + ts2 + ts3, refs + refs2 + refs3, 4.0, 2.0)


def test_leg_starts_from_a_moving_vehicle():
    f = LegFollower(5.0, 2.0, 0.05)
    f.start(0.0, (0, 0, 10), (3.0, -1.0, 0.5), (0.0, 20.0, 10.0))
    s = f.update(0.0, (0, 0, 10))
    assert s.pos_m == (0.0, 0.0, 10.0) and s.vel_m_s == (3.0, -1.0, 0.5)
    ts, refs = fly(f, 0.0, 60.0, (0.0, 0.0, 10.0))
    assert f.done and refs[-1].pos_m == (0.0, 20.0, 10.0)
    assert_run_smooth(ts, refs, 5.0, 2.0)


@settings(max_examples=8, deadline=None)
@given(wps=st.lists(st.tuples(*[st.floats(-60.0, 60.0)] * 2, st.floats(2.0, 60.0)),
                    min_size=1, max_size=3),
       retarget_at=st.floats(0.5, 20.0), new_goal=st.tuples(*[st.floats(-60.0, 60.0)] * 3))
def test_legs_random_missions(wps, retarget_at, new_goal):
    f = Chain(6.0, 3.0, 0.05, wps)
    ts, refs = fly(f, 0.0, retarget_at, (0.0, 0.0, 10.0))
    if not f.done:
        f.leg.retarget(retarget_at + DT, new_goal)
    ts2, refs2 = fly(f, retarget_at + DT, retarget_at + 200.0, refs[-1].pos_m)
    assert f.done
    assert [i for i, _ in f.reached] == list(range(len(wps)))
    times = [t for _, t in f.reached]
    assert times == sorted(times)
    assert_run_smooth(ts + ts2, refs + refs2, 6.0, 3.0)


def test_leg_needs_start():
    f = LegFollower(5.0, 2.0, 0.05)
    with pytest.raises(RuntimeError):
        f.update(0.0, (0, 0, 0))
    f.start(0.0, (1, 2, 3), (0, 0, 0), (1.0, 2.0, 3.0))
    fly(f, 0.0, 2.0, (1.0, 2.0, 3.0))
    assert f.done and f.update(5.0, (1, 2, 3)).pos_m == (1.0, 2.0, 3.0)
