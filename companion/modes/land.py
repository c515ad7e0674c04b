"""LAND: descend where the vehicle is (or at a mission landing's point), at
``speed_down_m_s`` to ``land_alt_low_m`` above the gear, then at ``land_speed_m_s`` to below
the ground; the land detector ends it and disarms."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from companion.legs import GotoItem
from companion.nav_types import LegTag, NavEvent
from companion.plan import Leg, stop_point

if TYPE_CHECKING:
    from companion.navigation import Navigator

Vec3 = tuple[float, float, float]


class Land:
    """The landing: its legs and the land detector (on the gear, or pushed
    ``land_stall_m`` below its reference, still, for ``land_detect_s``)."""

    def __init__(self, nav: Navigator) -> None:
        self.nav = nav
        self._still_since: float | None = None   # down and still since [s]

    def enter(self) -> None:
        """LAND has just been set: a flying vehicle lands where it is."""
        nav = self.nav
        nav.mission_running = False
        if nav.flying:
            self.land_here()

    def legs(self, xy: tuple[float, float], seq: int | None = None) -> list[Leg]:
        """The descent at ``xy`` [m] from the reference's height (for mission item
        ``seq``)."""
        nav = self.nav
        ref = nav.plan.current_ref()
        legs: list[Leg] = []
        low = nav.gear_height_m + nav.p.land_alt_low_m
        if ref.pos_m[2] > low + 0.5:
            legs.append(Leg(nav.plan.follower(nav.p.speed_down_m_s, 1.0),
                            GotoItem((xy[0], xy[1], low), None), seq=seq, tag=LegTag.LAND_HIGH))
        # the final descent aims below the ground: the land detector ends it
        legs.append(Leg(nav.plan.follower(nav.p.land_speed_m_s),
                        GotoItem((xy[0], xy[1], -1.0), None), landing=True, seq=seq,
                        tag=LegTag.LAND))
        return legs

    def land_here(self, seq: int | None = None) -> None:
        """Land below the reference's stopping point."""
        nav = self.nav
        ref = nav.plan.current_ref()
        stop = stop_point(ref, nav.p.acc_m_s2)
        nav.plan.vel = None
        nav.plan.queue(self.legs((stop[0], stop[1]), seq))

    def detect(self, t: float, pos: Vec3, vel: Vec3) -> None:
        """The land detector at ``t`` [s], the vehicle at ``pos`` [m] moving at ``vel``
        [m/s]: landed (and disarmed) after ``land_detect_s`` down and still on a final
        descent."""
        nav = self.nav
        leg = nav.plan.leg
        if leg is None or not leg.landing:     # not on a final descent (most periods)
            self._still_since = None
            return
        ref = nav.plan.ref
        down = (pos[2] <= nav.gear_height_m + 0.05
                or (ref is not None and ref.pos_m[2] <= pos[2] - nav.p.land_stall_m))
        if (down
                and math.sqrt(vel[0] * vel[0] + vel[1] * vel[1] + vel[2] * vel[2]) < 0.3):
            if self._still_since is None:
                self._still_since = t
            elif t - self._still_since >= nav.p.land_detect_s:
                self._still_since = None
                nav.landed = True
                was_mission = nav.mission_running
                nav._emit(NavEvent.LANDED, nav.plan.leg.seq if nav.plan.leg else None)
                if was_mission and nav.plan.leg is not None and nav.plan.leg.seq is not None:
                    nav._emit(NavEvent.REACHED, nav.plan.leg.seq)
                    nav._emit(NavEvent.MISSION_DONE, None)
                nav.disarm()
        else:
            self._still_since = None
