"""candump output formats (tuav_sitl.candump_format): known lines, round trips, and
cross-checks with cantools and, where installed, can-utils' own converters."""

import random
import shutil
import subprocess
import sys

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sitl.odrive_axis import OdriveAxis, WinchSensors
from tuav_sitl.candump_format import (
    format_default,
    format_log,
    format_timestamp,
    iface_width,
    parse_log_frame,
    parse_log_line,
)
from tuavdefs import can_protocol as cp

TORQUE_1 = bytes.fromhex("0000803F00000000")


@pytest.mark.parametrize(
    "args, kw, line",
    [
        (("vcan0", 0x00E, TORQUE_1, False, False, 5), {},
         "  vcan0  00E   [8]  00 00 80 3F 00 00 00 00"),
        (("vcan0", 0x009, bytes(8), True, False, 5), {}, "  vcan0  009   [8]  remote request"),
        (("vcan0", 0x009, b"", True, False, 5), {}, "  vcan0  009   [0]  remote request"),
        (("vcan0", 0x002, b"", False, False, 5), {}, "  vcan0  002   [0] "),
        (("vcan0", 0x7FF, b"\xab", False, False, 5), {}, "  vcan0  7FF   [1]  AB"),
        (("vcan0", 0x12345678, bytes.fromhex("DEADBEEF"), False, True, 5), {},
         "  vcan0  12345678   [4]  DE AD BE EF"),
        (("vcan0", 0x1ABCDEF0, bytes(4), True, True, 5), {},
         "  vcan0  1ABCDEF0   [4]  remote request"),
        (("vcan0", 0x00000001, b"", False, True, 5), {}, "  vcan0  00000001   [0] "),
        # interface names right-aligned to the longest one candump opened
        (("can0", 0x123, b"\xff", False, False, 6), {}, "    can0  123   [1]  FF"),
        (("vcan12", 0x123, b"\xff", False, False, 6), {}, "  vcan12  123   [1]  FF"),
        (("can0", 0x123, b"\xff", False, False, 0), {}, "  can0  123   [1]  FF"),
        # after an extended frame candump indents standard ids
        (("vcan0", 0x00E, TORQUE_1, False, False, 5), {"indent_sff": True},
         "  vcan0       00E   [8]  00 00 80 3F 00 00 00 00"),
        (("vcan0", 0x12345678, b"\x01", False, True, 5), {"indent_sff": True},
         "  vcan0  12345678   [1]  01"),
        # -ta
        (("vcan0", 0x00E, b"\x01\x02", False, False, 5), {"timestamp_s": 1700000000.123456},
         " (1700000000.123456)  vcan0  00E   [2]  01 02"),
    ],
)
def test_default_format_known_lines(args, kw, line):
    assert format_default(*args, **kw) == line


@pytest.mark.parametrize(
    "args, kw, line",
    [
        ((1700000000.123456, "vcan0", 0x00E, TORQUE_1), {},
         "(1700000000.123456) vcan0 00E#0000803F00000000"),
        ((1700000000.123456, "vcan0", 0x009, bytes(8), True), {},
         "(1700000000.123456) vcan0 009#R8"),
        ((1700000000.123456, "vcan0", 0x009, bytes(2), True), {},
         "(1700000000.123456) vcan0 009#R2"),
        ((1700000000.123456, "vcan0", 0x009, b"", True), {}, "(1700000000.123456) vcan0 009#R"),
        ((1700000000.123456, "vcan0", 0x002, b""), {}, "(1700000000.123456) vcan0 002#"),
        ((1700000000.0, "can0", 0x12345678, bytes.fromhex("deadbeef"), False, True), {},
         "(1700000000.000000) can0 12345678#DEADBEEF"),
        ((1700000000.0, "can0", 0x1ABCDEF0, bytes(4), True, True), {},
         "(1700000000.000000) can0 1ABCDEF0#R4"),
        ((12.5, "vcan0", 0x601, b"\x03\x07"), {}, "(0000000012.500000) vcan0 601#0307"),
        ((0.0000004, "vcan0", 0x601, b"\x03\x07"), {}, "(0000000000.000000) vcan0 601#0307"),
        ((12.5, "can0", 0x601, b""), {"iface_width": 6}, "(0000000012.500000)   can0 601#"),
        ((12.5, "can0", 0x601, b""), {"use_ns": True}, "(0000000012.500000000) can0 601#"),
    ],
)
def test_log_format_known_lines(args, kw, line):
    assert format_log(*args, **kw) == line


def test_bad_frames_are_refused():
    for bad in [(0x800, b"", False), (0x20000000, b"", True), (0x1, bytes(9), False)]:
        with pytest.raises(ValueError):
            format_log(0.0, "vcan0", bad[0], bad[1], False, bad[2])
        with pytest.raises(ValueError):
            format_default("vcan0", bad[0], bad[1], False, bad[2], 5)
    with pytest.raises(ValueError):
        format_timestamp(-1.0)
    assert iface_width(["can0", "vcan12", "x"]) == 6 and iface_width([]) == 0


def test_parse_known_lines():
    assert parse_log_line("(1700000000.123456) vcan0 00E#0000803F00000000") == (
        1700000000.123456, "vcan0", 0x00E, TORQUE_1, False)
    assert parse_log_line("(1700000000.123456) vcan0 009#R8\n") == (
        1700000000.123456, "vcan0", 0x009, bytes(8), True)
    assert parse_log_line("(1700000000.123456) vcan0 009#R") == (
        1700000000.123456, "vcan0", 0x009, b"", True)
    assert parse_log_line("(1700000000.123456) vcan0 002#").data == b""
    # python-can's logger and candump -x append a direction flag
    assert parse_log_line("(1.000000) vcan0 123#0102 R").data == b"\x01\x02"
    assert parse_log_line("(1.000000) vcan0 123#0102 T").data == b"\x01\x02"
    # right-aligned interface, cansend-style dots, a raw DLC suffix, 9-digit timestamps
    assert parse_log_line("(1.000000)   can0 123#01.02").interface == "can0"
    assert parse_log_line("(1.000000) can0 123#01.02").data == b"\x01\x02"
    assert parse_log_line("(1.000000) can0 123#0102030405060708_9").data == bytes(range(1, 9))
    assert parse_log_line("(1.123456789) can0 123#").timestamp == 1.123456789
    ext = parse_log_frame("(1.000000) can0 00000123#AA")
    assert ext.is_extended and ext.arbitration_id == 0x123
    assert not parse_log_frame("(1.000000) can0 123#AA").is_extended


@pytest.mark.parametrize("line", [
    "", "garbage", "(1.0) vcan0 0123#00", "(1.0) vcan0 12#00", "(1.0) vcan0 800#00",
    "(1.0) vcan0 123#0", "(1.0) vcan0 123#XY", "(1.0) vcan0 123##1001122",
    "(1.0) vcan0 123#001122334455667788", "(1.0) vcan0 20000001#00", "(1.0) vcan0 123#R9",
    "1.0 vcan0 123#00", "  vcan0  00E   [8]  00 00 80 3F 00 00 00 00",
])
def test_parse_rejects(line):
    with pytest.raises(ValueError):
        parse_log_line(line)


frames = st.one_of(
    st.tuples(st.integers(0, 0x7FF), st.just(False)),
    st.tuples(st.integers(0, 0x1FFFFFFF), st.just(True)),
).flatmap(lambda ide: st.tuples(st.just(ide[0]), st.just(ide[1]), st.binary(max_size=8),
                                st.booleans()))


@settings(max_examples=400, deadline=None)
@given(frame=frames, us=st.integers(0, 4_000_000_000 * 1_000_000),
       iface=st.sampled_from(["vcan0", "can0", "can1", "vcan12", "slcan0"]),
       width=st.integers(0, 8))
def test_log_round_trip(frame, us, iface, width):
    arbitration_id, is_extended, data, is_remote = frame
    if is_remote:
        data = bytes(len(data))  # only the DLC of a remote frame is meaningful
    ts = us / 1_000_000
    line = format_log(ts, iface, arbitration_id, data, is_remote, is_extended,
                      iface_width=width)
    assert line.startswith(f"({us // 1_000_000:010d}.{us % 1_000_000:06d}) ")
    parsed = parse_log_frame(line)
    assert parsed == (float(f"{us // 1_000_000}.{us % 1_000_000:06d}"), iface, arbitration_id,
                      data, is_remote, is_extended)
    assert parse_log_line(line) == parsed[:5]


def _bus_log(n_ms: int = 300) -> list[str]:
    """candump -L lines of a short simulated exchange: the axis armed in torque mode, the
    winch sensors, a few host commands."""
    axis, sensors = OdriveAxis(torque_constant_nm_a=0.1), WinchSensors()
    lines = []

    def log(t, frame_id, data, rtr=False):
        lines.append(format_log(1700000000.0 + t, "vcan0", frame_id, data, rtr))

    for fid, data in [(0x00B, cp.encode_set_controller_mode(1, 1)),
                      (0x007, cp.encode_set_axis_state(8)),
                      (0x00E, cp.encode_set_input_torque(1.5))]:
        log(0.0, fid, data)
        axis.handle(0.0, fid, data, False)
    for k in range(n_ms):
        t = k / 1000
        if k % 50 == 0:
            data = cp.encode_set_input_torque(1.5)
            axis.handle(t, 0x00E, data, False)
            log(t, 0x00E, data)
        for f in axis.tick(t, 2.0 + t, 0.5, 1.25, 48.0):
            log(t, *f)
        for f in sensors.tick(t, 30.0, 0.25, 123.5, False, False, False):
            log(t, *f)
    return lines


def test_cantools_decodes_our_log_lines():
    lines = _bus_log()
    proc = subprocess.run([sys.executable, "-m", "cantools", "decode", str(cp.dbc_path())],
                          input="\n".join(lines) + "\n", capture_output=True, text=True,
                          timeout=120, check=True)
    out = proc.stdout
    assert "Unknown frame id" not in out and "Wrong data size" not in out
    for needle in ["Set_Controller_Mode(", "Control_Mode: TORQUE", "Input_Mode: PASSTHROUGH",
                   "Axis_Requested_State: CLOSED_LOOP_CONTROL", "Input_Torque: 1.5 Nm",
                   "Axis_State: CLOSED_LOOP_CONTROL", "Procedure_Result: BUSY",
                   "Pos_Estimate: 2.0 rev", "Vel_Estimate: 0.5 rev/s",
                   "Line_Length: 30.0 m", "Line_Speed: 0.25 m/s", "Tension: 123.5 N",
                   "Load_Cell_Healthy: 1"]:
        assert needle in out, needle
    assert out.count("\nHeartbeat(") == 3 and out.count("\nWinch_Heartbeat(") == 3
    assert out.count("\nWinch_Tension(") == 30 and out.count("\nGet_Encoder_Estimates(") == 30


def _random_frames(n: int, seed: int = 7):
    rng = random.Random(seed)
    out = []
    for k in range(n):
        ext = rng.random() < 0.3
        fid = rng.randrange(0x20000000 if ext else 0x800)
        dlc = rng.randrange(9)
        rtr = rng.random() < 0.2
        data = bytes(dlc) if rtr else bytes(rng.randrange(256) for _ in range(dlc))
        out.append((1700000000.0 + k * 0.001, fid, data, rtr, ext))
    return out


@pytest.mark.skipif(shutil.which("log2long") is None, reason="can-utils not installed")
def test_default_format_matches_can_utils_log2long():
    """log2long prints each log line with can-utils' own long formatter (the one candump's
    default output uses), with extended-id indentation and an ASCII column on."""
    frames = _random_frames(300)
    log = "".join(format_log(ts, "vcan0", fid, d, r, e) + "\n" for ts, fid, d, r, e in frames)
    proc = subprocess.run(["log2long"], input=log, capture_output=True, text=True, timeout=60,
                          check=True)
    got = proc.stdout.splitlines()
    assert len(got) == len(frames)
    for line, (ts, fid, data, rtr, ext) in zip(got, frames, strict=True):
        ours = format_default("vcan0", fid, data, rtr, ext, 5, indent_sff=True)
        # log2long: "<(timestamp)>  <iface>  <frame>" + an ASCII column for data frames
        frame_part = line[len(format_timestamp(ts)) + 2:]
        if not rtr:
            ascii_len = 3 * (8 - len(data)) + 4 + len(data) + 1
            frame_part = frame_part[:-ascii_len]
        assert ours == "  " + frame_part


@pytest.mark.skipif(shutil.which("log2asc") is None or shutil.which("asc2log") is None,
                    reason="can-utils not installed")
def test_log_format_round_trips_through_can_utils():
    """log2asc parses our lines with can-utils' parser; asc2log prints them back with the
    formatter candump -L uses: the frame fields must come back identical."""
    frames = _random_frames(300, seed=11)
    ours = [format_log(ts, "vcan0", fid, d, r, e) for ts, fid, d, r, e in frames]
    asc = subprocess.run(["log2asc", "vcan0"], input="\n".join(ours) + "\n",
                         capture_output=True, text=True, timeout=60, check=True).stdout
    back = subprocess.run(["asc2log"], input=asc, capture_output=True, text=True, timeout=60,
                          check=True).stdout.splitlines()
    assert len(back) == len(ours)
    for theirs, mine in zip(back, ours, strict=True):
        assert theirs.split()[2] == mine.split()[2]


def test_the_recorder_skips_a_datagram_no_can_frame_can_be(tmp_path, capsys):
    """A standard frame with id 0x800 (no 11-bit id) on the bus: the recorder says so on
    stderr and goes on; the valid frames before and after it are logged (on python-can's
    in-process virtual bus)."""
    import argparse
    import signal
    import threading
    import time

    from tuav_sitl.candump import add_arguments, run_candump
    from tuavdefs.canbus import CanLink

    ap = argparse.ArgumentParser()
    add_arguments(ap)
    log = tmp_path / "can.log"
    args = ap.parse_args(["--can", "virtual:bad-frame-test", "--count", "2", "--log",
                          str(log), "--timeout", "5"])
    sender = CanLink("virtual:bad-frame-test")

    def send() -> None:
        time.sleep(0.3)
        sender.send(0x123, b"\x01\x02")
        sender.send(0x800, b"\x03")             # no CAN frame has this id
        sender.send(0x124, b"\x04")

    t = threading.Thread(target=send, daemon=True)
    t.start()
    handlers = {sig: signal.getsignal(sig) for sig in (signal.SIGTERM, signal.SIGINT)}
    try:
        assert run_candump(args) == 0          # (the recorder in the main thread: signals)
    finally:
        # its handlers would outlive it in this process (and in the pools forked later)
        for sig, handler in handlers.items():
            signal.signal(sig, handler)
    t.join(timeout=10)
    sender.close()
    lines = log.read_text().splitlines()
    assert [ln.split()[2] for ln in lines] == ["123#0102", "124#04"]
    assert "bad frame" in capsys.readouterr().err
