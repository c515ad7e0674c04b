"""The tether's reach enforced in every mode, flying the plant's truth model in closed loop:
RTL climbs no higher than the tether allows whatever RTL_ALT says, a mission item without
a position of its own is checked where it is flown, a streamed velocity target stops at the
reach, GUID_TIMEOUT is bounded, a braked drum bounds the reach by its length, and an
over-tension that lasts (not a snap) moves the vehicle towards the winder. The truth: the
distance from the winder against the reach, and the tether never taut (distance below the
paid-out length)."""

from __future__ import annotations

import math

import pytest
from nav_harness import Loop

from companion.navigation import (
    FlightMode,
    NavCommand,
    NavEvent,
    NavigationParams,
    NavKind,
    Reason,
)
from tuavdefs.paramspec import ParameterError

#: 0.3 of the 50 m tether less 0.5 m of slack: a reach of 14.5 m, met within seconds.
SHORT = {"reach_fraction": 0.3}


def flying_at(pos, nav_params: NavigationParams) -> Loop:
    """A loop with the vehicle taken off and holding at ``pos`` in GUIDED."""
    loop = Loop(nav=nav_params)
    nav = loop.nav
    assert nav.set_mode(FlightMode.GUIDED) is None and nav.arm() is None
    assert nav.takeoff(pos[2]) is None
    assert loop.run_until(lambda lp: NavEvent.TAKEOFF_DONE in lp.kinds(), 30.0)
    assert nav.goto(pos) is None
    assert loop.run_until(lambda lp: math.dist(lp.pos, pos) < 0.1, 30.0)
    return loop


def farthest(loop: Loop, cond, limit_s: float) -> float:
    """Run until ``cond`` (or ``limit_s``); the largest distance from the winder seen."""
    top = [math.dist(loop.pos, (0.0, 0.0, 0.0))]

    def watch(lp: Loop) -> bool:
        top[0] = max(top[0], math.dist(lp.pos, (0.0, 0.0, 0.0)))
        return cond(lp)

    loop.run_until(watch, limit_s)
    return top[0]


def texts(loop: Loop, kind: NavEvent) -> list[str]:
    return [str(v) for _, k, v in loop.events if k is kind]


def test_rtl_climbs_no_higher_than_the_tether_allows() -> None:
    # RTL_ALT 1500 "cm" taken as 1500 m climbed until the whole tether was out
    loop = flying_at((10.0, 0.0, 5.0), NavigationParams(rtl_alt_m=1500.0, **SHORT))
    nav = loop.nav
    reach = nav.reach_m
    assert reach == pytest.approx(14.5)
    assert nav.set_mode(FlightMode.RTL) is None
    top = farthest(loop, lambda lp: not lp.nav.armed, 90.0)
    assert not nav.armed and nav.landed                      # home and down
    assert top <= reach + 0.3
    assert loop.max_taut < 0.0
    assert any("cut to" in t and "tether" in t for t in texts(loop, NavEvent.WARNING))


def test_an_item_without_a_position_is_checked_where_it_is_flown() -> None:
    loop = flying_at((12.0, 0.0, 5.0), NavigationParams(**SHORT))
    nav = loop.nav
    # latitude = longitude = 0: flown from here, where 14 m up is out of reach
    # (at the winder, where the upload checks it, it is not)
    assert nav.check_target((0.0, 0.0, 14.0)) is None
    nav.set_mission([NavCommand(1, NavKind.WAYPOINT, None, 14.0)])
    assert nav.set_mode(FlightMode.AUTO) is None
    top = farthest(loop, lambda lp: False, 10.0)
    assert top <= nav.reach_m + 0.1
    assert loop.pos[2] == pytest.approx(5.0, abs=0.3)       # held where it was
    assert not nav.mission_running
    assert any("item 1" in t and "reach" in t for t in texts(loop, NavEvent.ERROR))
    assert loop.max_taut < 0.0


def test_a_streamed_velocity_target_stops_at_the_reach() -> None:
    loop = flying_at((5.0, 0.0, 5.0), NavigationParams(**SHORT))
    nav = loop.nav
    t0 = loop.t

    def stream(lp: Loop) -> bool:     # a ground station sending 2 m/s east at 4 Hz
        if lp.k % 250 == 0:
            assert lp.nav.set_velocity((2.0, 0.0, 0.0)) is None
        return lp.t - t0 > 12.0

    top = farthest(loop, stream, 13.0)
    assert top <= nav.reach_m + 0.1
    assert loop.pos[0] > 10.0                               # it did go until there
    assert texts(loop, NavEvent.WARNING)
    assert loop.max_taut < 0.0


def test_guid_timeout_is_bounded_as_arducopters() -> None:
    for bad in (0.0, 6.0, 1e9):
        with pytest.raises(ParameterError) as exc:
            NavigationParams.from_dict({"guided_velocity_timeout_s": bad})
        assert exc.value.field.endswith("guided_velocity_timeout_s")
    assert NavigationParams.from_dict({"guided_velocity_timeout_s": 5.0})


def test_a_braked_drum_bounds_the_reach_by_its_length() -> None:
    loop = flying_at((5.0, 0.0, 5.0), NavigationParams())
    nav, companion = loop.nav, loop.companion
    # the winch LOCKed at 8 m: 0.95 * 8 - 0.5 = 7.1 m of reach
    companion.winch_report(loop.t, 8.0, 0.0, 5.0, braked=True)
    why = nav.goto((9.0, 0.0, 5.0))
    assert why is not None and why.reason is Reason.BEYOND_REACH
    assert nav.goto((4.5, 0.0, 5.0)) is None                # within the locked length
    companion.winch_report(loop.t, 8.0, 0.0, 5.0, braked=False)
    assert nav.goto((9.0, 0.0, 5.0)) is None                # released: the whole tether


def test_over_tension_moves_the_vehicle_towards_the_winder() -> None:
    loop = flying_at((8.0, 0.0, 6.0), NavigationParams(tension_limit_n=20.0))
    nav, companion = loop.nav, loop.companion
    d0 = math.dist(loop.pos, (0.0, 0.0, 0.0))
    loop.winch_link = False             # the winch's reports are the test's from here

    def over_tension() -> list[float]:
        return [t for t, k, v in loop.events
                if k is NavEvent.FAILSAFE and "over-tension" in str(v)]

    # a snap of the line: one report at 8 kg, then the line's usual tension
    companion.winch_report(loop.t, 10.0, 0.0, 80.0)
    loop.run_until(lambda lp: False, 0.1)
    companion.winch_report(loop.t, 10.0, 0.0, 5.0)
    loop.run_until(lambda lp: False, 1.0)
    assert not over_tension()
    # 8 kg in every report (20 Hz): the vehicle moves once it has lasted tension_time_s
    start = loop.t
    clock = {"next": start}

    def loaded(lp: Loop) -> bool:
        if lp.t >= clock["next"] - 1e-9:
            clock["next"] += 0.05
            companion.winch_report(lp.t, 10.0, 0.0, 80.0)
        return bool(over_tension())

    assert loop.run_until(loaded, 2.0)
    assert nav.p.tension_time_s <= over_tension()[0] - start <= nav.p.tension_time_s + 0.06
    assert nav.mode is FlightMode.GUIDED
    loop.winch_link = True
    loop.run_until(lambda lp: False, 6.0)
    d1 = math.dist(loop.pos, (0.0, 0.0, 0.0))
    assert d1 == pytest.approx(d0 - nav.p.tension_step_m, abs=0.2)
    assert loop.max_taut < 0.0
