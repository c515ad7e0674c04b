"""A CAN host (a stand-in for the ground station) against the real plant and companion
processes on a python-can udp_multicast bus. Run inside a private network namespace; prints
one JSON line of observations for tests/test_can_bus.py to judge."""

import json
import math
import subprocess
import sys
import time
from pathlib import Path

import cantools

from tests.gcs_util import free_port
from tuavdefs import can_protocol as cp
from tuavdefs.canbus import CanLink

ROOT = Path(__file__).resolve().parents[2]
AX = cp.AXIS_NODE_ID_DEFAULT
SN = cp.WINCH_SENSOR_NODE_ID_DEFAULT



class Host:
    def __init__(self) -> None:
        self.link = CanLink("udp_multicast")
        self.heartbeats: list[tuple[float, cp.Heartbeat]] = []
        self.encoders: list[tuple[float, cp.EncoderEstimates]] = []
        self.lengths: list[tuple[float, cp.WinchLength]] = []
        self.tensions: list[tuple[float, cp.WinchTension]] = []
        self.replies: list[tuple[int, bytes]] = []
        self.raw: list[tuple[int, bytes, bool]] = []

    def pump(self, seconds: float, torque: float | None = None) -> None:
        """Receive for ``seconds``; when ``torque`` is given, send it every 10 ms."""
        end = time.monotonic() + seconds
        next_send = time.monotonic()
        while time.monotonic() < end:
            if torque is not None and time.monotonic() >= next_send:
                self.send(cp.Cmd.SET_INPUT_TORQUE, cp.encode_set_input_torque(torque))
                next_send += 0.01
            rx = self.link.recv(timeout_s=0.002)
            if rx is None:
                continue
            node, cmd = cp.split_id(rx.arbitration_id)
            now = time.monotonic()
            self.raw.append((rx.arbitration_id, rx.data, rx.is_remote))
            if node == AX and cmd == cp.Cmd.HEARTBEAT:
                self.heartbeats.append((now, cp.decode_heartbeat(rx.data)))
            elif node == AX and cmd == cp.Cmd.GET_ENCODER_ESTIMATES:
                self.encoders.append((now, cp.decode_encoder_estimates(rx.data)))
            elif node == SN and cmd == cp.SensorCmd.WINCH_LENGTH:
                self.lengths.append((now, cp.decode_winch_length(rx.data)))
            elif node == SN and cmd == cp.SensorCmd.WINCH_TENSION:
                self.tensions.append((now, cp.decode_winch_tension(rx.data)))
            elif node == AX:
                self.replies.append((cmd, rx.data))

    def send(self, cmd: int, data: bytes) -> None:
        self.link.send(cp.frame_id(AX, cmd), data)

    def request(self, cmd: int) -> bytes | None:
        self.replies.clear()
        self.link.send(cp.frame_id(AX, cmd), b"", is_remote=True, dlc=8)
        end = time.monotonic() + 1.0
        while time.monotonic() < end:
            self.pump(0.02)
            for c, data in self.replies:
                if c == cmd:
                    return data
        return None

    def state(self) -> int:
        return self.heartbeats[-1][1].axis_state if self.heartbeats else -1

    def error(self) -> int:
        return self.heartbeats[-1][1].axis_error if self.heartbeats else -1


def main() -> int:
    port = free_port()
    plant = subprocess.Popen(
        [sys.executable, "-m", "sitl", "--port", str(port), "--real-time", "--duration", "12",
         "--can", "udp_multicast", "--no-noise", "--position", "4", "0", "10",
         "--tether-length", "12.0"],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    ready = plant.stdout.readline()
    comp = subprocess.Popen([sys.executable, "-m", "companion", "--sim", f"127.0.0.1:{port}"],
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True)
    host = Host()
    out: dict = {"ready": ready.strip()}
    db = cantools.database.load_file(str(cp.dbc_path()), strict=True)
    try:
        # simulated time starts when the companion connects: wait for the axis to stream
        deadline = time.monotonic() + 60.0
        while len(host.heartbeats) < 10 and time.monotonic() < deadline:
            host.pump(0.1)
        out["idle_state"] = host.state()
        # cyclic rates as a ratio (10 ms vs 100 ms), independent of how fast time runs
        t_first, t_last = host.heartbeats[0][0], host.heartbeats[-1][0]
        between = sum(1 for t, _ in host.encoders if t_first <= t < t_last)
        out["encoders_per_heartbeat"] = between / max(len(host.heartbeats) - 1, 1)
        out["heartbeats_seen"] = len(host.heartbeats)
        out["brake_when_idle"] = host.tensions[-1][1].brake_engaged
        len0 = host.lengths[-1][1].length_m
        # closed loop, torque mode, paying out with +0.6 N m
        host.send(cp.Cmd.SET_CONTROLLER_MODE, cp.encode_set_controller_mode(
            cp.ControlMode.TORQUE, cp.InputMode.PASSTHROUGH))
        host.send(cp.Cmd.SET_AXIS_STATE, cp.encode_set_axis_state(cp.AxisState.CLOSED_LOOP_CONTROL))
        host.pump(1.5, torque=0.6)
        out["closed_loop_state"] = host.state()
        out["brake_in_closed_loop"] = host.tensions[-1][1].brake_engaged
        out["paid_out_m"] = host.lengths[-1][1].length_m - len0
        out["encoder_vel_rev_s"] = host.encoders[-1][1].vel_rev_s
        # a request answered, decoded independently with the DBC
        host.send(cp.Cmd.SET_INPUT_TORQUE, cp.encode_set_input_torque(100.0))  # over the limit
        reply = host.request(cp.Cmd.GET_TORQUES)
        out["torques_dbc"] = (db.get_message_by_frame_id(cp.frame_id(AX, cp.Cmd.GET_TORQUES))
                              .decode(reply) if reply else None)
        host.send(cp.Cmd.SET_INPUT_TORQUE, cp.encode_set_input_torque(0.6))
        # bad frames: NaN torque, a too-short torque frame; the target must stay 0.6
        host.send(cp.Cmd.SET_INPUT_TORQUE, cp.encode_set_input_torque(math.nan))
        host.send(cp.Cmd.SET_INPUT_TORQUE, b"\x00\x00")
        host.pump(0.05, torque=None)
        reply = host.request(cp.Cmd.GET_TORQUES)
        out["target_after_bad"] = cp.decode_torques(reply).target_nm if reply else None
        # stop feeding: the watchdog trips, the axis idles, the brake holds
        host.pump(0.5)
        out["after_silence_state"] = host.state()
        out["after_silence_error"] = host.error()
        out["brake_after_trip"] = host.tensions[-1][1].brake_engaged
        # a closed-loop request alone does not clear it
        host.send(cp.Cmd.SET_AXIS_STATE, cp.encode_set_axis_state(cp.AxisState.CLOSED_LOOP_CONTROL))
        host.pump(0.3)
        out["rearm_without_clear_state"] = host.state()
        host.send(cp.Cmd.CLEAR_ERRORS, cp.encode_clear_errors())
        host.send(cp.Cmd.SET_AXIS_STATE, cp.encode_set_axis_state(cp.AxisState.CLOSED_LOOP_CONTROL))
        host.pump(0.5, torque=0.0)
        out["recovered_state"] = host.state()
        out["recovered_error"] = host.error()
        out["own_frames_dropped"] = host.link.own_frames_dropped
        out["host_saw_own_frames"] = any(
            cp.split_id(i)[1] in (cp.Cmd.SET_INPUT_TORQUE, cp.Cmd.SET_AXIS_STATE)
            and cp.split_id(i)[0] == AX and not r for i, _, r in host.raw)
    finally:
        host.link.close()
        comp.terminate()
        plant.terminate()
        plant_out = plant.communicate(timeout=20)[0]
        comp.communicate(timeout=20)
    out["plant_out"] = plant_out
    print(json.dumps(out, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
