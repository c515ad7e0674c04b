"""AUTO: the mission. Take-off, waypoints (hold time, acceptance radius), loiter-turns
circles (the paper's circle), land, return to launch, change of speed, the winch's items;
an item whose horizontal position is unset (latitude = longitude = 0) is flown from where
the vehicle is, and checked against the tether's reach there."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from companion.legs import CircleItem, GotoItem
from companion.nav_types import (
    NAV_MOVES,
    FlightMode,
    LegTag,
    NavCommand,
    NavEvent,
    NavKind,
    Reason,
    Refusal,
)
from companion.plan import Leg
from companion.reference import Circle

if TYPE_CHECKING:
    from companion.navigation import Navigator

Vec3 = tuple[float, float, float]


class Auto:
    """The mission's sequencing (the mission itself, its current index and whether it
    runs are the navigator's state: :attr:`Navigator.mission` ...)."""

    def __init__(self, nav: Navigator) -> None:
        self.nav = nav
        #: armed on the ground in AUTO: the mission starts at the next step
        self.takeoff_pending = False

    def enter(self) -> None:
        """AUTO has just been set: a flying vehicle flies the mission (on from its
        current item if it ran), an armed one on the ground starts it at the next step."""
        nav = self.nav
        if nav.flying:
            self.start(nav.mission_index if nav.mission_running else 0)
        elif nav.armed:
            self.takeoff_pending = True

    def refuse(self) -> Refusal | None:
        """Why AUTO cannot be set now (a mission of no moves; on the ground and armed, a
        mission not starting with a take-off), or None."""
        nav = self.nav
        if not self.has_items():
            return Refusal(Reason.MISSION_EMPTY, "Auto: mission is empty")
        if nav.landed and nav.armed and self.first_nav().kind is not NavKind.TAKEOFF:
            return Refusal(Reason.MISSING_TAKEOFF, "Auto: Missing Takeoff Cmd")
        return None

    def start_pending(self) -> None:
        """On the ground, armed in AUTO: begin the mission if it starts with a take-off."""
        nav = self.nav
        if self.takeoff_pending and nav.mode == FlightMode.AUTO:
            self.takeoff_pending = False
            if self.has_items() and self.first_nav().kind is NavKind.TAKEOFF:
                self.start(0)

    # ----- the ground station's mission commands

    def set_mission(self, commands: list[NavCommand]) -> None:
        """A new mission (items from seq 1 on); the current item returns to the first."""
        nav = self.nav
        nav.mission = list(commands)
        nav.mission_index = 0
        if nav.mission_running and nav.mode == FlightMode.AUTO and nav.flying:
            if nav.mission:
                self.start(0)
            else:
                nav.mission_running = False
                nav.plan.hold()

    def set_current(self, seq: int) -> Refusal | None:
        """MISSION_SET_CURRENT: fly item ``seq`` next."""
        nav = self.nav
        for i, c in enumerate(nav.mission):
            if c.seq == seq:
                if nav.mission_running and nav.flying:
                    self.start(i)
                else:
                    nav.mission_index = i
                    nav._emit(NavEvent.CURRENT, c.seq)
                return None
        return Refusal(Reason.NO_SUCH_ITEM, f"no mission item {seq}")

    def start_mission(self, first_seq: int = 0) -> Refusal | None:
        """MISSION_START: AUTO, from ``first_seq`` (0: from the start)."""
        nav = self.nav
        if not self.has_items():
            return Refusal(Reason.MISSION_EMPTY, "Auto: mission is empty")
        if not nav.armed:
            return Refusal(Reason.NOT_ARMED, "MISSION_START: not armed")
        index = 0
        if first_seq > 0:
            for i, c in enumerate(nav.mission):
                if c.seq == first_seq:
                    index = i
                    break
        if nav.landed and nav.mission[index].kind is not NavKind.TAKEOFF:
            return Refusal(Reason.MISSING_TAKEOFF, "Auto: Missing Takeoff Cmd")
        nav.mode = FlightMode.AUTO
        nav.plan.vel = None
        self.start(index)
        return None

    # ----- sequencing

    def has_items(self) -> bool:
        """Whether the mission has a step that moves the vehicle."""
        return any(c.kind in NAV_MOVES for c in self.nav.mission)

    def first_nav(self) -> NavCommand:
        """The first moving step from the current item on (from the start if none)."""
        nav = self.nav
        for c in nav.mission[nav.mission_index:] or nav.mission:
            if c.kind in NAV_MOVES:
                return c
        return nav.mission[0]

    def start(self, index: int) -> None:
        """Run the mission from item ``index``."""
        nav = self.nav
        nav.mission_running = True
        nav.mission_index = max(0, min(index, len(nav.mission)))
        self.begin_item()

    def next_item(self) -> None:
        """The current item is done: the next one."""
        self.nav.mission_index += 1
        self.begin_item()

    def begin_item(self) -> None:
        """Begin the current item (the DO_ items run at once and the next begins); past
        the last, the mission is done and the vehicle holds."""
        nav = self.nav
        while nav.mission_index < len(nav.mission):
            c = nav.mission[nav.mission_index]
            nav._emit(NavEvent.CURRENT, c.seq)
            if c.kind is NavKind.SPEED:
                if c.speed_m_s is not None and c.speed_m_s > 0:
                    nav.speed_override_m_s = c.speed_m_s
                nav.mission_index += 1
                continue
            if c.kind is NavKind.WINCH:
                # as ArduPilot's DO_ commands: run as the item begins, then the next item
                nav._emit(NavEvent.WINCH, (c.seq, c.winch))
                nav.mission_index += 1
                continue
            self.fly_item(c)
            return
        # past the last item: ArduCopter holds where it is (the mission is complete)
        nav.mission_running = False
        nav._emit(NavEvent.MISSION_DONE, None)
        if nav.flying:
            nav.plan.hold()

    def check_item_here(self, c: NavCommand, xy: tuple[float, float]) -> Refusal | None:
        """Why an item without a position of its own cannot be flown from ``xy`` [m]."""
        nav = self.nav
        ref_z = nav.plan.current_ref().pos_m[2]
        z = c.z_m if c.z_m is not None else (nav.p.rtl_alt_m if c.kind is NavKind.TAKEOFF
                                             else ref_z)
        if c.kind is NavKind.TAKEOFF:
            z = max(z, ref_z)
        return nav.check_target(far_point(c, xy, z))

    def item_xy(self, c: NavCommand) -> tuple[float, float]:
        """Where item ``c`` is flown [m]: its own position, or the reference's."""
        if c.xy_m is not None:
            return c.xy_m
        ref = self.nav.plan.current_ref()
        return (ref.pos_m[0], ref.pos_m[1])

    def fly_item(self, c: NavCommand) -> None:
        """Fly the moving item ``c`` (an item without a position checked where it is
        flown: refused, the mission stops and the vehicle holds)."""
        nav = self.nav
        xy = self.item_xy(c)
        if c.xy_m is None and c.kind in (NavKind.WAYPOINT, NavKind.LOITER_TURNS,
                                         NavKind.TAKEOFF):
            # checked at the upload at the winder; flown from here: checked here
            why = self.check_item_here(c, xy)
            if why is not None:
                nav._emit(NavEvent.ERROR, f"Mission: item {c.seq} {why}; holding")
                nav.mission_running = False
                nav.plan.hold()
                return
        if c.kind is NavKind.TAKEOFF:
            z = c.z_m if c.z_m is not None else nav.p.rtl_alt_m
            if nav.landed:
                nav.begin_takeoff((nav.position_m[0], nav.position_m[1], z), seq=c.seq)
            else:
                # already flying: ArduCopter climbs to the altitude if below it
                ref = nav.plan.current_ref()
                nav.plan.queue([Leg(nav.plan.follower(nav.p.speed_up_m_s, nav.p.takeoff_accept_m),
                                GotoItem((ref.pos_m[0], ref.pos_m[1], max(z, ref.pos_m[2])),
                                         None), seq=c.seq, tag=LegTag.MISSION)])
        elif c.kind is NavKind.WAYPOINT:
            z = c.z_m if c.z_m is not None else nav.plan.current_ref().pos_m[2]
            nav.plan.queue([Leg(nav.plan.follower(nav.speed_m_s, c.accept_m, c.hold_s),
                            GotoItem((xy[0], xy[1], z), None), seq=c.seq, tag=LegTag.MISSION)])
        elif c.kind is NavKind.LOITER_TURNS:
            z = c.z_m if c.z_m is not None else nav.plan.current_ref().pos_m[2]
            radius = abs(c.circle_radius_m)
            # as ArduCopter's circle does, the speed is cut to what the acceleration limit
            # allows on this radius (centripetal acceleration v^2/r, with margin)
            speed = min(nav.speed_m_s, 0.95 * math.sqrt(nav.p.acc_m_s2 * radius))
            lead_in = max(5.0, 1.01 * Circle.min_lead_in_s(radius, speed, nav.p.acc_m_s2))
            item = CircleItem(xy, radius, z, speed, turns=c.turns, clockwise=c.clockwise,
                              lead_in_s=lead_in)
            nav.plan.queue([Leg(nav.plan.follower(speed, c.accept_m), item, seq=c.seq,
                            tag=LegTag.MISSION)])
        elif c.kind is NavKind.LAND:
            if c.xy_m is None:
                nav.land_mode.land_here(seq=c.seq)
            else:
                ref = nav.plan.current_ref()
                nav.plan.queue([Leg(nav.plan.follower(nav.speed_m_s),
                                GotoItem((xy[0], xy[1], ref.pos_m[2]), None), seq=c.seq,
                                tag=LegTag.LAND_APPROACH)])
        elif c.kind is NavKind.RTL:
            nav.rtl_mode.start(seq=c.seq)


def far_point(c: NavCommand, xy: tuple[float, float], z: float) -> Vec3:
    """The point [m] of item ``c`` flown around ``xy`` [m] at ``z`` [m] farthest from the
    winder."""
    if c.kind is not NavKind.LOITER_TURNS:
        return (xy[0], xy[1], z)
    h = math.hypot(xy[0], xy[1]) + abs(c.circle_radius_m)
    return (h, 0.0, z)
