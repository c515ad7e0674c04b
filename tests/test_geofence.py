"""The geofence: its geometry against shapely (a reference library) and analytic cases,
the tether's reach always on, the fence items' checks; and in the real processes, a
polygon uploaded with pymavlink (mission type 1) that the vehicle, flown out of it in
GUIDED, answers by RTL as FENCE_ACTION 1 says."""

from __future__ import annotations

import math
import random

import pytest
from gcs_util import Vehicle, arm, command, wait_msg
from pymavlink import mavutil

from companion.geofence import FenceBreach, FenceParams, Geofence, check_fence_item
from companion.mission_protocol import MissionItem, degrees_to_e7
from tuavdefs.frames import local_enu_to_global
from tuavdefs.simlink import HOME_DEFAULT

M = mavutil.mavlink
INC = M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION
EXC = M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION
CIRC_EXC = M.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION


def item(command: int, x: float, y: float, param1: float) -> MissionItem:
    lat, lon, _ = local_enu_to_global((x, y, 0.0), HOME_DEFAULT)
    return MissionItem(command=command, frame=M.MAV_FRAME_GLOBAL_INT, param1=param1,
                       x=degrees_to_e7(lat), y=degrees_to_e7(lon))


def polygon(command: int, corners: list[tuple[float, float]]) -> list[MissionItem]:
    return [item(command, x, y, len(corners)) for x, y in corners]


CONCAVE = [(-20.0, -20.0), (20.0, -20.0), (20.0, 20.0), (0.0, 5.0), (-20.0, 20.0)]
HOLE = [(-5.0, -15.0), (5.0, -15.0), (5.0, -8.0), (-5.0, -8.0)]


def test_polygons_and_circles_agree_with_shapely():
    shapely = pytest.importorskip("shapely.geometry")
    fence = Geofence(FenceParams(enable=True, type_mask=4), HOME_DEFAULT)
    assert fence.set_items([*polygon(INC, CONCAVE), *polygon(EXC, HOLE),
                            item(CIRC_EXC, 10.0, 0.0, 4.0)]) is None
    allowed = (shapely.Polygon(CONCAVE).difference(shapely.Polygon(HOLE))
               .difference(shapely.Point(10.0, 0.0).buffer(4.0, 256)))
    rng = random.Random(3)
    outside = 0
    for _ in range(2000):
        x, y = rng.uniform(-25, 25), rng.uniform(-25, 25)
        truth = allowed.contains(shapely.Point(x, y))
        if abs(allowed.exterior.distance(shapely.Point(x, y))) < 0.05 or any(
                hole.distance(shapely.Point(x, y)) < 0.05 for hole in allowed.interiors):
            continue          # on an edge (the circle is a 256-gon there)
        got = fence.breach((x, y, 5.0), None, 1000.0)
        assert (got is None) == truth, (x, y)
        outside += got is FenceBreach.POLYGON
    assert 300 < outside < 1700


def test_altitude_circle_and_the_tethers_reach():
    fence = Geofence(FenceParams(enable=True, type_mask=3, radius_m=30.0, alt_max_m=20.0),
                     HOME_DEFAULT)
    home = (2.0, 0.0, 0.2)
    assert fence.breach((2.0, 29.0, 10.0), home, 47.0) is None
    assert fence.breach((2.0, 31.0, 10.0), home, 47.0) is FenceBreach.CIRCLE
    assert fence.breach((2.0, 0.0, 21.0), home, 47.0) is FenceBreach.ALT_MAX
    # the tether's reach, fence disabled or not
    off = Geofence(FenceParams(enable=False), HOME_DEFAULT)
    assert off.breach((40.0, 0.0, 30.0), home, 47.0) is FenceBreach.TETHER
    assert off.breach((40.0, 0.0, 20.0), home, 47.0) is None
    assert math.dist((40.0, 0.0, 30.0), (0, 0, 0)) > 47.0


def test_fence_items_are_checked():
    assert check_fence_item(0, polygon(INC, HOLE)[0]) is None
    bad_count = item(INC, 0.0, 0.0, 2)
    assert check_fence_item(0, bad_count)[0] == M.MAV_MISSION_INVALID_PARAM1
    assert check_fence_item(0, item(CIRC_EXC, 0.0, 0.0, 0.0))[0] == \
        M.MAV_MISSION_INVALID_PARAM1
    wp = MissionItem(command=M.MAV_CMD_NAV_WAYPOINT, frame=M.MAV_FRAME_GLOBAL_INT)
    assert check_fence_item(0, wp)[0] == M.MAV_MISSION_UNSUPPORTED
    # a polygon cut short is refused and the previous fence kept
    fence = Geofence(FenceParams(enable=True, type_mask=4), HOME_DEFAULT)
    fence.set_items(polygon(INC, HOLE))
    assert fence.set_items(polygon(INC, HOLE)[:3]) is not None
    assert len(fence.include_polygons) == 1


def upload_fence(m, items: list[MissionItem]):
    m.mav.mission_count_send(1, 1, len(items), M.MAV_MISSION_TYPE_FENCE)
    while True:
        msg = wait_msg(m, ["MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"], timeout=10)
        assert msg is not None
        if msg.get_type() == "MISSION_ACK":
            return msg
        it = items[msg.seq]
        m.mav.mission_item_int_send(1, 1, msg.seq, it.frame, it.command, 0, 1, it.param1, 0,
                                    0, 0, it.x, it.y, 0, M.MAV_MISSION_TYPE_FENCE)


def test_a_polygon_breach_in_flight_is_answered_by_rtl(tmp_path):
    veh = Vehicle(tmp_path)
    try:
        m = veh.connect()
        # polygons only, none uploaded: no fence present (MAVProxy says no "fence present")
        m.mav.param_set_send(1, 1, b"FENCE_TYPE", 4, M.MAV_PARAM_TYPE_INT8)
        assert wait_msg(m, "PARAM_VALUE", lambda p: p.param_id == "FENCE_TYPE").param_value == 4
        assert not (wait_msg(m, "SYS_STATUS").onboard_control_sensors_present
                    & M.MAV_SYS_STATUS_GEOFENCE)
        square = [(-10.0, -10.0), (10.0, -10.0), (10.0, 10.0), (-10.0, 10.0)]
        assert upload_fence(m, polygon(INC, square)).type == M.MAV_MISSION_ACCEPTED
        assert (wait_msg(m, "SYS_STATUS").onboard_control_sensors_present
                & M.MAV_SYS_STATUS_GEOFENCE)             # the uploaded polygon: present
        for name, value, ptype in ((b"FENCE_TYPE", 4, M.MAV_PARAM_TYPE_INT8),
                                   (b"FENCE_ENABLE", 1, M.MAV_PARAM_TYPE_INT8)):
            m.mav.param_set_send(1, 1, name, value, ptype)
            assert wait_msg(m, "PARAM_VALUE",
                            lambda p, n=name: p.param_id == n.decode()).param_value == value
        sys_status = wait_msg(m, "SYS_STATUS")
        assert sys_status.onboard_control_sensors_enabled & M.MAV_SYS_STATUS_GEOFENCE
        m.set_mode("GUIDED")
        assert arm(m).result == M.MAV_RESULT_ACCEPTED
        command(m, M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 8)
        assert wait_msg(m, "STATUSTEXT", lambda s: "Takeoff complete" in s.text, 60)
        m.mav.set_position_target_local_ned_send(0, 1, 1, M.MAV_FRAME_LOCAL_NED,
                                                 0b110111111000, 0, 16, -8, 0, 0, 0, 0, 0,
                                                 0, 0, 0)
        seen: list = []
        assert wait_msg(m, "STATUSTEXT", lambda s: "Fence breach: polygon" in s.text, 60,
                        seen)
        hb = wait_msg(m, "HEARTBEAT", lambda h: h.get_srcComponent() == 1)
        assert hb.custom_mode == 6                                    # RTL
        where = [g for g in seen if g.get_type() == "LOCAL_POSITION_NED"][-1]
        assert 9.3 <= where.y < 11.0        # east: caught at the edge (5 Hz telemetry lags)
        unhealthy = wait_msg(m, "SYS_STATUS")
        assert not unhealthy.onboard_control_sensors_health & M.MAV_SYS_STATUS_GEOFENCE
        assert wait_msg(m, "STATUSTEXT", lambda s: "Disarmed" in s.text, 120)
        back = wait_msg(m, "LOCAL_POSITION_NED")
        assert math.hypot(back.x, back.y - 2.0) < 0.5           # landed at home
    finally:
        veh.stop()


def test_a_braked_drum_bounds_targets_not_where_the_vehicle_holds():
    """LOCK or HOLD at 15 m paid out, the vehicle 14 m from the winder (the tether slack):
    a target that far is refused (the reach keeps its margin: 0.95 x 15 - 0.5 = 13.75 m),
    but the vehicle is not in breach of the tether's fence (15 - 0.5 = 14.5 m): it holds."""
    from companion.navigation import NavigationParams, Navigator

    nav = Navigator(NavigationParams(), 0.1, 50.0)
    nav.winch_report(15.0, 5.0, True)
    assert nav.reach_m == pytest.approx(13.75)
    assert nav.tether_limit_m == pytest.approx(14.5)
    pos = (14.0, 0.0, 0.0)
    assert nav.check_target(pos) is not None
    fence = Geofence(FenceParams(), HOME_DEFAULT)
    assert fence.breach(pos, (2.0, 0.0, 0.0), nav.tether_limit_m) is None
    assert fence.breach((14.6, 0.0, 0.0), (2.0, 0.0, 0.0),
                        nav.tether_limit_m) is FenceBreach.TETHER


def test_pre_arm_checks_as_arducopter_orders_them():
    """Each of ArduCopter's fence pre-arm failures, alone; a disabled fence always passes."""
    on_ground = (2.0, 0.0, 0.0)
    off = Geofence(FenceParams(enable=False, type_mask=4), HOME_DEFAULT)
    assert off.pre_arm(None, None) is None
    assert Geofence(FenceParams(enable=True), HOME_DEFAULT).pre_arm(on_ground, None) is None
    # polygons only, none uploaded: nothing to check
    empty = Geofence(FenceParams(enable=True, type_mask=4), HOME_DEFAULT)
    assert empty.pre_arm(on_ground, None) == "enabled, but none selected"
    # the altitude alone needs no position; the circle does
    assert Geofence(FenceParams(enable=True, type_mask=1), HOME_DEFAULT).pre_arm(
        None, None) is None
    assert Geofence(FenceParams(enable=True, type_mask=2), HOME_DEFAULT).pre_arm(
        None, None) == "requires position"
    # FENCE_MARGIN against an inclusion circle and against the ceiling
    small = Geofence(FenceParams(enable=True, type_mask=4, margin_m=5.0), HOME_DEFAULT)
    assert small.set_items([item(M.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, 0.0, 0.0, 4.0)]) is None
    assert "inclusion circle" in small.pre_arm(on_ground, None)
    low = Geofence(FenceParams(enable=True, type_mask=1, alt_max_m=10.0, margin_m=5.0),
                   HOME_DEFAULT)
    assert low.pre_arm(on_ground, None) == "FENCE_MARGIN too big for FENCE_ALT_MAX"
    assert Geofence(FenceParams(enable=True, type_mask=1, alt_max_m=10.1, margin_m=5.0),
                    HOME_DEFAULT).pre_arm(on_ground, None) is None
    # outside: a polygon that leaves the vehicle out, a circle about home too small
    square = Geofence(FenceParams(enable=True, type_mask=4), HOME_DEFAULT)
    assert square.set_items(polygon(INC, [(5.0, -5.0), (15.0, -5.0), (15.0, 5.0),
                                          (5.0, 5.0)])) is None
    assert square.pre_arm(on_ground, None) == "vehicle outside fence"
    assert square.pre_arm((10.0, 0.0, 0.0), None) is None
    circle = Geofence(FenceParams(enable=True, type_mask=2, radius_m=30.0), HOME_DEFAULT)
    assert circle.pre_arm((29.0, 0.0, 0.0), (0.0, 0.0, 0.0)) is None
    assert circle.pre_arm((31.0, 0.0, 0.0), (0.0, 0.0, 0.0)) == "vehicle outside fence"
    assert circle.pre_arm((31.0, 0.0, 0.0), (10.0, 0.0, 0.0)) is None   # about home


def test_arming_outside_an_enabled_fence_is_denied(tmp_path):
    """The real companion: an inclusion polygon that leaves the vehicle (on the ground at
    home, 2 m east of the winder) out; enabled, arming is refused as ArduCopter refuses it
    (COMMAND_ACK DENIED, the answer to every pre-arm refusal) with its 'PreArm: Fence'
    STATUSTEXT, whatever ARMING_CHECK says; disabled, it arms."""
    veh = Vehicle(tmp_path)
    try:
        m = veh.connect()
        square = [(5.0, -5.0), (15.0, -5.0), (15.0, 5.0), (5.0, 5.0)]
        assert upload_fence(m, polygon(INC, square)).type == M.MAV_MISSION_ACCEPTED

        def set_param(name: bytes, value: float, ptype: int) -> None:
            m.mav.param_set_send(1, 1, name, value, ptype)
            assert wait_msg(m, "PARAM_VALUE",
                            lambda p: p.param_id == name.decode()).param_value == value

        set_param(b"FENCE_TYPE", 4, M.MAV_PARAM_TYPE_INT8)
        m.set_mode("GUIDED")
        assert arm(m).result == M.MAV_RESULT_ACCEPTED      # the EKF healthy: it can arm
        assert command(m, M.MAV_CMD_COMPONENT_ARM_DISARM, 0).result == M.MAV_RESULT_ACCEPTED
        set_param(b"FENCE_ENABLE", 1, M.MAV_PARAM_TYPE_INT8)
        arm_once = M.MAV_CMD_COMPONENT_ARM_DISARM
        assert command(m, arm_once, 1).result == M.MAV_RESULT_DENIED
        text = wait_msg(m, "STATUSTEXT", lambda s: s.text.startswith("PreArm: Fence"), 10)
        assert text.text == "PreArm: Fence: vehicle outside fence"
        set_param(b"ARMING_CHECK", 0, M.MAV_PARAM_TYPE_INT32)
        assert command(m, arm_once, 1).result == M.MAV_RESULT_DENIED
        set_param(b"FENCE_ENABLE", 0, M.MAV_PARAM_TYPE_INT8)
        assert command(m, arm_once, 1).result == M.MAV_RESULT_ACCEPTED
    finally:
        veh.stop()


def test_sys_status_bits_as_arducopter_sets_them():
    """AC_Fence: present when FENCE_TYPE holds the altitude or the circle (parameters, no
    fence items) or polygons with an upload; enabled when present, FENCE_ENABLE set and the
    action not report-only; unhealthy only when present and breached."""
    from companion.geofence import FenceStatus

    # ArduCopter's defaults (FENCE_TYPE 7, FENCE_ENABLE 0): present with no fence items
    assert Geofence(FenceParams(), HOME_DEFAULT).sys_status(False) == FenceStatus(
        True, False, True)
    polys = Geofence(FenceParams(enable=True, type_mask=4), HOME_DEFAULT)
    assert polys.sys_status(True) == FenceStatus(False, False, True)   # nothing to check
    assert polys.set_items(polygon(INC, CONCAVE)) is None
    assert polys.sys_status(False) == FenceStatus(True, True, True)
    assert polys.sys_status(True) == FenceStatus(True, True, False)
    report = Geofence(FenceParams(enable=True, action=0), HOME_DEFAULT)
    assert report.sys_status(True) == FenceStatus(True, False, False)
    assert Geofence(FenceParams(enable=True, type_mask=0), HOME_DEFAULT).sys_status(
        False) == FenceStatus(False, False, True)


def _fence_count(m) -> int:
    m.mav.mission_request_list_send(1, 1, M.MAV_MISSION_TYPE_FENCE)
    count = wait_msg(m, "MISSION_COUNT", lambda c: c.mission_type == M.MAV_MISSION_TYPE_FENCE)
    assert count is not None
    m.mav.mission_ack_send(1, 1, M.MAV_MISSION_ACCEPTED, M.MAV_MISSION_TYPE_FENCE)
    return count.count


def test_a_fence_that_cannot_be_used_is_refused_and_the_listed_count_stays_the_used_one(
        tmp_path):
    """A polygon cut short (four vertices announced, three sent) is refused as a whole,
    MISSION_ACK MAV_MISSION_ERROR and a STATUSTEXT saying why, as ArduPilot refuses a fence
    it cannot write: the count a ground station lists stays the fence in use."""
    veh = Vehicle(tmp_path)
    try:
        m = veh.connect()
        square = [(-10.0, -10.0), (10.0, -10.0), (10.0, 10.0), (-10.0, 10.0)]
        assert upload_fence(m, polygon(INC, square)).type == M.MAV_MISSION_ACCEPTED
        assert _fence_count(m) == 4
        short = polygon(INC, square)[:3]
        seen: list = []
        ack = upload_fence(m, short)
        assert ack.type == M.MAV_MISSION_ERROR
        said = wait_msg(m, "STATUSTEXT", lambda s: "fewer than 4 vertices" in s.text, 5, seen)
        assert said is not None
        assert _fence_count(m) == 4
    finally:
        veh.stop()
