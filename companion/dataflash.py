"""ArduPilot DataFlash logs (``.bin``), written off the control path.

A record is ``0xA3 0x95 <type>`` and its fields, little-endian, packed as its FMT record
says; FMT (type 128) describes each type: type, length (with the 3-byte header), name
(4 characters), format (16) and column names (64). The format characters are ArduPilot's:
``b``/``B`` int8/uint8, ``h``/``H`` int16/uint16, ``i``/``I`` int32/uint32, ``q``/``Q``
int64/uint64, ``f`` float32, ``d`` float64, ``c``/``C`` int16/uint16 in hundredths,
``e``/``E`` int32/uint32 in hundredths, ``L`` int32 latitude/longitude in 1e-7 degrees,
``M`` uint8 flight mode, ``n`` char[4], ``N`` char[16], ``Z`` char[64]. A caller passes the
stored integer of a scaled field (``c``: 100 x the value, ``L``: 1e7 x the degrees).

As ArduPilot does, the file opens with every type's FMT, then the units (UNIT: a character
and its SI unit), the multipliers (MULT: a character and its factor) and each type's FMTU
(a unit and a multiplier character per field), from which pymavlink's ``DFReader`` (and so
``mavlogdump.py``, MAVExplorer) label the values.

:class:`DataFlashWriter` packs a record in the caller's thread (microseconds) and hands the
bytes to a thread of its own that appends them to the file, so the control loop never
waits for the disk.
"""

from __future__ import annotations

import contextlib
import struct
import threading
from dataclasses import dataclass
from pathlib import Path

from tuavdefs.logfile import LogFile

__all__ = ["HEAD", "MULTIPLIERS", "UNITS", "LogFormat", "DataFlashWriter"]

HEAD = b"\xa3\x95"
FMT_TYPE = 128
_CODES = {"b": "b", "B": "B", "h": "h", "H": "H", "i": "i", "I": "I", "q": "q", "Q": "Q",
          "f": "f", "d": "d", "c": "h", "C": "H", "e": "i", "E": "I", "L": "i", "M": "B",
          "n": "4s", "N": "16s", "Z": "64s"}
_TEXT = frozenset("nNZ")

#: ArduPilot's unit characters (FMTU's UnitIds) and what they stand for; ``N`` (newton)
#: is the project's, for the tether's tension.
UNITS: dict[str, str] = {
    "-": "", "?": "UNKNOWN", "A": "A", "d": "deg", "b": "B", "k": "deg/s",
    "D": "deglatitude", "e": "deg/s/s", "E": "rad/s", "G": "Gauss", "h": "degheading",
    "L": "rad/s/s", "m": "m", "n": "m/s", "N": "N", "o": "m/s/s", "O": "degC", "%": "%",
    "S": "satellites", "s": "s", "r": "rad", "U": "deglongitude", "v": "V", "P": "Pa",
    "Y": "us", "z": "Hz", "#": "instance",
}
#: ArduPilot's multiplier characters (FMTU's MultIds): the factor from the stored number to
#: the unit (``-``: none, a text or a count).
MULTIPLIERS: dict[str, float] = {
    "-": 0.0, "?": 1.0, "2": 1e2, "1": 1e1, "0": 1e0, "A": 1e-1, "B": 1e-2, "C": 1e-3,
    "D": 1e-4, "E": 1e-5, "F": 1e-6, "G": 1e-7, "I": 1e-9,
}


@dataclass(frozen=True)
class LogFormat:
    """One record type: ``type`` id, ``name`` (at most 4 characters), ``fmt`` (format
    characters, at most 16), ``columns`` (comma-separated names, one per character),
    ``units`` and ``mults`` (a :data:`UNITS` and a :data:`MULTIPLIERS` character per
    field; empty: not described)."""

    type: int
    name: str
    fmt: str
    columns: str
    units: str = ""
    mults: str = ""

    def __post_init__(self) -> None:
        if len(self.name) > 4 or len(self.fmt) > 16 or len(self.columns) > 64:
            raise ValueError(f"log format {self.name}: name <= 4, format <= 16, "
                             "columns <= 64 characters")
        if len(self.columns.split(",")) != len(self.fmt):
            raise ValueError(f"log format {self.name}: one column per format character")
        if self.units or self.mults:
            if len(self.units) != len(self.fmt) or len(self.mults) != len(self.fmt):
                raise ValueError(f"log format {self.name}: one unit and one multiplier "
                                 "per format character")
            bad = set(self.units) - UNITS.keys() | set(self.mults) - MULTIPLIERS.keys()
            if bad:
                raise ValueError(f"log format {self.name}: unknown unit or multiplier "
                                 f"{''.join(sorted(bad))!r}")

    @property
    def struct(self) -> struct.Struct:
        return struct.Struct("<" + "".join(_CODES[c] for c in self.fmt))

    @property
    def length(self) -> int:
        """The record's length with its header [bytes]."""
        return 3 + self.struct.size


_FMT = LogFormat(FMT_TYPE, "FMT", "BBnNZ", "Type,Length,Name,Format,Columns", "-b---",
                 "-----")
#: The formats every log describes itself with (ArduPilot's names and layouts).
UNIT = LogFormat(177, "UNIT", "QbZ", "TimeUS,Id,Label", "s--", "F--")
MULT = LogFormat(178, "MULT", "Qbd", "TimeUS,Id,Mult", "s--", "F--")
FMTU = LogFormat(179, "FMTU", "QBNN", "TimeUS,FmtType,UnitIds,MultIds", "s---", "F---")


class DataFlashWriter:
    """A ``.bin`` log at ``path`` with record types ``formats``: their FMT records first,
    then UNIT, MULT and FMTU.

    :meth:`write` packs one record and returns; a thread of its own appends what was
    packed to the file (every ``flush_s`` [s] of wall time, and at :meth:`close`).
    ``size`` is the bytes written so far (what a reader may ask for). A write that fails (a
    full disk, a lost file) or would pass ``max_bytes`` ends the log (:attr:`file`, a
    :class:`tuavdefs.logfile.LogFile`, calls its ``on_end``); the records packed after it
    are dropped."""

    def __init__(self, path: Path, formats: list[LogFormat], flush_s: float = 0.2,
                 max_bytes: int | None = None) -> None:
        self.path = Path(path)
        with contextlib.suppress(OSError):   # if it fails, opening the file says so
            self.path.parent.mkdir(parents=True, exist_ok=True)
        every = [_FMT, UNIT, MULT, FMTU, *formats]
        if len({f.type for f in every}) != len(every) or len({f.name for f in every}) != len(
                every):
            raise ValueError("log formats: a type id or a name used twice")
        #: name -> (the record's header, its packer, whether it holds text)
        self._formats = {f.name: (HEAD + bytes((f.type,)), f.struct,
                                  any(c in _TEXT for c in f.fmt)) for f in every}
        #: packed records not yet written: appended by :meth:`write`, taken by the thread
        #: (a list's append and a slice's removal are atomic: no lock on the control path)
        self._pending: list[bytes] = []
        self._stop = threading.Event()
        self.size = 0
        """Bytes in the file (written and flushed)."""
        #: The file: its ``on_end`` is called once, from the writer's thread, with why the
        #: log ended (a full disk, a lost file, the cap; ``ended`` keeps it): the flight
        #: goes on without it.
        self.file = LogFile(self.path, name=f"log {self.path.name}", max_bytes=max_bytes,
                            flush_s=0.0)
        for f in every:
            self._pending.append(HEAD + bytes((FMT_TYPE,)) + _FMT.struct.pack(
                f.type, f.length, f.name.encode(), f.fmt.encode(), f.columns.encode()))
        for ident, label in UNITS.items():
            self.write("UNIT", 0, ord(ident), label)
        for ident, factor in MULTIPLIERS.items():
            self.write("MULT", 0, ord(ident), factor)
        for f in every:
            if f.units:
                self.write("FMTU", 0, f.type, f.units, f.mults)
        self._flush_s = flush_s
        self._thread = threading.Thread(target=self._run, name="dataflash", daemon=True)
        self._thread.start()

    def write(self, name: str, *values: object) -> None:
        """Record ``name`` with ``values`` (strings as text; numbers as the format stores
        them)."""
        head, st, text = self._formats[name]
        if text:
            values = tuple(v.encode("utf-8", "replace") if isinstance(v, str) else v
                           for v in values)
        self._pending.append(head + st.pack(*values))

    def _run(self) -> None:
        pending = self._pending
        while True:
            closed = self._stop.wait(self._flush_s)
            n = len(pending)
            data = b"".join(pending[:n])
            del pending[:n]
            if data and self.file.write(data):
                self.size += len(data)
            if closed:
                self.file.close()
                return

    def close(self, timeout_s: float = 10.0) -> None:
        """Write what is pending, close the file, end the thread."""
        self._stop.set()
        self._thread.join(timeout_s)
