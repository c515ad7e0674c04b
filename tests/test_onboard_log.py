"""The companion's onboard DataFlash log against real plant and companion processes: listed
and downloaded with LOG_REQUEST_LIST / LOG_REQUEST_DATA by pymavlink and by MAVProxy's
`log list` / `log download`, read back by pymavlink's DFReader (mavlogdump's reader). The
truths: the bytes on the companion's disk, the parameters the vehicle serves, the flight
pymavlink saw (its take-off altitude), simulated time between periodic records, a new log
per boot."""

from __future__ import annotations

import shutil
import time

import pytest
from gcs_util import Vehicle, arm, command, wait_msg
from pymavlink import DFReader, mavutil

from companion.flight_log import RATE_HZ
from companion.param_metadata import default_defs

M = mavutil.mavlink


def read_log(path) -> dict[str, list]:
    log = DFReader.DFReader_binary(str(path))
    out: dict[str, list] = {}
    while (msg := log.recv_msg()) is not None:
        out.setdefault(msg.get_type(), []).append(msg)
    return out


def download(m, log_id: int, timeout_s: float = 60.0) -> bytes:
    m.mav.log_request_data_send(1, 1, log_id, 0, 0xFFFFFFFF)
    data = bytearray()
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        d = wait_msg(m, "LOG_DATA", timeout=10)
        assert d is not None and d.id == log_id and d.ofs == len(data)
        data += bytes(d.data[:d.count])
        if d.count < 90:
            return bytes(data)
    raise AssertionError("download did not end")


@pytest.fixture(scope="module")
def flown(tmp_path_factory):
    """A take-off to 6 m and a landing, logged; the link kept for the tests."""
    tmp = tmp_path_factory.mktemp("log")
    veh = Vehicle(tmp, extra=("--log-dir", str(tmp / "logs")))
    try:
        m = veh.connect()
        m.set_mode("GUIDED")
        assert arm(m).result == M.MAV_RESULT_ACCEPTED
        command(m, M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 6)
        assert wait_msg(m, "STATUSTEXT", lambda s: "Takeoff complete" in s.text, 60)
        m.set_mode("LAND")
        assert wait_msg(m, "STATUSTEXT", lambda s: "Disarmed" in s.text, 90)
        time.sleep(0.5)     # the log's writer thread flushes every 0.2 s
        yield {"veh": veh, "m": m, "dir": tmp / "logs", "tmp": tmp}
    finally:
        veh.stop()


def test_log_list_and_download_give_the_bytes_on_disk(flown):
    m, logs = flown["m"], flown["dir"]
    m.mav.log_request_list_send(1, 1, 0, 0xFFFF)
    entry = wait_msg(m, "LOG_ENTRY")
    assert (entry.id, entry.num_logs, entry.last_log_num) == (1, 1, 1)
    assert (logs / "LASTLOG.TXT").read_text().strip() == "1"
    data = download(m, 1)
    on_disk = (logs / "00000001.BIN").read_bytes()
    assert len(data) >= entry.size and on_disk.startswith(data)
    # an unknown log: an empty answer
    m.mav.log_request_data_send(1, 1, 7, 0, 0xFFFFFFFF)
    assert wait_msg(m, "LOG_DATA", lambda d: d.id == 7).count == 0
    (flown["tmp"] / "download.bin").write_bytes(data)


def test_the_log_reads_with_dfreader_and_holds_the_flight(flown):
    rec = read_log(flown["tmp"] / "download.bin")
    parm = {p.Name: p.Value for p in rec["PARM"]}
    assert parm["RTL_ALT"] == 1000 and parm["WPNAV_SPEED"] == 200
    assert len(parm) == len(default_defs())
    texts = [x.Message for x in rec["MSG"]]
    assert "Takeoff complete" in texts and "Landed" in texts
    assert [x.ModeNum for x in rec["MODE"]][-2:] == [4, 9]      # GUIDED, then LAND
    pos = rec["POS"]
    assert 5.7 < max(p.RelHomeAlt for p in pos) < 6.4
    stamps = [a.TimeUS for a in rec["ATT"]]
    steps = {b - a for a, b in zip(stamps, stamps[1:], strict=False)}
    assert max(steps) <= 1e6 / RATE_HZ + 4000 and min(steps) >= 1e6 / RATE_HZ - 4000
    assert {"RATE", "CTUN", "RCOU"} <= set(rec)
    assert max(c.C1 for c in rec["RCOU"]) > 1200


@pytest.mark.skipif(shutil.which("mavproxy.py") is None, reason="MAVProxy is a test extra")
def test_mavproxy_log_list_and_download(flown, tmp_path):
    from test_mavproxy import MavProxy

    mp = MavProxy(flown["veh"].tcp_port, tmp_path)
    try:
        mp.wait_for("online system 1")
        line = mp.say("log list", "numLogs 1")
        assert "Log 1" in line
        out = tmp_path / "mp.bin"
        mp.say(f"log download 1 {out}", "Finished downloading", timeout_s=120)
    finally:
        mp.close()
    assert (flown["dir"] / "00000001.BIN").read_bytes().startswith(out.read_bytes())
    assert "PARM" in read_log(out)


def test_a_reboot_starts_the_next_log(flown):
    m = flown["m"]
    assert command(m, M.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, 1).result == M.MAV_RESULT_ACCEPTED
    end = time.monotonic() + 10
    while not (flown["dir"] / "00000002.BIN").exists():
        assert time.monotonic() < end
        time.sleep(0.1)
    m.mav.log_request_list_send(1, 1, 0, 0xFFFF)
    entries = [wait_msg(m, "LOG_ENTRY"), wait_msg(m, "LOG_ENTRY")]
    assert [e.id for e in entries] == [1, 2] and entries[0].num_logs == 2
