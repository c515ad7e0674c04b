"""Starting the plant and the companion as OS processes for ground-station tests, and small
pymavlink helpers (waiting for a message, uploading a mission) used by them."""

from __future__ import annotations

import ctypes
import re
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from pymavlink import mavutil

ROOT = Path(__file__).resolve().parents[1]
M = mavutil.mavlink


def free_port(kind: int = socket.SOCK_STREAM) -> int:
    """A free port on 127.0.0.1."""
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def die_with_parent() -> None:
    """``preexec_fn`` for a test's child process: SIGTERM it when the test's process dies
    (Linux ``PR_SET_PDEATHSIG``), so a worker killed mid-test (a timeout, ^C) leaves no
    plant or companion behind, flying and using a core, for hours."""
    ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)   # 1: PR_SET_PDEATHSIG


class Vehicle:
    """Plant (on the ground, a long slack tether, winder braked) + companion processes.
    ``sim_relay(plant_port)``, if given, returns the port the companion's simulator link
    connects to instead (a tap between the two)."""

    def __init__(self, tmp: Path, *, speedup: str = "max", extra: tuple[str, ...] = (),
                 udp_port: int | None = None, tether_length_m: float = 40.0,
                 sim_relay: Any = None) -> None:
        self.tmp = tmp
        sim_port = free_port()
        self.plant_log = tmp / "plant.log"
        self.comp_log = tmp / "companion.log"
        self.tlog = tmp / "flight.tlog"
        self.param_file = tmp / "companion.parm"
        plant_args = [sys.executable, "-m", "sitl", "--port", str(sim_port), "--position", "2",
                      "0", "0", "--tether-length", str(tether_length_m), "--no-noise",
                      "--accept-timeout", "60", "--truth-log", str(tmp / "truth.csv")]
        if speedup != "max":
            plant_args += ["--speedup", speedup]
        with open(self.plant_log, "w") as out:
            self.plant = subprocess.Popen(plant_args, cwd=ROOT, stdout=out,
                                          stderr=subprocess.STDOUT,
                                          preexec_fn=die_with_parent)
        udp = ["--gcs-udp", f"127.0.0.1:{udp_port}"] if udp_port else ["--gcs-udp", "none"]
        if sim_relay is not None:
            sim_port = sim_relay(sim_port)
        with open(self.comp_log, "w") as out:
            self.comp = subprocess.Popen(
                [sys.executable, "-m", "companion", "--sim", f"127.0.0.1:{sim_port}",
                 "--component-port", "0", "--gcs-tcp", "0", *udp, "--tlog", str(self.tlog),
                 "--param-file", str(self.param_file), *extra],
                cwd=ROOT, stdout=out, stderr=subprocess.STDOUT, preexec_fn=die_with_parent)
        self.tcp_port = self._wait_ready()

    def _wait_ready(self, timeout_s: float = 60.0) -> int:
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            m = re.search(r"MAVLink on tcp:127\.0\.0\.1:(\d+)", self.comp_log.read_text())
            if m:
                return int(m.group(1))
            if self.comp.poll() is not None:
                raise RuntimeError("companion exited: " + self.comp_log.read_text())
            time.sleep(0.05)
        raise TimeoutError("companion not ready: " + self.comp_log.read_text())

    def connect(self, **kw: Any) -> mavutil.mavfile:
        """A pymavlink TCP connection, after the first vehicle heartbeat."""
        m = mavutil.mavlink_connection(f"tcp:127.0.0.1:{self.tcp_port}", source_system=255,
                                       source_component=190, **kw)
        hb = m.wait_heartbeat(timeout=20)
        assert hb is not None, "no heartbeat"
        m.target_system, m.target_component = 1, 1
        return m

    def stop(self) -> tuple[str, str]:
        """Stop both; returns their logs."""
        for p in (self.comp, self.plant):
            if p.poll() is None:
                p.terminate()
        for p in (self.comp, self.plant):
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
        return self.plant_log.read_text(), self.comp_log.read_text()


def wait_msg(m: mavutil.mavfile, mtype: str | list[str], cond=None, timeout: float = 30.0,
             seen: list | None = None) -> Any:
    """The first message of ``mtype`` satisfying ``cond`` within ``timeout`` [s wall]; every
    message received on the way is appended to ``seen``."""
    end = time.monotonic() + timeout
    types = [mtype] if isinstance(mtype, str) else mtype
    while time.monotonic() < end:
        msg = m.recv_match(blocking=True, timeout=max(0.05, end - time.monotonic()))
        if msg is None:
            continue
        if seen is not None:
            seen.append(msg)
        if msg.get_type() in types and (cond is None or cond(msg)):
            return msg
    return None


def command(m: mavutil.mavfile, cmd: int, *params: float, target_component: int = 1,
            timeout: float = 5.0, seen: list | None = None) -> Any:
    """COMMAND_LONG and its COMMAND_ACK."""
    p = list(params) + [0.0] * (7 - len(params))
    m.mav.command_long_send(1, target_component, cmd, 0, *p)
    return wait_msg(m, "COMMAND_ACK", lambda a: a.command == cmd, timeout, seen)


def arm(m: mavutil.mavfile, timeout: float = 30.0) -> Any:
    """Arm as a ground-station user does: again until the vehicle accepts (its navigation
    filter must be healthy and settled first: "PreArm: EKF not healthy", "PreArm: EKF
    settling"), its HEARTBEAT going out meanwhile as a ground station's does (a vehicle
    with FS_GCS_ENABLE would otherwise take the wait for a lost ground station); the
    accepting COMMAND_ACK, or the last refusal after ``timeout`` [s wall]."""
    end = time.monotonic() + timeout
    while True:
        m.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        ack = command(m, M.MAV_CMD_COMPONENT_ARM_DISARM, 1)
        if ack is not None and ack.result == M.MAV_RESULT_ACCEPTED or time.monotonic() > end:
            return ack
        time.sleep(0.2)


def upload_mission(m: mavutil.mavfile, items: list[tuple], timeout: float = 10.0,
                   seen: list | None = None) -> Any:
    """Upload ``items`` (each (command, frame, p1, p2, p3, p4, lat_deg, lon_deg, alt)) as
    MISSION_ITEM_INT after a home at seq 0; returns the final MISSION_ACK."""
    all_items = [(M.MAV_CMD_NAV_WAYPOINT, M.MAV_FRAME_GLOBAL, 0, 0, 0, 0, 0, 0, 0), *items]
    m.mav.mission_count_send(1, 1, len(all_items), M.MAV_MISSION_TYPE_MISSION)
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        msg = m.recv_match(type=["MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"],
                           blocking=True, timeout=1.0)
        if msg is None:
            continue
        if seen is not None:
            seen.append(msg)
        if msg.get_type() == "MISSION_ACK":
            return msg
        cmd, frame, p1, p2, p3, p4, lat, lon, alt = all_items[msg.seq]
        m.mav.mission_item_int_send(1, 1, msg.seq, frame, cmd, 0, 1, p1, p2, p3, p4,
                                    round(lat * 1e7), round(lon * 1e7), alt,
                                    M.MAV_MISSION_TYPE_MISSION)
    return None


def download_mission(m: mavutil.mavfile, timeout: float = 10.0) -> list[Any]:
    """The vehicle's mission as MISSION_ITEM_INT messages (seq 0 is home)."""
    m.mav.mission_request_list_send(1, 1, M.MAV_MISSION_TYPE_MISSION)
    count = wait_msg(m, "MISSION_COUNT", timeout=timeout)
    items = []
    for seq in range(count.count):
        m.mav.mission_request_int_send(1, 1, seq, M.MAV_MISSION_TYPE_MISSION)
        items.append(wait_msg(m, "MISSION_ITEM_INT", lambda i, s=seq: i.seq == s, timeout))
    m.mav.mission_ack_send(1, 1, M.MAV_MISSION_ACCEPTED, M.MAV_MISSION_TYPE_MISSION)
    return items
