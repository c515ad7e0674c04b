"""Mission items → the navigator's commands: what a stored MAVLink mission item
(:class:`companion.mission_protocol.MissionItem`) asks the vehicle to do, as a
:class:`companion.navigation.NavCommand` in the inertial z-up frame, or why it is refused.

Pure functions of the item, the winder's global position (``origin``: latitude deg,
longitude deg, ground altitude m AMSL) and the navigator's target checks (tether reach,
ground): the autopilot validates and accepts uploads with them, and a runner without
MAVLink can fly a mission file with them. Frames are read through
:mod:`tuavdefs.mav_frames`.

Supported: NAV_WAYPOINT, NAV_LOITER_TIME (a waypoint held param1 s), NAV_LOITER_TURNS,
NAV_TAKEOFF, NAV_LAND, NAV_RETURN_TO_LAUNCH, DO_CHANGE_SPEED; positions in the global
frames only. Latitude = longitude = 0 (or INT32_MAX, "unset") means where the vehicle is
when the item begins.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from pymavlink.dialects.v20 import common as mavlink2

from companion.mission_protocol import MissionItem, home_item
from companion.navigation import NavCommand, Navigator, NavKind, Reason
from tuavdefs.frames import local_enu_to_global
from tuavdefs.mav_frames import GLOBAL_FRAMES, global_to_local

M = mavlink2
Origin = tuple[float, float, float]

__all__ = ["ItemRefused", "finite", "mission_home", "nav_command", "nav_commands"]

_INT32_MAX = 2**31 - 1
_KINDS = {M.MAV_CMD_NAV_WAYPOINT: NavKind.WAYPOINT,
          M.MAV_CMD_NAV_LOITER_TURNS: NavKind.LOITER_TURNS,
          M.MAV_CMD_NAV_TAKEOFF: NavKind.TAKEOFF, M.MAV_CMD_NAV_LAND: NavKind.LAND,
          M.MAV_CMD_NAV_LOITER_TIME: NavKind.WAYPOINT}


class ItemRefused(ValueError):  # noqa: N818 - the name the mission runners use
    """A mission item the vehicle cannot fly: ``result`` is the MAV_MISSION_RESULT to
    answer its upload with, the message (``str(exc)``) says why; ``seq`` is the item's
    sequence number when :func:`nav_commands` refused it (else None)."""

    def __init__(self, result: int, text: str, seq: int | None = None) -> None:
        super().__init__(text)
        self.result = result
        self.seq = seq


def finite(x: Any) -> bool:
    """Whether a MAVLink parameter is a number: converts to float and is neither NaN nor
    infinite."""
    try:
        return math.isfinite(float(x))
    except (TypeError, ValueError):
        return False


def nav_command(seq: int, item: MissionItem, origin: Origin, nav: Navigator) -> NavCommand:
    """The navigator's form of mission item ``seq``; ``origin`` is the winder's (latitude
    deg, longitude deg, ground altitude m AMSL), ``nav`` checks the targets against the
    tether's reach and the ground. Raises :class:`ItemRefused` why it is refused.

    Waypoints: param1 hold [s], param2 acceptance radius [m] (0: the navigator's).
    Loiter turns: param1 turns, param3 radius [m] (positive clockwise, at least 0.5 m).
    Take-off: the altitude must be above the ground. DO_CHANGE_SPEED: param2 [m/s] > 0.
    DO_WINCH: param1 instance, param2 action (WINCH_ACTIONS), param3 length [m], param4
    rate [m/s], handed to the winch as the item begins.
    """
    cmd, frame = item.command, item.frame
    if cmd == M.MAV_CMD_DO_CHANGE_SPEED:
        if not (finite(item.param2) and item.param2 > 0):
            raise ItemRefused(M.MAV_MISSION_INVALID_PARAM2, "speed must be > 0")
        return NavCommand(seq, NavKind.SPEED, speed_m_s=float(item.param2))
    if cmd == M.MAV_CMD_DO_WINCH:
        instance, action, length, rate = item.param1, item.param2, item.param3, item.param4
        if not (finite(action) and action == int(action)
                and int(action) in mavlink2.enums["WINCH_ACTIONS"]):
            raise ItemRefused(M.MAV_MISSION_INVALID_PARAM2, f"winch: bad action {action}")
        if not finite(instance):
            raise ItemRefused(M.MAV_MISSION_INVALID_PARAM1, "winch: instance is not a number")
        # the winch checks length and rate when it receives them
        return NavCommand(seq, NavKind.WINCH, winch=(float(instance), float(action),
                                                     float(length), float(rate)))
    if cmd == M.MAV_CMD_NAV_RETURN_TO_LAUNCH:
        return NavCommand(seq, NavKind.RTL)
    kind = _KINDS.get(cmd)
    if kind is None:
        raise ItemRefused(M.MAV_MISSION_UNSUPPORTED, f"command {cmd} not supported")
    if frame not in GLOBAL_FRAMES:
        raise ItemRefused(M.MAV_MISSION_UNSUPPORTED_FRAME, f"frame {frame} not supported")
    lat, lon = item.x * 1e-7, item.y * 1e-7
    if not finite(item.z):
        raise ItemRefused(M.MAV_MISSION_INVALID_PARAM7, "altitude is not a number")
    xy: tuple[float, float] | None = None
    x, y, z = global_to_local(lat, lon, item.z, frame, origin)
    # latitude = longitude = 0, or INT32_MAX ("unset"): where the vehicle is then
    if (item.x != 0 or item.y != 0) and _INT32_MAX not in (item.x, item.y):
        xy = (x, y)
    if kind is NavKind.LAND:
        return NavCommand(seq, NavKind.LAND, xy)
    if kind is NavKind.TAKEOFF and z <= 0.0:
        raise ItemRefused(M.MAV_MISSION_INVALID_PARAM7, "take-off altitude <= 0")
    check_xy = xy if xy is not None else (0.0, 0.0)
    reach = nav.check_target((*check_xy, z))
    if reach is not None:
        code = (M.MAV_MISSION_INVALID_PARAM7 if reach.reason is Reason.BELOW_GROUND or
                math.hypot(*check_xy) <= nav.reach_m else
                M.MAV_MISSION_INVALID_PARAM5_X)
        raise ItemRefused(code, reach)
    if kind is NavKind.TAKEOFF:
        return NavCommand(seq, NavKind.TAKEOFF, None, z)
    hold = float(item.param1) if finite(item.param1) and item.param1 > 0 else 0.0
    if kind is NavKind.WAYPOINT:
        accept = float(item.param2) if finite(item.param2) and item.param2 > 0 else None
        return NavCommand(seq, NavKind.WAYPOINT, xy, z, hold_s=hold, accept_m=accept)
    # loiter turns: param1 turns, param3 radius (positive: clockwise)
    radius = float(item.param3)
    turns = float(item.param1)
    if not (finite(radius) and abs(radius) >= 0.5):
        raise ItemRefused(M.MAV_MISSION_INVALID_PARAM3, "circle radius must be >= 0.5 m")
    if not (finite(turns) and turns > 0):
        raise ItemRefused(M.MAV_MISSION_INVALID_PARAM1, "turns must be > 0")
    far = math.hypot(math.hypot(*check_xy) + abs(radius), z)
    if far > nav.reach_m:
        raise ItemRefused(M.MAV_MISSION_INVALID_PARAM3,
                          f"circle beyond tether reach ({far:.1f} > {nav.reach_m:.1f} m)")
    return NavCommand(seq, NavKind.LOITER_TURNS, xy, z, turns=turns,
                      circle_radius_m=abs(radius), clockwise=radius > 0)


def nav_commands(items: Sequence[MissionItem], origin: Origin,
                 nav: Navigator) -> list[NavCommand]:
    """The navigator's commands of a whole mission, ``items[0]`` being home (skipped, as
    ArduPilot stores it); raises :class:`ItemRefused` for the first item refused, saying
    which ("item 3: ...")."""
    out = []
    for seq, item in enumerate(items):
        if seq == 0:
            continue
        try:
            out.append(nav_command(seq, item, origin, nav))
        except ItemRefused as exc:
            raise ItemRefused(exc.result, f"item {seq}: {exc}", seq) from None
    return out


def mission_home(home_m: Sequence[float], origin: Origin) -> MissionItem:
    """The home item (seq 0) of home at ``home_m`` (inertial z-up [m]; its z is ignored, home
    is on the ground): its latitude and longitude, at the ground's altitude AMSL
    (``origin[2]``)."""
    lat, lon, _ = local_enu_to_global((home_m[0], home_m[1], 0.0), origin)
    return home_item(lat, lon, origin[2])
