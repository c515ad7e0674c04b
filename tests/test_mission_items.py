"""Mission items translated into navigator commands without an autopilot
(``companion.mission_items``): what the offline runner does with a scenario's mission."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as mavlink2

from companion.mission_items import (
    ItemRefused,
    mission_home,
    nav_command,
    nav_commands,
)
from companion.mission_protocol import MissionItem, degrees_to_e7, home_item
from companion.navigation import NavigationParams, Navigator, NavKind
from tuavdefs.frames import local_enu_to_global

M = mavlink2
ORIGIN = (47.3977419, 8.5455938, 488.0)
REL = M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
AMSL = M.MAV_FRAME_GLOBAL_INT


@pytest.fixture
def nav() -> Navigator:
    return Navigator(NavigationParams(), 0.2, 60.0)


def at(x: float, y: float) -> tuple[int, int]:
    """The item's x, y (degrees x 1e7) of a point of the z-up frame [m]."""
    lat, lon, _ = local_enu_to_global((x, y, 0.0), ORIGIN)
    return degrees_to_e7(lat), degrees_to_e7(lon)


def test_takeoff(nav):
    cmd = nav_command(1, MissionItem(M.MAV_CMD_NAV_TAKEOFF, REL, z=10.0), ORIGIN, nav)
    assert (cmd.seq, cmd.kind, cmd.xy_m, cmd.z_m) == (1, NavKind.TAKEOFF, None, 10.0)
    with pytest.raises(ItemRefused) as exc:
        nav_command(1, MissionItem(M.MAV_CMD_NAV_TAKEOFF, REL, z=0.0), ORIGIN, nav)
    assert exc.value.result == M.MAV_MISSION_INVALID_PARAM7
    assert isinstance(exc.value, ValueError)


def test_waypoint_at_zero_is_where_the_vehicle_is(nav):
    cmd = nav_command(2, MissionItem(M.MAV_CMD_NAV_WAYPOINT, REL, param1=3.0, z=12.0),
                      ORIGIN, nav)
    assert (cmd.kind, cmd.xy_m, cmd.z_m, cmd.hold_s, cmd.accept_m) == (
        NavKind.WAYPOINT, None, 12.0, 3.0, None)


def test_waypoint_position_and_acceptance(nav):
    x, y = at(10.0, -5.0)
    cmd = nav_command(2, MissionItem(M.MAV_CMD_NAV_WAYPOINT, REL, param2=1.5, x=x, y=y,
                                     z=12.0), ORIGIN, nav)
    assert cmd.xy_m == pytest.approx((10.0, -5.0), abs=0.02)
    assert cmd.accept_m == 1.5


def test_loiter_turns_radius_sign_is_the_direction(nav):
    x, y = at(5.0, 5.0)
    cw = nav_command(3, MissionItem(M.MAV_CMD_NAV_LOITER_TURNS, REL, param1=2.0, param3=4.0,
                                    x=x, y=y, z=15.0), ORIGIN, nav)
    assert (cw.kind, cw.turns, cw.circle_radius_m, cw.clockwise) == (
        NavKind.LOITER_TURNS, 2.0, 4.0, True)
    ccw = nav_command(3, MissionItem(M.MAV_CMD_NAV_LOITER_TURNS, REL, param1=1.0,
                                     param3=-4.0, x=x, y=y, z=15.0), ORIGIN, nav)
    assert (ccw.circle_radius_m, ccw.clockwise) == (4.0, False)
    with pytest.raises(ItemRefused) as exc:
        nav_command(3, MissionItem(M.MAV_CMD_NAV_LOITER_TURNS, REL, param1=1.0, param3=0.1,
                                   x=x, y=y, z=15.0), ORIGIN, nav)
    assert exc.value.result == M.MAV_MISSION_INVALID_PARAM3


def test_beyond_tether_reach_is_refused(nav):
    far = nav.reach_m + 5.0
    x, y = at(far, 0.0)
    with pytest.raises(ItemRefused) as exc:
        nav_command(4, MissionItem(M.MAV_CMD_NAV_WAYPOINT, REL, x=x, y=y, z=10.0), ORIGIN,
                    nav)
    assert exc.value.result == M.MAV_MISSION_INVALID_PARAM5_X   # too far out: x, y
    assert "reach" in str(exc.value)
    with pytest.raises(ItemRefused) as exc:                     # straight up: the altitude
        nav_command(4, MissionItem(M.MAV_CMD_NAV_WAYPOINT, REL, z=far), ORIGIN, nav)
    assert exc.value.result == M.MAV_MISSION_INVALID_PARAM7
    x, y = at(nav.reach_m - 10.0, 0.0)                          # a circle that leaves it
    with pytest.raises(ItemRefused) as exc:
        nav_command(4, MissionItem(M.MAV_CMD_NAV_LOITER_TURNS, REL, param1=1.0,
                                   param3=15.0, x=x, y=y, z=5.0), ORIGIN, nav)
    assert exc.value.result == M.MAV_MISSION_INVALID_PARAM3


def test_relative_and_amsl_altitudes(nav):
    rel = nav_command(1, MissionItem(M.MAV_CMD_NAV_WAYPOINT, REL, z=20.0), ORIGIN, nav)
    amsl = nav_command(1, MissionItem(M.MAV_CMD_NAV_WAYPOINT, AMSL, z=ORIGIN[2] + 20.0),
                       ORIGIN, nav)
    assert rel.z_m == 20.0
    assert amsl.z_m == pytest.approx(20.0)
    with pytest.raises(ItemRefused) as exc:                     # below the winder's ground
        nav_command(1, MissionItem(M.MAV_CMD_NAV_WAYPOINT, AMSL, z=20.0), ORIGIN, nav)
    assert exc.value.result == M.MAV_MISSION_INVALID_PARAM7


def test_unsupported_commands_and_frames(nav):
    with pytest.raises(ItemRefused) as exc:
        nav_command(1, MissionItem(M.MAV_CMD_DO_SET_SERVO, M.MAV_FRAME_MISSION), ORIGIN, nav)
    assert exc.value.result == M.MAV_MISSION_UNSUPPORTED
    with pytest.raises(ItemRefused) as exc:
        nav_command(1, MissionItem(M.MAV_CMD_NAV_WAYPOINT, M.MAV_FRAME_LOCAL_NED, z=5.0),
                    ORIGIN, nav)
    assert exc.value.result == M.MAV_MISSION_UNSUPPORTED_FRAME
    with pytest.raises(ItemRefused) as exc:
        nav_command(1, MissionItem(M.MAV_CMD_NAV_WAYPOINT, REL, z=math.nan), ORIGIN, nav)
    assert exc.value.result == M.MAV_MISSION_INVALID_PARAM7


def test_a_whole_mission_skips_home(nav):
    items = [home_item(*ORIGIN),
             MissionItem(M.MAV_CMD_NAV_TAKEOFF, REL, z=10.0),
             MissionItem(M.MAV_CMD_DO_CHANGE_SPEED, M.MAV_FRAME_MISSION, param2=3.0),
             MissionItem(M.MAV_CMD_NAV_LAND, REL),
             MissionItem(M.MAV_CMD_NAV_RETURN_TO_LAUNCH, M.MAV_FRAME_MISSION)]
    cmds = nav_commands(items, ORIGIN, nav)
    assert [(c.seq, c.kind) for c in cmds] == [(1, NavKind.TAKEOFF), (2, NavKind.SPEED),
                                               (3, NavKind.LAND), (4, NavKind.RTL)]
    assert cmds[1].speed_m_s == 3.0
    assert nav_commands(items[:1], ORIGIN, nav) == []


def test_mission_home_is_on_the_ground(nav):
    item = mission_home((3.0, 4.0, 0.2), ORIGIN)
    x, y = at(3.0, 4.0)
    assert (item.command, item.frame, item.x, item.y, item.z) == (
        M.MAV_CMD_NAV_WAYPOINT, M.MAV_FRAME_GLOBAL, x, y, ORIGIN[2])


def test_do_winch_items_become_winch_commands_and_bad_actions_are_refused():
    nav = Navigator(NavigationParams(), 0.2, 50.0)
    cmd = nav_command(3, MissionItem(M.MAV_CMD_DO_WINCH, M.MAV_FRAME_MISSION, param1=1.0,
                                     param2=1.0, param3=2.0, param4=0.5), ORIGIN, nav)
    assert (cmd.seq, cmd.kind, cmd.winch) == (3, NavKind.WINCH, (1.0, 1.0, 2.0, 0.5))
    with pytest.raises(ItemRefused) as e:
        nav_command(3, MissionItem(M.MAV_CMD_DO_WINCH, M.MAV_FRAME_MISSION, param1=1.0,
                                   param2=99.0), ORIGIN, nav)
    assert e.value.result == M.MAV_MISSION_INVALID_PARAM2
