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
