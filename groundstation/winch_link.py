"""The winch component's end of the companion's component link (a TCP client)."""

from __future__ import annotations

import socket
import time

from pymavlink.dialects.v20 import common as mavlink2

from tuavdefs import component_link as cl
from tuavdefs.frames import ned_to_enu

Vec3 = tuple[float, float, float]


class WinchLinkClient:
    """Receives the UAV's position and velocity; sends WINCH_STATUS and heartbeats."""

    def __init__(self, address: str, connect_timeout_s: float = 30.0) -> None:
        host, _, port = address.rpartition(":")
        self.mav = cl.new_mavlink(cl.WINCH_COMPONENT_ID)
        self.sock: socket.socket | None = None
        self._addr = (host, int(port))
        self._deadline = time.monotonic() + connect_timeout_s
        self._state: tuple[Vec3, Vec3] | None = None
        self._last_heartbeat = 0.0
        self.bad_frames = 0

    def _connect(self) -> bool:
        if self.sock is not None:
            return True
        try:
            s = socket.create_connection(self._addr, timeout=0.2)
        except OSError:
            return False
        s.setblocking(False)
        s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.sock = s
        return True

    def poll(self) -> None:
        """Read what has arrived (non-blocking); connects (and reconnects) as needed."""
        if not self._connect():
            return
        assert self.sock is not None
        try:
            data = self.sock.recv(65536)
        except BlockingIOError:
            data = None
        except OSError:
            data = b""
        if data == b"":
            self.sock.close()
            self.sock = None
            return
        if data:
            try:
                msgs = self.mav.parse_buffer(data) or []
            except mavlink2.MAVError:
                self.bad_frames += 1
                msgs = []
            for m in msgs:
                if m.get_type() == "LOCAL_POSITION_NED":
                    self._state = (ned_to_enu((m.x, m.y, m.z)), ned_to_enu((m.vx, m.vy, m.vz)))
        now = time.monotonic()
        if now - self._last_heartbeat >= 1.0:
            self._last_heartbeat = now
            self._send(self.mav.heartbeat_encode(
                mavlink2.MAV_TYPE_WINCH, mavlink2.MAV_AUTOPILOT_INVALID, 0, 0,
                mavlink2.MAV_STATE_ACTIVE))

    def uav_state(self) -> tuple[Vec3, Vec3] | None:
        """The latest (position [m], velocity [m/s]) of the UAV, z-up frame, or None."""
        return self._state

    def winch_status(self, length_m: float, speed_m_s: float, tension_kg: float,
                     brake_engaged: bool) -> None:
        """Send WINCH_STATUS (tension in kg, as the message defines)."""
        flags = cl.winch_status_flags(brake_engaged, abs(speed_m_s) > 0.01)
        self._send(self.mav.winch_status_encode(
            int(time.monotonic() * 1e6), length_m, speed_m_s, tension_kg,
            float("nan"), float("nan"), 32767, flags))

    def _send(self, msg: mavlink2.MAVLink_message) -> None:
        if self.sock is None:
            return
        try:
            self.sock.sendall(msg.pack(self.mav))
        except (BlockingIOError, OSError):
            self.sock.close()
            self.sock = None

    def close(self) -> None:
        """Close the connection."""
        if self.sock is not None:
            self.sock.close()
            self.sock = None
