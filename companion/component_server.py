"""The companion's component link (TCP server): the UAV's position out, WINCH_STATUS in."""

from __future__ import annotations

import socket

from pymavlink.dialects.v20 import common as mavlink2

from tuavdefs import component_link as cl
from tuavdefs.frames import enu_to_ned

Vec3 = tuple[float, float, float]


class ComponentServer:
    """One component at a time on 127.0.0.1:``port``; never blocks the control loop."""

    def __init__(self, port: int = cl.COMPONENT_PORT_DEFAULT, host: str = "127.0.0.1") -> None:
        self.listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.listener.bind((host, port))
        self.listener.listen(1)
        self.listener.setblocking(False)
        self.port = self.listener.getsockname()[1]
        self.conn: socket.socket | None = None
        self.mav = cl.new_mavlink(cl.AUTOPILOT_COMPONENT_ID)
        self._next_position_s = 0.0
        self.bad_frames = 0

    def poll(self) -> list[mavlink2.MAVLink_message]:
        """Accept a waiting component and return the messages it sent since the last call."""
        if self.conn is None:
            try:
                self.conn, _ = self.listener.accept()
            except BlockingIOError:
                return []
            self.conn.setblocking(False)
            self.conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        msgs: list[mavlink2.MAVLink_message] = []
        while self.conn is not None:
            try:
                data = self.conn.recv(65536)
            except BlockingIOError:
                break
            except OSError:
                data = b""
            if data == b"":
                self._drop()
                break
            try:
                msgs.extend(self.mav.parse_buffer(data) or [])
            except mavlink2.MAVError:
                self.bad_frames += 1
        return msgs

    def send_position(self, t_s: float, pos_enu: Vec3, vel_enu: Vec3) -> None:
        """LOCAL_POSITION_NED at ``component_link.POSITION_RATE_HZ`` of simulated time."""
        if self.conn is None or t_s < self._next_position_s:
            return
        period = 1.0 / cl.POSITION_RATE_HZ
        # on the rate on average, whatever the control period
        self._next_position_s = max(self._next_position_s + period, t_s)
        n = enu_to_ned(pos_enu)
        v = enu_to_ned(vel_enu)
        msg = self.mav.local_position_ned_encode(int(t_s * 1000), *n, *v)
        self.send_bytes(msg.pack(self.mav))

    @property
    def connected(self) -> bool:
        """Whether a component is connected."""
        return self.conn is not None

    def send_bytes(self, data: bytes) -> None:
        """Write packed frames to the component (forwarded ground-station messages)."""
        if self.conn is None:
            return
        try:
            self.conn.setblocking(True)
            self.conn.settimeout(0.5)
            self.conn.sendall(data)
        except OSError:
            self._drop()
            return
        self.conn.setblocking(False)

    def _drop(self) -> None:
        if self.conn is not None:
            self.conn.close()
        self.conn = None

    def close(self) -> None:
        """Close the connection and stop listening."""
        self._drop()
        self.listener.close()
