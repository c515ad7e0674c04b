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

A process never sees its own frames: the multicast bus delivers a sender's datagrams back
to it, so :class:`CanLink` drops received frames that match, in order, what it sent in
the last half second (ids are directional in this protocol, so no other node sends a frame
identical to ours).
"""

from __future__ import annotations

import os
import time
from collections import deque
from typing import NamedTuple

import can

DEFAULT_GROUP = "239.74.163.2"
DEFAULT_SPEC = "auto"
#: How long a sent frame waits for its echo before it is forgotten [s].
ECHO_WINDOW_S = 0.5


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
    """A python-can bus that drops this process's own frames."""

    def __init__(self, spec: str = DEFAULT_SPEC) -> None:
        self.interface, self.channel = resolve_spec(spec)
        kwargs: dict = {}
        if self.interface == "udp_multicast":
            kwargs["hop_limit"] = 0
        if self.interface == "virtual":
            kwargs["receive_own_messages"] = False
        try:
            self.bus = can.Bus(interface=self.interface, channel=self.channel, **kwargs)
        except (OSError, can.CanError, ImportError) as exc:
            raise CanBusError(f"cannot open {self.interface}:{self.channel}: {exc}") from exc
        self._sent: deque[tuple[float, tuple[int, bytes, bool]]] = deque()
        self.own_frames_dropped = 0

    @property
    def description(self) -> str:
        """``interface:channel``, e.g. for banners."""
        return f"{self.interface}:{self.channel}"

    def send(self, arbitration_id: int, data: bytes = b"", is_remote: bool = False,
             dlc: int | None = None, is_extended: bool = False) -> None:
        """Send one frame (a remote frame carries ``dlc`` and no data)."""
        length = len(data) if dlc is None else dlc
        msg = can.Message(arbitration_id=arbitration_id, data=None if is_remote else data,
                          is_remote_frame=is_remote, dlc=length, is_extended_id=is_extended)
        self.bus.send(msg)
        if self.interface == "udp_multicast":
            self._sent.append((time.monotonic(), _key(arbitration_id, data, is_remote, length)))

    def recv(self, timeout_s: float | None = 0.0) -> RxFrame | None:
        """The next frame from another node, or None after ``timeout_s`` [s]."""
        end = None if timeout_s is None else time.monotonic() + timeout_s
        while True:
            remaining = None if end is None else max(end - time.monotonic(), 0.0)
            msg = self.bus.recv(timeout=remaining)
            if msg is None:
                return None
            data = bytes(msg.dlc) if msg.is_remote_frame else bytes(msg.data)
            if self._is_own(_key(msg.arbitration_id, data, msg.is_remote_frame, msg.dlc)):
                continue
            return RxFrame(msg.arbitration_id, data, msg.is_remote_frame, msg.is_extended_id,
                           msg.timestamp)

    def _is_own(self, key: tuple[int, bytes, bool]) -> bool:
        now = time.monotonic()
        while self._sent and now - self._sent[0][0] > ECHO_WINDOW_S:
            self._sent.popleft()
        for i, (_, sent) in enumerate(self._sent):
            if sent == key:
                del self._sent[i]
                self.own_frames_dropped += 1
                return True
        return False

    def close(self) -> None:
        """Shut the bus down."""
        self.bus.shutdown()


def _key(arbitration_id: int, data: bytes, is_remote: bool, dlc: int
         ) -> tuple[int, bytes, bool]:
    return (arbitration_id, bytes(dlc) if is_remote else bytes(data), is_remote)
