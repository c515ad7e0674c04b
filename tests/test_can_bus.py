"""The winder's CAN bus between real processes: a CAN host (standing in for the ground
station) drives the plant's simulated ODrive axis over python-can's udp_multicast bus,
inside a private network namespace (the suite creates it itself when run as root). Also
the udp_multicast wire format of :class:`tuavdefs.canbus.WireCodec` against python-can's
and msgpack's own, and the kernel's socket filter that drops a link's own datagrams."""

import math
import struct

import can
import msgpack
import pytest
from can.interfaces.udp_multicast.utils import pack_message
from hypothesis import given, settings
from hypothesis import strategies as st
from netns_util import netns_available, run_session

from tuavdefs.can_protocol import ODriveError
from tuavdefs.canbus import WireCodec, drop_source_port_filter

needs_netns = pytest.mark.skipif(not netns_available(),
                                 reason="needs root (unshare) for a private network namespace")


@pytest.fixture(scope="module")
def session() -> dict:
    if not netns_available():
        pytest.skip("needs root (unshare) for a private network namespace")
    return run_session("tests.netns.can_axis_session", timeout_s=180)


def test_axis_reports_idle_with_the_brake_on_and_streams_at_its_rates(session):
    assert "winder on CAN udp_multicast" in session["ready"]
    assert session["idle_state"] == 1
    assert session["brake_when_idle"] is True
    # Get_Encoder_Estimates every 10 ms, Heartbeat every 100 ms (of simulated time)
    assert session["heartbeats_seen"] >= 10
    assert session["encoders_per_heartbeat"] == pytest.approx(10.0, abs=0.5)


def test_closed_loop_torque_moves_the_drum(session):
    assert session["closed_loop_state"] == 8
    assert session["brake_in_closed_loop"] is False
    assert session["paid_out_m"] > 0.5                      # +0.6 N m pays line out
    assert session["encoder_vel_rev_s"] > 0.5


def test_torque_limit_and_bad_frames(session):
    torques = session["torques_dbc"]                        # decoded by cantools from the DBC
    assert torques["Torque_Target"] == pytest.approx(4.0)   # 100 N m asked, clamped to 4
    assert session["target_after_bad"] == pytest.approx(0.6, abs=1e-6)


def test_watchdog_trips_and_needs_clear_errors(session):
    assert session["after_silence_state"] == 1
    assert session["after_silence_error"] & ODriveError.WATCHDOG_TIMER_EXPIRED
    assert session["brake_after_trip"] is True
    assert session["rearm_without_clear_state"] == 1
    assert session["recovered_state"] == 8
    assert session["recovered_error"] == 0


def test_a_process_never_sees_its_own_frames(session):
    assert session["own_frames_dropped"] > 50
    assert session["host_saw_own_frames"] is False
    assert "0 bad frames" in session["plant_out"]


# ----------------------------------------------------------------------- the wire format

#: ids at every msgpack integer size (fixint, uint8, uint16, uint32) and the CAN limits
IDS = (0, 1, 0x7F, 0x80, 0xFF, 0x100, 0x7FF, 0x800, 0xFFFF, 0x10000, 0x1ABCDE, 0x1FFFFFFF)


def python_can_bytes(frame_id: int, data: bytes, remote: bool, dlc: int, extended: bool,
                     timestamp: float = 0.0, **extra: object) -> bytes:
    """What python-can's udp_multicast bus sends for this frame."""
    return pack_message(can.Message(
        timestamp=timestamp, arbitration_id=frame_id, is_extended_id=extended,
        is_remote_frame=remote, dlc=dlc, data=None if remote else data, check=False,
        **extra))


def general(raw: bytes) -> tuple | None:
    """msgpack's decoding and the checks alone (a codec that has learnt nothing)."""
    return WireCodec()._decode_map(raw)


def test_encoding_is_python_cans_for_every_id_size_flag_and_length():
    codec = WireCodec()
    cases = [(i, bytes(range(n)), False, n, ext) for i in IDS for n in (0, 1, 2, 7, 8)
             for ext in (False, True)]
    cases += [(i, b"", True, dlc, ext) for i in IDS for dlc in (0, 1, 8) for ext in (False, True)]
    cases += [(0x123, bytes(64), False, 64, False), (0x123, b"\x01\x02", False, 5, False)]
    for _ in range(2):                                   # worked out, then from the cache
        for frame_id, data, remote, dlc, ext in cases:
            raw = codec.encode(frame_id, data, remote, dlc, ext)
            assert raw == python_can_bytes(frame_id, data, remote, dlc, ext)
            assert raw == msgpack.packb({
                "timestamp": 0.0, "arbitration_id": frame_id, "is_extended_id": ext,
                "is_remote_frame": remote, "is_error_frame": False, "channel": None,
                "dlc": dlc, "data": data, "is_fd": False, "bitrate_switch": False,
                "error_state_indicator": False}, use_bin_type=True)


def test_decoding_known_layouts_matches_msgpacks():
    codec = WireCodec()
    for frame_id in IDS:
        for data, remote, dlc in ((b"\x01\x02\x03", False, 3), (bytes(8), False, 8),
                                  (b"", True, 8), (b"", False, 0)):
            for stamp in (0.0, 1.7e9, math.nan):
                raw = python_can_bytes(frame_id, data, remote, dlc, frame_id > 0x7FF, stamp)
                expected = general(raw)
                assert expected == (frame_id, bytes(dlc) if remote else data, remote,
                                    frame_id > 0x7FF)
                assert codec.decode(raw) == expected             # learns the layout
                assert codec.decode(raw) == expected             # from the layout
    assert len(codec._known) == len(IDS) * 4


def test_what_the_checks_refuse_is_refused_from_a_known_layout_too():
    codec = WireCodec()
    codec.decode(codec.encode(0x29, bytes(8), False, 8, False))
    refused = [
        python_can_bytes(0x29, bytes(8), False, 8, False, is_error_frame=True),
        python_can_bytes(0x29, bytes(7), False, 8, False),            # payload != DLC
        python_can_bytes(0x29, bytes(8), False, 65, False),           # DLC beyond 64
        codec.encode(0x29, bytes(8), False, 8, False)[:-1],           # truncated
        b"\x01\x02", b"", msgpack.packb([1, 2, 3]),
    ]
    for raw in refused:
        assert general(raw) is None
        assert codec.decode(raw) is None
    # FD frames, a channel or a 32-bit timestamp are not our layout: decoded by msgpack
    for raw in (python_can_bytes(0x29, bytes(12), False, 12, False, is_fd=True),
                python_can_bytes(0x29, bytes(8), False, 8, False, channel="vcan0"),
                codec.encode(0x29, bytes(8), False, 8, False).replace(
                    b"\xcb" + bytes(8), b"\xca" + bytes(4), 1)):
        assert codec.decode(raw) == general(raw) is not None


def test_odd_maps_msgpack_accepts_are_accepted():
    codec = WireCodec()
    base = {"timestamp": 0.0, "arbitration_id": 0x29, "is_extended_id": False,
            "is_remote_frame": False, "is_error_frame": False, "channel": None, "dlc": 1,
            "data": b"\x05", "is_fd": False, "bitrate_switch": False,
            "error_state_indicator": False}
    remote = {k: v for k, v in base.items() if k != "data"} | {"is_remote_frame": True}
    for m in (base | {"arbitration_id": 1e30}, base | {"dlc": 1.0}, remote,
              base | {"data": [5]}):
        raw = msgpack.packb(m, use_bin_type=True)
        assert codec.decode(raw) == general(raw) is not None
        assert codec.decode(raw) == general(raw)


def test_the_data_key_inside_a_payload_or_a_64_bit_id_fools_nothing():
    marker = msgpack.packb("data") + b"\xc4"
    codec = WireCodec()
    tricky = [python_can_bytes(0x29, marker + b"\x02", False, 7, False),
              python_can_bytes(0x29, b"\x00" + marker + b"\x00", False, 8, False)]
    big_id = int.from_bytes(b"\x00" + marker + b"\x01", "big")     # a uint64 holding it
    raw = msgpack.packb({"timestamp": 0.0, "arbitration_id": big_id, "is_extended_id": True,
                         "is_remote_frame": False, "is_error_frame": False, "channel": None,
                         "dlc": 1, "data": b"\x05", "is_fd": False, "bitrate_switch": False,
                         "error_state_indicator": False}, use_bin_type=True)
    tricky += [raw, raw.replace(b"\xa3dlc\x01", b"\xa3dlc\x02", 1)]
    for _ in range(2):
        for raw in tricky:
            assert codec.decode(raw) == general(raw)


frames = st.tuples(st.sampled_from(IDS), st.binary(max_size=8), st.booleans(),
                   st.booleans(), st.floats(allow_nan=False) | st.just(0.0))


@settings(max_examples=300, deadline=None)
@given(st.lists(frames, min_size=1, max_size=4), st.data())
def test_decoding_equals_msgpacks_for_mutated_datagrams(sent, draw):
    codec = WireCodec()
    for frame_id, data, remote, ext, stamp in sent:
        raw = python_can_bytes(frame_id, b"" if remote else data, remote, len(data), ext,
                               stamp)
        assert codec.decode(raw) == general(raw)
        # damage it: cut, extend, or change one byte
        cut = draw.draw(st.integers(0, len(raw)))
        pos = draw.draw(st.integers(0, len(raw) - 1))
        byte = draw.draw(st.integers(0, 255))
        for bad in (raw[:cut], raw + raw[cut:], raw[:pos] + bytes((byte,)) + raw[pos + 1:]):
            assert codec.decode(bad) == general(bad)


def test_the_socket_filter_program():
    insns = list(struct.iter_unpack("=HBBI", drop_source_port_filter(43113)))
    assert insns == [(0x28, 0, 0, 0), (0x15, 0, 1, 43113), (0x06, 0, 0, 0),
                     (0x06, 0, 0, 0xFFFFFFFF)]


@needs_netns
def test_the_kernel_drops_own_datagrams_by_their_source_port():
    out = run_session("tests.netns.can_filter_session", timeout_s=120)
    assert out["filter_attached"] is True
    # the filter looks at the UDP source port: a socket filtering another link's port
    # never sees that link's frames, and sees the others'
    assert out["filtered_socket_got"] == ["from a"]
    # a link's own frames never reach it; the kernel counted them
    assert out["a_got"] == ["from b"] and out["a_user_dropped"] == 0
    assert out["a_own_dropped"] == 3
    # without the filter (a kernel that refuses it) the same frames, dropped here
    assert out["fallback_filter"] is False
    assert out["fallback_got"] == ["from b"] and out["fallback_own_dropped"] == 2
    # a recorder's receive buffer (root may exceed rmem_max): 3000 unread frames all kept,
    # in order, where the default buffer drops some
    assert out["burst_granted"] >= 4 * 1024 * 1024
    assert out["burst_big_got"] == list(range(3000))
    assert out["burst_small_got"] < 3000
