"""The companion as an ArduCopter-compatible vehicle: real plant and companion processes
driven by a real pymavlink client over TCP (and UDP): connect, GUIDED, arm, take off,
guided targets, parameters, a mission in AUTO, landing and disarming, the refusals of bad
input, malformed frames, and the telemetry log. Then the companion's sockets on their own:
the component link's position frames, clients that fall behind, and input handled as it
arrives."""

from __future__ import annotations

import contextlib
import math
import select
import socket
import struct
import time

import pytest
from gcs_util import Vehicle, command, download_mission, free_port, upload_mission, wait_msg
from pymavlink import mavutil

from companion.autopilot import Autopilot
from companion.component_server import ComponentServer
from companion.mavlink_io import MavlinkEndpoints
from companion.navigation import NavigationParams, Navigator
from companion.telemetry import Telemetry
from tuavdefs import simlink
from tuavdefs.frames import global_to_local_enu, local_enu_to_global
from tuavdefs.simlink import HOME_DEFAULT

M = mavutil.mavlink
REL = M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT


def ll(x: float, y: float) -> tuple[float, float]:
    """Latitude and longitude [deg] of a point of the z-up frame."""
    lat, lon, _ = local_enu_to_global((x, y, 0.0), HOME_DEFAULT)
    return lat, lon


def local(msg) -> tuple[float, float, float]:
    """The z-up position of a GLOBAL_POSITION_INT."""
    x, y, _ = global_to_local_enu(msg.lat * 1e-7, msg.lon * 1e-7, 0.0, HOME_DEFAULT)
    return (x, y, msg.relative_alt * 1e-3)


@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    """One flight shared by the tests below, in order; records what each step saw."""
    tmp = tmp_path_factory.mktemp("gcs")
    udp_port = free_port(socket.SOCK_DGRAM)
    component_port = free_port()
    veh = Vehicle(tmp, udp_port=udp_port, extra=("--component-port", str(component_port)))
    rec: dict = {"veh": veh, "udp_port": udp_port, "component_port": component_port}
    try:
        m = veh.connect()
        rec["m"] = m
        yield rec
    finally:
        rec["logs"] = veh.stop()


def test_heartbeat_identifies_an_arducopter_on_the_ground(flight):
    m = flight["m"]
    hb = wait_msg(m, "HEARTBEAT", lambda h: h.get_srcComponent() == 1)
    assert (hb.type, hb.autopilot) == (M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA)
    assert hb.get_srcSystem() == 1 and hb.base_mode & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    assert not hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED
    assert hb.system_status == M.MAV_STATE_STANDBY
    assert m.flightmode == "STABILIZE"
    m.mav.command_long_send(1, 1, M.MAV_CMD_REQUEST_MESSAGE, 0,
                            M.MAVLINK_MSG_ID_AUTOPILOT_VERSION, 0, 0, 0, 0, 0, 0)
    ver = wait_msg(m, "AUTOPILOT_VERSION")
    for cap in (M.MAV_PROTOCOL_CAPABILITY_MISSION_INT, M.MAV_PROTOCOL_CAPABILITY_COMMAND_INT,
                M.MAV_PROTOCOL_CAPABILITY_MAVLINK2,
                M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED):
        assert ver.capabilities & cap
    # the default streams arrive without asking
    seen = set()
    end = time.monotonic() + 20
    want = {"SYS_STATUS", "GLOBAL_POSITION_INT", "LOCAL_POSITION_NED", "ATTITUDE",
            "GPS_RAW_INT", "VFR_HUD", "EXTENDED_SYS_STATE", "BATTERY_STATUS"}
    while not want <= seen and time.monotonic() < end:
        msg = m.recv_match(blocking=True, timeout=1)
        if msg is not None:
            seen.add(msg.get_type())
    assert want <= seen
    gps = m.messages["GPS_RAW_INT"]
    assert gps.fix_type == M.GPS_FIX_TYPE_3D_FIX
    pos = local(m.messages["GLOBAL_POSITION_INT"])
    assert pos[0] == pytest.approx(2.0, abs=0.01) and pos[1] == pytest.approx(0.0, abs=0.01)
    lp = m.messages["LOCAL_POSITION_NED"]
    assert (lp.x, lp.y) == pytest.approx((0.0, 2.0), abs=0.01)   # NED: 2 m east of winder
    assert m.messages["EXTENDED_SYS_STATE"].landed_state == M.MAV_LANDED_STATE_ON_GROUND
    # the receiver's fix is healthy once the estimate it feeds is ready to arm on
    assert wait_msg(m, "SYS_STATUS", lambda s: s.onboard_control_sensors_health
                    & M.MAV_SYS_STATUS_SENSOR_GPS, 20)


def test_set_a_parameter_and_read_it_back(flight):
    m = flight["m"]
    m.mav.param_set_send(1, 1, b"TUAV_PSC_K1_Z", 2.5, M.MAV_PARAM_TYPE_REAL32)
    v = wait_msg(m, "PARAM_VALUE", lambda p: p.param_id == "TUAV_PSC_K1_Z")
    assert v.param_value == pytest.approx(2.5)
    m.mav.param_request_read_send(1, 1, b"TUAV_PSC_K1_Z", -1)
    v = wait_msg(m, "PARAM_VALUE", lambda p: p.param_id == "TUAV_PSC_K1_Z")
    assert v.param_value == pytest.approx(2.5)
    # out of bounds: refused by name, value unchanged
    m.mav.param_set_send(1, 1, b"TUAV_PSC_K1_Z", -1.0, M.MAV_PARAM_TYPE_REAL32)
    v = wait_msg(m, "PARAM_VALUE", lambda p: p.param_id == "TUAV_PSC_K1_Z")
    assert v.param_value == pytest.approx(2.5)
    # the .parm file is written off the control loop, soon after
    parm, end = flight["veh"].param_file, time.monotonic() + 10.0
    while not (parm.exists() and "TUAV_PSC_K1_Z" in parm.read_text()) and time.monotonic() < end:
        time.sleep(0.05)
    assert "TUAV_PSC_K1_Z" in parm.read_text()
    # the whole list arrives
    m.mav.param_request_list_send(1, 1)
    names = set()
    count = None
    end = time.monotonic() + 20
    while time.monotonic() < end and (count is None or len(names) < count):
        p = m.recv_match(type="PARAM_VALUE", blocking=True, timeout=1)
        if p is not None:
            names.add(p.param_id)
            count = p.param_count
    assert count is not None and len(names) == count
    assert {"WPNAV_SPEED", "TUAV_PSC_K1_X", "TUAV_ATC_K3_Z", "RTL_ALT", "RTL_ALT_M",
            "TUAV_TETH_REACH", "ARMING_CHECK"} <= names


def test_guided_arm_and_take_off_to_10_m(flight):
    m = flight["m"]
    ack = command(m, M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 10)
    assert ack.result == M.MAV_RESULT_FAILED                  # not in GUIDED, not armed
    m.set_mode("GUIDED")
    assert wait_msg(m, "COMMAND_ACK", lambda a: a.command == M.MAV_CMD_DO_SET_MODE).result \
        == M.MAV_RESULT_ACCEPTED
    ack = command(m, M.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    assert ack.result == M.MAV_RESULT_ACCEPTED
    hb = wait_msg(m, "HEARTBEAT", lambda h: h.get_srcComponent() == 1
                  and h.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)
    assert hb.custom_mode == 4 and hb.system_status == M.MAV_STATE_ACTIVE
    home = wait_msg(m, "HOME_POSITION")
    assert local(type("G", (), {"lat": home.latitude, "lon": home.longitude,
                                "relative_alt": 0})())[:2] == pytest.approx((2.0, 0.0),
                                                                           abs=0.01)
    ack = command(m, M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, 0, 0, 10)
    assert ack.result == M.MAV_RESULT_ACCEPTED
    assert wait_msg(m, "GLOBAL_POSITION_INT", lambda g: g.relative_alt > 9700, 60)
    assert wait_msg(m, "STATUSTEXT", lambda s: "Takeoff complete" in s.text, 30)
    # hovering at the take-off point: the rotors near hover (PWM 1000..2000), the target
    # reached, no wind in this run (the disturbance estimate is the tether model's error)
    servo = wait_msg(m, "SERVO_OUTPUT_RAW")
    pwm = [servo.servo1_raw, servo.servo2_raw, servo.servo3_raw, servo.servo4_raw]
    assert all(1200 < v < 1900 for v in pwm) and max(pwm) - min(pwm) < 100
    nav = wait_msg(m, "NAV_CONTROLLER_OUTPUT")
    assert nav.wp_dist == 0 and abs(nav.alt_error) < 0.3 and nav.xtrack_error < 0.2
    assert wait_msg(m, "WIND").speed < 1.0


def test_streams_follow_set_message_interval_and_request_data_stream(flight):
    m = flight["m"]
    ack = command(m, M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_ATTITUDE, 20_000)
    assert ack.result == M.MAV_RESULT_ACCEPTED
    stamps = []
    end = time.monotonic() + 20
    while len(stamps) < 30 and time.monotonic() < end:
        a = m.recv_match(type="ATTITUDE", blocking=True, timeout=1)
        if a is not None:
            stamps.append(a.time_boot_ms)
    steps = sorted(set(b - a for a, b in zip(stamps[5:], stamps[6:], strict=False)))
    assert steps and max(steps) <= 24 and min(steps) >= 16   # 50 Hz of simulated time
    command(m, M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_ATTITUDE, 0)  # default
    # POSITION group off on this link: no GLOBAL_POSITION_INT, heartbeats go on
    m.mav.request_data_stream_send(1, 1, M.MAV_DATA_STREAM_POSITION, 0, 0)
    wait_msg(m, "HEARTBEAT")
    wait_msg(m, "HEARTBEAT")
    seen: list = []
    wait_msg(m, "HEARTBEAT", seen=seen)
    wait_msg(m, "HEARTBEAT", seen=seen)
    assert not any(x.get_type() == "GLOBAL_POSITION_INT" for x in seen)
    m.mav.request_data_stream_send(1, 1, M.MAV_DATA_STREAM_POSITION, 10, 1)
    assert wait_msg(m, "GLOBAL_POSITION_INT", timeout=10) is not None
    # an unknown message id is refused
    assert command(m, M.MAV_CMD_REQUEST_MESSAGE, 9999).result == M.MAV_RESULT_UNSUPPORTED


def test_mavftp_is_refused_at_once_so_clients_fall_back(flight):
    m = flight["m"]
    path = b"@PARAM/param.pck"
    payload = struct.pack("<HBBBBBBI", 7, 0, 4, len(path), 0, 0, 0, 0) + path
    m.mav.file_transfer_protocol_send(0, 1, 1, list(payload.ljust(251, b"\0")))
    nak = wait_msg(m, "FILE_TRANSFER_PROTOCOL", timeout=5)
    data = bytes(nak.payload)
    seq, session, opcode, size, req_opcode = struct.unpack("<HBBBB", data[:6])
    assert (opcode, req_opcode, size, data[12]) == (129, 4, 1, 10)   # NAK FileNotFound
    assert seq == 8


def test_winch_commands_without_a_winch_fail_cleanly(flight):
    m = flight["m"]
    seen: list = []
    ack = command(m, M.MAV_CMD_DO_WINCH, 1, M.WINCH_RELAXED, seen=seen)
    assert ack.result == M.MAV_RESULT_FAILED
    assert wait_msg(m, "STATUSTEXT", lambda s: "Winch" in s.text, 5, seen) is not None


def test_guided_target_and_reposition(flight):
    m = flight["m"]
    # a waypoint-speed change takes effect on the next move
    m.mav.param_set_send(1, 1, b"WPNAV_SPEED", 300.0, M.MAV_PARAM_TYPE_REAL32)   # cm/s
    assert wait_msg(m, "PARAM_VALUE",
                    lambda p: p.param_id == "WPNAV_SPEED").param_value == 300.0
    # SET_POSITION_TARGET_LOCAL_NED: 14 m east, 10 m north, 12 m up (NED: x north, y east)
    mask = 0b0000111111111000
    m.mav.set_position_target_local_ned_send(0, 1, 1, M.MAV_FRAME_LOCAL_NED, mask,
                                             10.0, 14.0, -12.0, 0, 0, 0, 0, 0, 0, 0, 0)
    speeds: list[float] = []

    def arrived(g) -> bool:
        speeds.append(math.hypot(g.vx, g.vy) * 0.01)
        return math.dist(local(g), (14.0, 10.0, 12.0)) < 0.2

    assert wait_msg(m, "GLOBAL_POSITION_INT", arrived, 60) is not None
    assert 2.7 < max(speeds) < 3.3                           # cruised at WPNAV_SPEED
    # SET_POSITION_TARGET_GLOBAL_INT, relative altitude
    lat, lon = ll(2.0, 6.0)
    m.mav.set_position_target_global_int_send(0, 1, 1, REL, mask, round(lat * 1e7),
                                              round(lon * 1e7), 10.0, 0, 0, 0, 0, 0, 0, 0, 0)
    assert wait_msg(m, "GLOBAL_POSITION_INT",
                    lambda g: math.dist(local(g), (2.0, 6.0, 10.0)) < 0.2, 60)
    # a guided mission item (current = 2), as MAVProxy's "guided" command sends
    lat, lon = ll(4.0, 4.0)
    m.mav.mission_item_int_send(1, 1, 0, REL, M.MAV_CMD_NAV_WAYPOINT, 2, 0, 0, 0, 0, 0,
                                round(lat * 1e7), round(lon * 1e7), 11.0)
    assert wait_msg(m, "MISSION_ACK").type == M.MAV_MISSION_ACCEPTED
    assert wait_msg(m, "GLOBAL_POSITION_INT",
                    lambda g: math.dist(local(g), (4.0, 4.0, 11.0)) < 0.2, 60)
    # DO_REPOSITION (COMMAND_INT, relative altitude)
    lat, lon = ll(0.0, 8.0)
    m.mav.command_int_send(1, 1, REL, M.MAV_CMD_DO_REPOSITION, 0, 0, -1, 0, 0, math.nan,
                           round(lat * 1e7), round(lon * 1e7), 11.0)
    ack = wait_msg(m, "COMMAND_ACK", lambda a: a.command == M.MAV_CMD_DO_REPOSITION)
    assert ack.result == M.MAV_RESULT_ACCEPTED
    assert wait_msg(m, "GLOBAL_POSITION_INT",
                    lambda g: math.dist(local(g), (0.0, 8.0, 11.0)) < 0.2, 60)


def test_targets_beyond_the_tether_or_below_ground_are_refused(flight):
    m = flight["m"]
    seen: list = []
    lat, lon = ll(80.0, 0.0)
    m.mav.command_int_send(1, 1, REL, M.MAV_CMD_DO_REPOSITION, 0, 0, -1, 0, 0, math.nan,
                           round(lat * 1e7), round(lon * 1e7), 10.0)
    ack = wait_msg(m, "COMMAND_ACK", lambda a: a.command == M.MAV_CMD_DO_REPOSITION,
                   seen=seen)
    assert ack.result == M.MAV_RESULT_DENIED
    text = wait_msg(m, "STATUSTEXT", lambda s: "reach" in s.text, seen=seen)
    assert text is not None and text.severity <= M.MAV_SEVERITY_WARNING
    ack = command(m, M.MAV_CMD_DO_REPOSITION, 0, 0, 0, 0, math.nan, math.nan, 10)
    assert ack.result == M.MAV_RESULT_DENIED
    mask = 0b0000111111111000
    m.mav.set_position_target_local_ned_send(0, 1, 1, M.MAV_FRAME_LOCAL_NED, mask,
                                             0.0, 0.0, 5.0, 0, 0, 0, 0, 0, 0, 0, 0)
    assert wait_msg(m, "STATUSTEXT", lambda s: "below the ground" in s.text)
    # the vehicle stayed where it was
    g = wait_msg(m, "GLOBAL_POSITION_INT")
    assert math.dist(local(g), (0.0, 8.0, 11.0)) < 0.2
    # a mission with an unreachable waypoint: the error names it, the old mission stays
    before = download_mission(m)
    lat_far, lon_far = ll(0.0, 70.0)
    ack = upload_mission(m, [(M.MAV_CMD_NAV_TAKEOFF, REL, 0, 0, 0, 0, 0, 0, 10),
                             (M.MAV_CMD_NAV_WAYPOINT, REL, 0, 0, 0, 0, lat_far, lon_far, 10)])
    assert ack.type == M.MAV_MISSION_INVALID_PARAM5_X
    assert wait_msg(m, "STATUSTEXT", lambda s: "item 2" in s.text)
    assert len(download_mission(m)) == len(before)
    ack = upload_mission(m, [(M.MAV_CMD_NAV_WAYPOINT, REL, 0, 0, 0, 0, *ll(3, 3), -5)])
    assert ack.type == M.MAV_MISSION_INVALID_PARAM7
    ack = command(m, 31999)                                   # no such command
    assert ack.result == M.MAV_RESULT_UNSUPPORTED
    assert command(m, M.MAV_CMD_COMPONENT_ARM_DISARM, 0).result == M.MAV_RESULT_FAILED


def test_malformed_frames_are_dropped_and_mavlink1_is_accepted(flight):
    veh = flight["veh"]
    with socket.create_connection(("127.0.0.1", veh.tcp_port)) as s:
        s.sendall(b"\xfd\x09\x00\x00\x00\xff\xbe\x00\x00\x00" + b"\x00" * 4)   # truncated
        s.sendall(b"\xfd" + bytes(range(40)))                                  # garbage
        good = M.MAVLink(None, srcSystem=255, srcComponent=190)
        frame = bytearray(good.heartbeat_encode(6, 8, 0, 0, 0).pack(good))
        frame[-1] ^= 0xFF                                                      # bad CRC
        s.sendall(bytes(frame))
        v1 = mavutil.mavlink_connection(f"tcp:127.0.0.1:{veh.tcp_port}", source_system=254,
                                        dialect="ardupilotmega")
    v1 = mavutil.mavlink_connection(f"tcp:127.0.0.1:{veh.tcp_port}", source_system=254)
    v1.WIRE_PROTOCOL_VERSION = "1.0"
    mav1 = mavutil.mavlink.MAVLink(None, srcSystem=254, srcComponent=190)
    # a MAVLink 1 COMMAND_LONG: an STX of 0xFE frame
    try:
        from pymavlink.dialects.v10 import common as v10
        mav1 = v10.MAVLink(None, srcSystem=254, srcComponent=190)
        data = mav1.command_long_encode(1, 1, M.MAV_CMD_REQUEST_MESSAGE, 0,
                                        M.MAVLINK_MSG_ID_AUTOPILOT_VERSION, 0, 0, 0, 0, 0,
                                        0).pack(mav1)
        assert data[0] == 0xFE
        v1.write(data)
        ack = wait_msg(v1, "COMMAND_ACK", lambda a: a.command == M.MAV_CMD_REQUEST_MESSAGE)
        assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
    finally:
        v1.close()
    # the vehicle still flies and answers
    assert wait_msg(flight["m"], "HEARTBEAT", lambda h: h.get_srcComponent() == 1)


def test_udp_endpoint_pushes_and_answers(flight):
    u = mavutil.mavlink_connection(f"udpin:127.0.0.1:{flight['udp_port']}",
                                   source_system=253, source_component=190)
    try:
        assert u.wait_heartbeat(timeout=10) is not None
        u.target_system, u.target_component = 1, 1
        u.mav.command_long_send(1, 1, M.MAV_CMD_REQUEST_MESSAGE, 0,
                                M.MAVLINK_MSG_ID_HOME_POSITION, 0, 0, 0, 0, 0, 0)
        ack = wait_msg(u, "COMMAND_ACK", lambda a: a.command == M.MAV_CMD_REQUEST_MESSAGE)
        assert ack.result == M.MAV_RESULT_ACCEPTED
        assert (ack.target_system, ack.target_component) == (253, 190)
        assert wait_msg(u, "HOME_POSITION") is not None
    finally:
        u.close()


def test_mission_in_auto_reaches_every_item_then_lands_and_disarms(flight):
    """A mission with a DO_WINCH item: the autopilot hands it to the winch (a pymavlink
    component 169 on the component link here), which answers; the nav items are reached in
    order and the vehicle lands and disarms."""
    m = flight["m"]
    items = [
        (M.MAV_CMD_NAV_TAKEOFF, REL, 0, 0, 0, 0, 0, 0, 10),
        (M.MAV_CMD_NAV_WAYPOINT, REL, 0, 0, 0, 0, *ll(5.0, 0.0), 10),
        (M.MAV_CMD_DO_WINCH, M.MAV_FRAME_MISSION, 1, 1, 0.5, 0.25, 0, 0, 0),
        (M.MAV_CMD_NAV_WAYPOINT, REL, 1, 0, 0, 0, *ll(5.0, 6.0), 12),
        (M.MAV_CMD_NAV_WAYPOINT, REL, 0, 0, 0, 0, *ll(-3.0, 6.0), 12),
        (M.MAV_CMD_NAV_LAND, REL, 0, 0, 0, 0, 0, 0, 0),
    ]
    winch = mavutil.mavlink_connection(f"tcp:127.0.0.1:{flight['component_port']}",
                                       source_system=1, source_component=169)
    ack = upload_mission(m, items)
    assert ack.type == M.MAV_MISSION_ACCEPTED
    got = download_mission(m)
    assert [i.command for i in got[1:]] == [c[0] for c in items]
    # MISSION_CURRENT's mission_state as ArduCopter reports it: not started, active,
    # complete at the end (what MAVSDK's is_mission_finished reads)
    before = wait_msg(m, "MISSION_CURRENT")
    assert (before.total, before.mission_state) == (6, M.MISSION_STATE_NOT_STARTED)
    m.set_mode("AUTO")
    seen: list = []
    reached: list[int] = []
    to_winch: list = []
    disarmed = None
    end = time.monotonic() + 180
    try:
        while time.monotonic() < end:
            cmd = winch.recv_match(type="COMMAND_LONG", blocking=False)
            if cmd is not None:
                to_winch.append(cmd)
                winch.mav.command_ack_send(cmd.command, M.MAV_RESULT_ACCEPTED, 0, 0,
                                           cmd.get_srcSystem(), cmd.get_srcComponent())
            msg = wait_msg(m, ["MISSION_ITEM_REACHED", "HEARTBEAT"], timeout=5, seen=seen)
            if msg is None:
                continue
            if msg.get_type() == "MISSION_ITEM_REACHED":
                reached.append(msg.seq)
                if msg.seq == 4:
                    pos = local(m.messages["GLOBAL_POSITION_INT"])
                    assert math.dist(pos, (5.0, 6.0, 12.0)) < 0.6
            elif (msg.get_srcComponent() == 1
                  and not msg.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED):
                disarmed = msg
                break
    finally:
        winch.close()
    assert reached == [1, 2, 4, 5, 6]          # a DO_ item is run, not reached
    assert disarmed is not None
    states = [x.mission_state for x in seen if x.get_type() == "MISSION_CURRENT"]
    assert M.MISSION_STATE_ACTIVE in states
    assert wait_msg(m, "MISSION_CURRENT").mission_state == M.MISSION_STATE_COMPLETE
    assert len(to_winch) == 1
    w = to_winch[0]
    assert (w.command, w.target_system, w.target_component) == (M.MAV_CMD_DO_WINCH, 1, 169)
    assert (w.get_srcSystem(), w.get_srcComponent()) == (1, 1)
    assert (w.param1, w.param2, w.param3, w.param4) == (1, 1, 0.5, 0.25)
    # the winch's answer to the autopilot's own command is not routed to ground stations
    assert not any(x.get_type() == "COMMAND_ACK" and x.command == M.MAV_CMD_DO_WINCH
                   for x in seen)
    g = wait_msg(m, "GLOBAL_POSITION_INT")
    assert local(g)[2] < 0.3
    assert math.hypot(local(g)[0] + 3.0, local(g)[1] - 6.0) < 0.3
    texts = [s.text for s in seen if s.get_type() == "STATUSTEXT"]
    assert any("Reached command #2" in t for t in texts)
    assert not any("winch" in t for t in texts)
    assert wait_msg(m, "EXTENDED_SYS_STATE").landed_state == M.MAV_LANDED_STATE_ON_GROUND


def test_the_telemetry_log_parses_completely(flight):
    veh = flight["veh"]
    plant_log, comp_log = veh.stop()
    assert "Traceback" not in comp_log
    assert "bad MAVLink frames dropped" in comp_log
    bad = int(comp_log.split("; ")[-1].split()[0])
    assert bad >= 3                                 # the malformed frames were counted
    tlog = mavutil.mavlink_connection(str(veh.tlog))
    kinds: dict[str, int] = {}
    last_t = 0.0
    while True:
        msg = tlog.recv_match()
        if msg is None:
            break
        kinds[msg.get_type()] = kinds.get(msg.get_type(), 0) + 1
        assert msg._timestamp >= last_t - 1.0
        last_t = msg._timestamp
    assert kinds.get("BAD_DATA", 0) == 0
    for k in ("HEARTBEAT", "COMMAND_LONG", "COMMAND_ACK", "MISSION_ITEM_INT",
              "MISSION_ITEM_REACHED", "PARAM_SET", "GLOBAL_POSITION_INT"):
        assert kinds.get(k, 0) > 0, k
    # each record is an 8-byte big-endian microsecond stamp followed by a frame
    raw = veh.tlog.read_bytes()
    (stamp,) = struct.unpack(">Q", raw[:8])
    assert abs(stamp * 1e-6 - time.time()) < 3600
    assert raw[8] in (0xFD, 0xFE)


# ----- the companion's sockets on their own (no processes)


def _parse_all(data: bytes) -> list:
    parser = M.MAVLink(None)
    parser.robust_parsing = True
    msgs = parser.parse_buffer(data) or []
    assert all(m.get_type() != "BAD_DATA" for m in msgs)
    return msgs


def _slow_reader(port: int) -> socket.socket:
    """A TCP client of 127.0.0.1:``port`` with a small receive buffer (a reader that falls
    behind soon)."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    sock.connect(("127.0.0.1", port))
    return sock


def _read_until(sock: socket.socket, n_bytes: int, flush=None) -> bytes:
    """Read from a blocking ``sock`` until ``n_bytes`` came (calling ``flush`` between
    reads: what the control loop does at every period)."""
    data = b""
    sock.settimeout(5.0)
    while len(data) < n_bytes:
        if flush is not None:
            flush()
        data += sock.recv(1 << 16)
    return data


@pytest.mark.parametrize("crc_helper", ["fastcrc", "pure python"])
def test_component_position_frames_are_pymavlinks(crc_helper, monkeypatch):
    if crc_helper == "pure python":
        monkeypatch.setattr(simlink.codec, "_MCRF4XX", None)   # mavlink_crc's C helper
    server = ComponentServer(0)
    try:
        mav = server.mav
        cases = [(0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0),           # all but one byte trimmed
                 (1234, 1.5, -2.25, -10.0, 0.1, 0.2, 0.0),    # trailing zero bytes trimmed
                 (4294967295, -0.0, 3.0, -0.0, -1.0, 1e-30, -0.0),
                 (85240, 12.345678, -5.5e3, -7.0, 1.0 / 3.0, -2.0 / 3.0, 0.125)]
        for seq in (0, 7, 255):
            mav.seq = seq
            for args in cases:
                expected = mav.local_position_ned_encode(*args).pack(mav)
                assert server.pack_position(*args) == expected
        mav.seq = 0
    finally:
        server.close()


def test_component_link_sends_positions_at_100_hz_in_ned_without_blocking():
    server = ComponentServer(0)
    client = _slow_reader(server.port)
    try:
        server.send_position(0.0, (1.0, 2.0, 3.0), (0.0, 0.0, 0.0))   # nobody yet: nothing
        time.sleep(0.05)
        server.poll()                          # accepts
        assert server.connected and server.selectable is server.conn
        # a component that does not read: nothing blocks, frames queue whole
        server.conn.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 4096)
        n = 3000
        for k in range(n):
            t = 0.004 * k
            server.send_position(t, (1.0, 2.0, 3.0 + k), (0.5, -0.25, 1.0))
        assert server.backlogged
        frame_len = len(server.pack_position(0, 2.0, 1.0, -3.0, -0.25, 0.5, -1.0))
        sent = sum(1 for k in range(n) if k % 5 in (0, 3))   # 100 Hz of 250 Hz periods
        data = _read_until(client, sent * frame_len, server.flush)
        msgs = _parse_all(data)
        assert not server.backlogged
        assert len(msgs) == sent == len(data) // frame_len
        first, second = msgs[0], msgs[1]
        assert (first.time_boot_ms, first.x, first.y, first.z) == (0, 2.0, 1.0, -3.0)
        assert (first.vx, first.vy, first.vz) == (-0.25, 0.5, -1.0)
        assert second.time_boot_ms == 12 and second.z == -6.0
    finally:
        client.close()
        server.close()


def test_ground_station_tcp_frames_stay_whole_when_a_client_falls_behind():
    ep = MavlinkEndpoints(0, [])
    client = _slow_reader(ep.tcp_port)
    try:
        time.sleep(0.05)
        assert ep.poll(0.5) == []              # accepts
        assert [p[0] for p in ep.links()] == ["tcp"]
        (sock,) = ep._tcp.values()
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 4096)
        n = 2000
        for k in range(n):
            ep.send(M.MAVLink_named_value_int_message(k, b"count", k))
        assert ep.backlogged
        frame_len = len(ep.pack(M.MAVLink_named_value_int_message(1, b"count", 1)))
        data = _read_until(client, n * frame_len, ep.flush)
        assert [m.value for m in _parse_all(data)] == list(range(n))
        assert not ep.backlogged
        client.close()
        deadline = time.monotonic() + 5.0
        while ep.links() and time.monotonic() < deadline:
            ep.poll(0.1)
        assert ep.links() == [] and len(ep.pop_closed()) == 1
    finally:
        ep.close()


def test_input_is_handled_as_it_arrives_and_service_sends_what_is_due():
    ep = MavlinkEndpoints(0, [])
    comp = ComponentServer(0)
    nav = Navigator(NavigationParams(), 0.2, 60.0)
    ap = Autopilot(ep, nav, HOME_DEFAULT, [], component=comp, log=lambda text: None)
    gcs = mavutil.mavlink_connection(f"tcp:127.0.0.1:{ep.tcp_port}", source_system=255)
    winch = socket.create_connection(("127.0.0.1", comp.port))
    try:
        watched = ap.selectables()
        assert set(watched) == {ep.listener, comp.listener}
        assert ap.selectables() is watched              # unchanged: the same list

        def wait_input(timeout_s: float = 2.0) -> None:
            ready = select.select(ap.selectables(), [], [], timeout_s)[0]
            assert ready
            ap.receive([-1, *ready])                    # what is not its own is ignored

        while not (comp.connected and ep.links()):
            wait_input()                                # the two connections
        assert set(ap.selectables()) == {ep.listener, comp.conn, *ep._tcp.values()}
        telem = Telemetry(0.0, (0.0, 0.0, 0.2), (0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0),
                          (0.0, 0.0, 0.0), 0.0)
        ap.service(telem)                               # the first streams and heartbeat
        assert wait_msg(gcs, "HEARTBEAT", timeout=2.0) is not None
        gcs.mav.command_long_send(1, 1, M.MAV_CMD_REQUEST_PROTOCOL_VERSION, 0,
                                  0, 0, 0, 0, 0, 0, 0)
        wait_input()
        # answered at once, not at the next control period
        ack = wait_msg(gcs, "COMMAND_ACK", timeout=2.0)
        assert (ack.command, ack.result) == (M.MAV_CMD_REQUEST_PROTOCOL_VERSION,
                                            M.MAV_RESULT_UNSUPPORTED)
        for k in range(1, 600):                         # 2.4 s of control periods
            ap.service(telem._replace(t_s=0.004 * k))
        counts: dict[str, int] = {}
        deadline = time.monotonic() + 1.0
        while (msg := gcs.recv_match(blocking=True, timeout=0.2)) is not None \
                and time.monotonic() < deadline:
            counts[msg.get_type()] = counts.get(msg.get_type(), 0) + 1
        # ATTITUDE at 10 Hz of simulated time, SYS_STATUS at 1 Hz, over t = 0.004 .. 2.396
        assert 23 <= counts["ATTITUDE"] <= 24 and counts["SYS_STATUS"] == 2
    finally:
        gcs.close()
        winch.close()
        ep.close()
        comp.close()


def test_telemetry_due_at_one_instant_goes_out_in_one_period():
    """The default streams (10, 5, 2, 1, 0.5 and 0.2 Hz) all lie on the 10 Hz grid, so a
    ground station gets data in 10 periods per simulated second and no more, however the
    sums of their intervals round."""
    ep = MavlinkEndpoints(0, [])
    nav = Navigator(NavigationParams(), 0.2, 60.0)
    ap = Autopilot(ep, nav, HOME_DEFAULT, [], log=lambda text: None)
    gcs = socket.create_connection(("127.0.0.1", ep.tcp_port))
    gcs.setblocking(False)
    try:
        while not ep.links():
            ap.receive(select.select(ap.selectables(), [], [], 2.0)[0])
        telem = Telemetry(0.0, (0.0, 0.0, 0.2), (0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0),
                          (0.0, 0.0, 0.0), 0.0)
        t0 = 3.212     # the link opens at some period's time, off the grid of round numbers
        periods_with_data = 0
        for k in range(2500):                           # 10 s of 4 ms control periods
            ap.service(telem._replace(t_s=t0 + 0.004 * k))
            time.sleep(0.0002 if k % 50 else 0.002)     # loopback delivery
            got = b""
            with contextlib.suppress(BlockingIOError):
                while chunk := gcs.recv(65536):
                    got += chunk
            periods_with_data += bool(got)
        assert periods_with_data == 100
    finally:
        gcs.close()
        ep.close()


def test_batched_telemetry_waits_for_its_interval_and_replies_take_it_along():
    """With ``batch_s``, what a TCP ground station did not ask for goes out at most every
    ``batch_s`` of wall time (flush), and a reply carries what waited ahead of it: every
    frame arrives, in the order sent."""
    ep = MavlinkEndpoints(0, [], batch_s=0.3)
    gcs = socket.create_connection(("127.0.0.1", ep.tcp_port))
    gcs.settimeout(0.05)
    try:
        while not ep.links():
            ep.poll(0.1)
        peer = ep.links()[0]

        def frame(k: int) -> bytes:
            return ep.pack(M.MAVLink_system_time_message(k, k))

        def received() -> bytes:
            got = b""
            with contextlib.suppress(TimeoutError):
                while chunk := gcs.recv(65536):
                    got += chunk
            return got

        ep.send_frames([frame(1)], peer)        # the first in a while: at once
        assert received() == frame(1)
        ep.send_frames([frame(2)], peer)        # within the interval: held
        ep.send_bytes(frame(3))                 # a broadcast too
        ep.flush()
        assert ep.backlogged and received() == b""
        time.sleep(0.35)
        ep.flush()                              # its time has come
        assert not ep.backlogged and received() == frame(2) + frame(3)
        four = frame(4)
        ep.send_frames([four], peer)            # held again ...
        ep.send(M.MAVLink_command_ack_message(1, 0), peer)   # ... until a reply
        got = received()
        assert got.startswith(four)
        msgs = mavutil.mavlink.MAVLink(None).parse_buffer(got[len(four):])
        assert [m.get_type() for m in msgs] == ["COMMAND_ACK"]
    finally:
        gcs.close()
        ep.close()
