"""ArduPilot DataFlash logs (``.bin``), written off the control path.

A record is ``0xA3 0x95 <type>`` and its fields, little-endian, packed as its FMT record
says; FMT (type 128) describes each type: type, length (with the 3-byte header), name
(4 characters), format (16) and column names (64). The format characters used here are
ArduPilot's: ``B`` uint8, ``H`` uint16, ``i`` int32, ``f`` float32, ``Q`` uint64, ``L``
int32 latitude/longitude in 1e-7 degrees, ``M`` uint8 flight mode, ``N`` char[16], ``Z``
char[64]. pymavlink's ``DFReader`` (and so ``mavlogdump.py``, MAVExplorer) reads them.

:class:`DataFlashWriter` packs a record in the caller's thread (microseconds) and hands the
bytes to a thread of its own that appends them to the file, so the control loop never
waits for the disk.
"""

from __future__ import annotations

import struct
import threading
from dataclasses import dataclass
from pathlib import Path

__all__ = ["HEAD", "LogFormat", "DataFlashWriter"]

HEAD = b"\xa3\x95"
FMT_TYPE = 128
_CODES = {"B": "B", "H": "H", "i": "i", "f": "f", "Q": "Q", "L": "i", "M": "B", "n": "4s",
          "N": "16s", "Z": "64s"}


@dataclass(frozen=True)
class LogFormat:
    """One record type: ``type`` id, ``name`` (at most 4 characters), ``fmt`` (format
    characters, at most 16), ``columns`` (comma-separated names, one per character)."""

    type: int
    name: str
    fmt: str
    columns: str

    def __post_init__(self) -> None:
        if len(self.name) > 4 or len(self.fmt) > 16 or len(self.columns) > 64:
            raise ValueError(f"log format {self.name}: name <= 4, format <= 16, "
                             "columns <= 64 characters")
        if len(self.columns.split(",")) != len(self.fmt):
            raise ValueError(f"log format {self.name}: one column per format character")

    @property
    def struct(self) -> struct.Struct:
        return struct.Struct("<" + "".join(_CODES[c] for c in self.fmt))

    @property
    def length(self) -> int:
        """The record's length with its header [bytes]."""
        return 3 + self.struct.size


_FMT = LogFormat(FMT_TYPE, "FMT", "BBnNZ", "Type,Length,Name,Format,Columns")


class DataFlashWriter:
    """A ``.bin`` log at ``path`` with record types ``formats`` (their FMT records first).

    :meth:`write` packs one record and returns; a thread of its own appends what was
    packed to the file (every ``flush_s`` [s] of wall time, and at :meth:`close`).
    ``size`` is the bytes written so far (what a reader may ask for)."""

    def __init__(self, path: Path, formats: list[LogFormat], flush_s: float = 0.2) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._formats = {f.name: (f, f.struct) for f in formats}
        self._pending = bytearray()
        self._cond = threading.Condition()
        self._closed = False
        self.size = 0
        """Bytes in the file (written and flushed)."""
        self.errors: list[OSError] = []
        self._file = open(self.path, "wb")  # noqa: SIM115 - kept open for the thread
        for f in (_FMT, *formats):
            self._pending += HEAD + bytes((FMT_TYPE,)) + _FMT.struct.pack(
                f.type, f.length, f.name.encode(), f.fmt.encode(), f.columns.encode())
        self._flush_s = flush_s
        self._thread = threading.Thread(target=self._run, name="dataflash", daemon=True)
        self._thread.start()

    def write(self, name: str, *values: object) -> None:
        """Record ``name`` with ``values`` (strings as text; numbers as the format says)."""
        fmt, st = self._formats[name]
        packed = st.pack(*[v.encode("utf-8", "replace") if isinstance(v, str) else v
                           for v in values])
        with self._cond:
            self._pending += HEAD + bytes((fmt.type,)) + packed

    def _run(self) -> None:
        while True:
            with self._cond:
                self._cond.wait(self._flush_s)
                data, self._pending = bytes(self._pending), bytearray()
                closed = self._closed
            if data:
                try:
                    self._file.write(data)
                    self._file.flush()
                    self.size += len(data)
                except OSError as exc:
                    self.errors.append(exc)
            if closed:
                self._file.close()
                return

    def close(self, timeout_s: float = 10.0) -> None:
        """Write what is pending, close the file, end the thread."""
        with self._cond:
            self._closed = True
            self._cond.notify()
        self._thread.join(timeout_s)
