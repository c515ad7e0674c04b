"""RTL ends at the nearest rally point when one is nearer than home (ArduCopter with
RALLY_INCL_HOME = 1), never at one beyond the tether's reach; flown in closed loop on the
plant's truth model."""

from __future__ import annotations

import math

from nav_harness import Loop

from companion.navigation import FlightMode, NavEvent, NavigationParams


def flying_at(pos) -> Loop:
    loop = Loop(nav=NavigationParams())
    nav = loop.nav
    assert nav.set_mode(FlightMode.GUIDED) is None and nav.arm() is None
    assert nav.takeoff(pos[2]) is None
    assert loop.run_until(lambda lp: NavEvent.TAKEOFF_DONE in lp.kinds(), 30.0)
    assert nav.goto(pos) is None
    assert loop.run_until(lambda lp: math.dist(lp.pos, pos) < 0.1, 30.0)
    return loop


def test_rtl_lands_at_the_nearest_rally_point():
    loop = flying_at((14.0, 6.0, 8.0))
    loop.nav.rally_m = ((12.0, 9.0, 0.0), (-20.0, 0.0, 0.0))   # near, and farther than home
    assert loop.nav.set_mode(FlightMode.RTL) is None
    assert loop.run_until(lambda lp: not lp.nav.armed, 120.0)
    assert math.dist(loop.pos[:2], (12.0, 9.0)) < 0.5
    assert loop.max_taut < 0.0


def test_home_when_it_is_nearer_and_never_beyond_the_reach():
    loop = flying_at((6.0, 2.0, 8.0))
    nav = loop.nav
    assert nav.rtl_destination((6.0, 2.0, 8.0)) == nav.home_m
    nav.rally_m = ((300.0, 0.0, 0.0),)                 # beyond the 50 m tether
    assert nav.rtl_destination((250.0, 0.0, 8.0)) == nav.home_m
    nav.rally_m = ((5.0, 2.5, 0.0),)
    assert nav.rtl_destination((6.0, 2.0, 8.0)) == (5.0, 2.5, 0.0)
