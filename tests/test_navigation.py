"""The flight logic (companion.navigation) flying the plant's truth model in closed loop:
take-off from the ground, guided moves, a mission with the paper's circle, landing and the
land detector, RTL, and the refusals (tether reach, below ground, NaN, wrong mode)."""

from __future__ import annotations

import math

import pytest
from nav_harness import Loop

from companion.navigation import (
    FlightMode,
    MotorState,
    NavCommand,
    NavEvent,
    NavigationParams,
    NavKind,
    Reason,
)


def test_takeoff_from_the_ground_goto_and_land() -> None:
    loop = Loop()
    nav = loop.nav
    assert nav.landed and not nav.armed
    assert loop.pos[2] == pytest.approx(loop.params.vehicle.gear_height_m)
    why = nav.takeoff(10.0)
    assert why.reason is Reason.WRONG_MODE and str(why) == "Takeoff: not in GUIDED"
    assert nav.set_mode(FlightMode.GUIDED) is None
    assert nav.takeoff(10.0).reason is Reason.NOT_ARMED
    assert nav.arm() is None
    loop.run_until(lambda lp: False, 1.0)
    assert loop.motors is MotorState.IDLE and loop.pos[2] == pytest.approx(0.2, abs=1e-6)
    assert nav.takeoff(10.0) is None
    assert loop.run_until(lambda lp: NavEvent.TAKEOFF_DONE in lp.kinds(), 30.0)
    assert loop.pos[2] == pytest.approx(10.0, abs=0.3)
    assert nav.takeoff(12.0).reason is Reason.FLYING
    assert nav.disarm() is not None          # not in flight without force
    assert nav.goto((8.0, 6.0, 12.0)) is None
    assert loop.run_until(lambda lp: math.dist(lp.pos, (8.0, 6.0, 12.0)) < 0.05, 30.0)
    assert nav.set_mode(FlightMode.LAND) is None
    assert loop.run_until(lambda lp: not lp.nav.armed, 60.0)
    assert nav.landed
    assert math.hypot(loop.pos[0] - 8.0, loop.pos[1] - 6.0) < 0.1   # lands where it was
    assert NavEvent.LANDED in loop.kinds() and NavEvent.DISARMED in loop.kinds()
    assert loop.motors is MotorState.OFF
    assert loop.max_taut < 0.0               # the winder kept the tether slack throughout


def test_mission_with_circle_reaches_every_item_in_order() -> None:
    loop = Loop()
    nav = loop.nav
    nav.set_mission([
        NavCommand(1, NavKind.TAKEOFF, None, 10.0),
        NavCommand(2, NavKind.SPEED, speed_m_s=3.0),
        NavCommand(3, NavKind.WAYPOINT, (6.0, 0.0), 10.0),
        NavCommand(4, NavKind.LOITER_TURNS, (6.0, 6.0), 10.0, turns=1.0, circle_radius_m=6.0,
                   clockwise=False),
        NavCommand(5, NavKind.WAYPOINT, (0.0, 12.0), 12.0, hold_s=2.0),
        NavCommand(6, NavKind.LAND),
    ])
    assert nav.set_mode(FlightMode.AUTO) is None
    assert nav.arm() is None
    assert loop.run_until(lambda lp: not lp.nav.armed, 200.0)
    reached = [v for _, k, v in loop.events if k == NavEvent.REACHED]
    assert reached == [1, 3, 4, 5, 6]
    current = [v for _, k, v in loop.events if k == NavEvent.CURRENT]
    assert current == [1, 2, 3, 4, 5, 6]
    assert NavEvent.MISSION_DONE in loop.kinds()
    assert math.hypot(loop.pos[0], loop.pos[1] - 12.0) < 0.1
    assert nav.speed_m_s == 3.0
    # the hold at item 5 lasted its 2 s
    t5 = next(t for t, k, v in loop.events if k == NavEvent.REACHED and v == 5)
    t6 = next(t for t, k, v in loop.events if k == NavEvent.CURRENT and v == 6)
    assert t6 - t5 == pytest.approx(2.0, abs=0.02)
    assert loop.max_taut < 0.0


def test_rtl_returns_to_launch_and_disarms() -> None:
    loop = Loop(start_xy=(3.0, -1.0))
    nav = loop.nav
    nav.set_mode(FlightMode.GUIDED)
    nav.arm()
    nav.takeoff(6.0)
    assert loop.run_until(lambda lp: NavEvent.TAKEOFF_DONE in lp.kinds(), 30.0)
    nav.goto((12.0, 8.0, 8.0))
    assert loop.run_until(lambda lp: math.dist(lp.pos, (12.0, 8.0, 8.0)) < 0.1, 30.0)
    assert nav.set_mode(FlightMode.RTL) is None
    top = [0.0]

    def done(lp: Loop) -> bool:
        top[0] = max(top[0], lp.pos[2])
        return not lp.nav.armed

    assert loop.run_until(done, 120.0)
    assert math.hypot(loop.pos[0] - 3.0, loop.pos[1] + 1.0) < 0.1
    assert top[0] >= 10.0 + loop.params.vehicle.gear_height_m - 0.2   # climbed to RTL_ALT
    assert loop.max_taut < 0.0


def test_targets_beyond_reach_below_ground_or_nan_are_refused() -> None:
    loop = Loop()
    nav = loop.nav
    reach = nav.reach_m
    assert reach == pytest.approx(0.95 * loop.params.tether.total_length_m - 0.5)
    assert nav.check_target((reach + 0.5, 0.0, 0.0)).reason is Reason.BEYOND_REACH
    assert nav.check_target((reach - 0.5, 0.0, 0.0)) is None
    assert nav.check_target((1.0, 1.0, -0.5)).reason is Reason.BELOW_GROUND
    assert nav.check_target((math.nan, 0.0, 5.0)).reason is Reason.NOT_A_NUMBER
    nav.set_mode(FlightMode.GUIDED)
    nav.arm()
    assert nav.takeoff(60.0).reason is Reason.BEYOND_REACH
    nav.takeoff(5.0)
    assert loop.run_until(lambda lp: NavEvent.TAKEOFF_DONE in lp.kinds(), 30.0)
    before = loop.pos
    assert nav.goto((40.0, 30.0, 10.0)).reason is Reason.BEYOND_REACH
    assert nav.set_velocity((math.nan, 0.0, 0.0)).reason is Reason.NOT_A_NUMBER
    loop.run_until(lambda lp: False, 3.0)
    assert math.dist(loop.pos, before) < 0.05     # the refused targets changed nothing


def test_arming_rules_and_auto_disarm() -> None:
    loop = Loop(nav=NavigationParams(disarm_delay_s=2.0))
    nav = loop.nav
    assert nav.set_mode(FlightMode.LAND) is None
    assert nav.arm().reason is Reason.MODE_NOT_ARMABLE
    assert nav.arm(force=True) is None
    assert nav.disarm() is None
    nav.set_mode(FlightMode.LOITER)
    assert nav.arm() is None
    assert loop.run_until(lambda lp: not lp.nav.armed, 3.0)
    assert loop.t == pytest.approx(2.0, abs=0.05)
    assert nav.set_mode(FlightMode.AUTO).reason is Reason.MISSION_EMPTY
    assert nav.set_mode(FlightMode.ACRO).reason is Reason.UNSUPPORTED_MODE
    assert nav.set_mode(99).reason is Reason.UNKNOWN_MODE


def test_guided_velocity_target_moves_then_stops_after_timeout() -> None:
    loop = Loop()
    nav = loop.nav
    nav.set_mode(FlightMode.GUIDED)
    nav.arm()
    nav.takeoff(8.0)
    assert loop.run_until(lambda lp: NavEvent.TAKEOFF_DONE in lp.kinds(), 30.0)
    x0 = loop.pos[0]
    assert nav.set_velocity((1.0, 0.0, 0.0)) is None
    loop.run_until(lambda lp: False, 2.0)
    assert loop.plant.x[3] == pytest.approx(1.0, abs=0.15)
    loop.run_until(lambda lp: False, 5.0)          # past the 3 s timeout: it stops
    assert abs(loop.plant.x[3]) < 0.05
    travelled = loop.pos[0] - x0
    assert 2.5 < travelled < 5.0


def _rtl_run(loop: Loop, limit_s: float = 120.0) -> tuple[float, float, list]:
    """RTL from where the loop is: (its duration [s] to the disarm, the highest the
    vehicle went [m], the events meanwhile)."""
    n0, t0, top = len(loop.events), loop.t, [loop.pos[2]]
    assert loop.nav.set_mode(FlightMode.RTL) is None

    def done(lp: Loop) -> bool:
        top[0] = max(top[0], lp.pos[2])
        return not lp.nav.armed

    assert loop.run_until(done, limit_s)
    return loop.t - t0, top[0], loop.events[n0:]


def _descent_s(nav, x: float, y: float, z: float) -> float:
    """The time [s] RTL's descent from (x, y, z) [m] takes by its plans: to land_alt_low_m
    at speed_down_m_s, then at land_speed_m_s until the gear is on the ground, and the
    land detector's land_detect_s."""
    from companion.reference import Transition

    p, gear = nav.p, nav.gear_height_m
    low = gear + p.land_alt_low_m
    t = 0.0
    if z > low + 0.5:
        t += Transition((x, y, z), (x, y, low), 0.0, p.speed_down_m_s, p.acc_m_s2).end_s
        z = low
    final = Transition((x, y, z), (x, y, -1.0), 0.0, p.land_speed_m_s, p.acc_m_s2)
    lo, hi = 0.0, final.end_s        # when the plan reaches the gear's height
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if final.sample(mid).pos_m[2] > gear else (lo, mid)
    return t + hi + p.land_detect_s


def test_rtl_from_10_m_above_home_descends_at_once_unbraked_in_the_time_its_speeds_set():
    """ArduCopter's RTL near home: within its cone (RTL_CONE_SLOPE 3 x the distance from
    home) it does not climb to RTL_ALT; it waits RTL_LOIT_TIME and lands. Near the vertical
    above the winder the tether governor has nothing to slow or brake on the way down."""
    loop = Loop(start_xy=(2.0, 0.0))
    nav = loop.nav
    nav.set_mode(FlightMode.GUIDED)
    nav.arm()
    nav.takeoff(10.0)
    assert loop.run_until(lambda lp: NavEvent.TAKEOFF_DONE in lp.kinds(), 30.0)
    loop.run_until(lambda lp: False, 3.0)
    z0 = loop.pos[2]
    took, top, events = _rtl_run(loop)
    assert top < z0 + 0.05                                  # no climb
    planned = nav.p.rtl_loiter_s + _descent_s(nav, 2.0, 0.0, z0)
    assert planned - 0.5 < took < planned + 1.5, (took, planned)
    said = [str(v) for _, k, v in events if k in (NavEvent.WARNING, NavEvent.ERROR)]
    assert said == []                                       # nothing to say
    assert math.hypot(loop.pos[0] - 2.0, loop.pos[1]) < 0.1
    assert loop.max_taut < 0.0


def test_rtl_climbs_within_its_cone_and_its_descent_is_never_braked():
    """From farther out RTL climbs to RTL_ALT (within the cone), flies home, descends and
    lands: the descent (the line only shortening) meets no brake and no slowing, and the
    governor's texts, if any, come at most once per kind every few seconds."""
    from companion.statustext import TEXT_KIND_INTERVAL_S, Notice

    loop = Loop(start_xy=(3.0, -1.0))
    nav = loop.nav
    nav.set_mode(FlightMode.GUIDED)
    nav.arm()
    nav.takeoff(4.0)
    assert loop.run_until(lambda lp: NavEvent.TAKEOFF_DONE in lp.kinds(), 30.0)
    assert nav.goto((6.0, 1.0, 4.0)) is None      # 3.6 m from home: the cone allows 10.9 m
    assert loop.run_until(lambda lp: math.dist(lp.pos, (6.0, 1.0, 4.0)) < 0.1, 30.0)
    took, top, events = _rtl_run(loop)
    gear = nav.gear_height_m
    assert top == pytest.approx(gear + nav.p.rtl_alt_m, abs=0.1)
    assert math.hypot(loop.pos[0] - 3.0, loop.pos[1] + 1.0) < 0.1
    # the descent began when the vehicle, home, started down: no governor text after it
    down = next(t for t, k, v in events if k is NavEvent.LANDED) - _descent_s(
        nav, 3.0, -1.0, gear + nav.p.rtl_alt_m)
    late = [(t, str(v)) for t, k, v in events if isinstance(v, Notice) and t > down - 1.0]
    assert late == []
    kinds: dict[object, list[float]] = {}
    for t, _, v in events:
        if isinstance(v, Notice):
            kinds.setdefault(v.kind, []).append(t)
    for times in kinds.values():
        assert all(b - a >= TEXT_KIND_INTERVAL_S for a, b in zip(times, times[1:], strict=False))
    assert loop.max_taut < 0.0


def test_rtl_altitude_is_arducopters_return_target():
    """RTL_ALT above home unless home is near (RTL_CONE_SLOPE 3 x the horizontal distance,
    never below RTL_ALT_MIN 2 m), never below where the vehicle is."""
    loop = Loop(start_xy=(2.0, 0.0))
    nav = loop.nav
    g, home = nav.gear_height_m, (2.0, 0.0, nav.gear_height_m)
    assert nav.rtl_altitude_m((2.0, 0.0, g + 9.8), home) == pytest.approx(g + 9.8)
    assert nav.rtl_altitude_m((2.0, 0.0, g + 1.0), home) == pytest.approx(g + 2.0)
    assert nav.rtl_altitude_m((3.0, 0.0, g + 1.0), home) == pytest.approx(g + 3.0)
    assert nav.rtl_altitude_m((22.0, 0.0, g + 1.0), home) == pytest.approx(g + 10.0)
    assert nav.rtl_altitude_m((22.0, 0.0, g + 15.0), home) == pytest.approx(g + 15.0)
