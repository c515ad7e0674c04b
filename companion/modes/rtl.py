"""RTL: climb to the return altitude if lower (within the tether's reach), fly back above
home or the nearest rally point, pause ``rtl_loiter_s``, and land there (while the ground
winds the tether in: the winder follows L-bar)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from companion.legs import GotoItem
from companion.nav_types import LegTag, NavEvent
from companion.plan import Leg, stop_point
from companion.statustext import Notice, TextKind

if TYPE_CHECKING:
    from companion.navigation import Navigator

Vec3 = tuple[float, float, float]

#: ArduCopter's RTL_CONE_SLOPE default: RTL climbs to at most this many times its
#: horizontal distance from home (0.5 and more; ArduCopter's 0 switches the cone off).
RTL_CONE_SLOPE = 3.0
#: ArduCopter's RTL_ALT_MIN: the least height [m] above home RTL returns at.
RTL_ALT_MIN_M = 2.0


class Rtl:
    """The return to launch: where to, at which height, and its legs (the landing's are
    :class:`companion.modes.land.Land`'s, begun when the way home ends)."""

    def __init__(self, nav: Navigator) -> None:
        self.nav = nav

    def enter(self) -> None:
        """RTL has just been set: a flying vehicle returns."""
        nav = self.nav
        nav.mission_running = False
        if nav.flying:
            self.start()

    def destination(self, stop: Vec3) -> Vec3:
        """Where RTL goes from ``stop`` [m]: home, or the nearest rally point (as
        ArduCopter with RALLY_INCL_HOME 1: home counts as one) that is within the reach."""
        nav = self.nav
        home = nav.home_m if nav.home_m is not None else (0.0, 0.0, 0.0)
        best, best_d = home, math.hypot(home[0] - stop[0], home[1] - stop[1])
        for r in nav.rally_m:
            d = math.hypot(r[0] - stop[0], r[1] - stop[1])
            if d < best_d and nav.check_target((r[0], r[1], max(r[2], 0.0))) is None:
                best, best_d = r, d
        return best

    def altitude_m(self, stop: Vec3, home: Vec3) -> float:
        """The height [m] RTL returns at from ``stop`` [m] to ``home`` [m], as ArduCopter
        computes it (ModeRTL's return target, its default RTL_CONE_SLOPE and RTL_CLIMB_MIN
        0): ``rtl_alt_m`` above home, at least :data:`RTL_ALT_MIN_M`, but within a cone
        of :data:`RTL_CONE_SLOPE` above home (a vehicle near home climbs little or not
        at all), and never below where it is. The tether's reach bounds it after."""
        nav = self.nav
        base = nav.gear_height_m
        here = stop[2] - base
        least = max(RTL_ALT_MIN_M, here)
        target = max(nav.p.rtl_alt_m, least)
        cone = RTL_CONE_SLOPE * math.hypot(home[0] - stop[0], home[1] - stop[1])
        target = min(target, max(cone, least))
        return base + max(target, here)

    def start(self, seq: int | None = None) -> None:
        """Fly the return (for mission item ``seq``) from the reference's stopping point."""
        nav = self.nav
        ref = nav.plan.current_ref()
        legs: list[Leg] = []
        stop = stop_point(ref, nav.p.acc_m_s2)
        home = self.destination(stop)
        alt = self.altitude_m(stop, home)
        # the climb and the way home stay within the tether's reach, whatever RTL_ALT says
        # (a level line's farthest point from the winder is one of its ends)
        reach = nav.reach_m
        far_h = max(math.hypot(stop[0], stop[1]), math.hypot(home[0], home[1]))
        cap = math.sqrt(max(reach * reach - far_h * far_h, 0.0))
        if alt > cap:
            nav._emit(NavEvent.WARNING, Notice(
                TextKind.RTL_ALT_LIMITED, f"RTL: altitude {alt:.1f} m cut to {cap:.1f} m by "
                "the tether"))
            alt = max(cap, nav.gear_height_m)
        if alt > stop[2] + 0.5:
            legs.append(Leg(nav.plan.follower(nav.p.speed_up_m_s),
                            GotoItem((stop[0], stop[1], alt), None), seq=seq,
                            tag=LegTag.RTL_CLIMB))
        legs.append(Leg(nav.plan.follower(nav.speed_m_s, hold_s=nav.p.rtl_loiter_s),
                        GotoItem((home[0], home[1], alt), None), seq=seq, tag=LegTag.RTL_HOME))
        nav.plan.vel = None
        nav.plan.queue(legs)
