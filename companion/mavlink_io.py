"""The companion's ground-station endpoints: MAVLink over TCP and UDP, with a telemetry log.

As ArduPilot SITL presents them: a TCP server (``127.0.0.1:5760``) that takes any number
of clients, and UDP sockets that push to fixed addresses (``127.0.0.1:14550`` for ground
stations, ``127.0.0.1:14540`` for APIs) and answer whoever writes back, each peer at its
own address. Every link has its own parser, so MAVLink 1 and 2 frames are both accepted;
everything sent is MAVLink 2, from system 1 component 1 unless the bytes are forwarded
from another component (the winch).

A *peer* is a hashable tuple: ``("tcp", fd)`` or ``("udp", socket_index, (host, port))``.
Malformed or truncated frames are counted (``bad_frames``) and dropped; a peer that goes
away is forgotten. Nothing here raises on what arrives from the network.

The ``.tlog`` is what MAVProxy and QGroundControl write: each frame, in and out, prefixed
by its wall-clock time as a big-endian unsigned 64-bit count of microseconds since the
Unix epoch; pymavlink's ``mavutil.mavlink_connection(path)`` reads it back.
"""

from __future__ import annotations

import contextlib
import math
import select
import socket
import struct
import time
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from pymavlink.dialects.v20 import common as mavlink2

from tuavdefs import gcs
from tuavdefs.gcs import GCS_TCP_PORT_DEFAULT, UDP_API_PORT_DEFAULT, UDP_GCS_PORT_DEFAULT
from tuavdefs.logfile import LogFile
from tuavdefs.signing import SigningMavlink

Peer = tuple[Any, ...]
#: What :meth:`MavlinkEndpoints._next` returns for a frame that is no message.
_SKIP = object()
Address = tuple[str, int]

SYSTEM_ID = gcs.SYSTEM_ID
COMPONENT_ID = gcs.AUTOPILOT_COMPONENT_ID

_TLOG_STAMP = struct.Struct(">Q")
_TLOG_FLUSH_S = 1.0
#: UDP addresses a push socket answers besides its own target, at most: a new one beyond
#: this takes the place of the one heard from longest ago.
MAX_UDP_PEERS = 8
#: A UDP address silent this long [s, wall] is no longer sent telemetry (ArduPilot, too,
#: sends only to whoever wrote last).
UDP_PEER_TIMEOUT_S = 10.0
#: Unsent bytes a TCP client may fall behind by before frames to it are dropped.
_TCP_BACKLOG_BYTES = 1 << 20
#: Bytes read from a TCP client at one :meth:`MavlinkEndpoints.receive` (about 60
#: messages: what the rest of the kernel's buffer holds waits, and TCP pushes back).
READ_TCP_BYTES = 2048
#: Datagrams read from a UDP socket at one :meth:`MavlinkEndpoints.receive`.
READ_UDP_DATAGRAMS = 8
#: Bytes a link's parser may hold unparsed; a datagram beyond them is dropped.
UNPARSED_MAX_BYTES = 1 << 16


class TelemetryLog(LogFile):
    """A ``.tlog``: timestamped raw frames, appended, flushed at least once a second. A
    write that fails (a full disk, a lost file) or would pass ``max_bytes`` ends the log,
    not the process (:class:`tuavdefs.logfile.LogFile`: its ``on_end`` is called once; the
    autopilot sets it to say so)."""

    def __init__(self, path: Path | str, max_bytes: int | None = None) -> None:
        super().__init__(path, append=True, max_bytes=max_bytes, flush_s=_TLOG_FLUSH_S)

    def write(self, data: bytes | str) -> bool:
        """Record one frame (or several back to back) with the current wall time."""
        raw = data.encode() if isinstance(data, str) else data
        return super().write(_TLOG_STAMP.pack(int(time.time() * 1e6)) + raw)


class _Link:
    """One peer's parser (accepts MAVLink 1 and 2), on the endpoints' shared signing
    state."""

    def __init__(self, signing: Any) -> None:
        self.parser = SigningMavlink(None, srcSystem=SYSTEM_ID, srcComponent=COMPONENT_ID)
        self.parser.robust_parsing = True
        self.parser.signing = signing
        self.last_rx = time.monotonic()


class MavlinkEndpoints:
    """The TCP server and the UDP push sockets, polled without blocking.

    ``tcp_port`` 0 picks a free port (see :attr:`tcp_port`); ``None`` disables TCP.
    ``udp_targets`` are the push addresses (one socket each, bound to an ephemeral port on
    127.0.0.1). ``tlog`` records every frame in and out.

    ``batch_s`` [s of wall time], when positive, batches what goes to a TCP client
    unasked (telemetry streams, broadcasts, forwarded messages): it waits until ``batch_s``
    has passed since the client's last write and goes out with the next write, which
    :meth:`flush` makes once it is due, and at once with any reply to the client (ahead of
    it, so the order is kept). In lockstep many times faster than real time a period's
    telemetry otherwise wakes a ground station several hundred times a second of wall
    time, and its CPU is taken from the simulation.

    ``signing`` is the pymavlink ``MAVLinkSigning`` state every link shares (the key, the
    outgoing timestamp, the replay table: ``companion.signing``); with a key set, what is
    sent is signed and only correctly signed frames are taken (the others are counted in
    its ``reject_count`` and dropped). :attr:`on_setup_signing`, when set, is called with
    (peer, message) for each ``SETUP_SIGNING`` as soon as it is parsed, before the frames
    after it, which may already be signed with the new key.
    """

    def __init__(self, tcp_port: int | None = GCS_TCP_PORT_DEFAULT,
                 udp_targets: Iterable[Address] = (("127.0.0.1", UDP_GCS_PORT_DEFAULT),
                                                   ("127.0.0.1", UDP_API_PORT_DEFAULT)),
                 host: str = "127.0.0.1", tlog: TelemetryLog | None = None,
                 batch_s: float = 0.0, signing: Any = None) -> None:
        self.mav = SigningMavlink(None, srcSystem=SYSTEM_ID, srcComponent=COMPONENT_ID)
        if signing is not None:
            self.mav.signing = signing
        self.signing = self.mav.signing
        self.on_setup_signing: Callable[[Peer, Any], None] | None = None
        self.tlog = tlog
        self.batch_s = batch_s
        self._last_write: dict[int, float] = {}   # wall time of each TCP client's last write
        self._held: set[int] = set()              # TCP clients with batched bytes waiting
        self.bad_frames = 0
        self.listener: socket.socket | None = None
        if tcp_port is not None:
            lst = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            lst.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            try:
                lst.bind((host, tcp_port))
            except OSError:
                lst.close()
                raise
            lst.listen(8)
            lst.setblocking(False)
            self.listener = lst
        self.tcp_port = self.listener.getsockname()[1] if self.listener else None
        self._tcp: dict[int, socket.socket] = {}
        self._pending: dict[int, bytearray] = {}
        self._backlogged: set[int] = set()     # TCP clients with unsent bytes
        #: Links whose parser may hold whole messages not yet taken (an ordered set).
        self._unparsed: dict[Peer, None] = {}
        self._closed: list[Peer] = []
        self.udp: list[socket.socket] = []
        self.udp_targets: list[Address] = []
        for target in udp_targets:
            s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            s.bind((host, 0))
            s.setblocking(False)
            self.udp.append(s)
            self.udp_targets.append((target[0], int(target[1])))
        self._links: dict[Peer, _Link] = {}
        #: per UDP socket: the addresses that wrote to it -> when they last did [s, wall]
        self._udp_peers: list[dict[Address, float]] = [{} for _ in self.udp]
        self._udp_expiry_s = time.monotonic() + 1.0
        # what select() watches and where telemetry goes, rebuilt only when they change
        self._socks: list[socket.socket] = []
        self._udp_index: dict[socket.socket, int] = {s: i for i, s in enumerate(self.udp)}
        self._links_cache: list[Peer] = []
        self._broadcast: list[list[Address]] = []
        self.generation = 0
        """Incremented whenever :meth:`sockets` or :meth:`links` change."""
        self._changed()

    # ----- receiving

    @property
    def peers(self) -> list[Peer]:
        """Peers heard from (TCP clients, UDP addresses that wrote to us)."""
        return list(self._links)

    def links(self) -> list[Peer]:
        """Every link telemetry goes to: TCP clients, each UDP push address, and every
        address that has written to a UDP socket. The same list object until the links
        change (see :attr:`generation`); do not modify it."""
        return self._links_cache

    def sockets(self) -> list[socket.socket]:
        """The sockets to watch for input (for a caller's ``select``, then
        :meth:`receive`). The same list object until they change (see
        :attr:`generation`); do not modify it."""
        return self._socks

    def _changed(self) -> None:
        """Rebuild what :meth:`sockets` and :meth:`links` return and the broadcast
        addresses (a client came or went, a UDP peer wrote for the first time)."""
        socks = [*self._tcp.values(), *self.udp]
        if self.listener is not None:
            socks.append(self.listener)
        self._socks = socks
        out: list[Peer] = [("tcp", fd) for fd in self._tcp]
        for i, target in enumerate(self.udp_targets):
            out.append(("udp", i, target))
            out.extend(("udp", i, a) for a in self._udp_peers[i] if a != target)
        self._links_cache = out
        self._broadcast = [list({self.udp_targets[i], *self._udp_peers[i]})
                           for i in range(len(self.udp))]
        self.generation += 1

    def poll(self, timeout_s: float = 0.0) -> list[tuple[Peer, Any]]:
        """Messages that arrived, as (peer, message), waiting at most ``timeout_s`` [s];
        also writes out what TCP clients could not take before (:meth:`flush`)."""
        try:
            ready, _, _ = select.select(self._socks, [], [], timeout_s)
        except (OSError, ValueError):
            ready = []
        self.flush()
        return self.receive(ready)

    def receive(self, ready: Iterable[Any], max_messages: int | None = None
                ) -> list[tuple[Peer, Any]]:
        """Read the sockets in ``ready`` that are this object's (others are ignored: the
        caller may have watched more in the same ``select``); returns the messages that
        arrived, as (peer, message): all of them, or at most ``max_messages``, the rest
        parsed at the next calls (:attr:`unparsed`; parsing costs some 15 us a message,
        so a flood's bytes must not be parsed all at once). A read is bounded too
        (:data:`READ_TCP_BYTES`, :data:`READ_UDP_DATAGRAMS`), and a TCP client whose bytes
        still wait to be parsed is not read."""
        out: list[tuple[Peer, Any]] = []
        self.expire_udp_peers()
        for sock in ready:
            if sock is self.listener:
                self._accept()
            elif sock in self._udp_index:
                self._read_udp(self._udp_index[sock], sock, out)
            elif (isinstance(sock, socket.socket) and self._tcp.get(sock.fileno()) is sock
                  and ("tcp", sock.fileno()) not in self._unparsed):
                self._read_tcp(sock, out)
        self._drain(out, max_messages)
        return out

    @property
    def unparsed(self) -> bool:
        """Whether bytes read wait to be parsed (:meth:`receive` with ``max_messages``)."""
        return bool(self._unparsed)

    def _drain(self, out: list[tuple[Peer, Any]], max_messages: int | None) -> None:
        """Parse the links' waiting bytes into ``out``, one message from each link in
        turn, until ``out`` holds ``max_messages`` (None: all)."""
        waiting = self._unparsed
        while waiting and (max_messages is None or len(out) < max_messages):
            for peer in list(waiting):
                link = self._links.get(peer)
                m = self._next(link.parser) if link is not None else None
                if m is None:
                    del waiting[peer]   # nothing whole left (a part waits for its rest)
                elif m is not _SKIP:
                    self._emit(peer, m, out)
                if max_messages is not None and len(out) >= max_messages:
                    break

    def _next(self, p: Any, data: bytes = b"") -> Any:
        """The parser's next message after taking ``data`` (None: none whole; ``_SKIP``:
        a frame that is no message, already counted)."""
        before = p.total_receive_errors
        try:
            m = p.parse_char(data)
        except (mavlink2.MAVError, struct.error, ValueError, IndexError):
            self.bad_frames += 1
            return _SKIP
        finally:
            self.bad_frames += p.total_receive_errors - before
        if m is not None and m.get_type() == "BAD_DATA":   # already in the error count
            return _SKIP
        return m

    def _emit(self, peer: Peer, m: Any, out: list[tuple[Peer, Any]]) -> None:
        if self.tlog is not None:
            self.tlog.write(m.get_msgbuf())
        if m.get_type() == "SETUP_SIGNING" and self.on_setup_signing is not None:
            self.on_setup_signing(peer, m)   # the frames after it: on the new key
            return
        out.append((peer, m))

    @property
    def backlogged(self) -> bool:
        """Whether some TCP client has bytes waiting: that it could not take yet, or
        batched (see :meth:`flush`)."""
        return bool(self._backlogged)

    def flush(self) -> None:
        """Write out what TCP clients could not take before, as far as they take it now,
        and batched bytes whose time has come."""
        held = self._held
        now = time.monotonic() if held else 0.0
        for fd in list(self._backlogged):
            if fd in held and now - self._last_write.get(fd, -math.inf) < self.batch_s:
                continue
            self._flush_tcp(("tcp", fd))    # (which un-holds it)

    def _accept(self) -> None:
        assert self.listener is not None
        while True:
            try:
                conn, _ = self.listener.accept()
            except (BlockingIOError, OSError):
                return
            conn.setblocking(False)
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._tcp[conn.fileno()] = conn
            self._links[("tcp", conn.fileno())] = _Link(self.signing)
            self._changed()

    def _read_tcp(self, sock: socket.socket, out: list[tuple[Peer, Any]]) -> None:
        peer: Peer = ("tcp", sock.fileno())
        try:
            data = sock.recv(READ_TCP_BYTES)
        except BlockingIOError:
            return
        except OSError:
            data = b""
        if not data:
            self._drop_tcp(peer)
            return
        self._parse(peer, data, out)

    def _read_udp(self, index: int, sock: socket.socket, out: list[tuple[Peer, Any]]) -> None:
        for _ in range(READ_UDP_DATAGRAMS):
            try:
                data, addr = sock.recvfrom(65536)
            except (BlockingIOError, ConnectionRefusedError):
                return
            except OSError:
                return
            addr = (addr[0], addr[1])
            peers = self._udp_peers[index]
            if addr not in peers:
                if len(peers) >= MAX_UDP_PEERS:   # the table is full: the stalest goes
                    stalest = min(peers, key=peers.__getitem__)
                    self._forget_udp(index, stalest)
                peers[addr] = time.monotonic()
                self._changed()
            else:
                peers[addr] = time.monotonic()
            self._parse(("udp", index, addr), data, out)

    def _forget_udp(self, index: int, addr: Address) -> None:
        """No more telemetry to ``addr`` on UDP socket ``index`` (said as a closed peer)."""
        del self._udp_peers[index][addr]
        peer = ("udp", index, addr)
        self._links.pop(peer, None)
        self._closed.append(peer)

    def expire_udp_peers(self, now_s: float | None = None) -> None:
        """Forget the UDP addresses silent for :data:`UDP_PEER_TIMEOUT_S` (checked at most
        once a second; ``now_s`` [s, time.monotonic])."""
        now = time.monotonic() if now_s is None else now_s
        if now < self._udp_expiry_s:
            return
        self._udp_expiry_s = now + 1.0
        changed = False
        for index, peers in enumerate(self._udp_peers):
            for addr in [a for a, t in peers.items() if now - t > UDP_PEER_TIMEOUT_S]:
                self._forget_udp(index, addr)
                changed = True
        if changed:
            self._changed()

    def _parse(self, peer: Peer, data: bytes, out: list[tuple[Peer, Any]]) -> None:
        """Give ``data`` to ``peer``'s parser; its messages are taken by :meth:`_drain`."""
        link = self._links.get(peer)
        if link is None:
            link = self._links[peer] = _Link(self.signing)
        link.last_rx = time.monotonic()
        if link.parser.buf_len() > UNPARSED_MAX_BYTES:
            self.bad_frames += 1     # a datagram the parser has no room for: dropped
            return
        m = self._next(link.parser, data)
        if m is not None and m is not _SKIP:
            self._emit(peer, m, out)
        self._unparsed[peer] = None   # what follows it, if anything

    @property
    def closed_pending(self) -> bool:
        """Whether connections closed since the last :meth:`pop_closed`."""
        return bool(self._closed)

    def pop_closed(self) -> list[Peer]:
        """Peers whose connection closed since the last call."""
        out, self._closed = self._closed, []
        return out

    def _drop_tcp(self, peer: Peer) -> None:
        if peer[1] in self._tcp:
            self._closed.append(peer)
        sock = self._tcp.pop(peer[1], None)
        self._pending.pop(peer[1], None)
        self._backlogged.discard(peer[1])
        self._held.discard(peer[1])
        self._last_write.pop(peer[1], None)
        self._links.pop(peer, None)
        if sock is not None:
            sock.close()
            self._changed()

    # ----- sending

    def pack(self, msg: Any) -> bytes:
        """MAVLink 2 bytes of ``msg`` from system 1, component 1."""
        return msg.pack(self.mav)

    def send(self, msg: Any, peer: Peer | None = None) -> None:
        """Send ``msg`` (a pymavlink message object) to ``peer``, or to every link."""
        self.send_bytes(self.pack(msg), peer)

    def send_frames(self, frames: list[bytes], peer: Peer) -> None:
        """Send several packed frames to ``peer`` in one write (one wake-up of the ground
        station for a period's telemetry); the telemetry log still stamps each frame."""
        if self.tlog is not None:
            for frame in frames:
                self.tlog.write(frame)
        self._send_to(peer, frames[0] if len(frames) == 1 else b"".join(frames),
                      unasked=True)

    def send_bytes(self, data: bytes, peer: Peer | None = None) -> None:
        """Send packed frames as they are (used to forward other components' messages)."""
        if self.tlog is not None:
            self.tlog.write(data)
        if peer is None:
            for peer_ in self._links_cache:
                if peer_[0] == "tcp":
                    self._send_tcp(peer_, data, unasked=True)
            for sock, targets in zip(self.udp, self._broadcast, strict=True):
                for addr in targets:
                    self._send_udp(sock, addr, data)
        else:
            self._send_to(peer, data)

    def _send_to(self, peer: Peer, data: bytes, unasked: bool = False) -> None:
        """``data`` to one link: a TCP client (``unasked``: see ``batch_s``) or a UDP
        peer."""
        if peer[0] == "tcp":
            self._send_tcp(peer, data, unasked)
        elif peer[0] == "udp":
            self._send_udp(self.udp[peer[1]], peer[2], data)

    def _send_tcp(self, peer: Peer, data: bytes, unasked: bool = False) -> None:
        fd = peer[1]
        sock = self._tcp.get(fd)
        if sock is None:
            return
        if unasked and self.batch_s > 0.0 and (
                fd in self._held or (fd not in self._backlogged and time.monotonic()
                                     - self._last_write.get(fd, -math.inf) < self.batch_s)):
            # batched: out with the next write (flush, or a reply)
            pending = self._pending.get(fd)
            if pending is None:
                self._pending[fd] = bytearray(data)
            elif len(pending) <= _TCP_BACKLOG_BYTES:
                pending += data
            self._held.add(fd)
            self._backlogged.add(fd)
            return
        if fd not in self._backlogged:
            # nothing queued before (the usual case): straight to the socket
            n = self._write_tcp(peer, sock, data)
            if n is not None and n < len(data):
                self._pending[fd] = bytearray(data[n:])
                self._backlogged.add(fd)
            return
        pending = self._pending[fd]
        if len(pending) > _TCP_BACKLOG_BYTES:
            # a client that does not read loses whole frames rather than stalling the vehicle
            return
        pending += data
        self._flush_tcp(peer)

    def _flush_tcp(self, peer: Peer) -> None:
        sock = self._tcp.get(peer[1])
        pending = self._pending.get(peer[1])
        if sock is None or not pending:
            return
        self._held.discard(peer[1])     # a write now: whatever was batched goes with it
        n = self._write_tcp(peer, sock, pending)
        if n is None:
            return
        del pending[:n]
        if not pending:
            self._backlogged.discard(peer[1])

    def _write_tcp(self, peer: Peer, sock: socket.socket, data: bytes | bytearray
                   ) -> int | None:
        """How many bytes of ``data`` the client took now; None if its connection failed
        (then it is dropped)."""
        if self.batch_s > 0.0:
            self._last_write[peer[1]] = time.monotonic()
        try:
            return sock.send(data)
        except BlockingIOError:
            return 0
        except OSError:
            self._drop_tcp(peer)
            return None

    @staticmethod
    def _send_udp(sock: socket.socket, addr: Address, data: bytes) -> None:
        # nobody listening (ICMP port unreachable) or a full buffer: UDP drops the frame
        with contextlib.suppress(OSError):
            sock.sendto(data, addr)

    def close(self) -> None:
        """Close every socket and flush the log."""
        for sock in self._socks:
            sock.close()
        self._tcp.clear()
        self._links.clear()
        if self.tlog is not None:
            self.tlog.flush()
