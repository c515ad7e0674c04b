"""The companion's component link (TCP server): the UAV's position out, WINCH_STATUS in."""

from __future__ import annotations

import socket
import struct
from collections.abc import Callable
from typing import Any

from pymavlink.dialects.v20 import common as mavlink2

from tuavdefs import component_link as cl
from tuavdefs.simlink import mavlink_crc

Vec3 = tuple[float, float, float]

#: Unsent bytes the component may fall behind by before it counts as gone (~4 minutes of
#: positions at 100 Hz): writing never blocks the control loop.
_BACKLOG_BYTES = 1 << 20

_LPN = mavlink2.MAVLink_local_position_ned_message
_LPN_PAYLOAD: struct.Struct = _LPN.unpacker    # the payload's layout, as pymavlink packs it
_LPN_CRC_EXTRA = bytes((_LPN.crc_extra,))
_LPN_ID = (_LPN.id & 0xFFFF, _LPN.id >> 16)
#: MAVLink 2 header after its magic byte: length, flags x2, seq, system, component, id.
_HEADER = struct.Struct("<BBBBBBHB")
_MAGIC = bytes((mavlink2.PROTOCOL_MARKER_V2,))
_CRC = struct.Struct("<H")
class ComponentServer:
    """One component at a time on 127.0.0.1:``port``; never blocks the control loop.

    Input is read when a caller's ``select`` finds :attr:`selectable` readable
    (:meth:`poll`); output that the component cannot take at once is queued and written
    by later calls (:meth:`flush`). ``signing`` is the link's pymavlink ``MAVLinkSigning``
    state: with a key set, what is sent is signed and only correctly signed frames are
    taken."""

    def __init__(self, port: int = cl.COMPONENT_PORT_DEFAULT, host: str = "127.0.0.1",
                 signing: Any = None) -> None:
        self.listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.listener.bind((host, port))
        self.listener.listen(1)
        self.listener.setblocking(False)
        self.port = self.listener.getsockname()[1]
        self.conn: socket.socket | None = None
        self.mav = cl.new_mavlink(cl.AUTOPILOT_COMPONENT_ID)
        if signing is not None:     # the link's signing state (companion.signing)
            self.mav.signing = signing
        self._next_position_s = 0.0
        self._next_wind_s = 0.0
        self._pending = bytearray()
        self.bad_frames = 0

    @property
    def selectable(self) -> socket.socket:
        """The socket to watch for input: the connection, or the listener while no
        component is connected (it changes when one connects or goes)."""
        return self.conn if self.conn is not None else self.listener

    def poll(self) -> list[mavlink2.MAVLink_message]:
        """Accept a waiting component, or read what it sent: one read, for a call after a
        ``select`` found :attr:`selectable` readable (otherwise nothing is read). Returns
        the messages completed."""
        if self.conn is None:
            try:
                self.conn, _ = self.listener.accept()
            except BlockingIOError:
                return []
            self.conn.setblocking(False)
            self.conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            return []
        try:
            data = self.conn.recv(65536)
        except BlockingIOError:
            return []
        except OSError:
            data = b""
        if data == b"":
            self._drop()
            return []
        try:
            return self.mav.parse_buffer(data) or []
        except mavlink2.MAVError:
            self.bad_frames += 1
            return []

    def send_position(self, t_s: float, pos_enu: Vec3, vel_enu: Vec3) -> None:
        """LOCAL_POSITION_NED at ``component_link.POSITION_RATE_HZ`` of simulated time."""
        if self.conn is None or t_s < self._next_position_s:
            return
        period = 1.0 / cl.POSITION_RATE_HZ
        # on the rate on average, whatever the control period
        self._next_position_s = max(self._next_position_s + period, t_s)
        # NED: (north, east, down) = (y, x, -z) of ENU
        self.send_bytes(self.pack_position(int(t_s * 1000), pos_enu[1], pos_enu[0],
                                           -pos_enu[2], vel_enu[1], vel_enu[0], -vel_enu[2]))

    def send_wind(self, t_s: float, estimate: Callable[[], Vec3]) -> None:
        """``WIND_COV`` at ``component_link.WIND_RATE_HZ`` of simulated time: the onboard
        wind estimate ``estimate()`` (z-up [m/s], asked only when one is due) as NED,
        its variances, altitude and accuracies NaN (unknown); the winch's tether fix may
        take it (groundstation.tether_fix.ReportedWind)."""
        if self.conn is None or t_s < self._next_wind_s:
            return
        self._next_wind_s = max(self._next_wind_s + 1.0 / cl.WIND_RATE_HZ, t_s)
        self.send(cl.wind_message(int(t_s * 1e6), estimate()))

    def pack_position(self, time_boot_ms: int, x: float, y: float, z: float, vx: float,
                      vy: float, vz: float) -> bytes:
        """The MAVLink 2 frame of LOCAL_POSITION_NED (NED [m], [m/s]) from this link's
        system and component, byte for byte what pymavlink packs, without building the
        message object."""
        mav = self.mav
        if mav.signing.sign_outgoing:
            return _LPN(time_boot_ms, x, y, z, vx, vy, vz).pack(mav)
        payload = _LPN_PAYLOAD.pack(time_boot_ms, x, y, z, vx, vy, vz)
        n = len(payload)
        while n > 1 and payload[n - 1] == 0:   # MAVLink 2 drops trailing zero bytes
            n -= 1
        body = _HEADER.pack(n, 0, 0, mav.seq, mav.srcSystem, mav.srcComponent,
                            *_LPN_ID) + payload[:n]
        return _MAGIC + body + _CRC.pack(mavlink_crc(body + _LPN_CRC_EXTRA))

    def send(self, msg: mavlink2.MAVLink_message) -> None:
        """``msg`` from this link's system and component (the autopilot's own commands to
        the winch)."""
        if self.conn is not None:
            self.send_bytes(msg.pack(self.mav))

    @property
    def connected(self) -> bool:
        """Whether a component is connected."""
        return self.conn is not None

    def send_bytes(self, data: bytes) -> None:
        """Write packed frames to the component (positions, forwarded ground-station
        messages) without blocking: what it cannot take now waits for the next write or
        :meth:`flush`; a component more than ``_BACKLOG_BYTES`` behind is dropped."""
        if self.conn is None:
            return
        if self._pending:
            self._pending += data
            self.flush()
            return
        n = self._write(data)
        if n is not None and n < len(data):
            self._pending += data[n:]

    @property
    def backlogged(self) -> bool:
        """Whether bytes wait for the component to take them (see :meth:`flush`)."""
        return bool(self._pending)

    def flush(self) -> None:
        """Write what waits for the component, as far as it takes it now."""
        if self.conn is None or not self._pending:
            return
        n = self._write(self._pending)
        if n is None:
            return
        del self._pending[:n]
        if len(self._pending) > _BACKLOG_BYTES:
            self._drop()

    def _write(self, data: bytes | bytearray) -> int | None:
        """How many bytes of ``data`` the connection took now; None if it failed (then
        it is dropped)."""
        assert self.conn is not None
        try:
            return self.conn.send(data)
        except BlockingIOError:
            return 0
        except OSError:
            self._drop()
            return None

    def _drop(self) -> None:
        if self.conn is not None:
            self.conn.close()
        self.conn = None
        self._pending.clear()

    def close(self) -> None:
        """Close the connection and stop listening."""
        self._drop()
        self.listener.close()
