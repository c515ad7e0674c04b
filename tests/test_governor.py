"""The tether governor's interface (companion.governor.TetherGovernor) against its definition,
without a plant: for a given reported tether state (length, line speed, braked drum), the
limit it keeps, the speed it allows (the stop from it, a latency at that speed then a
constant deceleration, ends on the limit: the analytic v t + v^2 / 2a = r), the brake
decision at the analytic stopping distance of its jerk-limited brake, the brake itself
integrated against that distance, where it resumes and moves in, and the over-tension's
timing."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.governor import (
    GOVERNOR_SLOW_MARGIN_M,
    GOVERNOR_SLOW_RAMP_S,
    GOVERNOR_SLOWING_OVER_ABOVE,
    TENSION_REPEAT_S,
    TETHER_BRAKE_JERK_M_S3,
    TETHER_RESUME_ROOM_M,
    WIND_IN_LEAD_S,
    TetherGovernor,
    Verdict,
    brake_distance_m,
    check_kernel,
    governed_speed_m_s,
    slow_clock_kernel,
)
from companion.navigation import NavigationParams
from companion.reference import RefSample

FULL_M = 50.0       # the length on the full drum
GEAR_M = 0.2
ZERO = (0.0, 0.0, 0.0)


def governor(**params: float) -> TetherGovernor:
    """The governor for a length law (``tether_governor`` 1, the paper's winder; the
    default, 2, counts on the tension law: tests/test_tension_law.py)."""
    return TetherGovernor(NavigationParams(**{"tether_governor": 1, **params}), FULL_M,
                          GEAR_M)


def radial(d_m: float, speed_m_s: float) -> RefSample:
    """A reference at ``d_m`` from the winder on a 45-degree line, moving outward along it
    at ``speed_m_s``, not accelerating."""
    u = (math.sqrt(0.5), 0.0, math.sqrt(0.5))
    return RefSample(tuple(d_m * c for c in u), tuple(speed_m_s * c for c in u), ZERO, ZERO,
                     0.0, 0.0)


def test_the_limit_is_the_reported_length_less_the_margin() -> None:
    gov = governor()
    margin = NavigationParams().tether_margin_m
    assert gov.limit_m == pytest.approx(FULL_M - margin)          # before any report
    assert gov.reach_length_m == FULL_M
    gov.report(20.0, braked=False, speed_m_s=0.8)                  # paying out
    assert gov.limit_m == pytest.approx(20.0 - margin)
    assert gov.reach_length_m == FULL_M                            # a free drum pays out
    gov.report(20.0, braked=False, speed_m_s=-1.0)                 # winding in: 0.15 s on
    assert gov.limit_m == pytest.approx(20.0 - WIND_IN_LEAD_S * 1.0 - margin)
    gov.report(18.0, braked=True, speed_m_s=0.0)                   # braked: its length
    assert gov.limit_m == pytest.approx(18.0 - margin)
    assert gov.reach_length_m == 18.0
    gov.report(float("nan"), braked=True, speed_m_s=None)          # a bad report: kept
    assert gov.limit_m == pytest.approx(18.0 - margin) and gov.locked_length_m is None


@pytest.mark.parametrize("latency_s", [0.0, 0.3, 1.0])
def test_the_governed_speed_stops_on_the_limit(latency_s: float) -> None:
    a = 3.0
    u = (0.6, 0.0, 0.8)
    for d, lim in ((2.0, 10.0), (9.5, 10.0), (0.0, 3.0)):
        p = (d * u[0], d * u[1], d * u[2])
        v = governed_speed_m_s(p, u, lim, latency_s, a)
        assert v * latency_s + v * v / (2.0 * a) == pytest.approx(lim - d, abs=1e-9)
    # across the line: the distance to the sphere along the direction
    p, side = (3.0, 0.0, 4.0), (0.0, 1.0, 0.0)
    v = governed_speed_m_s(p, side, 10.0, latency_s, a)
    assert v * latency_s + v * v / (2.0 * a) == pytest.approx(math.sqrt(100.0 - 25.0))
    # beyond the limit: nothing outward, anything inward
    beyond = (0.0, 0.0, 11.0)
    assert governed_speed_m_s(beyond, (0.0, 0.0, 1.0), 10.0, latency_s, a) == 0.0
    assert governed_speed_m_s(beyond, (0.0, 0.0, -1.0), 10.0, latency_s, a) == math.inf


def test_the_velocity_cap_for_a_reported_length() -> None:
    """A velocity target streamed outward is capped at the speed whose stop (the
    vehicle's latency, then the brake's deceleration) ends on the reported length less the
    margins: the estimate's sigma_k standard deviations and the slowing's own."""
    p = NavigationParams()
    gov = governor()
    gov.report(20.0, braked=False, speed_m_s=0.0)
    sigma = 0.1
    pos = radial(19.0, 0.0).pos_m
    cap, notice = gov.velocity_cap((1.5, 0.0, 1.5), pos, pos, sigma)
    room = 20.0 - p.tether_margin_m - GOVERNOR_SLOW_MARGIN_M - p.tether_sigma_k * sigma - 19.0
    assert cap * p.tether_latency_s + cap * cap / (2.0 * p.tether_brake_acc_m_s2) \
        == pytest.approx(room, abs=1e-9)
    assert cap < math.hypot(1.5, 1.5) and notice is not None      # slowed, said once
    assert gov.velocity_cap((1.5, 0.0, 1.5), pos, pos, sigma)[1] is None
    # inward: the room through the winder to the far side, without the margins
    cap_in = gov.velocity_cap((-1.5, 0.0, -1.5), pos, pos, sigma)[0]
    assert cap_in * p.tether_latency_s + cap_in * cap_in / (2.0 * p.tether_brake_acc_m_s2) \
        == pytest.approx(gov.limit_m + 19.0, abs=1e-9)
    # the drum reports more line: a higher cap
    gov.report(30.0, braked=False, speed_m_s=0.0)
    assert gov.velocity_cap((1.5, 0.0, 1.5), pos, pos, sigma)[0] > cap


def brake_run_m(v: float, a: float, j: float) -> float:
    """The exact run of a brake from ``v`` [m/s], not accelerating: the deceleration
    reaches ``a`` at jerk ``j``, then holds."""
    t1 = a / j
    v1 = v - 0.5 * a * t1
    return v * t1 - j * t1 ** 3 / 6.0 + v1 * v1 / (2.0 * a)


def test_the_brake_decision_at_its_stopping_distance() -> None:
    """With the vehicle still where the reference is, the governor brakes a reference
    moving outward exactly when the bound of its brake's run (the build-up at the speed it
    had, then v^2 / 2a; above the exact run) would pass the limit."""
    p = NavigationParams(tether_sigma_k=0.0)
    gov = governor(tether_sigma_k=0.0)
    gov.report(20.0, braked=False, speed_m_s=0.0)
    lim = 20.0 - p.tether_margin_m
    v, a = 2.0, p.tether_brake_acc_m_s2
    run = v * a / TETHER_BRAKE_JERK_M_S3 + v * v / (2.0 * a)
    assert run == pytest.approx(brake_distance_m(v, 0.0, a, TETHER_BRAKE_JERK_M_S3))
    assert run > brake_run_m(v, a, TETHER_BRAKE_JERK_M_S3)
    for d, want in ((lim - run - 0.01, Verdict.FLY), (lim - run + 0.01, Verdict.BRAKE)):
        ref = radial(d, v)
        decision = gov.check(ref, ref.pos_m, ZERO, 0.0)
        assert decision.verdict is want and decision.limit_m == pytest.approx(lim)
    # moving inward, or at rest: never a brake
    ref = radial(lim - 0.01, -v)
    assert gov.check(ref, ref.pos_m, ZERO, 0.0).verdict is Verdict.FLY
    ref = radial(lim + 1.0, 0.0)
    assert gov.check(ref, ref.pos_m, ZERO, 0.0).verdict is Verdict.AT_REST
    # the vehicle's own stop counts too: a reference far inside, the vehicle near the limit
    # moving outward at v (its latency at v, then the deceleration)
    ref = radial(5.0, v)
    veh = radial(lim - v * p.tether_latency_s - v * v / (2.0 * a) + 0.01, v)
    assert gov.check(ref, veh.pos_m, veh.vel_m_s, 0.0).verdict is Verdict.BRAKE


def test_the_brake_runs_its_analytic_distance() -> None:
    """The brake's run from a speed [m/s] against the exact jerk-limited stop (its steps
    take the acceleration at their end: a run short by O(dt)) and within the bound the
    decision uses."""
    gov = governor()
    v, a, dt = 2.0, NavigationParams().tether_brake_acc_m_s2, 0.0005
    ref = gov.start_brake(radial(10.0, v), dt)
    for _ in range(100_000):
        ref, stopped = gov.step_brake(dt)
        if stopped:
            break
    assert stopped and gov.brake is None
    run = math.dist(ref.pos_m, ZERO) - 10.0
    assert run == pytest.approx(brake_run_m(v, a, TETHER_BRAKE_JERK_M_S3), abs=1e-3)
    assert run <= brake_distance_m(v, 0.0, a, TETHER_BRAKE_JERK_M_S3)


def test_resume_and_move_in_for_a_reported_drum() -> None:
    gov = governor()
    here = radial(15.0, 0.0).pos_m
    gov.report(15.0 + TETHER_RESUME_ROOM_M + 0.05, braked=False, speed_m_s=0.5)
    assert gov.may_resume(here, here, gov.limit_m)                  # the room to resume
    gov.report(15.05, braked=False, speed_m_s=0.5)                  # paying out, short
    assert not gov.may_resume(here, here, gov.limit_m)
    gov.report(15.05, braked=False, speed_m_s=0.0)                  # caught up, some room
    assert gov.may_resume(here, here, gov.limit_m)
    assert gov.move_in_target(here, gov.limit_m) is None            # a free drum
    gov.report(14.0, braked=True, speed_m_s=0.0)                    # braked short of it
    assert not gov.may_resume(here, here, gov.limit_m)
    target = gov.move_in_target(here, gov.limit_m)
    assert math.dist(target, ZERO) == pytest.approx(gov.limit_m - TETHER_RESUME_ROOM_M)
    assert target[0] == pytest.approx(target[2])                     # on the same line
    low = (14.5, 0.0, 0.5)                                           # kept 1 m above gear
    assert gov.move_in_target(low, gov.limit_m)[2] == 0.5


def test_over_tension_lasting_then_repeating() -> None:
    """An over-tension in every report for tension_time_s moves the vehicle
    tension_step_m towards the winder along its line (not a snap, not while it may not
    move, again only TENSION_REPEAT_S later), never lower than 1 m above the gear."""
    p = NavigationParams()
    gov = governor()
    over = p.tension_limit_n + 1.0
    here = radial(10.0, 0.0).pos_m

    def move(t: float, tension: float | None, may: bool = True):
        return gov.over_tension(t, tension, may, here)

    assert move(0.0, over) is None
    assert move(p.tension_time_s - 0.01, over) is None
    assert move(p.tension_time_s - 0.005, p.tension_limit_n) is None   # a snap: reset
    assert move(1.0, over) is None                                      # starts again
    target = move(1.0 + p.tension_time_s, over)
    assert math.dist(target, ZERO) == pytest.approx(10.0 - p.tension_step_m)
    assert target[0] == pytest.approx(target[2]) and target[1] == 0.0  # on its line
    assert move(1.0 + p.tension_time_s + 0.1, over) is None
    t = 1.0 + p.tension_time_s + TENSION_REPEAT_S
    assert move(t, over, may=False) is None                             # may not move now
    assert move(t, over) is not None
    assert move(t + 5.0, None) is None                                  # unknown: reset
    low = (20.0, 0.0, 0.5)
    for k in range(3):
        gov.over_tension(10.0 + k, over, True, low)
    assert gov.over_tension(10.0 + 2 * TENSION_REPEAT_S, over, True, low)[2] == 0.5


def test_slow_clock_follows_the_room_and_gives_it_back() -> None:
    """A leg moving outward faster than the room allows: the clock's rate falls below 1
    (said once), and the reference it scales moves no faster than the governed speed plus
    what the rate's own lag leaves; moving inward, the rate returns to 1."""
    p = NavigationParams()
    gov = governor()
    gov.report(20.0, braked=False, speed_m_s=0.0)
    nom = radial(19.0, 2.0)
    notices = [gov.slow_clock(nom, nom.pos_m, ZERO, 0.0, 0.01) for _ in range(300)]
    assert sum(n is not None for n in notices) == 1
    # the speed it leaves stops within the limit (its latency, with the clock's own
    # build-up, at that speed, then the brake's deceleration)
    speed = math.dist(gov.scaled(nom).vel_m_s, ZERO)
    lat, a = p.tether_latency_s + GOVERNOR_SLOW_RAMP_S, p.tether_brake_acc_m_s2
    assert 0.0 < gov.s < 1.0 and gov.clock_lag > 0.0
    assert speed * lat + speed * speed / (2.0 * a) <= gov.limit_m - 19.0 + 1e-4
    back = radial(19.0, -2.0)
    for _ in range(1000):
        gov.slow_clock(back, back.pos_m, ZERO, 0.0, 0.01)
    assert gov.s == pytest.approx(1.0, abs=1e-9) and gov.sd == pytest.approx(0.0, abs=1e-9)


def test_each_slowing_of_the_clock_is_said_once() -> None:
    """Out, back in, out again: two slowings, each said once, though the clock returning
    critically damped never rounds to a rate of exactly 1 (the notice's hysteresis:
    said below GOVERNOR_SLOWING_SAID_BELOW, over above GOVERNOR_SLOWING_OVER_ABOVE)."""
    gov = governor()
    gov.report(20.0, braked=False, speed_m_s=0.0)
    out, back = radial(19.0, 2.0), radial(19.0, -2.0)
    said = []
    for nom, periods in ((out, 300), (back, 3000), (out, 300)):
        notices = [gov.slow_clock(nom, nom.pos_m, ZERO, 0.0, 0.01) for _ in range(periods)]
        said.append(sum(n is not None for n in notices))
        if nom is back:
            assert GOVERNOR_SLOWING_OVER_ABOVE <= gov.s < 1.0
    assert said == [1, 0, 1]


def test_the_compiled_decisions_are_their_python_to_the_bit() -> None:
    """The governor's compiled period (companion.governor.slow_clock_kernel, check_kernel)
    gives the same bits as its own Python source interpreted, over references and vehicles
    moving every way near and far from the limit, with and without a margin, a clock
    slowed or not; each verdict is seen, the clock's rate stays in [0, 1]."""
    rng = np.random.default_rng(11)
    kernels = (slow_clock_kernel, check_kernel)
    verdicts: set[int] = set()
    for _ in range(3000):
        p = rng.normal(0.0, 10.0, 3)
        p[2] = abs(p[2]) + 0.5
        d = float(np.linalg.norm(p))
        period = tuple(float(x) for x in (
            *p, *rng.normal(0.0, 2.0, 3), *rng.normal(0.0, 1.0, 3),
            *(p + rng.normal(0.0, 0.2, 3)), *rng.normal(0.0, 1.0, 3),
            rng.uniform(0.0, 0.3), rng.uniform(0.0, 1.0), rng.uniform(-1.0, 1.0), 0.004))
        if rng.uniform() < 0.1:      # at rest
            period = period[:3] + ZERO + period[6:]
        room = (d + float(rng.uniform(-0.2, 2.0)), 3.0, 0.4, 3.0, float(rng.uniform(-1, 1)))
        for kernel in kernels:
            got, want = kernel(period, room), getattr(kernel, "py_func", kernel)(period, room)
            assert np.array(got, float).tobytes() == np.array(want, float).tobytes()
        verdicts.add(check_kernel(period, room)[0])
        assert 0.0 <= slow_clock_kernel(period, room)[0] <= 1.0
    assert verdicts == {int(v) for v in Verdict}


def test_the_reach_and_the_mode_follow_each_report_and_parameter_set() -> None:
    """The navigator's reach (``reach_fraction`` x the length targets may use, less
    ``reach_slack_m``) and the governor's mode, read every period, are those of the last
    winch report and the last parameters, read before and after each change."""
    from companion.navigation import Navigator

    nav = Navigator(NavigationParams(tether_governor=1), GEAR_M, FULL_M)
    assert nav.reach_m == pytest.approx(0.95 * FULL_M - 0.5)
    assert nav.governor.enabled
    nav.winch_report(15.0, 5.0, True)                              # braked at 15 m
    assert nav.reach_m == pytest.approx(0.95 * 15.0 - 0.5)
    nav.winch_report(15.0, 5.0, False)                             # released
    assert nav.reach_m == pytest.approx(0.95 * FULL_M - 0.5)
    nav.p = NavigationParams(tether_governor=0, reach_fraction=0.8, reach_slack_m=1.0)
    assert nav.reach_m == pytest.approx(0.8 * FULL_M - 1.0)
    assert not nav.governor.enabled
    nav.p = NavigationParams(tether_governor=2)
    assert nav.governor.enabled and nav.governor.mode == 2
