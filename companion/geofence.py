"""The geofence, as ArduCopter keeps one, with the tether's reach as a fence that is always
on inside it.

ArduCopter's parameters (:class:`FenceParams`; ``FENCE_*`` on the wire): ``FENCE_ENABLE``,
``FENCE_TYPE`` (bitmask: 1 maximum altitude, 2 circle about home, 4 the uploaded polygons
and circles), ``FENCE_RADIUS``, ``FENCE_ALT_MAX`` [m above home], ``FENCE_ACTION`` (0 report
only, 1 RTL, 2 land) and ``FENCE_MARGIN``. The uploaded fence (mission type 1) is MAVLink's
fence items: inclusion and exclusion polygons (``NAV_FENCE_POLYGON_VERTEX_*``, ``param1``
the vertex count) and circles (``NAV_FENCE_CIRCLE_*``, ``param1`` the radius [m]), in
global coordinates, turned into the inertial frame once at upload (:meth:`Geofence.set_items`).

:meth:`Geofence.breach` says which fence a position is outside of (an enum), the tether's
reach first: farther from the winder than the tether allows less its slack margin (the
navigator's ``tether_limit_m``: the whole tether, or what a braked drum paid out; targets
keep ``reach_m``'s margin inside it) is a breach whatever ``FENCE_ENABLE`` says.

:meth:`Geofence.pre_arm` is ArduCopter's fence pre-arm check, in its order: an enabled fence
with nothing to check, no position for a horizontal fence, ``FENCE_MARGIN`` against the
fences (at most an inclusion circle's radius and ``FENCE_RADIUS``, and less than half of
``FENCE_ALT_MAX``: the height between the ground and the ceiling), and the vehicle outside
a fence. ``FENCE_MARGIN`` is, as in ArduCopter, the distance the vehicle should keep from a
fence: the breach itself is at the fence.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

from pymavlink.dialects.v20 import common as mavlink2

from companion.mission_protocol import MissionItem, e7_to_degrees
from tuavdefs.frames import global_to_local_enu
from tuavdefs.paramspec import Params, quantity

__all__ = ["FENCE_COMMANDS", "FenceAction", "FenceBreach", "FenceParams", "FenceStatus",
           "Geofence", "check_fence_item"]

M = mavlink2
Vec2 = tuple[float, float]
Vec3 = tuple[float, float, float]

TYPE_ALT_MAX, TYPE_CIRCLE, TYPE_POLYGON = 1, 2, 4
FENCE_COMMANDS = frozenset({M.MAV_CMD_NAV_FENCE_RETURN_POINT,
                            M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION,
                            M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION,
                            M.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION,
                            M.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION})
_GLOBAL = frozenset({M.MAV_FRAME_GLOBAL, M.MAV_FRAME_GLOBAL_INT,
                     M.MAV_FRAME_GLOBAL_RELATIVE_ALT, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT})


@dataclass(frozen=True)
class FenceParams(Params):
    """ArduCopter's fence parameters (SI; the wire's names in companion/param_names.py)."""

    enable: bool = quantity(False, "", "the fence is enabled (the tether's reach always is)")
    type_mask: int = quantity(7, "", "fences: 1 maximum altitude, 2 circle, 4 polygons", ge=0,
                              le=15)
    radius_m: float = quantity(300.0, "m", "circle fence about home", ge=30, le=10000)
    alt_max_m: float = quantity(100.0, "m", "maximum altitude above home", ge=10, le=1000)
    action: int = quantity(1, "", "on a breach: 0 report, 1 RTL, 2 land", ge=0, le=2)
    margin_m: float = quantity(2.0, "m", "the distance to keep from a fence (checked "
                               "against the fences before arming; a breach is at the fence)",
                               ge=1, le=10)


class FenceBreach(Enum):
    """Which fence a position is outside of."""

    TETHER = "tether reach"
    ALT_MAX = "maximum altitude"
    CIRCLE = "circle"
    POLYGON = "polygon"


@dataclass(frozen=True)
class FenceStatus:
    """SYS_STATUS's ``MAV_SYS_STATUS_GEOFENCE`` bits as ArduPilot sets them (AC_Fence's
    ``sys_status_present``, ``_enabled`` and ``_failed``; MAVProxy's fence module says
    "fence present", "fence enabled", "fence breach" from them)."""

    present: bool
    """A fence type of ``FENCE_TYPE`` has something to check: the maximum altitude or the
    circle (parameters: no fence items), or polygons with an upload (the fence mission
    type's items)."""
    enabled: bool
    """Present, ``FENCE_ENABLE`` set and ``FENCE_ACTION`` not report-only."""
    healthy: bool
    """Not present, or present and not breached."""


class FenceAction(Enum):
    """FENCE_ACTION's values."""

    REPORT = 0
    RTL = 1
    LAND = 2


def check_fence_item(seq: int, item: MissionItem) -> tuple[int, str] | None:
    """A fence upload's item: None, or its (MAV_MISSION_RESULT, reason)."""
    if item.command not in FENCE_COMMANDS:
        return M.MAV_MISSION_UNSUPPORTED, f"Fence: item {seq}: command {item.command}"
    if item.frame not in _GLOBAL:
        return M.MAV_MISSION_UNSUPPORTED_FRAME, f"Fence: item {seq}: frame {item.frame}"
    if not (-90e7 <= item.x <= 90e7 and -180e7 <= item.y <= 180e7):
        return M.MAV_MISSION_INVALID_PARAM5_X, f"Fence: item {seq}: position"
    p1 = item.param1
    if item.command in (M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION,
                        M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION) and not (
            math.isfinite(p1) and p1 >= 3 and float(p1).is_integer()):
        return M.MAV_MISSION_INVALID_PARAM1, f"Fence: item {seq}: vertex count {p1}"
    if item.command in (M.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION,
                        M.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION) and not (
            math.isfinite(p1) and p1 > 0):
        return M.MAV_MISSION_INVALID_PARAM1, f"Fence: item {seq}: radius {p1}"
    return None


def _inside_polygon(p: Vec2, poly: list[Vec2]) -> bool:
    """Even-odd rule."""
    x, y = p
    inside = False
    j = len(poly) - 1
    for i in range(len(poly)):
        xi, yi = poly[i]
        xj, yj = poly[j]
        if (yi > y) != (yj > y) and x < (xj - xi) * (y - yi) / (yj - yi) + xi:
            inside = not inside
        j = i
    return inside


class Geofence:
    """The fences of ``params`` and the uploaded items, in the inertial frame about the
    winder; ``origin`` the winder's (latitude deg, longitude deg, ground altitude m)."""

    def __init__(self, params: FenceParams, origin: Vec3) -> None:
        self.p = params
        self.origin = origin
        self.include_polygons: list[list[Vec2]] = []
        self.exclude_polygons: list[list[Vec2]] = []
        self.include_circles: list[tuple[Vec2, float]] = []
        self.exclude_circles: list[tuple[Vec2, float]] = []

    def set_items(self, items: list[MissionItem]) -> str | None:
        """The uploaded fence (checked items); None, or why it cannot be used (a polygon
        cut short), in which case the previous one stays."""
        inc_p: list[list[Vec2]] = []
        exc_p: list[list[Vec2]] = []
        inc_c: list[tuple[Vec2, float]] = []
        exc_c: list[tuple[Vec2, float]] = []
        i = 0
        while i < len(items):
            it = items[i]
            xy = self._xy(it)
            if it.command in (M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION,
                              M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION):
                n = int(it.param1)
                group = items[i:i + n]
                if len(group) < n or any(g.command != it.command for g in group):
                    return f"Fence: polygon at item {i} has fewer than {n} vertices"
                (inc_p if it.command == M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION
                 else exc_p).append([self._xy(g) for g in group])
                i += n
                continue
            if it.command == M.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION:
                inc_c.append((xy, float(it.param1)))
            elif it.command == M.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION:
                exc_c.append((xy, float(it.param1)))
            i += 1
        self.include_polygons, self.exclude_polygons = inc_p, exc_p
        self.include_circles, self.exclude_circles = inc_c, exc_c
        return None

    def present(self) -> bool:
        """Whether an enabled fence type has something to check (ArduCopter: the circle or
        the altitude, or polygons with an upload)."""
        mask = self.p.type_mask
        uploaded = bool(self.include_polygons or self.exclude_polygons
                        or self.include_circles or self.exclude_circles)
        return bool(mask & (TYPE_ALT_MAX | TYPE_CIRCLE) or (mask & TYPE_POLYGON and uploaded))

    def sys_status(self, breached: bool) -> FenceStatus:
        """The geofence bits of SYS_STATUS as ArduPilot sets them, with ``breached``
        whether a fence is breached now."""
        present = self.present()
        return FenceStatus(present, present and self.p.enable
                           and self.p.action != FenceAction.REPORT.value,
                           not (present and breached))

    def pre_arm(self, pos_m: Vec3 | None, home_m: Vec3 | None) -> str | None:
        """ArduCopter's fence pre-arm check: None (arming may go on) or why not, as the
        text after ``PreArm: Fence: ``. ``pos_m`` the vehicle's position [m] (None: not
        known yet), ``home_m`` the circle's centre (None: the winder). The tether's reach is
        not checked here: a vehicle on the ground is always within it."""
        p = self.p
        if not p.enable:
            return None
        if not self.present():
            return "enabled, but none selected"
        if p.type_mask & (TYPE_CIRCLE | TYPE_POLYGON) and pos_m is None:
            return "requires position"
        if p.type_mask & TYPE_POLYGON and any(r < p.margin_m for _, r in self.include_circles):
            return "an inclusion circle's radius is less than FENCE_MARGIN"
        if p.type_mask & TYPE_CIRCLE and p.radius_m < p.margin_m:
            return "FENCE_RADIUS is less than FENCE_MARGIN"
        if pos_m is not None and self.breach(pos_m, home_m, math.inf) is not None:
            return "vehicle outside fence"
        if p.type_mask & TYPE_ALT_MAX and p.alt_max_m <= 2.0 * p.margin_m:
            return "FENCE_MARGIN too big for FENCE_ALT_MAX"
        return None

    def _xy(self, item: MissionItem) -> Vec2:
        x, y, _ = global_to_local_enu(e7_to_degrees(item.x), e7_to_degrees(item.y),
                                      self.origin[2], self.origin)
        return (x, y)

    def breach(self, pos_m: Vec3, home_m: Vec3 | None, reach_m: float
               ) -> FenceBreach | None:
        """The fence ``pos_m`` [m] is outside of (None: inside all); ``home_m`` the home
        the circle is about (None: the winder; the altitude is above the flat ground),
        ``reach_m`` the tether's."""
        if math.sqrt(pos_m[0] ** 2 + pos_m[1] ** 2 + pos_m[2] ** 2) > reach_m:
            return FenceBreach.TETHER
        p = self.p
        if not p.enable:
            return None
        home = home_m if home_m is not None else (0.0, 0.0, 0.0)
        if p.type_mask & TYPE_ALT_MAX and pos_m[2] > p.alt_max_m:   # above the ground
            return FenceBreach.ALT_MAX
        if (p.type_mask & TYPE_CIRCLE
                and math.hypot(pos_m[0] - home[0], pos_m[1] - home[1]) > p.radius_m):
            return FenceBreach.CIRCLE
        if p.type_mask & TYPE_POLYGON and not self._inside_polygons((pos_m[0], pos_m[1])):
            return FenceBreach.POLYGON
        return None

    def _inside_polygons(self, xy: Vec2) -> bool:
        """Inside every inclusion fence and outside every exclusion fence."""
        for poly in self.include_polygons:
            if not _inside_polygon(xy, poly):
                return False
        for (cx, cy), r in self.include_circles:
            if math.hypot(xy[0] - cx, xy[1] - cy) > r:
                return False
        for poly in self.exclude_polygons:
            if _inside_polygon(xy, poly):
                return False
        return all(math.hypot(xy[0] - cx, xy[1] - cy) >= r
                   for (cx, cy), r in self.exclude_circles)
