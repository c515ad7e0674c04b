"""The simulator link's frames (:mod:`tuavdefs.simlink`): each end's :class:`Encoder`, the
link's values of a message, the split of whole frames and the :class:`FrameParser` of a
byte stream."""

from __future__ import annotations

import struct
from collections.abc import Mapping, Sequence
from typing import Any

from pymavlink.dialects.v20 import common as mavlink2

from tuavdefs.simlink.codec import (
    _CODECS,
    _CRC_STRUCT,
    _HEADER_V1,
    _HEADER_V2,
    _HEADER_V2_STRUCT,
    _IFLAG_SIGNED,
    _MAGIC_V1,
    _MAGIC_V2,
    _MCRF4XX,
    _SIGNATURE_LEN,
    _Codec,
    _Sink,
    count_sent,
    mavlink_crc,
)
from tuavdefs.simlink.constants import (
    FLAG_LOCKSTEP,
    MODE_ARMED,
    MODE_DISARMED,
    MSG_HIL_ACTUATOR_CONTROLS,
    MSG_HIL_GPS,
    MSG_HIL_SENSOR,
    MSG_HIL_STATE_QUATERNION,
    MSG_PARAM_SET,
    MSG_PARAM_VALUE,
    N_ROTORS,
)
from tuavdefs.simlink.fields import (
    _UNUSED_CONTROLS,
    _clean_command,
    actuator_controls_values,
)

_ACTUATOR_FRAME = struct.Struct(
    _HEADER_V2_STRUCT.format + _CODECS[MSG_HIL_ACTUATOR_CONTROLS].unpacker.format[1:])
_ACTUATOR_PAYLOAD = _CODECS[MSG_HIL_ACTUATOR_CONTROLS].unpacker.size
_ACTUATOR_CRC_EXTRA = _CODECS[MSG_HIL_ACTUATOR_CONTROLS].crc_extra


def link_values(msg: mavlink2.MAVLink_message) -> tuple[int, tuple] | None:
    """(message id, values in wire order) of one of the link's messages (None for any
    other message): what :meth:`FrameParser.feed_link` returns for it. PARAM_SET and
    PARAM_VALUE give (name, value) instead."""
    mid = msg.get_msgId()
    codec = _CODECS.get(mid)
    if codec is None:
        if mid in (MSG_PARAM_SET, MSG_PARAM_VALUE):
            name = msg.param_id
            if isinstance(name, bytes):
                name = name.decode("ascii", "replace")
            return mid, (str(name).split("\0", 1)[0], float(msg.param_value))
        return None
    return (codec.msg_id, codec.wire_of(msg))


def param_set_frame(encoder: Encoder, target: tuple[int, int], name: str,
                    value: float) -> bytes:
    """A PARAM_SET of a simulator parameter (a REAL32 on the wire) for ``target``
    (system, component)."""
    return encoder.pack(mavlink2.MAVLink_param_set_message(
        target[0], target[1], name.encode("ascii"), float(value),
        mavlink2.MAV_PARAM_TYPE_REAL32))


def param_value_frame(encoder: Encoder, name: str, value: float, index: int,
                      count: int) -> bytes:
    """A PARAM_VALUE of a simulator parameter (a REAL32 on the wire)."""
    return encoder.pack(mavlink2.MAVLink_param_value_message(
        name.encode("ascii"), float(value), mavlink2.MAV_PARAM_TYPE_REAL32, count, index))


class Encoder:
    """Packs MAVLink 2 messages into bytes, with this end's ids and a running sequence."""

    def __init__(self, sysid: int, compid: int) -> None:
        self._sink = _Sink()
        self.mav = mavlink2.MAVLink(self._sink, srcSystem=sysid, srcComponent=compid)

    def pack(self, msg: mavlink2.MAVLink_message) -> bytes:
        """The frame of one message (advances the sequence number)."""
        self.mav.send(msg)
        return self._sink.take()

    def _fast(self, msg_id: int, fields: Mapping[str, Any]) -> bytes:
        return self.pack_values(msg_id, _CODECS[msg_id].values(fields))

    def pack_values(self, msg_id: int, values: Sequence[Any]) -> bytes:
        """The frame of one of the link's messages from its values in wire order (the
        ``*_values`` functions here), advancing the sequence number."""
        codec = _CODECS[msg_id]
        if self.mav.signing.sign_outgoing:   # pymavlink signs: let it pack
            cls = mavlink2.mavlink_map[msg_id]
            return self.pack(cls(**codec.fields(values)))
        return codec.pack_values(self.mav, values)

    def actuator_controls(self, time_us: int, rotor_commands: Sequence[float], armed: bool,
                          lockstep: bool = True) -> bytes:
        """The HIL_ACTUATOR_CONTROLS frame answering ``time_us`` [us] with four rotor
        commands in [0, 1] and the armed flag: the bytes of :meth:`pack_values` of
        :func:`actuator_controls_values`, packed in one go (its payload never ends in a
        zero: ``mode`` is never 0)."""
        mav = self.mav
        if len(rotor_commands) != N_ROTORS or mav.signing.sign_outgoing:
            return self.pack_values(MSG_HIL_ACTUATOR_CONTROLS, actuator_controls_values(
                time_us, rotor_commands, armed, lockstep))
        c0, c1, c2, c3 = rotor_commands
        seq = mav.seq
        frame = _ACTUATOR_FRAME.pack(
            _MAGIC_V2, _ACTUATOR_PAYLOAD, 0, 0, seq, mav.srcSystem, mav.srcComponent,
            MSG_HIL_ACTUATOR_CONTROLS, 0, int(time_us), FLAG_LOCKSTEP if lockstep else 0,
            c0 if 0.0 <= c0 <= 1.0 else _clean_command(c0),
            c1 if 0.0 <= c1 <= 1.0 else _clean_command(c1),
            c2 if 0.0 <= c2 <= 1.0 else _clean_command(c2),
            c3 if 0.0 <= c3 <= 1.0 else _clean_command(c3),
            *_UNUSED_CONTROLS, MODE_ARMED if armed else MODE_DISARMED)
        frame += _CRC_STRUCT.pack(mavlink_crc(frame[1:] + _ACTUATOR_CRC_EXTRA))
        count_sent(mav, 1, len(frame))
        return frame

    def hil_sensor(self, fields: Mapping[str, Any]) -> bytes:
        """A HIL_SENSOR frame from :func:`hil_sensor_fields`' output."""
        return self._fast(MSG_HIL_SENSOR, fields)

    def hil_gps(self, fields: Mapping[str, Any]) -> bytes:
        """A HIL_GPS frame from :func:`hil_gps_fields`' output."""
        return self._fast(MSG_HIL_GPS, fields)

    def hil_state_quaternion(self, fields: Mapping[str, Any]) -> bytes:
        """A HIL_STATE_QUATERNION frame from :func:`hil_state_quaternion_fields`' output."""
        return self._fast(MSG_HIL_STATE_QUATERNION, fields)

    def hil_actuator_controls(self, time_us: int, fields: Mapping[str, Any]) -> bytes:
        """A HIL_ACTUATOR_CONTROLS frame from :func:`actuator_controls_fields`' output."""
        return self._fast(MSG_HIL_ACTUATOR_CONTROLS, {**fields, "time_usec": int(time_us)})


def whole_frames(data: bytes, codecs: Mapping[int, _Codec], check_crc: bool = True
                 ) -> list[tuple[int, tuple]] | None:
    """(message id, values in wire order) of each frame of ``data`` when it is nothing but
    whole, unsigned MAVLink 2 frames of the ``codecs``' messages with valid CRCs (what a
    parser holding no partial frame decodes from it); None for anything else, which is
    then a general parser's to read. ``check_crc`` False skips the checksums: only for
    bytes that never crossed a wire (a batch built in the same process, offline)."""
    out = []
    i, n = 0, len(data)
    mcrf = _MCRF4XX
    while i < n:
        if data[i] != _MAGIC_V2 or n - i < _HEADER_V2 + 2 or data[i + 2]:
            return None   # not a frame start, short, signed or impossible flags
        size = data[i + 1]
        end = i + _HEADER_V2 + size + 2
        codec = codecs.get(data[i + 7] | (data[i + 8] << 8) | (data[i + 9] << 16))
        if codec is None or end > n:
            return None
        if check_crc:
            body = data[i + 1:end - 2] + codec.crc_extra
            if ((mcrf(body, 0xFFFF) if mcrf is not None else mavlink_crc(body))
                    != data[end - 2] | (data[end - 1] << 8)):
                return None
        # a whole payload straight from the stream; one short of its trailing zeros
        # through unpack
        out.append((codec.msg_id, codec.unpacker.unpack_from(data, i + _HEADER_V2)
                    if size == codec.unpacker.size
                    else codec.unpack(data[i + _HEADER_V2:end - 2])))
        i = end
    return out


class FrameParser:
    """Splits a byte stream into MAVLink (1 or 2) messages of the common dialect.

    A frame is accepted only if its message id is known and its CRC (with the id's
    CRC_EXTRA) checks. Anything else is dropped: bytes before a start marker, frames with
    a bad CRC, unknown ids or invalid flags (dropped one byte at a time so that a valid
    frame hidden behind a false start is still found), and truncated frames, recognised
    when a complete valid frame starts inside the span a partial frame claims. Each run of
    dropped bytes between two accepted frames counts as one bad frame (``bad_frames``;
    ``bad_bytes`` counts the bytes), so the counts do not depend on how TCP splits the
    stream. Never raises on content.
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        self._mav = mavlink2.MAVLink(None)
        self._in_bad_run = False
        self.frames = 0
        self.bad_frames = 0
        self.bad_bytes = 0

    @property
    def pending_bytes(self) -> int:
        """Bytes held waiting for the rest of a frame."""
        return len(self._buf)

    def feed(self, data: bytes) -> list[mavlink2.MAVLink_message]:
        """Add received bytes; return the messages completed by them, in order."""
        buf = self._buf
        buf += data
        out: list[mavlink2.MAVLink_message] = []
        while buf:
            start = _find_magic(buf, 0)
            if start < 0:
                self._drop(len(buf))
                break
            if start > 0:
                self._drop(start)
            n = _frame_length(buf, 0)
            if n == 0:            # impossible header (flags): not a frame start
                self._drop(1)
                continue
            if n is not None and len(buf) >= n:
                msg = self._decode(buf, 0, n)
                if msg is None:
                    self._drop(1)
                    continue
                del buf[:n]
                self._accept(msg, out)
                continue
            # a partial frame at the head: wait, unless a complete valid frame starts
            # inside it, which shows the partial frame was truncated
            found = self._valid_frame_after(buf, 1)
            if found is None:
                break
            j, m, msg = found
            self._drop(j)
            del buf[:m]
            self._accept(msg, out)
        return out

    def feed_link(self, data: bytes) -> list[tuple[int, tuple]] | None:
        """The usual case of :meth:`feed`, fast: when nothing is pending and ``data`` is
        whole unsigned MAVLink 2 frames of the link's own messages with valid CRCs, their
        (message id, values in wire order), counted as :meth:`feed` counts them. Anything
        else returns None and changes nothing: pass ``data`` to :meth:`feed` then."""
        if self._buf:
            return None
        out = whole_frames(data, _CODECS)
        if out:
            self.frames += len(out)
            self._in_bad_run = False
        return out

    def _accept(self, msg: mavlink2.MAVLink_message, out: list) -> None:
        self.frames += 1
        self._in_bad_run = False
        out.append(msg)

    def _drop(self, n: int) -> None:
        del self._buf[:n]
        self.bad_bytes += n
        if not self._in_bad_run:
            self.bad_frames += 1
            self._in_bad_run = True

    def _valid_frame_after(self, buf: bytearray, start: int
                           ) -> tuple[int, int, mavlink2.MAVLink_message] | None:
        j = _find_magic(buf, start)
        while j >= 0:
            n = _frame_length(buf, j)
            if n and len(buf) - j >= n:
                msg = self._decode(buf, j, n)
                if msg is not None:
                    return j, n, msg
            j = _find_magic(buf, j + 1)
        return None

    def _decode(self, buf: bytearray, i: int, n: int) -> mavlink2.MAVLink_message | None:
        frame = buf[i:i + n]
        if buf[i] == _MAGIC_V2:
            msg_id = buf[i + 7] | (buf[i + 8] << 8) | (buf[i + 9] << 16)
        else:
            msg_id = buf[i + 5]
        if msg_id not in mavlink2.mavlink_map:
            return None     # its CRC cannot be checked: not trusted
        codec = _CODECS.get(msg_id)
        if codec is not None and buf[i] == _MAGIC_V2 and not buf[i + 2] & _IFLAG_SIGNED:
            try:
                return codec.decode(frame)
            except Exception:   # noqa: BLE001 - any decoding failure is a bad frame
                return None
        try:
            msg = self._mav.decode(frame)
        except Exception:   # noqa: BLE001 - any decoding failure is a bad frame
            return None
        if isinstance(msg, (mavlink2.MAVLink_bad_data, mavlink2.MAVLink_unknown)):
            return None
        return msg


def _find_magic(buf: bytearray, start: int) -> int:
    """Index of the first MAVLink start marker at or after ``start`` (-1 if none)."""
    a = buf.find(_MAGIC_V2, start)
    b = buf.find(_MAGIC_V1, start)
    if a < 0:
        return b
    if b < 0:
        return a
    return min(a, b)


def _frame_length(buf: bytearray, i: int) -> int | None:
    """Total length [bytes] of the frame starting at ``buf[i]``; None when its header is
    not all there yet, 0 when the header is impossible (unknown incompatibility flags)."""
    if buf[i] == _MAGIC_V2:
        if len(buf) - i < 3:
            return None
        flags = buf[i + 2]
        if flags & ~_IFLAG_SIGNED:
            return 0
        return (_HEADER_V2 + buf[i + 1] + 2
                + (_SIGNATURE_LEN if flags & _IFLAG_SIGNED else 0))
    if len(buf) - i < 2:
        return None
    return _HEADER_V1 + buf[i + 1] + 2
