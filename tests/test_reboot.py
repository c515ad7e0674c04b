"""MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN restarts the companion's onboard state as an
ArduCopter's reboot does, against real plant and companion processes driven by pymavlink
(and MAVProxy's `reboot`, when installed): refused while armed; accepted disarmed, the
vehicle comes back in STABILIZE, disarmed, its EKF aligning again before it may arm, with
its parameters and its stored mission kept."""

from __future__ import annotations

import shutil
import time

import pytest
from gcs_util import Vehicle, arm, command, download_mission, upload_mission, wait_msg
from pymavlink import mavutil

M = mavutil.mavlink
REL = M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
EKF_READY = 512   # PRED_POS_HORIZ_ABS: ArduPilot's pre-arm reads it


@pytest.fixture(scope="module")
def vehicle(tmp_path_factory):
    veh = Vehicle(tmp_path_factory.mktemp("reboot"))
    try:
        yield veh
    finally:
        veh.stop()


def test_reboot_is_refused_armed_and_restarts_the_onboard_state_disarmed(vehicle):
    m = vehicle.connect()
    assert upload_mission(m, [(M.MAV_CMD_NAV_TAKEOFF, REL, 0, 0, 0, 0, 0, 0, 10),
                              (M.MAV_CMD_NAV_LAND, REL, 0, 0, 0, 0, 0, 0, 0)]
                          ).type == M.MAV_MISSION_ACCEPTED
    m.mav.param_set_send(1, 1, b"WPNAV_SPEED", 300.0, M.MAV_PARAM_TYPE_REAL32)
    assert wait_msg(m, "PARAM_VALUE", lambda p: p.param_id == "WPNAV_SPEED") is not None
    m.set_mode("GUIDED")
    assert arm(m).result == M.MAV_RESULT_ACCEPTED
    seen: list = []
    ack = command(m, M.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, 1, seen=seen)
    assert ack.result == M.MAV_RESULT_FAILED
    assert wait_msg(m, "STATUSTEXT", lambda s: "disarm first" in s.text, 5, seen)
    assert command(m, M.MAV_CMD_COMPONENT_ARM_DISARM, 0).result == M.MAV_RESULT_ACCEPTED
    # shutting down is not offered; 0 does nothing
    assert command(m, M.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, 2).result == \
        M.MAV_RESULT_UNSUPPORTED
    assert command(m, M.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, 0).result == M.MAV_RESULT_ACCEPTED
    assert wait_msg(m, "HEARTBEAT", lambda h: h.get_srcComponent() == 1).custom_mode == 4

    seen = []
    assert command(m, M.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, 1,
                   seen=seen).result == M.MAV_RESULT_ACCEPTED
    # the filter aligns again: arming is refused until it is ready (asked at once; the
    # alignment takes a second of simulated time, which a fast lockstep host may have
    # run before the request is read: then the filter must have been seen not ready)
    answer = command(m, M.MAV_CMD_COMPONENT_ARM_DISARM, 1, seen=seen)
    if answer.result == M.MAV_RESULT_ACCEPTED:
        assert any(x.get_type() == "EKF_STATUS_REPORT" and not x.flags & EKF_READY
                   for x in seen)
        assert command(m, M.MAV_CMD_COMPONENT_ARM_DISARM, 0).result == M.MAV_RESULT_ACCEPTED
    else:
        assert answer.result == M.MAV_RESULT_DENIED
        assert wait_msg(m, "STATUSTEXT", lambda s: "EKF" in s.text, 5, seen)
    hb = wait_msg(m, "HEARTBEAT", lambda h: h.get_srcComponent() == 1)
    assert hb.custom_mode == 0 and not hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED
    assert wait_msg(m, "EKF_STATUS_REPORT", lambda e: e.flags & EKF_READY, 30)
    m.set_mode("GUIDED")
    assert arm(m).result == M.MAV_RESULT_ACCEPTED
    assert command(m, M.MAV_CMD_COMPONENT_ARM_DISARM, 0).result == M.MAV_RESULT_ACCEPTED
    # what a reboot keeps: the parameters, the mission
    m.mav.param_request_read_send(1, 1, b"WPNAV_SPEED", -1)
    assert wait_msg(m, "PARAM_VALUE",
                    lambda p: p.param_id == "WPNAV_SPEED").param_value == 300.0
    assert [i.command for i in download_mission(m)[1:]] == [M.MAV_CMD_NAV_TAKEOFF,
                                                           M.MAV_CMD_NAV_LAND]
    assert "Rebooting" in vehicle.comp_log.read_text()
    m.close()


@pytest.mark.skipif(shutil.which("mavproxy.py") is None, reason="MAVProxy is a test extra")
def test_mavproxys_reboot_command(vehicle, tmp_path):
    from test_mavproxy import MavProxy

    before = vehicle.comp_log.read_text().count("Rebooting")
    mp = MavProxy(vehicle.tcp_port, tmp_path)
    try:
        mp.wait_for("online system 1")
        mp.say("mode GUIDED", "GUIDED")
        time.sleep(0.5)
        since = len(mp.lines)
        mp.send("reboot")
        mp.wait_for("STABILIZE", since, 30)      # MAVProxy shows the mode the vehicle came back in
    finally:
        mp.close()
    assert vehicle.comp_log.read_text().count("Rebooting") == before + 1
