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
source port: a socket filter drops them in the kernel (where it cannot be attached, they
are dropped before decoding anything). That is also several times cheaper per frame than
going through python-can's ``Message`` objects, which matters in lockstep, where every frame
is on the simulation's critical path.
"""

from __future__ import annotations

import contextlib
import math
import os
import select
import socket
import struct
import time
from collections.abc import Iterable
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


_rx_frame = RxFrame._make

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
        self._ready_poll: select.poll | None = None
        fd = self.fileno()
        if fd >= 0:
            self._ready_poll = select.poll()
            self._ready_poll.register(fd, select.POLLIN)

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

    def send_frames(self, frames: Iterable[tuple[int, bytes, bool]]) -> int:
        """Send ``(arbitration_id, data, is_remote)`` frames (e.g. ``can_protocol.Frame``)
        back to back, in order, 11-bit ids, each with DLC ``len(data)`` (a remote frame's
        ``data`` is ``bytes(dlc)``): what :meth:`send` does for each, with less work between
        them, so that a receiver tends to find the frames of one instant together. Returns
        the number of frames sent."""
        if self._mc is None:
            n = 0
            for arbitration_id, data, is_remote in frames:
                self.send(arbitration_id, data, is_remote, len(data))
                n += 1
            return n
        return self._mc.send_frames(frames)

    def fileno(self) -> int:
        """The descriptor that polls readable when a frame may be waiting (for a
        ``select.poll`` shared with other sockets), or -1 where the bus has none (then only
        :meth:`recv` with a timeout can wait)."""
        if self._mc is not None:
            return self._mc.rx.fileno()
        assert self.bus is not None
        try:
            return int(self.bus.fileno())
        except (NotImplementedError, AttributeError, OSError, TypeError, ValueError):
            return -1

    def set_receive_buffer(self, size_bytes: int) -> int:
        """Ask the kernel for a receive buffer of ``size_bytes`` [bytes] on the receiving
        socket (beyond ``net.core.rmem_max`` where the process may: root or CAP_NET_ADMIN), so
        that a reader which falls behind for a while (a recorder running at idle priority)
        finds its frames queued rather than dropped. Returns the size granted [bytes] (the
        kernel's count, about twice what it keeps for data), or 0 where the bus has no
        socket."""
        if self._mc is not None:
            sock = self._mc.rx
        else:
            sock = getattr(self.bus, "socket", None)
            if not isinstance(sock, socket.socket):
                return 0
        force = getattr(socket, "SO_RCVBUFFORCE", 33)
        try:
            sock.setsockopt(socket.SOL_SOCKET, force, size_bytes)
        except OSError:     # not permitted: as much as rmem_max allows
            with contextlib.suppress(OSError):
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, size_bytes)
        return sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)

    @property
    def pollable(self) -> bool:
        """Whether :meth:`readable` can tell (the bus has a descriptor to poll)."""
        return self._ready_poll is not None

    def readable(self) -> bool:
        """Whether something waits to be read, without reading it: one ``poll(0)`` (on
        udp_multicast it may be one of this link's own datagrams or a malformed one, and
        :meth:`recv` then finds nothing). Always False where the bus is not
        :attr:`pollable`."""
        return bool(self._ready_poll.poll(0)) if self._ready_poll is not None else False

    def recv_ready(self) -> list[RxFrame]:
        """Every frame from another node that has already arrived (none: an empty list),
        without waiting: what calling ``recv(0.0)`` until it returns None gives, in one
        call."""
        if self._mc is not None:
            return self._mc.recv_ready()
        frames = []
        while (rx := self.recv(0.0)) is not None:
            frames.append(rx)
        return frames

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


#: SO_ATTACH_FILTER (Linux): a classic BPF program that accepts or drops each datagram
#: before it is queued on the socket.
_SO_ATTACH_FILTER = getattr(socket, "SO_ATTACH_FILTER", 26)
#: SO_MEMINFO (Linux): the socket's memory counters, u32 each; SK_MEMINFO_DROPS counts the
#: datagrams the kernel dropped for this socket (by its filter, or for a full buffer).
_SO_MEMINFO = getattr(socket, "SO_MEMINFO", 55)
_SK_MEMINFO_DROPS = 8
_BPF_INSN = struct.Struct("=HBBI")      # struct sock_filter: code, jt, jf, k
_BPF_LDH_ABS = 0x28                     # BPF_LD | BPF_H | BPF_ABS: A = half-word at k
_BPF_JEQ_K = 0x15                       # BPF_JMP | BPF_JEQ | BPF_K: A == k ? jt : jf
_BPF_RET_K = 0x06                       # BPF_RET | BPF_K: keep k bytes (0: drop)


def drop_source_port_filter(port: int) -> bytes:
    """A classic BPF socket filter (``struct sock_filter`` array) that drops the UDP
    datagrams whose source port is ``port`` and keeps the others whole. On a UDP socket the
    kernel runs the filter on the datagram from its UDP header on, so the half-word at
    offset 0 is the source port (BPF loads it in network byte order, as a number)."""
    return b"".join(_BPF_INSN.pack(*insn) for insn in (
        (_BPF_LDH_ABS, 0, 0, 0),
        (_BPF_JEQ_K, 0, 1, port),
        (_BPF_RET_K, 0, 0, 0),
        (_BPF_RET_K, 0, 0, 0xFFFFFFFF),
    ))


def attach_socket_filter(sock: socket.socket, program: bytes) -> bool:
    """Attach a classic BPF ``program`` to ``sock`` (SO_ATTACH_FILTER); False where the
    platform does not allow it."""
    try:
        import ctypes

        buf = ctypes.create_string_buffer(program, len(program))
        # struct sock_fprog {unsigned short len; struct sock_filter *filter;}: the kernel
        # copies the program during the call
        fprog = struct.pack("@HP", len(program) // _BPF_INSN.size, ctypes.addressof(buf))
        sock.setsockopt(socket.SOL_SOCKET, _SO_ATTACH_FILTER, fprog)
    except (OSError, ImportError, AttributeError, struct.error):
        return False
    return True


def _msgpack(*values: object) -> bytes:
    return b"".join(msgpack.packb(v, use_bin_type=True) for v in values)


#: python-can's map of a frame: 11 keys, the timestamp first as a float64 (its 8 bytes follow).
_LEAD = b"\x8b" + _msgpack("timestamp") + b"\xcb"
_HEAD_START = len(_LEAD) + 8
#: the ``data`` key and a bin8 header (its length byte follows, then the payload).
_DATA_KEY = _msgpack("data") + b"\xc4"
_PAYLOAD_AFTER_KEY = len(_DATA_KEY) + 1
#: what follows the payload: is_fd, bitrate_switch and error_state_indicator, all False.
_TAIL = _msgpack("is_fd", False, "bitrate_switch", False, "error_state_indicator", False)
_TAIL_LEN = len(_TAIL)
#: the most distinct frame layouts each cache of :class:`WireCodec` holds.
_CACHE_MAX = 1024


class WireCodec:
    """python-can's udp_multicast wire format of one frame (``udp_multicast/utils.py``:
    ``pack_message``, a msgpack map of the ``can.Message`` fields), with the bytes that do
    not depend on the payload worked out once per frame layout.

    Encoding builds exactly what msgpack packs for the map, timestamp 0.0 (the bytes of a
    layout are msgpack's own, cached). Decoding recognises the bytes of a layout it has
    decoded before, through msgpack, as the canonical packing of such a map (any timestamp,
    channel None, no error, FD or flags) and then only slices the payload out; anything
    else goes through msgpack and its checks."""

    def __init__(self) -> None:
        self._pack = msgpack.Packer(use_bin_type=True).pack
        # (id, remote, dlc, extended, payload length) -> the bytes before the payload
        self._heads: dict[tuple, bytes] = {}
        # the bytes from the timestamp's end to the payload -> (id, remote, extended,
        # payload length, data of a remote frame)
        self._known: dict[bytes, tuple[int, bool, bool, int, bytes]] = {}

    def encode(self, arbitration_id: int, data: bytes, is_remote: bool, dlc: int,
               is_extended: bool) -> bytes:
        """The datagram of one frame, as ``pack_message`` packs it with timestamp 0.0 and
        no channel. ``is_remote``/``is_extended`` must be bools and the id and ``dlc`` ints
        (an int flag would be packed as an int, a bool id as a bool: the cache keeps one
        of each equal pair)."""
        head = self._heads.get((arbitration_id, is_remote, dlc, is_extended, len(data)))
        if head is not None:
            return head + data + _TAIL
        packed = self._map(0.0, arbitration_id, data, is_remote, dlc, is_extended)
        if len(self._heads) < _CACHE_MAX:
            self._heads[arbitration_id, is_remote, dlc, is_extended, len(data)] = (
                packed[:len(packed) - len(data) - len(_TAIL)])
        return packed

    def _map(self, timestamp: float, arbitration_id: int, data: bytes, is_remote: bool,
             dlc: int, is_extended: bool) -> bytes:
        return self._pack({
            "timestamp": timestamp, "arbitration_id": arbitration_id,
            "is_extended_id": is_extended, "is_remote_frame": is_remote,
            "is_error_frame": False, "channel": None, "dlc": dlc, "data": data,
            "is_fd": False, "bitrate_switch": False, "error_state_indicator": False})

    def decode(self, raw: bytes) -> tuple[int, bytes, bool, bool] | None:
        """(id, data, remote, extended) of a datagram, data ``bytes(dlc)`` for a remote
        frame; None if it is not a classic or FD data/remote frame (an error frame, a DLC
        outside 0..64, a payload whose length is not the DLC, or not a frame at all)."""
        if raw.startswith(_LEAD):
            i = raw.find(_DATA_KEY, _HEAD_START)
            start = i + _PAYLOAD_AFTER_KEY
            known = self._known.get(raw[_HEAD_START:start])
            if known is not None and raw.endswith(_TAIL):
                frame_id, is_remote, extended, n, remote_data = known
                if len(raw) == start + n + _TAIL_LEN:
                    return (frame_id, remote_data if is_remote else raw[start:start + n],
                            is_remote, extended)
        return self._decode_map(raw)

    def _decode_map(self, raw: bytes) -> tuple[int, bytes, bool, bool] | None:
        try:
            m = msgpack.unpackb(raw, raw=False)
            is_remote = bool(m["is_remote_frame"])
            dlc = int(m["dlc"])
            data = bytes(dlc) if is_remote else bytes(m["data"])
            if m.get("is_error_frame") or not 0 <= dlc <= 64 or (
                    not is_remote and len(data) != dlc and not m.get("is_fd")):
                return None
            frame_id, extended = int(m["arbitration_id"]), bool(m["is_extended_id"])
        except Exception:  # noqa: BLE001 - anything malformed is a dropped datagram
            return None
        self._learn(raw, m, frame_id, is_remote, dlc, extended)
        return frame_id, data, is_remote, extended

    def _learn(self, raw: bytes, m: dict, frame_id: int, is_remote: bool, dlc: int,
               extended: bool) -> None:
        """Remember the layout of an accepted datagram when it is the canonical packing of
        its fields (then the same bytes before the payload always mean the same frame)."""
        if len(self._known) >= _CACHE_MAX or not raw.startswith(_LEAD):
            return
        wire_data = m.get("data")
        # only what msgpack packs back as it came can be canonical (and packs at all)
        if (type(wire_data) is not bytes or type(m["arbitration_id"]) is not int
                or type(m["dlc"]) is not int):
            return
        canonical = self._map(0.0, frame_id, wire_data, is_remote, dlc, extended)
        end = len(canonical) - len(wire_data) - len(_TAIL)   # the payload's start
        if (canonical[_HEAD_START:] == raw[_HEAD_START:]
                and raw.find(_DATA_KEY, _HEAD_START) == end - _PAYLOAD_AFTER_KEY):
            self._known[raw[_HEAD_START:end]] = (frame_id, is_remote, extended,
                                                 len(wire_data), bytes(dlc))


class _MulticastBus:
    """python-can's udp_multicast bus (IPv4) on plain sockets, for :class:`CanLink`.

    The wire format is python-can's (:class:`WireCodec`): each frame one datagram to
    ``group:port``. Frames are received on a socket bound to ``port`` that joined the group
    (with SO_REUSEPORT, like every other member), with the kernel's receive time, and sent
    from a second socket with an ephemeral port, TTL ``hop_limit`` (0: the datagrams never
    leave the host) and multicast loop-back on: the group delivers them back to the
    receiving socket too, and their source port tells they are ours. A socket filter drops
    them in the kernel (:func:`drop_source_port_filter`); where it cannot be attached they
    are dropped here, by their source port, before anything is decoded.
    """

    def __init__(self, group: str, port: int, hop_limit: int = 0) -> None:
        self.dest = (group, port)
        rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            tx.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL,
                          struct.pack("@I", hop_limit))
            tx.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP, 1)
            tx.bind(("", 0))
            tx.connect(self.dest)
            own_port = tx.getsockname()[1]
            # before the socket can receive anything, so no own datagram gets through
            self.kernel_filter = attach_socket_filter(rx, drop_source_port_filter(own_port))
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
        except OSError:
            rx.close()
            tx.close()
            raise
        rx.setblocking(False)
        self.rx, self.tx = rx, tx
        self.own_port = own_port
        self._own_dropped = 0
        self.bad = 0
        self._codec = WireCodec()
        self._poll = select.poll()
        self._poll.register(rx, select.POLLIN)

    @property
    def own_dropped(self) -> int:
        """Own datagrams dropped: by the socket filter in the kernel (its count of this
        socket's drops, which would also count datagrams dropped for a full receive buffer)
        and here."""
        kernel = 0
        if self.kernel_filter:
            with contextlib.suppress(OSError, struct.error):
                info = self.rx.getsockopt(socket.SOL_SOCKET, _SO_MEMINFO,
                                          4 * (_SK_MEMINFO_DROPS + 1))
                kernel = struct.unpack_from("@I", info, 4 * _SK_MEMINFO_DROPS)[0]
        return kernel + self._own_dropped

    def send(self, arbitration_id: int, data: bytes, is_remote: bool, dlc: int,
             is_extended: bool) -> None:
        """One frame, as python-can's ``pack_message`` packs it (:meth:`WireCodec.encode`)."""
        self.tx.send(self._codec.encode(arbitration_id, data, is_remote, dlc, is_extended))

    def send_frames(self, frames: Iterable[tuple[int, bytes, bool]]) -> int:
        """:meth:`CanLink.send_frames`: one datagram per frame, in order."""
        encode, send = self._codec.encode, self.tx.send
        n = 0
        for arbitration_id, data, is_remote in frames:
            if is_remote:
                send(encode(arbitration_id, b"", True, len(data), False))
            else:
                data = bytes(data)
                send(encode(arbitration_id, data, False, len(data), False))
            n += 1
        return n

    def recv(self, timeout_s: float | None) -> RxFrame | None:
        """The next frame of another sender, or None after ``timeout_s`` [s] (None: wait).

        Waits are rounded up to whole milliseconds (poll's resolution)."""
        poll = self._poll.poll
        if timeout_s == 0.0:
            # poll first: on an empty socket it costs less than a failing recvmsg (an
            # exception)
            return self._next_frame() if poll(0) else None
        end = None if timeout_s is None else time.monotonic() + timeout_s
        while True:
            if end is None:
                poll(None)
            else:
                left = end - time.monotonic()
                if not poll(math.ceil(left * 1e3) if left > 0.0 else 0):
                    if left <= 0.0:
                        return None
                    continue
            frame = self._next_frame()
            if frame is not None:
                return frame

    def recv_ready(self) -> list[RxFrame]:
        """:meth:`CanLink.recv_ready`: read until the socket is empty."""
        frames = []
        while (frame := self._next_frame()) is not None:
            frames.append(frame)
        return frames

    def _next_frame(self) -> RxFrame | None:
        """The next queued frame of another sender; None once the socket is empty (own and
        malformed datagrams are counted and skipped)."""
        rx = self.rx
        while True:
            try:
                raw, anc, _, sender = rx.recvmsg(_MAX_DATAGRAM, _ANCILLARY_SIZE)
            except BlockingIOError:
                return None
            if sender[1] == self.own_port:
                self._own_dropped += 1
                continue
            frame = self._codec.decode(raw)
            if frame is None:
                self.bad += 1
                continue
            if anc and self._timestamps:
                seconds, nanoseconds = _TIMESPEC.unpack_from(anc[0][2])
                stamp = seconds + nanoseconds * 1.0e-9
            else:
                stamp = time.time()
            return _rx_frame((*frame, stamp))

    def close(self) -> None:
        """Leave the group and close both sockets."""
        for sock in (self.rx, self.tx):
            with contextlib.suppress(OSError):
                sock.close()
