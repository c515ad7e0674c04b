"""The MAVLink parameter micro-service of the companion, behaving as ArduPilot does.

:class:`ParamProtocol` serves a fixed list of :class:`ParamDef` to ground control stations as
system 1 / component 1; :func:`params_to_defs` makes that list from a frozen
:class:`~tuavdefs.paramspec.Params` dataclass (e.g. ``FlightControlParams``). Like the mission
service it is transport-free: ``handle(peer, msg, now_s)`` in, ``send(peer, msg)`` out (peer
None = every link), ``tick(now_s)`` paces the parameter stream.

Value encoding
    ArduPilot's "C cast" encoding: PARAM_VALUE/PARAM_SET carry the *numeric value* of every
    parameter in their float32 field (an INT32 parameter 5 travels as 5.0), never the bytes of
    an integer reinterpreted as a float (PX4's bytewise encoding). Integers beyond 2**24 lose
    precision on the wire. QGC (APMFirmwarePlugin) and MAVSDK convert from this encoding only
    for a vehicle whose HEARTBEAT says ``MAV_AUTOPILOT_ARDUPILOTMEGA``; AUTOPILOT_VERSION should
    advertise ``MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST``. A received float32 is read back
    as the shortest decimal that maps to the same float32 (1.7 arrives as 1.70000005; 1.7 is
    stored), so values typed in a GCS stay as typed.

PARAM_REQUEST_LIST
    Every parameter as PARAM_VALUE (``param_index``, ``param_count``) to the requesting peer,
    paced by a token bucket (``stream_rate_hz`` parameters per second, bursts of at most
    ``stream_burst``) so that a UDP client that reads slowly does not lose any to its socket
    buffer: the first burst goes out at once, the rest from :meth:`ParamProtocol.tick`.
    ArduPilot paces the same way (at most 30 % of the link's bandwidth, 5 per pass without
    flow control). A new request restarts the stream from index 0.

PARAM_REQUEST_READ
    ``param_index`` -1 looks the name up, any other index the index (the name is then
    ignored); the PARAM_VALUE goes to the requester. Unknown names and indices get no answer,
    as in ArduPilot. The reply carries the parameter's real index (ArduPilot sends -1 for
    by-name reads and set confirmations; QGC, MAVProxy, MAVSDK and pymavlink match on the name).

PARAM_SET
    An unknown name is ignored, as ArduPilot does, with a STATUSTEXT ``MAV_SEVERITY_WARNING``.
    NaN or infinity, an integer value outside its MAV_PARAM_TYPE's range, or a value the
    setter rejects (it returns the reason, e.g. a ``paramspec`` bound) leaves the parameter
    unchanged: the requester gets a PARAM_VALUE with the unchanged value and a STATUSTEXT names
    the parameter and the reason (ArduPilot has no such rejection; it clamps). Integer types
    are rounded to the nearest integer first (ArduPilot's ``nearbyintf``). An accepted value
    is broadcast (peer None) as PARAM_VALUE and the file is rewritten.

Persistence
    ``persist_path`` holds every parameter in ArduPilot/MAVProxy ``.parm`` form, ``NAME VALUE``
    per line (MAVProxy's ``param load`` and Mission Planner read it; a comma is accepted as
    separator when loading, ``#`` starts a comment). Every accepted PARAM_SET rewrites it
    atomically (temporary file, fsync, ``os.replace``); :meth:`ParamProtocol.load` applies it
    at start, returning a warning for each unknown name or rejected value.

MAVLink FTP (FILE_TRANSFER_PROTOCOL)
    The companion has no file system to offer, but QGC (whose ParameterManager first asks an
    ArduPilot vehicle for ``@PARAM/param.pck`` by FTP, whatever its capability bits, and drops
    the autopilot's PARAM_VALUE until that attempt ends), MAVProxy (``param ftp``) and MAVSDK
    must learn that at once. Every request addressed to us is answered immediately as
    ArduPilot's FTP server answers (AP_Filesystem, GCS_FTP): the 12-byte header is
    ``seq_number`` u16 = request's + 1 (QGC discards replies with any other number), ``session``
    u8 = request's, ``opcode`` u8, ``size`` u8, ``req_opcode`` u8 = request's opcode,
    ``burst_complete`` u8 = 0, padding u8 = 0, ``offset`` u32 = 0, then ``data``; the message is
    addressed to the requester (``target_network`` 0). TerminateSession and ResetSessions get
    an ACK (opcode 128, size 0), as ArduPilot acknowledges ending a session it does not hold.
    Everything else gets a NAK (opcode 129, size 1, ``data[0]`` = error):
    ``FileNotFound`` (10) for requests naming a path: QGC's parameter manager falls back to
    PARAM_REQUEST_LIST immediately only on "File Not Found" (any other error waits for its
    retry timer), MAVProxy's ``ftp get`` fails at once on any NAK to OpenFileRO and its param
    module then uses PARAM_REQUEST_LIST; ``InvalidSession`` (4) for reads and writes (no session
    is ever open); ``InvalidDataSize`` (3) for ``size`` > 239; ``UnknownCommand`` (7) for
    unknown opcodes. ACKs and NAKs sent to us are ignored.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import os
import re
import struct
import tempfile
import threading
import time
import typing
from collections.abc import Callable, Hashable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import common as mavlink2

from tuavdefs.paramspec import ParameterError, Params

__all__ = ["ParamDef", "ParamProtocol", "WireName", "apply_parm_text", "apply_value",
           "params_to_defs", "FTP_HEADER",
           "FTP_MAX_DATA"]

log = logging.getLogger(__name__)

#: The shortest wall time between two texts of the parameter file [s] (changes in between
#: are written together: a PARAM_SET flood costs one text per this, not one per message).
SAVE_EVERY_S = 0.2

SendFn = Callable[[Hashable | None, Any], None]
StatusTextFn = Callable[[int, str], None]

OWN_SYSTEM_ID = 1
OWN_COMPONENT_ID = 1
PARAM_NAME_MAX = 16
_NAME_RE = re.compile(r"[A-Z][A-Z0-9_]*")

#: Inclusive value range of each integer MAV_PARAM_TYPE.
_INT_RANGES = {
    mavlink2.MAV_PARAM_TYPE_UINT8: (0, 2**8 - 1),
    mavlink2.MAV_PARAM_TYPE_INT8: (-(2**7), 2**7 - 1),
    mavlink2.MAV_PARAM_TYPE_UINT16: (0, 2**16 - 1),
    mavlink2.MAV_PARAM_TYPE_INT16: (-(2**15), 2**15 - 1),
    mavlink2.MAV_PARAM_TYPE_UINT32: (0, 2**32 - 1),
    mavlink2.MAV_PARAM_TYPE_INT32: (-(2**31), 2**31 - 1),
}
_FLOAT_TYPES = frozenset({mavlink2.MAV_PARAM_TYPE_REAL32})

#: The MAVLink FTP header: seq_number, session, opcode, size, req_opcode, burst_complete,
#: padding, offset (little-endian, 12 bytes).
FTP_HEADER = struct.Struct("<HBBBBBBI")
FTP_PAYLOAD_LEN = 251
FTP_MAX_DATA = FTP_PAYLOAD_LEN - FTP_HEADER.size  # 239
FTP_OP_TERMINATE_SESSION = 1
FTP_OP_RESET_SESSIONS = 2
FTP_OP_LIST_DIRECTORY = 3
FTP_OP_OPEN_FILE_RO = 4
FTP_OP_READ_FILE = 5
FTP_OP_CREATE_FILE = 6
FTP_OP_WRITE_FILE = 7
FTP_OP_REMOVE_FILE = 8
FTP_OP_CREATE_DIRECTORY = 9
FTP_OP_REMOVE_DIRECTORY = 10
FTP_OP_OPEN_FILE_WO = 11
FTP_OP_TRUNCATE_FILE = 12
FTP_OP_RENAME = 13
FTP_OP_CALC_FILE_CRC32 = 14
FTP_OP_BURST_READ_FILE = 15
FTP_OP_ACK = 128
FTP_OP_NAK = 129
FTP_ERR_INVALID_DATA_SIZE = 3
FTP_ERR_INVALID_SESSION = 4
FTP_ERR_UNKNOWN_COMMAND = 7
FTP_ERR_FILE_NOT_FOUND = 10
_FTP_PATH_OPS = frozenset({
    FTP_OP_LIST_DIRECTORY, FTP_OP_OPEN_FILE_RO, FTP_OP_CREATE_FILE, FTP_OP_REMOVE_FILE,
    FTP_OP_CREATE_DIRECTORY, FTP_OP_REMOVE_DIRECTORY, FTP_OP_OPEN_FILE_WO,
    FTP_OP_TRUNCATE_FILE, FTP_OP_RENAME, FTP_OP_CALC_FILE_CRC32,
})
_FTP_SESSION_OPS = frozenset({FTP_OP_READ_FILE, FTP_OP_WRITE_FILE, FTP_OP_BURST_READ_FILE})


@dataclass(frozen=True)
class ParamDef:
    """One parameter as the GCS sees it.

    ``name``: at most 16 characters, ASCII upper case, digits and ``_``, starting with a
    letter (ArduPilot style). ``param_type``: a MAV_PARAM_TYPE (REAL32 for floats, INT8 for
    booleans, INT32 for integers). ``get()`` returns the current value as a float (booleans
    0/1); ``set(value)`` applies one and returns None, or the reason it refused (the value
    unchanged). ``unit`` (the unit on the wire, ArduPilot's spelling: ``cm/s``, ``cdeg``),
    ``description`` and the range ``low``..``high`` (on the wire, None: unbounded) are the
    metadata ground stations show (:func:`companion.param_metadata.pdef_xml`).
    """

    name: str
    param_type: int
    get: Callable[[], float]
    set: Callable[[float], str | None]
    unit: str = ""
    description: str = ""
    low: float | None = None
    high: float | None = None

    def __post_init__(self) -> None:
        if len(self.name) > PARAM_NAME_MAX or not _NAME_RE.fullmatch(self.name):
            raise ValueError(f"parameter name {self.name!r}: need 1..{PARAM_NAME_MAX} of "
                             "A-Z, 0-9, _ starting with a letter")
        if self.param_type not in _FLOAT_TYPES and self.param_type not in _INT_RANGES:
            raise ValueError(f"parameter {self.name}: unsupported MAV_PARAM_TYPE "
                             f"{self.param_type}")


def write_atomically(path: Path, text: str) -> None:
    """``text`` into ``path`` atomically: a temporary file beside it, fsync, rename."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="ascii") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


class FileWriter:
    """Writes the parameter file off the control path: :meth:`submit` hands over the text
    and returns at once; a thread of its own writes the latest text submitted (older ones
    are dropped: the file only ever needs the newest) with :func:`write_atomically`."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._cond = threading.Condition()
        self._text: str | None = None       # the newest text not yet written
        self._busy = False
        self._closed = False
        self.errors: list[OSError] = []
        """Write failures not yet reported (taken by the protocol's :meth:`tick`)."""
        self._thread = threading.Thread(target=self._run, name="param-writer", daemon=True)
        self._thread.start()

    def submit(self, text: str) -> None:
        """Write ``text`` soon (instead of whatever is still waiting)."""
        with self._cond:
            self._text = text
            self._cond.notify()

    def flush(self, timeout_s: float | None = 10.0) -> bool:
        """Wait until everything submitted is written; whether it was in time."""
        with self._cond:
            return self._cond.wait_for(lambda: self._text is None and not self._busy,
                                       timeout_s)

    def close(self, timeout_s: float = 10.0) -> None:
        """Write what is waiting, then end the thread."""
        self.flush(timeout_s)
        with self._cond:
            self._closed = True
            self._cond.notify()
        self._thread.join(timeout_s)

    def _run(self) -> None:
        while True:
            with self._cond:
                self._cond.wait_for(lambda: self._text is not None or self._closed)
                if self._text is None:
                    return
                text, self._text, self._busy = self._text, None, True
            try:
                write_atomically(self.path, text)
            except OSError as exc:
                self.errors.append(exc)
            finally:
                with self._cond:
                    self._busy = False
                    self._cond.notify_all()


@dataclass
class _Stream:
    """A PARAM_REQUEST_LIST being answered: next index and the pacing budget."""

    next_index: int
    tokens: float
    last_s: float


class ParamProtocol:
    """The vehicle side of the MAVLink parameter protocol (see the module docstring).

    ``defs``: the parameters, in index order (names unique). ``send(peer, msg)`` delivers a
    PARAM_VALUE or FILE_TRANSFER_PROTOCOL (peer None: every link); ``statustext(severity,
    text)`` raises a STATUSTEXT. ``persist_path``: the ``.parm`` file, or None. The list
    stream runs at ``stream_rate_hz`` parameters per second in bursts of ``stream_burst``.
    """

    def __init__(self, defs: Iterable[ParamDef], send: SendFn, statustext: StatusTextFn, *,
                 persist_path: Path | str | None = None, stream_rate_hz: float = 400.0,
                 stream_burst: int = 20) -> None:
        self.defs: list[ParamDef] = list(defs)
        if len(self.defs) > 65535:
            raise ValueError("at most 65535 parameters fit PARAM_VALUE.param_count")
        self._by_name: dict[str, int] = {}
        for i, d in enumerate(self.defs):
            if d.name in self._by_name:
                raise ValueError(f"duplicate parameter name {d.name}")
            self._by_name[d.name] = i
        if stream_rate_hz <= 0 or stream_burst < 1:
            raise ValueError("stream_rate_hz must be > 0 and stream_burst >= 1")
        self._send = send
        self._statustext = statustext
        self.persist_path = Path(persist_path) if persist_path is not None else None
        self._writer = FileWriter(self.persist_path) if self.persist_path is not None else None
        self._dirty = False                     # a change not yet handed to the writer
        self._saved_wall = -math.inf            # when the last text was made [s, monotonic]
        self._sorted_defs = sorted(self.defs, key=lambda d: d.name)
        self.stream_rate_hz = float(stream_rate_hz)
        self.stream_burst = int(stream_burst)
        self._streams: dict[Hashable, _Stream] = {}

    # --- entry points ------------------------------------------------------------------

    @property
    def streaming(self) -> bool:
        """True while a PARAM_REQUEST_LIST answer is still being sent."""
        return bool(self._streams)

    def handle(self, peer: Hashable, msg: Any, now_s: float) -> bool:
        """Process one message from ``peer`` at wall-clock time ``now_s`` [s].

        Returns True when the message belonged to this service (and was consumed).
        """
        kind = msg.get_type()
        handler = self._HANDLERS.get(kind)
        if handler is None:
            return False
        if (getattr(msg, "target_system", None) not in (0, OWN_SYSTEM_ID)
                or getattr(msg, "target_component", None) not in (0, OWN_COMPONENT_ID)):
            return False
        handler(self, peer, msg, float(now_s))
        return True

    def tick(self, now_s: float) -> None:
        """Send the parameters the list streams' budgets allow, and say a failed write of
        the parameter file; call often (>= 20 Hz)."""
        w = self._writer
        if (w is not None and self._dirty
                and time.monotonic() - self._saved_wall >= SAVE_EVERY_S):
            self._submit()
        if w is not None and w.errors:
            exc = w.errors.pop(0)
            log.error("cannot save parameters to %s: %s", self.persist_path, exc)
            self._statustext(mavlink2.MAV_SEVERITY_ERROR, "Parameter save failed")
        if not self._streams:
            return
        for peer in list(self._streams):
            self._pump(peer, float(now_s))

    def peer_closed(self, peer: Hashable) -> None:
        """Stop streaming to a link that has gone."""
        self._streams.pop(peer, None)

    def announce(self, name: str) -> None:
        """Broadcast a parameter's current value (after a change made on board); an unknown
        name raises KeyError."""
        self._send(None, self._value_message(self._by_name[name]))

    # --- persistence -------------------------------------------------------------------

    def load(self) -> list[str]:
        """Apply ``persist_path`` if it exists; return a warning per line not applied
        (:func:`apply_parm_text`). Nothing is sent."""
        if self.persist_path is None or not self.persist_path.exists():
            return []
        try:
            text = self.persist_path.read_text(encoding="utf-8", errors="replace")
        except OSError as exc:
            warnings = [f"{self.persist_path}: {exc}"]
        else:
            warnings = apply_parm_text(self.defs, text, self.persist_path.name)
        for w in warnings:
            log.warning("parameter file: %s", w)
        return warnings

    def save(self) -> None:
        """Have every parameter written to ``persist_path`` (no-op without a path), off the
        control path and coalesced: the change is marked now; :meth:`tick` makes the
        file's text at most every :data:`SAVE_EVERY_S` of wall time and a thread of its own
        writes it atomically (:meth:`flush` makes and waits for it at once). A flood of
        PARAM_SETs costs one text a period at most, not one a message."""
        if self._writer is not None:
            self._dirty = True

    def _submit(self) -> None:
        assert self._writer is not None
        self._dirty = False
        self._saved_wall = time.monotonic()
        lines = ["# tuav-sitl companion parameters (ArduPilot .parm format: NAME VALUE)"]
        for d in self._sorted_defs:
            lines.append(f"{d.name:<16} {_format_value(d, d.get())}")
        self._writer.submit("\n".join(lines) + "\n")

    def flush(self, timeout_s: float | None = 10.0) -> bool:
        """Wait until the parameter file holds every accepted change; whether it does."""
        if self._writer is None:
            return True
        if self._dirty:
            self._submit()
        return self._writer.flush(timeout_s)

    def close(self) -> None:
        """Write what is waiting and end the writer's thread."""
        if self._writer is not None:
            if self._dirty:
                self._submit()
            self._writer.close()

    # --- handlers ----------------------------------------------------------------------

    def _on_request_list(self, peer: Hashable, msg: Any, now_s: float) -> None:
        # the list starts again from its first parameter; a peer asking again while its
        # list is still sent keeps its bucket (the pacing is the peer's, not the
        # request's: a flood of requests costs no more than one list)
        stream = self._streams.get(peer)
        if stream is None:
            self._streams[peer] = _Stream(next_index=0, tokens=float(self.stream_burst),
                                          last_s=now_s)
        else:
            stream.next_index = 0
        self._pump(peer, now_s)

    def _on_request_read(self, peer: Hashable, msg: Any, now_s: float) -> None:
        if msg.param_index == -1:
            index = self._by_name.get(_param_name(msg.param_id))
        else:
            index = msg.param_index if 0 <= msg.param_index < len(self.defs) else None
        if index is not None:
            self._send(peer, self._value_message(index))

    def _on_param_set(self, peer: Hashable, msg: Any, now_s: float) -> None:
        name = _param_name(msg.param_id)
        index = self._by_name.get(name)
        if index is None:
            self._statustext(mavlink2.MAV_SEVERITY_WARNING,
                             f"Unknown parameter {_printable(name)}")
            return
        d = self.defs[index]
        value = _from_float32(float(msg.param_value))
        error = self._apply(d, value)
        if error is not None:
            self._statustext(mavlink2.MAV_SEVERITY_WARNING, f"{d.name}: {error}")
            self._send(peer, self._value_message(index))
            return
        self._send(None, self._value_message(index))
        self.save()

    def _on_ftp(self, peer: Hashable, msg: Any, now_s: float) -> None:
        raw = bytes(int(b) & 0xFF for b in list(msg.payload)[:FTP_PAYLOAD_LEN])
        raw = raw.ljust(FTP_PAYLOAD_LEN, b"\0")
        seq, session, opcode, size, _req, _burst, _pad, _offset = FTP_HEADER.unpack_from(raw)
        if opcode in (FTP_OP_ACK, FTP_OP_NAK):
            return
        if opcode in (FTP_OP_TERMINATE_SESSION, FTP_OP_RESET_SESSIONS):
            reply_opcode, data = FTP_OP_ACK, b""
        elif size > FTP_MAX_DATA:
            reply_opcode, data = FTP_OP_NAK, bytes([FTP_ERR_INVALID_DATA_SIZE])
        elif opcode in _FTP_PATH_OPS:
            reply_opcode, data = FTP_OP_NAK, bytes([FTP_ERR_FILE_NOT_FOUND])
        elif opcode in _FTP_SESSION_OPS:
            reply_opcode, data = FTP_OP_NAK, bytes([FTP_ERR_INVALID_SESSION])
        else:
            reply_opcode, data = FTP_OP_NAK, bytes([FTP_ERR_UNKNOWN_COMMAND])
        header = FTP_HEADER.pack((seq + 1) & 0xFFFF, session, reply_opcode, len(data), opcode,
                                 0, 0, 0)
        payload = (header + data).ljust(FTP_PAYLOAD_LEN, b"\0")
        sysid, compid = _source(msg)
        self._send(peer, mavlink2.MAVLink_file_transfer_protocol_message(
            0, sysid, compid, list(payload)))

    _HANDLERS: dict[str, Callable[[ParamProtocol, Hashable, Any, float], None]] = {
        "PARAM_REQUEST_LIST": _on_request_list,
        "PARAM_REQUEST_READ": _on_request_read,
        "PARAM_SET": _on_param_set,
        "FILE_TRANSFER_PROTOCOL": _on_ftp,
    }

    # --- helpers -----------------------------------------------------------------------

    def _pump(self, peer: Hashable, now_s: float) -> None:
        stream = self._streams[peer]
        elapsed = max(0.0, now_s - stream.last_s)
        stream.tokens = min(float(self.stream_burst),
                            stream.tokens + elapsed * self.stream_rate_hz)
        stream.last_s = now_s
        while stream.tokens >= 1.0 and stream.next_index < len(self.defs):
            self._send(peer, self._value_message(stream.next_index))
            stream.next_index += 1
            stream.tokens -= 1.0
        if stream.next_index >= len(self.defs):
            del self._streams[peer]

    def _value_message(self, index: int) -> Any:
        d = self.defs[index]
        return mavlink2.MAVLink_param_value_message(
            d.name.encode("ascii"), float(d.get()), d.param_type, len(self.defs), index)

    def _apply(self, d: ParamDef, value: float) -> str | None:
        """Set ``d`` to ``value``: None if applied, else the reason it was not."""
        return apply_value(d, value)


def apply_value(d: ParamDef, value: float) -> str | None:
    """Set ``d`` to ``value`` as a PARAM_SET would: None if applied, else the reason it was
    not (not finite, outside the integer type's range, refused by the setter)."""
    if not math.isfinite(value):
        return f"{value} rejected"
    if d.param_type in _INT_RANGES:
        lo, hi = _INT_RANGES[d.param_type]
        value = float(round(value))
        if not lo <= value <= hi:
            return f"{value:g} outside {lo}..{hi}"
    try:
        return d.set(value)
    except Exception as exc:  # a setter failing on an odd value refuses it
        return str(exc) or type(exc).__name__


def apply_parm_text(defs: list[ParamDef], text: str, source: str) -> list[str]:
    """Apply a parameter file's ``text`` (ArduPilot's .parm: lines ``NAME VALUE`` or
    ``NAME,VALUE``, ``#`` starts a comment) to ``defs`` in order; returns a warning per line
    not applied, each ``SOURCE:LINE: ...`` naming the parameter where there is one."""
    by_name = {d.name: d for d in defs}
    warnings: list[str] = []
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        where = f"{source}:{lineno}"
        fields = line.replace(",", " ").split()
        if len(fields) != 2:
            warnings.append(f"{where}: expected NAME VALUE, got {_printable(raw.strip())!r}")
            continue
        name, text_value = fields
        d = by_name.get(name)
        if d is None:
            warnings.append(f"{where}: unknown parameter {_printable(name)}")
            continue
        try:
            value = float(text_value)
        except ValueError:
            warnings.append(f"{where}: {name}: not a number: {_printable(text_value)!r}")
            continue
        error = apply_value(d, value)
        if error is not None:
            warnings.append(f"{where}: {name}: {error}")
    return warnings


def _source(msg: Any) -> tuple[int, int]:
    """(system id, component id) of a message's sender, for replies' targets."""
    return int(msg.get_srcSystem() or 0), int(msg.get_srcComponent() or 0)


def _param_name(param_id: Any) -> str:
    """A PARAM_* message's ``param_id`` as text, without padding NULs."""
    if isinstance(param_id, (bytes, bytearray)):
        param_id = bytes(param_id).decode("ascii", errors="replace")
    return str(param_id).split("\0", 1)[0]


def _printable(text: str) -> str:
    return "".join(c if " " <= c <= "~" else "?" for c in text)


def _from_float32(value: float) -> float:
    """The shortest decimal that rounds to the same float32 as ``value``."""
    if not math.isfinite(value):
        return value
    return float(np.format_float_positional(np.float32(value), unique=True, trim="-"))


def _format_value(d: ParamDef, value: float) -> str:
    if d.param_type in _INT_RANGES:
        return str(int(round(value)))
    return repr(float(value))


@dataclass(frozen=True)
class WireName:
    """How a field travels as a parameter: its ``name``, ``scale`` (wire value = field value
    x scale: 100 for metres as ArduPilot's centimetres), ``param_type`` (a MAV_PARAM_TYPE;
    None: from the field's type) and ``unit`` on the wire (None: the field's SI unit)."""

    name: str
    scale: float = 1.0
    param_type: int | None = None
    unit: str | None = None


def params_to_defs(obj: Params, names: dict[str, str | WireName | tuple[WireName, ...]],
                   on_change: Callable[[Params], None]) -> list[ParamDef]:
    """Parameters for every number, boolean and number tuple of a frozen ``Params``.

    ``names`` maps each such field to its parameter name, a :class:`WireName` (a scale, a
    type, a unit on the wire) or several (one field under two names, e.g. ArduCopter's
    ``RTL_ALT`` in cm and the newer ``RTL_ALT_M`` in m: setting either changes both); a
    tuple field gives one parameter per element, named with the suffix ``_X``, ``_Y``,
    ``_Z`` (length 3) or ``_1``..``_n``. By default floats are REAL32, integers INT32,
    booleans INT8 (0/1); an integer type given to a float field carries the rounded scaled
    value. The range is the field's bounds, scaled. Setting one builds a new instance with
    ``dataclasses.replace`` (so the dataclass's bounds and cross-field checks run; a
    ``ParameterError`` becomes the refusal reason), keeps it as the current instance shared
    by all the returned parameters, and calls ``on_change(new_instance)``.

    Raises ValueError for a field without a name, a name for no such field (or for a field of
    another type), or a parameter name that is not ArduPilot style or longer than 16.
    """
    hints = typing.get_type_hints(type(obj))
    exposable: dict[str, tuple[type, int | None]] = {}
    for f in dataclasses.fields(obj):
        kind = _param_kind(hints[f.name])
        if kind is not None:
            value = getattr(obj, f.name)
            exposable[f.name] = (kind[0], len(value) if kind[1] else None)
    unknown = sorted(set(names) - set(exposable))
    if unknown:
        raise ValueError(f"{type(obj).__name__}: no number, boolean or number tuple field "
                         f"named {', '.join(unknown)}")
    missing = sorted(set(exposable) - set(names))
    if missing:
        raise ValueError(f"{type(obj).__name__}: no parameter name for {', '.join(missing)}")

    holder = [obj]  # the current instance, shared by every returned parameter
    meta = {f.name: f.metadata for f in dataclasses.fields(obj)}
    defs: list[ParamDef] = []
    for field_name, (elem_type, length) in exposable.items():
        spec = names[field_name]
        wires = (spec if isinstance(spec, tuple)
                 else (spec if isinstance(spec, WireName) else WireName(spec),))
        m = meta[field_name]
        doc = str(m.get("doc", "") or "")
        for wire in wires:
            if length is None:
                defs.append(_field_def(wire, wire.name, field_name, None, elem_type, m, doc,
                                       holder, on_change))
                continue
            suffixes = (("X", "Y", "Z") if length == 3
                        else tuple(str(i + 1) for i in range(length)))
            for i, suffix in enumerate(suffixes):
                defs.append(_field_def(wire, f"{wire.name}_{suffix}", field_name, i,
                                       elem_type, m, f"{doc} [{suffix}]", holder, on_change))
    return defs


def _param_kind(tp: Any) -> tuple[type, bool] | None:
    """(element type, is_tuple) for the field types a parameter can represent."""
    if tp in (float, int, bool):
        return tp, False
    if typing.get_origin(tp) is tuple:
        args = typing.get_args(tp)
        if args and args[0] in (float, int, bool) and (len(args) == 1 or args[-1] is ...
                                                        or len(set(args)) == 1):
            return args[0], True
    return None


def _field_def(wire: WireName, name: str, field_name: str, index: int | None,
               elem_type: type, meta: Any, doc: str, holder: list[Params],
               on_change: Callable[[Params], None]) -> ParamDef:
    param_type = wire.param_type
    if param_type is None:
        param_type = {bool: mavlink2.MAV_PARAM_TYPE_INT8,
                      int: mavlink2.MAV_PARAM_TYPE_INT32}.get(elem_type,
                                                              mavlink2.MAV_PARAM_TYPE_REAL32)
    scale = float(wire.scale)
    integral = param_type in _INT_RANGES

    def get() -> float:
        value = getattr(holder[0], field_name)
        v = float(value if index is None else value[index]) * scale
        return float(round(v)) if integral and elem_type is not bool else v

    def set_(value: float) -> str | None:
        if elem_type is bool:
            if value not in (0.0, 1.0):
                return "must be 0 or 1"
            new: Any = value == 1.0
        elif elem_type is int:
            if not float(value / scale).is_integer():
                return "must be an integer"
            new = int(value / scale)
        else:
            new = float(value) / scale
        current = holder[0]
        if index is not None:
            items = list(getattr(current, field_name))
            items[index] = new
            new = tuple(items)
        try:
            replaced = dataclasses.replace(current, **{field_name: new})
        except ParameterError as exc:
            return _reason(exc)
        holder[0] = replaced
        on_change(replaced)
        return None

    lows = [meta.get(k) for k in ("gt", "ge") if meta.get(k) is not None]
    highs = [meta.get(k) for k in ("lt", "le") if meta.get(k) is not None]
    unit = wire.unit if wire.unit is not None else str(meta.get("unit", "") or "")
    return ParamDef(name=name, param_type=param_type, get=get, set=set_, unit=unit,
                    description=doc, low=max(lows) * scale if lows else None,
                    high=min(highs) * scale if highs else None)


def _reason(exc: ParameterError) -> str:
    """A ParameterError's message without its dotted field name (the parameter names it)."""
    text = str(exc)
    prefix = f"{exc.field}: "
    return text[len(prefix):] if text.startswith(prefix) else text
