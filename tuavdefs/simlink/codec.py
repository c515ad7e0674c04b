"""MAVLink 2 packing and unpacking of one message type without pymavlink's generic
machinery (:class:`_Codec`), the checksum and the sequence's accounting
(:mod:`tuavdefs.simlink`)."""

from __future__ import annotations

import inspect
import struct
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from pymavlink.dialects.v20 import common as mavlink2


# ----- framing
def _field(msg: Any, name: str) -> Any:
    """Field ``name`` of a pymavlink message or of a mapping of field names."""
    if isinstance(msg, mavlink2.MAVLink_message):   # (a plain class check: fast)
        return getattr(msg, name)
    if isinstance(msg, Mapping):
        return msg[name]
    return getattr(msg, name)


_MAGIC_V1 = 0xFE
_MAGIC_V2 = 0xFD
_HEADER_V1 = 6
_HEADER_V2 = 10
_SIGNATURE_LEN = 13
_IFLAG_SIGNED = 0x01


class _Sink:
    """A file-like object collecting what pymavlink writes."""

    def __init__(self) -> None:
        self.chunks: list[bytes] = []

    def write(self, data: bytes) -> None:
        self.chunks.append(bytes(data))

    def take(self) -> bytes:
        out = b"".join(self.chunks)
        self.chunks.clear()
        return out


#: pymavlink's C helper for the checksum (``mcrf4xx(data, 0xFFFF)``), None if not installed
_MCRF4XX: Callable[[bytes, int], int] | None = getattr(mavlink2, "mcrf4xx", None)


def mavlink_crc(data: bytes) -> int:
    """MAVLink's checksum (CRC-16/MCRF4XX) of ``data`` (a frame after its magic byte, then
    the message's CRC extra), as pymavlink computes it: its C helper where installed."""
    if _MCRF4XX is not None:
        return int(_MCRF4XX(data, 0xFFFF))
    return int(mavlink2.x25crc(data).crc)


_HEADER_V2_STRUCT = struct.Struct("<BBBBBBBHB")
_CRC_STRUCT = struct.Struct("<H")


def count_sent(mav: mavlink2.MAVLink, frames: int, nbytes: int) -> None:
    """Account ``frames`` frames of ``nbytes`` bytes in all, packed here with ``mav``'s
    ids from its current sequence number, as ``MAVLink.send`` does: the sequence advances
    (modulo 256) and the sent counters grow."""
    mav.seq = (mav.seq + frames) % 256
    mav.total_packets_sent += frames
    mav.total_bytes_sent += nbytes


class _Codec:
    """MAVLink 2 packing and unpacking of one message type, without pymavlink's generic
    per-message machinery: the same bytes as ``MAVLink.send`` writes and the same message
    objects as ``MAVLink.decode`` returns (``tests/test_simlink.py`` compares them), about
    three times faster. For messages without strings, unsigned (the simulator link's own,
    and the component link's LOCAL_POSITION_NED through :func:`whole_frames`).

    A message's *values* are its fields in wire order with the arrays spread out: what its
    ``struct`` packs (``cls.unpacker``)."""

    def __init__(self, cls: type) -> None:
        self.cls = cls
        self.msg_id = int(cls.id)
        self.crc_extra = bytes((cls.crc_extra,))
        self.unpacker: struct.Struct = cls.unpacker
        arrays = dict(zip(cls.ordered_fieldnames, cls.array_lengths, strict=True))
        if "char" in cls.fieldtypes or 1 in arrays.values():
            raise ValueError(f"{cls.__name__}: strings and 1-element arrays are pymavlink's")
        self.wire = [(name, arrays[name]) for name in cls.ordered_fieldnames]
        init = inspect.signature(cls.__init__).parameters
        self.defaults = {n: p.default for n, p in init.items()
                         if p.default is not inspect.Parameter.empty}
        # where each constructor argument lies in the unpacked tuple (wire order)
        starts, pos = {}, 0
        for name, n in self.wire:
            starts[name] = pos
            pos += max(n, 1)
        self.plan = [(starts[name], arrays[name]) for name in cls.fieldnames]

    def _spread(self, get: Callable[[str], Any]) -> list[Any]:
        """The values of the fields ``get`` returns by name."""
        values: list[Any] = []
        for name, n in self.wire:
            v = get(name)
            if n:
                values.extend(v[k] for k in range(n))
            else:
                values.append(v)
        return values

    def values(self, fields: Mapping[str, Any]) -> list[Any]:
        """The values of ``fields`` (missing ones take pymavlink's defaults)."""
        defaults = self.defaults
        return self._spread(lambda name: fields[name] if name in fields else defaults[name])

    def wire_of(self, msg_fields: Any) -> tuple:
        """The values of a pymavlink message or of a mapping of all its fields."""
        return tuple(self._spread(lambda name: _field(msg_fields, name)))

    def fields(self, values: Sequence[Any]) -> dict[str, Any]:
        """The mapping of field names (arrays as lists) of ``values``."""
        out: dict[str, Any] = {}
        i = 0
        for name, n in self.wire:
            if n:
                out[name] = list(values[i:i + n])
                i += n
            else:
                out[name] = values[i]
                i += 1
        return out

    def pack(self, mav: mavlink2.MAVLink, fields: Mapping[str, Any]) -> bytes:
        """The frame of a message with ``fields`` from ``mav`` (its ids and sequence)."""
        return self.pack_values(mav, self.values(fields))

    def pack_values(self, mav: mavlink2.MAVLink, values: Sequence[Any]) -> bytes:
        """The frame of a message with ``values`` from ``mav`` (its ids and sequence)."""
        payload = self.unpacker.pack(*values).rstrip(b"\0") or b"\0"
        mid = self.msg_id
        seq = mav.seq
        body = _HEADER_V2_STRUCT.pack(_MAGIC_V2, len(payload), 0, 0, seq, mav.srcSystem,
                                      mav.srcComponent, mid & 0xFFFF, mid >> 16) + payload
        frame = body + _CRC_STRUCT.pack(mavlink_crc(body[1:] + self.crc_extra))
        count_sent(mav, 1, len(frame))
        return frame

    def unpack(self, payload: bytes) -> tuple:
        """The values of a MAVLink 2 payload (which drops its trailing zeros)."""
        size = self.unpacker.size
        if len(payload) != size:
            payload = payload[:size] + bytes(size - len(payload))
        return self.unpacker.unpack(payload)

    def decode(self, frame: bytearray) -> mavlink2.MAVLink_message | None:
        """The message of an unsigned MAVLink 2 ``frame`` of this type (None: bad CRC)."""
        (_, mlen, incompat, compat, seq, sysid, compid, _, _) = _HEADER_V2_STRUCT.unpack_from(
            frame)
        crc = frame[-2] | (frame[-1] << 8)
        if crc != mavlink_crc(bytes(frame[1:-2]) + self.crc_extra):
            return None
        t = self.unpack(bytes(frame[_HEADER_V2:-2]))
        m = self.cls(*[t[a] if n == 0 else list(t[a:a + n]) for a, n in self.plan])
        m._signed = False
        m._msgbuf = frame
        m._payload = frame[6:-2]
        m._crc = crc
        m._header = mavlink2.MAVLink_header(self.msg_id, incompat, compat, mlen, seq, sysid,
                                            compid)
        return m


def frame_codecs(*classes: type) -> dict[int, _Codec]:
    """Codecs for :func:`whole_frames` of pymavlink message classes (without strings or
    one-element arrays), by message id."""
    return {c.msg_id: c for c in map(_Codec, classes)}


#: The simulator link's messages, packed and parsed by :class:`_Codec`.
_CODECS = frame_codecs(
    mavlink2.MAVLink_hil_sensor_message, mavlink2.MAVLink_hil_gps_message,
    mavlink2.MAVLink_hil_state_quaternion_message,
    mavlink2.MAVLink_hil_actuator_controls_message)
#: The same, by the name :func:`whole_frames`' callers outside this module use.
LINK_CODECS = _CODECS

#: A whole HIL_ACTUATOR_CONTROLS frame but its checksum: header, then the payload.
