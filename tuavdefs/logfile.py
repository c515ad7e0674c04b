"""Log files that may fail without failing their process, and stdio that may too.

A simulation's logs are its by-products: when the disk fills, the file is lost or a cap is
reached, the log ends and the flight goes on, as ArduPilot keeps flying when its logging
fails and says so. :class:`LogFile` is that file: every write and flush is guarded; the
first failure (or the cap, ``max_bytes``) closes it, keeps why in :attr:`LogFile.ended` and
calls ``on_end(text)`` once, where the process says so (a line on stderr, a STATUSTEXT);
later writes are dropped. :func:`guard_stdio` makes a process's stdout and stderr drop what
they cannot write (a process log on a full disk) instead of raising in whatever printed.

Shared by the plant's truth log, the companion's telemetry log and the bus recorder's
``can.log`` (each names its file in ``on_end``'s text).
"""

from __future__ import annotations

import contextlib
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, BinaryIO

__all__ = ["LogFile", "guard_stdio", "mb_to_bytes"]


def mb_to_bytes(max_mb: float | None) -> int | None:
    """A cap given in MB (10^6 bytes; None or 0: none) in bytes."""
    return None if not max_mb or max_mb <= 0 else int(max_mb * 1e6)


class LogFile:
    """An append-only log file ``path`` (created or truncated; ``append`` keeps what is
    there) that ends instead of raising: on an ``OSError`` (a full disk, a lost file) or
    when the next write would pass ``max_bytes`` [bytes] (None: no cap), it closes,
    :attr:`ended` says why and ``on_end(text)`` is called once. ``text``: writes take str
    (UTF-8). Flushed at least every ``flush_s`` [s] of wall time by the writes
    themselves, so that a reader of a live run sees it fill. ``name`` is how the texts
    call the file (default: its file name)."""

    def __init__(self, path: Path | str, *, name: str | None = None, text: bool = False,
                 append: bool = False, max_bytes: int | None = None,
                 on_end: Callable[[str], None] | None = None, flush_s: float = 1.0) -> None:
        self.path = Path(path)
        self.name = name or self.path.name
        self.text = text
        self.max_bytes = max_bytes
        self.on_end = on_end
        self.flush_s = flush_s
        #: Why the log ended (None while it is written).
        self.ended: str | None = None
        #: Bytes handed to the file so far.
        self.size_bytes = 0
        self._flushed = time.monotonic()
        self._file: BinaryIO | None = None
        try:
            self._file = open(self.path, "ab" if append else "wb")  # noqa: SIM115
            if append:
                self.size_bytes = self._file.tell()
        except OSError as exc:
            self._end(f"{self.name}: cannot open it: {exc.strerror or exc}")

    def write(self, data: bytes | str) -> bool:
        """Append ``data``; whether the log still runs."""
        f = self._file
        if f is None:
            return False
        raw = data.encode() if self.text else data
        n = len(raw)
        if self.max_bytes is not None and self.size_bytes + n > self.max_bytes:
            self._end(f"{self.name} reached its cap of {self.max_bytes / 1e6:g} MB "
                      "(--log-max-mb): it stops here")
            return False
        try:
            f.write(raw)
        except (OSError, ValueError) as exc:
            self._fail(exc)
            return False
        self.size_bytes += n
        now = time.monotonic()
        if now - self._flushed >= self.flush_s:
            self._flushed = now
            return self.flush()
        return True

    def flush(self) -> bool:
        """Write what is buffered; whether the log still runs."""
        f = self._file
        if f is None:
            return False
        try:
            f.flush()
        except (OSError, ValueError) as exc:
            self._fail(exc)
            return False
        return True

    def close(self) -> None:
        """Write what is buffered and close (a failure then only ends the log)."""
        if self._file is not None and self.flush():
            self._close_quietly()

    def _fail(self, exc: BaseException) -> None:
        why = getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
        self._end(f"{self.name} stopped: {why}")

    def _end(self, why: str) -> None:
        self._close_quietly()
        if self.ended is None:
            self.ended = why
            if self.on_end is not None:
                self.on_end(why)

    def _close_quietly(self) -> None:
        f, self._file = self._file, None
        if f is None:
            return
        # what was buffered is lost with the disk; the descriptor is released anyway
        with contextlib.suppress(OSError, ValueError):
            f.close()


class _GuardedStream:
    """A text stream that drops what it cannot write (and says nothing: where would it?)."""

    def __init__(self, stream: Any) -> None:
        self._stream = stream

    def write(self, text: str) -> int:
        try:
            return int(self._stream.write(text))
        except (OSError, ValueError):
            return len(text)

    def flush(self) -> None:
        with contextlib.suppress(OSError, ValueError):
            self._stream.flush()

    def __getattr__(self, name: str) -> Any:
        return getattr(self._stream, name)


def guard_stdio() -> None:
    """Make this process's stdout and stderr drop what cannot be written instead of
    raising (a process whose log is on a full disk flies on)."""
    for name in ("stdout", "stderr"):
        stream = getattr(sys, name)
        if stream is not None and not isinstance(stream, _GuardedStream):
            setattr(sys, name, _GuardedStream(stream))
