"""Logs end, processes do not: tuavdefs.logfile.LogFile against a real full device
(/dev/full answers every write with ENOSPC, as a full disk does), a cap, a file that cannot
be opened; guard_stdio on a full stdout; the logs built on it (the truth log, the tlog)."""

from __future__ import annotations

import errno
import io
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tuavdefs.logfile import LogFile, guard_stdio, mb_to_bytes

needs_dev_full = pytest.mark.skipif(not os.path.exists("/dev/full"),
                                    reason="needs /dev/full")


@needs_dev_full
def test_a_full_disk_ends_the_log_once_and_writes_go_on_returning():
    said: list[str] = []
    log = LogFile("/dev/full", name="truth.csv", text=True, append=True, on_end=said.append,
                  flush_s=0.0)
    assert log.write("t_s,x_m\n") is False          # the flush that follows fails
    assert log.ended is not None and os.strerror(errno.ENOSPC) in log.ended
    assert said == [log.ended] and said[0].startswith("truth.csv stopped")
    for _ in range(1000):
        assert log.write("1.0,2.0\n") is False
    log.close()
    assert len(said) == 1


@needs_dev_full
def test_a_buffered_log_ends_when_its_buffer_meets_the_full_disk():
    said: list[str] = []
    log = LogFile("/dev/full", append=True, on_end=said.append, flush_s=3600.0)
    n = 0
    while log.write(b"x" * 100):
        n += 1
        assert n < 10_000, "a buffered file must meet ENOSPC when its buffer fills"
    assert said and log.size_bytes == 100 * n


def test_the_cap_ends_the_log_at_a_whole_write(tmp_path: Path):
    said: list[str] = []
    path = tmp_path / "can.log"
    log = LogFile(path, text=True, max_bytes=mb_to_bytes(0.001), on_end=said.append)
    rows = 0
    while log.write("(1.0) vcan0 123#00\n"):
        rows += 1
    log.close()
    assert path.read_text() == "(1.0) vcan0 123#00\n" * rows   # whole rows, nothing more
    assert 0 < path.stat().st_size <= 1000 < path.stat().st_size + 19
    assert "cap of 0.001 MB" in said[0] and len(said) == 1
    assert mb_to_bytes(None) is None and mb_to_bytes(0) is None


def test_a_log_that_cannot_be_opened_is_said_not_raised(tmp_path: Path):
    said: list[str] = []
    log = LogFile(tmp_path / "no" / "such" / "dir.log", on_end=said.append)
    assert log.write(b"x") is False and "cannot open" in said[0]


@needs_dev_full
def test_a_process_whose_stdout_is_full_prints_on():
    code = ("import sys; from tuavdefs.logfile import guard_stdio; guard_stdio()\n"
            "for i in range(10000): print('line', i, flush=True)\n"
            "sys.stderr.write('x' * 100000); sys.stderr.flush(); print('done')\n")
    with open("/dev/full", "w") as full:
        run = subprocess.run([sys.executable, "-c", code], stdout=full, stderr=full,
                             cwd=Path(__file__).resolve().parents[1], timeout=120)
    assert run.returncode == 0
    with open("/dev/full", "w") as full:   # and without the guard it would have failed
        bare = subprocess.run([sys.executable, "-c", "print('x', flush=True)"],
                              stdout=full, stderr=subprocess.PIPE, timeout=120)
    assert bare.returncode != 0


def test_guard_stdio_keeps_what_can_be_written(monkeypatch):
    out = io.StringIO()
    monkeypatch.setattr(sys, "stdout", out)
    guard_stdio()
    print("kept")
    assert out.getvalue() == "kept\n"


@needs_dev_full
def test_the_tlog_on_a_full_disk_calls_its_end_once():
    from companion.mavlink_io import TelemetryLog

    tlog = TelemetryLog("/dev/full")
    said: list[str] = []
    tlog.on_end = said.append
    for _ in range(2000):
        tlog.write(b"\xfd" + b"\0" * 40)
    tlog.flush()
    tlog.close()
    assert len(said) == 1 and tlog.ended == said[0]


def test_an_onboard_log_that_cannot_be_made_ends_and_the_boot_goes_on(tmp_path: Path):
    """The companion's DataFlash log in a folder that cannot exist (a file is in its way):
    the boot's log object is made, says its end once through the writer, takes records."""
    from companion.flight_log import FlightLog

    blocker = tmp_path / "logs"
    blocker.write_text("a file where the folder should be")
    log = FlightLog(blocker, (47.0, 8.0, 400.0))
    said: list[str] = []
    log.writer.file.on_end = said.append
    log.message("still flying")
    log.close()
    assert log.writer.file.ended is not None and "cannot open" in log.writer.file.ended
