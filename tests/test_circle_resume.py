"""A loiter-turns circle the tether governor pauses resumes with the turns it has left
(companion.navigation with companion.legs): flown on a vehicle that tracks its reference
exactly, the angle swept about the centre from the circle's entry to its end is the item's
turns, however often the drum stops it, not the turns again from each resumption."""

from __future__ import annotations

import math

import pytest

from companion.legs import CircleItem, GotoItem, LegFollower
from companion.navigation import NavCommand, NavEvent, NavigationParams, Navigator, NavKind

CENTRE = (10.0, 0.0)
RADIUS_M = 5.0
ALT_M = 10.0


def _fly(turns: float, stops_at_s: tuple[float, ...]) -> tuple[float, int, float]:
    """Fly one loiter-turns item; the drum reports itself braked at the vehicle's distance
    (plus 0.5 m) at the first moment after each of ``stops_at_s`` [s] it moves outward
    at 0.5 m/s or more, for 3 s. Returns (turns swept about the
    centre after the first reach of the circle, brakes, time [s] the item was reached)."""
    nav = Navigator(NavigationParams(), 0.2, 60.0)
    dt = 0.004
    start = (CENTRE[0] + RADIUS_M, CENTRE[1], ALT_M)
    nav.start(0.0, start, (0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0))
    assert nav.flying
    nav.set_mission([NavCommand(1, NavKind.LOITER_TURNS, CENTRE, ALT_M, turns=turns,
                                circle_radius_m=RADIUS_M)])
    assert nav.start_mission() is None
    pos, vel = start, (0.0, 0.0, 0.0)
    swept, last, brakes, braked_until = 0.0, None, 0, -1.0
    stops = list(stops_at_s)
    t = 0.0
    while t < 300.0:
        t += dt
        d = math.dist(pos, (0.0, 0.0, 0.0))
        outward = sum(p * v for p, v in zip(pos, vel, strict=True)) / d
        if stops and t >= stops[0] and outward > 0.5:
            stops.pop(0)
            braked_until = t + 3.0
        braked = t < braked_until
        nav.winch_report(d + 0.5 if braked else 40.0, 5.0, braked, 0.0)
        ref, _ = nav.step(t, pos, vel, (1.0, 0.0, 0.0, 0.0), dt)
        assert ref is not None
        pos, vel = ref.pos_m, ref.vel_m_s
        a = math.atan2(pos[1] - CENTRE[1], pos[0] - CENTRE[0])
        if last is not None:
            swept += math.remainder(a - last, 2.0 * math.pi)
        last = a
        for kind, value in nav.pop_events():
            if kind is NavEvent.WARNING and str(value).startswith("Tether: braking"):
                brakes += 1
            if kind is NavEvent.REACHED and value == 1:
                return abs(swept) / (2.0 * math.pi), brakes, t
    raise AssertionError("the circle never ended")


@pytest.mark.parametrize("turns", [1.5, 3.0])
def test_a_paused_circle_resumes_with_the_turns_it_has_left(turns: float) -> None:
    free, brakes, t_free = _fly(turns, ())
    assert brakes == 0 and free == pytest.approx(turns, abs=0.02)
    stops = tuple(12.0 + 14.0 * k for k in range(int(turns)))
    paused, brakes, t_paused = _fly(turns, stops)
    assert brakes >= 1
    # the brake runs on along the tangent: a few degrees more than the item's turns
    assert turns - 0.02 <= paused <= turns + 0.1
    assert t_paused < t_free + len(stops) * 20.0


def test_remaining_item_of_a_circle() -> None:
    f = LegFollower(3.0, 2.0, 0.5)
    item = CircleItem(CENTRE, RADIUS_M, ALT_M, 3.0, turns=2.0)
    f.start(0.0, (CENTRE[0] + RADIUS_M, CENTRE[1], ALT_M), (0.0, 0.0, 0.0), item)
    assert f.remaining_item(0.0) == item               # not on the circle yet: all of it
    t = 0.0
    while f.phase.value != "circle":
        t += 0.01
        f.update(t, f.trajectory.sample(t).pos_m)
    circle = f.trajectory
    t_mid = circle.start_s + 0.5 * (circle.end_s - circle.start_s)
    f.update(t_mid, circle.sample(t_mid).pos_m)
    left = f.remaining_item(t_mid)
    assert isinstance(left, CircleItem) and left.start_angle_rad is None
    assert left.turns == pytest.approx(1.0, abs=1e-6)   # symmetric ramps: half the arc
    near_end = circle.end_s - 1e-3
    f.update(near_end, circle.sample(near_end).pos_m)
    end = f.remaining_item(near_end)
    assert isinstance(end, GotoItem) and end.pos_m == pytest.approx(circle.final_pos_m)
