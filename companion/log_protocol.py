"""The MAVLink onboard-log micro-service of the companion, as ArduPilot serves its
DataFlash logs (MAVProxy's ``log list`` / ``log download``, QGC's and Mission Planner's
log download).

- LOG_REQUEST_LIST (``start``..``end`` log numbers; ``end`` 0xFFFF: the last): a LOG_ENTRY
  per log (``id``, ``num_logs``, ``last_log_num``, ``time_utc`` the file's modification
  time [s], ``size`` [bytes]); without logs one LOG_ENTRY with ``id`` 0 and ``num_logs`` 0.
- LOG_REQUEST_DATA (``id``, ``ofs``, ``count`` [bytes]; 0xFFFFFFFF: to the end): LOG_DATA
  of 90 bytes each from ``ofs``, the last shorter (``count`` 0 at the end of the log); a
  new request or LOG_REQUEST_END stops the one before. An unknown id gets a LOG_DATA of
  ``count`` 0.
- LOG_ERASE: every log but the one being written is removed.

The files are read by a thread of its own, which queues the replies; :meth:`LogProtocol.tick`
(every control period) sends at most ``burst`` of them, so the control loop neither reads
the disk nor floods a link.
"""

from __future__ import annotations

import collections
import queue
import threading
import time
from collections.abc import Callable, Hashable
from pathlib import Path
from typing import Any

from pymavlink.dialects.v20 import common as mavlink2

from companion.flight_log import log_path

__all__ = ["CHUNK", "LogProtocol"]

M = mavlink2
#: Bytes of one LOG_DATA.
CHUNK = 90
_ALL = 0xFFFFFFFF
_QUEUE_MAX = 512


class LogProtocol:
    """Serves the logs of ``log_dir``; ``send(peer, msg)`` delivers a reply;
    ``current()`` is the number of the log being written (not erased; None: none)."""

    def __init__(self, log_dir: Path, send: Callable[[Hashable, Any], None],
                 current: Callable[[], int | None] = lambda: None, burst: int = 16) -> None:
        self.dir = Path(log_dir)
        self._send = send
        self._current = current
        self.burst = burst
        self._out: collections.deque[tuple[Hashable, Any]] = collections.deque()
        self._requests: queue.Queue[tuple[str, Hashable, Any]] = queue.Queue()
        self._generation = 0          # a new data request or an end cancels the older
        self._thread = threading.Thread(target=self._run, name="log-server", daemon=True)
        self._thread.start()

    def handle(self, peer: Hashable, msg: Any) -> bool:
        """Take a LOG_* request from ``peer``; True if it was one (addressed to us)."""
        kind = msg.get_type()
        if kind not in ("LOG_REQUEST_LIST", "LOG_REQUEST_DATA", "LOG_REQUEST_END",
                        "LOG_ERASE"):
            return False
        if msg.target_system not in (0, 1) or msg.target_component not in (0, 1):
            return False
        if kind in ("LOG_REQUEST_DATA", "LOG_REQUEST_END"):
            self._generation += 1
        if kind != "LOG_REQUEST_END":
            self._requests.put((kind, peer, (msg, self._generation)))
        return True

    def tick(self) -> None:
        """Send up to ``burst`` queued replies."""
        out = self._out
        for _ in range(min(self.burst, len(out))):
            peer, msg = out.popleft()
            self._send(peer, msg)

    def peer_closed(self, peer: Hashable) -> None:
        """Drop the replies queued for a link that has gone."""
        self._generation += 1
        self._out = collections.deque((p, m) for p, m in list(self._out) if p != peer)

    def close(self) -> None:
        self._requests.put(("stop", None, None))
        self._thread.join(5.0)

    # ----- the reader thread

    def _logs(self) -> list[int]:
        return sorted(int(p.stem) for p in self.dir.glob("*.BIN") if p.stem.isdigit())

    def _run(self) -> None:
        while True:
            kind, peer, arg = self._requests.get()
            if kind == "stop":
                return
            msg, gen = arg
            try:
                if kind == "LOG_REQUEST_LIST":
                    self._list(peer, msg)
                elif kind == "LOG_REQUEST_DATA":
                    self._data(peer, msg, gen)
                elif kind == "LOG_ERASE":
                    current = self._current()
                    for n in self._logs():
                        if n != current:
                            log_path(self.dir, n).unlink(missing_ok=True)
            except OSError:
                continue     # a file gone or unreadable: the client asks again

    def _list(self, peer: Hashable, msg: Any) -> None:
        logs = self._logs()
        if not logs:
            self._out.append((peer, M.MAVLink_log_entry_message(0, 0, 0, 0, 0)))
            return
        last = logs[-1]
        end = last if msg.end == 0xFFFF else msg.end
        for n in logs:
            if msg.start <= n <= end:
                st = log_path(self.dir, n).stat()
                self._out.append((peer, M.MAVLink_log_entry_message(
                    n, len(logs), last, int(st.st_mtime), st.st_size)))

    def _data(self, peer: Hashable, msg: Any, gen: int) -> None:
        path = log_path(self.dir, msg.id)
        if msg.id == 0 or not path.is_file():
            self._out.append((peer, M.MAVLink_log_data_message(msg.id, msg.ofs, 0,
                                                               [0] * CHUNK)))
            return
        ofs, count = int(msg.ofs), int(msg.count)
        with open(path, "rb") as f:
            f.seek(ofs)
            left = count if count != _ALL else None
            while gen == self._generation:
                want = CHUNK if left is None else min(CHUNK, left)
                data = f.read(want) if want > 0 else b""
                self._out.append((peer, M.MAVLink_log_data_message(
                    msg.id, ofs, len(data), list(data.ljust(CHUNK, b"\0")))))
                ofs += len(data)
                if left is not None:
                    left -= len(data)
                if len(data) < CHUNK or left == 0:
                    return
                while len(self._out) > _QUEUE_MAX and gen == self._generation:
                    time.sleep(0.005)
