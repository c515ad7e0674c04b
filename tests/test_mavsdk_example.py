"""MAVSDK-Python, unchanged, flies the vehicle: examples/mavsdk_mission.py against the real
plant and companion processes (UDP, as MAVSDK connects to an ArduCopter SITL)."""

import socket
import subprocess
import sys

import pytest
from gcs_util import ROOT, Vehicle, free_port

pytest.importorskip("mavsdk_grpc", reason="MAVSDK-Python (mavsdk-grpc) is a test extra")


def test_mavsdk_flies_takeoff_goto_and_a_mission_raw_with_rtl(tmp_path):
    udp_port = free_port(socket.SOCK_DGRAM)
    veh = Vehicle(tmp_path, udp_port=udp_port, speedup="4")
    try:
        res = subprocess.run(
            [sys.executable, "examples/mavsdk_mission.py", "--connect",
             f"udpin://127.0.0.1:{udp_port}", "--grpc-port", str(free_port()),
             "--timeout", "240"],
            cwd=ROOT, capture_output=True, text=True, timeout=300)
    finally:
        _, comp_log = veh.stop()
    assert res.returncode == 0, res.stdout + res.stderr[-3000:] + comp_log
    assert "WPNAV_SPEED = 250.0 cm/s" in res.stdout
    assert "mission items reached: [1, 2, 3, 4]" in res.stdout
    assert "Reached command #3" in comp_log and "Disarmed" in comp_log
    assert "Traceback" not in comp_log
