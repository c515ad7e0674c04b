"""Opening the winder's CAN bus, one option for every python-can interface.

A bus is named by a spec string:

- ``auto`` (the default): SocketCAN ``vcan0`` when the kernel has it, else
  ``udp_multicast`` on the project's IPv4 group;
- ``socketcan:IFACE`` (``vcan0``, ``can0``, ...);
- ``udp_multicast[:GROUP]``: python-can's multicast bus on an IPv4 group (default
  239.74.163.2) with ``hop_limit=0``, so datagrams never leave the host. Joining a group
  sends IGMP by the default route: on a machine with other networks run the processes in a
  private network namespace (the test suite does);
- ``virtual[:CHANNEL]``: python-can's in-process bus, for tests of one process.

A process never sees its own frames. On ``udp_multicast`` the group delivers a sender's
datagrams back to it: :class:`CanLink` speaks python-can's wire format itself there
(:class:`_MulticastBus`: one msgpack map per frame on UDP port 43113, what
``can.Bus(interface="udp_multicast")`` sends and reads, so python-can peers and tools work
alongside) and sends from a socket of its own, so it recognises its own datagrams by their
source port and drops them before decoding anything. That is also about three times
cheaper per frame than going through python-can's ``Message`` objects, which matters in
lockstep, where every frame is on the simulation's critical path.
"""

from __future__ import annotations

import contextlib
import os
import select
import socket
import struct
import time
from typing import NamedTuple

import can
import msgpack

DEFAULT_GROUP = "239.74.163.2"
DEFAULT_SPEC = "auto"
#: python-can's udp_multicast port.
MULTICAST_PORT = 43113
#: SO_TIMESTAMPNS (Linux): the kernel's receive time of each datagram.
_SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35)
_TIMESPEC = struct.Struct("@ll")
_ANCILLARY_SIZE = socket.CMSG_SPACE(_TIMESPEC.size) if hasattr(socket, "CMSG_SPACE") else 0
_MAX_DATAGRAM = 4096


class CanBusError(ValueError):
    """A bus spec that cannot be understood or opened."""


class RxFrame(NamedTuple):
    """A received frame: id, payload (``bytes(dlc)`` for a remote frame), remote flag,
    extended-id flag, and the receive time [s, wall clock]."""

    arbitration_id: int
    data: bytes
    is_remote: bool
    is_extended: bool
    timestamp: float


def resolve_spec(spec: str) -> tuple[str, str]:
    """(interface, channel) for a bus spec; ``auto`` picks SocketCAN vcan0 if present."""
    spec = spec.strip()
    if spec == "auto":
        if os.path.exists("/sys/class/net/vcan0"):
            return "socketcan", "vcan0"
        return "udp_multicast", DEFAULT_GROUP
    kind, _, channel = spec.partition(":")
    if kind == "socketcan":
        if not channel:
            raise CanBusError(f"{spec!r}: socketcan needs an interface, e.g. socketcan:vcan0")
        return kind, channel
    if kind == "udp_multicast":
        return kind, channel or DEFAULT_GROUP
    if kind == "virtual":
        return kind, channel or "tuav"
    raise CanBusError(f"{spec!r}: expected auto, socketcan:IFACE, udp_multicast[:GROUP] or "
                      "virtual[:CHANNEL]")


class CanLink:
    """A CAN bus that drops this process's own frames (python-can's for SocketCAN and the
    in-process virtual bus; :class:`_MulticastBus` for udp_multicast)."""

    def __init__(self, spec: str = DEFAULT_SPEC) -> None:
        self.interface, self.channel = resolve_spec(spec)
        self.bus: can.BusABC | None = None
        self._mc: _MulticastBus | None = None
        try:
            if self.interface == "udp_multicast":
                self._mc = _MulticastBus(self.channel, MULTICAST_PORT, hop_limit=0)
            else:
                kwargs: dict = {}
                if self.interface == "virtual":
                    kwargs["receive_own_messages"] = False
                self.bus = can.Bus(interface=self.interface, channel=self.channel, **kwargs)
        except (OSError, can.CanError, ImportError) as exc:
            raise CanBusError(f"cannot open {self.interface}:{self.channel}: {exc}") from exc

    @property
    def description(self) -> str:
        """``interface:channel``, e.g. for banners."""
        return f"{self.interface}:{self.channel}"

    @property
    def own_frames_dropped(self) -> int:
        """Own frames the bus delivered back to this link and it dropped."""
        return self._mc.own_dropped if self._mc is not None else 0

    @property
    def bad_frames(self) -> int:
        """Received datagrams that were not a CAN frame (dropped)."""
        return self._mc.bad if self._mc is not None else 0

    def send(self, arbitration_id: int, data: bytes = b"", is_remote: bool = False,
             dlc: int | None = None, is_extended: bool = False) -> None:
        """Send one frame (a remote frame carries ``dlc`` and no data)."""
        length = len(data) if dlc is None else dlc
        if self._mc is not None:
            self._mc.send(arbitration_id, b"" if is_remote else bytes(data), is_remote,
                          length, is_extended)
            return
        assert self.bus is not None
        msg = can.Message(arbitration_id=arbitration_id, data=None if is_remote else data,
                          is_remote_frame=is_remote, dlc=length, is_extended_id=is_extended)
        self.bus.send(msg)

    def recv(self, timeout_s: float | None = 0.0) -> RxFrame | None:
        """The next frame from another node, or None after ``timeout_s`` [s]."""
        if self._mc is not None:
            return self._mc.recv(timeout_s)
        assert self.bus is not None
        msg = self.bus.recv(timeout=timeout_s)
        if msg is None:
            return None
        data = bytes(msg.dlc) if msg.is_remote_frame else bytes(msg.data)
        return RxFrame(msg.arbitration_id, data, msg.is_remote_frame, msg.is_extended_id,
                       msg.timestamp)

    def close(self) -> None:
        """Shut the bus down."""
        if self._mc is not None:
            self._mc.close()
        if self.bus is not None:
            self.bus.shutdown()


class _MulticastBus:
    """python-can's udp_multicast bus (IPv4) on plain sockets, for :class:`CanLink`.

    The wire format is python-can's: each frame one datagram to ``group:port``, a msgpack
    map of the ``can.Message`` fields (``udp_multicast/utils.py: pack_message``). Frames are
    received on a socket bound to ``port`` that joined the group (with SO_REUSEPORT, like
    every other member), with the kernel's receive time, and sent from a second socket with
    an ephemeral port, TTL ``hop_limit`` (0: the datagrams never leave the host) and
    multicast loop-back on: the group delivers them back to the receiving socket too, and
    their source port tells they are ours.
    """

    def __init__(self, group: str, port: int, hop_limit: int = 0) -> None:
        self.dest = (group, port)
        rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            rx.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            if hasattr(socket, "SO_REUSEPORT"):
                rx.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)
            try:
                rx.setsockopt(socket.SOL_SOCKET, _SO_TIMESTAMPNS, 1)
                self._timestamps = True
            except OSError:
                self._timestamps = False
            rx.bind(("", port))
            rx.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP,
                          socket.inet_aton(group) + struct.pack("@I", socket.INADDR_ANY))
            tx.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL,
                          struct.pack("@I", hop_limit))
            tx.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP, 1)
            tx.bind(("", 0))
        except OSError:
            rx.close()
            tx.close()
            raise
        rx.setblocking(False)
        self.rx, self.tx = rx, tx
        self.own_port = tx.getsockname()[1]
        self.own_dropped = 0
        self.bad = 0
        self._pack = msgpack.Packer(use_bin_type=True).pack
        self._unpack = msgpack.unpackb

    def send(self, arbitration_id: int, data: bytes, is_remote: bool, dlc: int,
             is_extended: bool) -> None:
        """One frame, as python-can's ``pack_message`` packs it."""
        self.tx.sendto(self._pack({
            "timestamp": 0.0, "arbitration_id": arbitration_id, "is_extended_id": is_extended,
            "is_remote_frame": is_remote, "is_error_frame": False, "channel": None,
            "dlc": dlc, "data": data, "is_fd": False, "bitrate_switch": False,
            "error_state_indicator": False}), self.dest)

    def recv(self, timeout_s: float | None) -> RxFrame | None:
        """The next frame of another sender, or None after ``timeout_s`` [s] (None: wait)."""
        end = None if timeout_s is None else time.monotonic() + timeout_s
        rx = self.rx
        while True:
            try:
                raw, anc, _, sender = rx.recvmsg(_MAX_DATAGRAM, _ANCILLARY_SIZE)
            except BlockingIOError:
                left = None if end is None else end - time.monotonic()
                if left is not None and left <= 0.0:
                    return None
                select.select((rx,), (), (), left)   # (retried on EINTR by Python)
                continue
            if sender[1] == self.own_port:
                self.own_dropped += 1
                continue
            frame = self._frame(raw, anc)
            if frame is not None:
                return frame
            self.bad += 1

    def _frame(self, raw: bytes, anc: list) -> RxFrame | None:
        try:
            m = self._unpack(raw, raw=False)
            is_remote = bool(m["is_remote_frame"])
            dlc = int(m["dlc"])
            data = bytes(dlc) if is_remote else bytes(m["data"])
            if m.get("is_error_frame") or not 0 <= dlc <= 64 or (
                    not is_remote and len(data) != dlc and not m.get("is_fd")):
                return None
            frame_id, extended = int(m["arbitration_id"]), bool(m["is_extended_id"])
        except Exception:  # noqa: BLE001 - anything malformed is a dropped datagram
            return None
        if anc and self._timestamps:
            seconds, nanoseconds = _TIMESPEC.unpack(anc[0][2][:_TIMESPEC.size])
            stamp = seconds + nanoseconds * 1.0e-9
        else:
            stamp = time.time()
        return RxFrame(frame_id, data, is_remote, extended, stamp)

    def close(self) -> None:
        """Leave the group and close both sockets."""
        for sock in (self.rx, self.tx):
            with contextlib.suppress(OSError):
                sock.close()
