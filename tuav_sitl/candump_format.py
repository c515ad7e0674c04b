"""can-utils ``candump`` output formats, byte for byte, for classic CAN frames.

Two formats, as can-utils' ``candump`` (``candump.c``, ``lib.c``) prints them:

- **default** (``candump vcan0``)::

      "  vcan0  00E   [8]  00 00 80 3F 00 00 00 00"
      "  vcan0  009   [8]  remote request"
      "  vcan0  002   [0] "                              (note the trailing space)
      "  vcan0  12345678   [4]  DE AD BE EF"

  A leading space, the (absent) timestamp, a space, the interface right-aligned to the
  longest interface name candump opened, two spaces, then the frame: the id in upper-case
  hex (3 digits, or 8 for an extended id) in a 5-column (10 for extended) field, ``[len]``,
  and each data byte preceded by one space after a first extra one. Once candump has seen
  an extended frame it indents standard ids by five columns (``indent_sff``) so the columns
  line up. With ``-ta`` the timestamp ``(1700000000.123456) `` follows the leading space.

- **log** (``candump -L``, also ``candump -l`` files and ``python -m can.logger``)::

      "(1700000000.123456) vcan0 00E#0000803F00000000"
      "(1700000000.123456) vcan0 009#R8"      (remote request with DLC 8)
      "(1700000000.123456) vcan0 009#R"       (remote request with DLC 0)
      "(1700000000.123456) vcan0 002#"        (no data)

  Seconds are zero-padded to 10 digits, microseconds to 6; the interface is right-aligned
  to the longest name too (no padding with a single interface).

Remote frames here follow :class:`tuavdefs.can_protocol.Frame`'s convention: ``data`` is
``bytes(dlc)``, only its length counts.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from typing import NamedTuple

__all__ = [
    "format_default",
    "format_log",
    "format_timestamp",
    "iface_width",
    "parse_log_line",
    "parse_log_frame",
    "LogLine",
    "LogFrame",
]

_SFF_MASK = 0x7FF
_EFF_MASK = 0x1FFFFFFF
_MAX_DLEN = 8


class LogLine(NamedTuple):
    """A parsed ``candump -L`` line: time [s], interface, id, payload, remote flag."""

    timestamp: float
    interface: str
    arbitration_id: int
    data: bytes
    is_remote: bool


class LogFrame(NamedTuple):
    """:class:`LogLine` plus whether the id was written as an extended (8-digit) id."""

    timestamp: float
    interface: str
    arbitration_id: int
    data: bytes
    is_remote: bool
    is_extended: bool


def iface_width(interfaces: Iterable[str]) -> int:
    """The width candump aligns interface names to: the longest name's length."""
    return max((len(i) for i in interfaces), default=0)


def _check_frame(arbitration_id: int, data: bytes, is_extended: bool) -> bytes:
    data = bytes(data)
    limit = _EFF_MASK if is_extended else _SFF_MASK
    if not 0 <= arbitration_id <= limit:
        kind = "extended" if is_extended else "standard"
        raise ValueError(f"id {arbitration_id:#x} out of range for a {kind} frame")
    if len(data) > _MAX_DLEN:
        raise ValueError(f"classic CAN carries at most 8 bytes, got {len(data)}")
    return data


def format_timestamp(timestamp_s: float, use_ns: bool = False) -> str:
    """``(SSSSSSSSSS.uuuuuu)`` as candump prints absolute time (``-N``: 9 fraction digits).
    ``timestamp_s`` [s] is rounded to the nearest microsecond (nanosecond)."""
    if not timestamp_s >= 0.0:
        raise ValueError(f"timestamp must be a non-negative number, got {timestamp_s!r}")
    scale = 1_000_000_000 if use_ns else 1_000_000
    sec, frac = divmod(round(timestamp_s * scale), scale)
    return f"({sec:010d}.{frac:09d})" if use_ns else f"({sec:010d}.{frac:06d})"


def _id_field(arbitration_id: int, is_extended: bool) -> str:
    return f"{arbitration_id:08X}" if is_extended else f"{arbitration_id:03X}"


def format_default(interface: str, arbitration_id: int, data: bytes, is_remote: bool = False,
                   is_extended: bool = False, iface_width: int = 0, *,
                   timestamp_s: float | None = None, indent_sff: bool = False) -> str:
    """One line of ``candump``'s default output (no trailing newline).

    ``iface_width`` is the longest interface name candump listens on (names are
    right-aligned to it); ``timestamp_s`` [s] adds ``-ta``'s absolute timestamp;
    ``indent_sff`` indents standard ids as candump does after it has seen an extended one.
    """
    data = _check_frame(arbitration_id, data, is_extended)
    stamp = "" if timestamp_s is None else format_timestamp(timestamp_s) + " "
    head = f" {stamp} {interface:>{iface_width}}  "
    ident = _id_field(arbitration_id, is_extended)
    if not is_extended and indent_sff:
        ident = " " * 5 + ident
    # id field of 5 (standard) or 10 (extended/indented) columns, then "[n]" after a space
    body = f"{ident:<{len(ident) + 2}} [{len(data)}] "
    if is_remote:
        return f"{head}{body} remote request"
    return head + body + "".join(f" {b:02X}" for b in data)


def format_log(timestamp_s: float, interface: str, arbitration_id: int, data: bytes,
               is_remote: bool = False, is_extended: bool = False, *, iface_width: int = 0,
               use_ns: bool = False) -> str:
    """One line of ``candump -L`` / log-file output (no trailing newline).

    ``timestamp_s`` [s] since the epoch (or since the start of a simulation); a remote
    frame prints ``R`` followed by its DLC when that is not zero.
    """
    data = _check_frame(arbitration_id, data, is_extended)
    ident = _id_field(arbitration_id, is_extended)
    rtr = "R" + (f"{len(data):X}" if data else "")
    payload = rtr if is_remote else data.hex().upper()
    return f"{format_timestamp(timestamp_s, use_ns)} {interface:>{iface_width}} {ident}#{payload}"


_LOG_RE = re.compile(
    r"^\s*\((?P<sec>\d+)\.(?P<frac>\d+)\)\s+(?P<iface>\S+)\s+"
    r"(?P<id>[0-9A-Fa-f]{3}|[0-9A-Fa-f]{8})#(?P<frame>\S*)(?:\s+[RT])?\s*$")
_RTR_RE = re.compile(r"^[Rr](?P<dlc>[0-8])?(?:_[0-9A-Fa-f])?$")
_DATA_RE = re.compile(r"^(?P<hex>(?:[0-9A-Fa-f]{2}\.?)*)(?:_[0-9A-Fa-f])?$")


def parse_log_frame(line: str) -> LogFrame:
    """Parse a ``candump -L`` line (also with python-can's trailing `` R``/`` T``).

    Raises ValueError for anything else, CAN FD (``##``) and error frames included.
    """
    m = _LOG_RE.match(line)
    if m is None:
        raise ValueError(f"not a candump log line: {line!r}")
    is_extended = len(m["id"]) == 8
    arbitration_id = int(m["id"], 16)
    if is_extended and arbitration_id > _EFF_MASK:
        raise ValueError(f"error frame or flags in id: {line!r}")
    if not is_extended and arbitration_id > _SFF_MASK:
        raise ValueError(f"standard id above 0x7FF: {line!r}")
    frame = m["frame"]
    if frame.startswith("#"):
        raise ValueError(f"CAN FD frames are not supported: {line!r}")
    timestamp = float(f"{m['sec']}.{m['frac']}")
    rtr = _RTR_RE.match(frame)
    if rtr is not None:
        dlc = int(rtr["dlc"] or "0")
        return LogFrame(timestamp, m["iface"], arbitration_id, bytes(dlc), True, is_extended)
    d = _DATA_RE.match(frame)
    if d is None:
        raise ValueError(f"bad payload in candump log line: {line!r}")
    hexstr = d["hex"].replace(".", "")
    data = bytes.fromhex(hexstr)
    if len(data) > _MAX_DLEN:
        raise ValueError(f"more than 8 data bytes: {line!r}")
    return LogFrame(timestamp, m["iface"], arbitration_id, data, False, is_extended)


def parse_log_line(line: str) -> LogLine:
    """Parse a ``candump -L`` line to ``(timestamp [s], interface, id, data, is_remote)``
    (see :func:`parse_log_frame`, which also says whether the id was extended)."""
    f = parse_log_frame(line)
    return LogLine(f.timestamp, f.interface, f.arbitration_id, f.data, f.is_remote)
