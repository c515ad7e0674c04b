"""The ground-station failsafe as an ArduCopter user meets it: a real plant and companion,
a pymavlink ground station that sets FS_GCS_ENABLE and FS_GCS_TIMEOUT, sends its
HEARTBEAT while the vehicle takes off, then falls silent: the vehicle says so and flies
RTL."""

from __future__ import annotations

import time

import pytest
from gcs_util import Vehicle, arm, command
from pymavlink import mavutil

M = mavutil.mavlink


def pump(m, until, timeout_s: float, heartbeat: bool) -> object:
    """Read messages until ``until(msg)`` (sending a GCS HEARTBEAT every 0.5 s of wall time
    if ``heartbeat``); the message, or None after ``timeout_s``."""
    end = time.monotonic() + timeout_s
    last = 0.0
    while time.monotonic() < end:
        if heartbeat and time.monotonic() - last > 0.5:
            m.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            last = time.monotonic()
        msg = m.recv_match(blocking=True, timeout=0.1)
        if msg is not None and until(msg):
            return msg
    return None


@pytest.fixture
def vehicle(tmp_path):
    v = Vehicle(tmp_path, speedup="2")
    yield v
    v.stop()


def test_a_silent_ground_station_sends_the_vehicle_home(vehicle):
    m = vehicle.connect()
    for name, value, kind in ((b"FS_GCS_ENABLE", 1, M.MAV_PARAM_TYPE_INT8),
                              (b"FS_GCS_TIMEOUT", 3.0, M.MAV_PARAM_TYPE_REAL32)):
        m.mav.param_set_send(1, 1, name, value, kind)
        got = pump(m, lambda x, n=name: x.get_type() == "PARAM_VALUE"
                   and x.param_id == n.decode(), 10.0, True)
        assert got is not None and got.param_value == pytest.approx(value)
    m.set_mode("GUIDED")
    assert pump(m, lambda x: x.get_type() == "COMMAND_ACK"
                and x.command == M.MAV_CMD_DO_SET_MODE, 10.0, True).result == 0
    assert arm(m).result == M.MAV_RESULT_ACCEPTED
    assert command(m, M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, float("nan"), 0, 0, 6).result == 0
    assert pump(m, lambda x: x.get_type() == "STATUSTEXT" and "Takeoff complete" in x.text,
                60.0, True) is not None
    # silence: 3 s of simulated time (1.5 s of wall time at 2x) and the failsafe acts
    text = pump(m, lambda x: x.get_type() == "STATUSTEXT" and "GCS Failsafe" in x.text,
                30.0, False)
    assert text is not None and text.text == "GCS Failsafe: RTL"
    assert text.severity == M.MAV_SEVERITY_CRITICAL
    hb = pump(m, lambda x: x.get_type() == "HEARTBEAT" and x.get_srcComponent() == 1
              and x.custom_mode == 6, 10.0, False)
    assert hb is not None                                   # RTL
