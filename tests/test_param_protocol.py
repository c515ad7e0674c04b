"""The companion's parameter micro-service against real pymavlink messages.

Requests are packed by a GCS-side pymavlink encoder (255/190) and parsed back, replies are
packed as system 1 / component 1 and parsed by the GCS side. The truths: the MAVLink
parameter-protocol rules (indices, counts, broadcast of accepted values), ArduPilot's
behaviour (silence for unknown names and indices, numeric "C cast" values, the ``.parm``
file), the MAVLink FTP header layout decoded byte by byte as the FTP specification defines it,
the bounds of ``FlightControlParams``, and a real ``pymavlink.mavutil`` client over UDP.
"""

from __future__ import annotations

import dataclasses
import math
import os
import socket
import struct
import threading
import time
from decimal import ROUND_CEILING, ROUND_FLOOR, Decimal

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink2

from companion.gains import FlightControlParams
from companion.param_protocol import ParamDef, ParamProtocol, params_to_defs

GCS_SYS, GCS_COMP = 255, 190
PEER = ("tcp", 3)
OTHER = ("udp", ("127.0.0.1", 14550))
REAL32 = mavlink2.MAV_PARAM_TYPE_REAL32
INT8 = mavlink2.MAV_PARAM_TYPE_INT8
INT32 = mavlink2.MAV_PARAM_TYPE_INT32

FC_NAMES = {
    "rate_hz": "FC_RATE_HZ",
    "pos_k1_1_s": "FC_POS_K1",
    "pos_k2_1_s": "FC_POS_K2",
    "disturbance_gain_1_s2": "FC_DIST_GAIN",
    "disturbance_limit_m_s2": "FC_DIST_LIM",
    "max_tilt_rad": "FC_MAX_TILT",
    "max_thrust_fraction": "FC_MAX_THR",
    "att_k3_1_s": "FC_ATT_K3",
    "att_k4_n_m_s": "FC_ATT_K4",
    "att_disturbance_gain_n_m_rad": "FC_ATT_DIST_G",
    "att_disturbance_limit_n_m": "FC_ATT_DIST_LIM",
    "command_filter_hz": "FC_CMDF_HZ",
    "command_filter_damping": "FC_CMDF_DAMP",
    "command_filter_pole_hz": "FC_CMDF_POLE",
    "use_tether_model": "FC_USE_TETHER",
    "use_measured_tension": "FC_USE_TENSION",
}


def f32(x: float) -> float:
    return struct.unpack("<f", struct.pack("<f", x))[0]


def wire(msg, src_system: int = GCS_SYS, src_component: int = GCS_COMP):
    packer = mavlink2.MAVLink(None, srcSystem=src_system, srcComponent=src_component)
    out = mavlink2.MAVLink(None).parse_buffer(msg.pack(packer))
    assert out is not None and len(out) == 1
    return out[0]


class Vehicle:
    """FlightControlParams served by a ParamProtocol, with recording callbacks."""

    def __init__(self, persist_path=None, params=None, **kw):
        self.sent: list[tuple[object, object]] = []
        self.texts: list[tuple[int, str]] = []
        self.instances: list[FlightControlParams] = []
        self.defs = params_to_defs(params or FlightControlParams(), FC_NAMES,
                                   self.instances.append)
        self.proto = ParamProtocol(self.defs, self._send, self._text,
                                   persist_path=persist_path, **kw)

    def _send(self, peer, msg):
        self.sent.append((peer, wire(msg, 1, 1)))

    def _text(self, severity, text):
        assert len(text) <= 50
        self.texts.append((severity, text))

    def rx(self, msg, peer=PEER, now=0.0) -> bool:
        return self.proto.handle(peer, wire(msg), now)

    def take(self):
        out, self.sent = self.sent, []
        return out

    def set(self, name: str, value: float, peer=PEER):
        return self.rx(mavlink2.MAVLink_param_set_message(1, 1, name.encode(), value, REAL32),
                       peer)

    @property
    def current(self) -> FlightControlParams:
        return self.instances[-1] if self.instances else FlightControlParams()


def n_params() -> int:
    values = dataclasses.astuple(FlightControlParams())
    return sum(len(v) if isinstance(v, tuple) else 1 for v in values)


# ------------------------------------------------------------- params_to_defs
def test_params_to_defs_covers_every_field_of_flight_control_params():
    v = Vehicle()
    names = [d.name for d in v.defs]
    assert len(names) == n_params() == 28
    assert len(set(names)) == len(names)
    assert all(len(n) <= 16 and n.isascii() and n == n.upper() for n in names)
    p = FlightControlParams()
    by_name = {d.name: d for d in v.defs}
    for f in dataclasses.fields(p):
        value = getattr(p, f.name)
        base = FC_NAMES[f.name]
        if isinstance(value, tuple):
            for axis, element in zip("XYZ", value, strict=True):
                d = by_name[f"{base}_{axis}"]
                assert d.get() == element and d.param_type == REAL32
                assert d.unit == f.metadata["unit"]
        elif isinstance(value, bool):
            assert by_name[base].param_type == INT8 and by_name[base].get() == 1.0
        else:
            assert by_name[base].param_type == REAL32 and by_name[base].get() == value
            assert by_name[base].description == f.metadata["doc"]


def test_setting_a_k1_element_changes_exactly_that_element():
    v = Vehicle()
    d = {d.name: d for d in v.defs}["FC_POS_K1_Y"]
    assert d.set(2.25) is None
    new = v.instances[-1]
    old = FlightControlParams()
    assert new.pos_k1_1_s == (old.pos_k1_1_s[0], 2.25, old.pos_k1_1_s[2])
    changed = [f.name for f in dataclasses.fields(old)
               if getattr(old, f.name) != getattr(new, f.name)]
    assert changed == ["pos_k1_1_s"]
    # later sets build on the current instance, not the original one
    assert {d.name: d for d in v.defs}["FC_POS_K1_Z"].set(3.0) is None
    assert v.instances[-1].pos_k1_1_s == (old.pos_k1_1_s[0], 2.25, 3.0)


def test_paramspec_bounds_refuse_and_keep_the_instance():
    v = Vehicle()
    by = {d.name: d for d in v.defs}
    assert by["FC_POS_K1_X"].set(0.0) == "must be > 0 1/s, got 0.0"
    assert by["FC_MAX_THR"].set(1.5) == "must be <= 1, got 1.5"
    assert by["FC_USE_TETHER"].set(2.0) == "must be 0 or 1"
    assert v.instances == []
    assert by["FC_USE_TETHER"].set(0.0) is None
    assert v.instances[-1].use_tether_model is False and by["FC_USE_TETHER"].get() == 0.0


def test_params_to_defs_rejects_bad_name_maps():
    p = FlightControlParams()
    with pytest.raises(ValueError, match="rate_hz"):
        params_to_defs(p, {k: v for k, v in FC_NAMES.items() if k != "rate_hz"}, print)
    with pytest.raises(ValueError, match="no_such_field"):
        params_to_defs(p, {**FC_NAMES, "no_such_field": "FC_X"}, print)
    with pytest.raises(ValueError, match="16"):
        params_to_defs(p, {**FC_NAMES, "disturbance_gain_1_s2": "FC_DISTURB_GAIN"}, print)
    with pytest.raises(ValueError):
        params_to_defs(p, {**FC_NAMES, "rate_hz": "fc_rate"}, print)


def test_int_fields_and_long_tuples():
    @dataclasses.dataclass(frozen=True)
    class Demo(FlightControlParams):
        count: int = dataclasses.field(default=3, metadata={"unit": "1", "doc": "n",
                                                             "ge": 0, "le": 10})
        taps: tuple[float, ...] = dataclasses.field(default=(0.1, 0.2, 0.3, 0.4),
                                                    metadata={"unit": "1", "doc": "t"})

    seen = []
    defs = params_to_defs(Demo(), {**FC_NAMES, "count": "DEMO_N", "taps": "DEMO_TAP"},
                          seen.append)
    by = {d.name: d for d in defs}
    assert [n for n in by if n.startswith("DEMO_TAP")] == [f"DEMO_TAP_{i}" for i in range(1, 5)]
    assert by["DEMO_N"].param_type == INT32
    assert by["DEMO_N"].set(2.5) == "must be an integer"
    assert by["DEMO_N"].set(11.0) == "must be <= 10, got 11"
    assert by["DEMO_N"].set(7.0) is None and seen[-1].count == 7
    assert by["DEMO_TAP_4"].set(-1.0) is None and seen[-1].taps == (0.1, 0.2, 0.3, -1.0)


def test_param_def_names_are_checked():
    for bad in ("", "lower", "1ABC", "WITH SPACE", "A" * 17, "ÄÖ"):
        with pytest.raises(ValueError):
            ParamDef(bad, REAL32, lambda: 0.0, lambda v: None)
    with pytest.raises(ValueError):
        ParamDef("OK", 42, lambda: 0.0, lambda v: None)
    ParamDef("A" * 16, REAL32, lambda: 0.0, lambda v: None)
    with pytest.raises(ValueError, match="duplicate"):
        ParamProtocol([ParamDef("A", REAL32, lambda: 0.0, lambda v: None)] * 2,
                      lambda p, m: None, lambda s, t: None)


# ---------------------------------------------------------------------- list
def collect_list(v: Vehicle, peer=PEER, t0=0.0, dt=0.02, limit_s=5.0):
    v.rx(mavlink2.MAVLink_param_request_list_message(1, 1), peer, t0)
    got = v.take()
    first_burst = len(got)
    t = t0
    while v.proto.streaming and t < t0 + limit_s:
        t += dt
        v.proto.tick(t)
        got += v.take()
    return got, first_burst, t - t0


def test_list_sends_every_parameter_once_with_index_and_count():
    v = Vehicle()
    got, first_burst, _ = collect_list(v)
    n = n_params()
    assert len(got) == n
    assert all(p == PEER for p, _ in got)
    msgs = [m for _, m in got]
    assert all(m.get_type() == "PARAM_VALUE" for m in msgs)
    assert sorted(m.param_index for m in msgs) == list(range(n))
    assert {m.param_count for m in msgs} == {n}
    by_index = {d.name: i for i, d in enumerate(v.defs)}
    for m in msgs:
        assert by_index[m.param_id] == m.param_index
        d = v.defs[m.param_index]
        assert m.param_type == d.param_type
        assert m.param_value == f32(d.get())  # the numeric value ("C cast"), not bytes
        assert (m.get_srcSystem(), m.get_srcComponent()) == (1, 1)
    assert first_burst == v.proto.stream_burst == 20


def test_list_is_paced_and_restarts_on_a_new_request():
    many = [ParamDef(f"P{i:04d}", REAL32, (lambda i=i: float(i)), lambda x: None)
            for i in range(1000)]
    sent = []
    proto = ParamProtocol(many, lambda p, m: sent.append((p, m)), lambda s, t: None,
                          stream_rate_hz=512.0, stream_burst=25)
    proto.handle(PEER, wire(mavlink2.MAVLink_param_request_list_message(1, 1)), 10.0)
    assert len(sent) == 25
    proto.tick(10.0 + 1 / 64)  # 1/64 s at 512/s: 8 more
    assert len(sent) == 33
    proto.tick(11.0)  # a long gap refills at most one burst
    assert len(sent) == 58
    # asked again while it streams: from index 0, on the bucket the peer has (empty now),
    # however often it asks
    for _ in range(100):
        proto.handle(PEER, wire(mavlink2.MAVLink_param_request_list_message(1, 1)), 11.0)
    assert len(sent) == 58
    t = 11.0
    while proto.streaming:
        t += 0.01
        proto.tick(t)
    tail = [m.param_index for _, m in sent[58:]]
    assert tail == list(range(1000))  # restarted at index 0, none skipped
    assert t - 11.0 == pytest.approx(1000 / 512.0, abs=0.02)
    # a list asked for after the last one ended starts with a burst again
    proto.handle(PEER, wire(mavlink2.MAVLink_param_request_list_message(1, 1)), t + 1.0)
    assert len(sent) == 58 + 1000 + 25


def test_two_links_stream_independently():
    v = Vehicle()
    v.rx(mavlink2.MAVLink_param_request_list_message(1, 1), PEER, 0.0)
    v.rx(mavlink2.MAVLink_param_request_list_message(0, 0), OTHER, 0.0)
    t = 0.0
    while v.proto.streaming:
        t += 0.01
        v.proto.tick(t)
    got = v.take()
    for peer in (PEER, OTHER):
        assert sorted(m.param_index for p, m in got if p == peer) == list(range(n_params()))
    v.rx(mavlink2.MAVLink_param_request_list_message(1, 1), PEER, t)
    v.proto.peer_closed(PEER)
    assert not v.proto.streaming


# ---------------------------------------------------------------------- read
def test_read_by_name_and_by_index():
    v = Vehicle()
    v.rx(mavlink2.MAVLink_param_request_read_message(1, 1, b"FC_ATT_K4_Z", -1))
    ((peer, m),) = v.take()
    assert peer == PEER
    assert (m.param_id, m.param_value, m.param_type) == ("FC_ATT_K4_Z", f32(0.6), REAL32)
    assert v.defs[m.param_index].name == "FC_ATT_K4_Z"
    assert m.param_count == n_params()
    v.rx(mavlink2.MAVLink_param_request_read_message(1, 1, b"IGNORED_NAME", 0))
    ((_, m),) = v.take()
    assert (m.param_id, m.param_index, m.param_value) == ("FC_RATE_HZ", 0, 250.0)
    v.rx(mavlink2.MAVLink_param_request_read_message(1, 1, b"FC_USE_TENSION", -1))
    ((_, m),) = v.take()
    assert (m.param_type, m.param_value) == (INT8, 1.0)


@pytest.mark.parametrize("name,index", [(b"NO_SUCH_PARAM", -1), (b"", -1), (b"x", 28),
                                        (b"x", 32767), (b"x", -2), (b"\xff\xfe", -1)])
def test_unknown_reads_get_no_answer(name, index):
    v = Vehicle()
    assert v.rx(mavlink2.MAVLink_param_request_read_message(1, 1, name, index))
    assert v.take() == [] and v.texts == []


def test_requests_for_other_components_are_not_consumed():
    v = Vehicle()
    assert not v.rx(mavlink2.MAVLink_param_request_list_message(1, 169))
    assert not v.rx(mavlink2.MAVLink_param_request_read_message(2, 1, b"FC_RATE_HZ", -1))
    assert not v.rx(mavlink2.MAVLink_param_set_message(1, 190, b"FC_RATE_HZ", 100.0, REAL32))
    assert not v.rx(mavlink2.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3))
    assert v.take() == [] and v.current == FlightControlParams()


# ----------------------------------------------------------------------- set
def test_accepted_set_is_broadcast_persisted_and_reloads(tmp_path):
    path = tmp_path / "companion.parm"
    v = Vehicle(persist_path=path)
    assert v.set("FC_POS_K1_X", 2.7)
    ((peer, m),) = v.take()
    assert peer is None  # every link
    assert (m.param_id, m.param_value) == ("FC_POS_K1_X", f32(2.7))
    assert v.defs[m.param_index].name == "FC_POS_K1_X"
    # the float32 from the wire is stored as the decimal the GCS sent
    assert v.current.pos_k1_1_s[0] == 2.7
    assert v.texts == []

    assert v.proto.flush()          # the file is written off the control path
    lines = [ln for ln in path.read_text().splitlines() if ln and not ln.startswith("#")]
    table = dict(ln.split() for ln in lines)
    assert len(table) == n_params()
    assert float(table["FC_POS_K1_X"]) == 2.7
    assert float(table["FC_POS_K1_Y"]) == 1.6
    assert table["FC_USE_TETHER"] == "1"
    assert os.listdir(tmp_path) == ["companion.parm"]  # no temporary file left behind

    fresh = Vehicle(persist_path=path)
    assert fresh.proto.load() == []
    assert fresh.current.pos_k1_1_s == (2.7, 1.6, 2.0)
    assert fresh.current == v.current


def test_out_of_bounds_set_leaves_the_value_and_says_why(tmp_path):
    path = tmp_path / "p.parm"
    v = Vehicle(persist_path=path)
    assert v.set("FC_POS_K1_Z", -1.0)
    ((peer, m),) = v.take()
    assert peer == PEER  # to the requester only
    assert (m.param_id, m.param_value) == ("FC_POS_K1_Z", 2.0)
    severity, text = v.texts[-1]
    assert severity == mavlink2.MAV_SEVERITY_WARNING
    assert text.startswith("FC_POS_K1_Z") and "must be > 0" in text
    assert v.instances == [] and not path.exists()


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf])
def test_non_finite_set_is_refused(value):
    v = Vehicle()
    assert v.set("FC_RATE_HZ", value)
    ((peer, m),) = v.take()
    assert peer == PEER and (m.param_id, m.param_value) == ("FC_RATE_HZ", 250.0)
    assert v.texts[-1][1].startswith("FC_RATE_HZ") and v.instances == []


def test_unknown_name_is_ignored_with_a_statustext():
    v = Vehicle()
    assert v.set("NO_SUCH_PARAM", 1.0)
    assert v.take() == []
    assert v.texts == [(mavlink2.MAV_SEVERITY_WARNING, "Unknown parameter NO_SUCH_PARAM")]


def test_sixteen_character_names_round_trip():
    value = [1.0]
    d = ParamDef("ABCDEFGHIJKLMNOP", REAL32, lambda: value[0],
                 lambda x: value.__setitem__(0, x))
    sent = []
    proto = ParamProtocol([d], lambda p, m: sent.append(wire(m, 1, 1)), lambda s, t: None)
    proto.handle(PEER, wire(mavlink2.MAVLink_param_set_message(
        1, 1, b"ABCDEFGHIJKLMNOP", 5.5, REAL32)), 0.0)
    assert value == [5.5] and sent[-1].param_id == "ABCDEFGHIJKLMNOP"


def test_integer_types_round_and_range_check():
    store = {"I8": 0.0, "I32": 0.0}

    def setter(name):
        def apply(x):
            store[name] = x
        return apply

    defs = [ParamDef("I8", INT8, lambda: store["I8"], setter("I8")),
            ParamDef("I32", INT32, lambda: store["I32"], setter("I32"))]
    sent, texts = [], []
    proto = ParamProtocol(defs, lambda p, m: sent.append(wire(m, 1, 1)),
                          lambda s, t: texts.append(t))

    def set_(name, value):
        proto.handle(PEER, wire(mavlink2.MAVLink_param_set_message(
            1, 1, name.encode(), value, REAL32)), 0.0)
        return sent[-1]

    assert set_("I8", 2.6).param_value == 3.0 and store["I8"] == 3.0
    assert set_("I8", 128.0).param_value == 3.0 and "I8" in texts[-1]
    assert set_("I8", -128.0).param_value == -128.0
    assert set_("I32", 1_000_000.0).param_value == 1_000_000.0
    assert set_("I32", 3e9).param_value == 1_000_000.0


def test_a_setter_that_raises_is_a_refusal():
    def boom(x):
        raise RuntimeError("hardware busy")

    texts = []
    proto = ParamProtocol([ParamDef("P", REAL32, lambda: 1.0, boom)], lambda p, m: None,
                          lambda s, t: texts.append(t))
    proto.handle(PEER, wire(mavlink2.MAVLink_param_set_message(1, 1, b"P", 2.0, REAL32)), 0)
    assert texts == ["P: hardware busy"]


def _significant_digits(x: float) -> int:
    return len(Decimal(repr(x)).normalize().as_tuple().digits)


def _same_f32_with_fewer_digits(x: float, digits: int) -> bool:
    """Whether some decimal of ``digits`` significant digits maps to float32(x): the closest
    ones below and above ``x`` are the only candidates (the float32 interval is convex)."""
    d = Decimal(repr(x))
    quantum = Decimal(1).scaleb(d.adjusted() - digits + 1)
    below = d.quantize(quantum, rounding=ROUND_FLOOR)
    above = d.quantize(quantum, rounding=ROUND_CEILING)
    return any(f32(float(c)) == f32(x) for c in (below, above))


@given(st.floats(width=32, allow_nan=False, allow_infinity=False,
                 min_value=2.0**-10, max_value=2.0**20))
def test_values_typed_in_a_gcs_are_stored_as_typed(x):
    """Whatever float32 arrives, the stored double maps back to that same float32 and is
    the shortest decimal doing so (1.7 arrives as 1.70000005 and is stored as 1.7)."""
    store = [0.0]
    proto = ParamProtocol([ParamDef("P", REAL32, lambda: store[0],
                                    lambda v: store.__setitem__(0, v))],
                          lambda p, m: None, lambda s, t: None)
    proto.handle(PEER, wire(mavlink2.MAVLink_param_set_message(1, 1, b"P", x, REAL32)), 0)
    assert f32(store[0]) == f32(x)
    n = _significant_digits(store[0])
    assert n == 1 or not _same_f32_with_fewer_digits(store[0], n - 1)


def test_seventeen_tenths_is_stored_as_typed():
    store = [0.0]
    proto = ParamProtocol([ParamDef("P", REAL32, lambda: store[0],
                                    lambda v: store.__setitem__(0, v))],
                          lambda p, m: None, lambda s, t: None)
    msg = wire(mavlink2.MAVLink_param_set_message(1, 1, b"P", 1.7, REAL32))
    assert msg.param_value != 1.7 and msg.param_value == f32(1.7)
    proto.handle(PEER, msg, 0)
    assert store[0] == 1.7


# ---------------------------------------------------------------- persistence
def test_load_reports_bad_lines_and_applies_good_ones(tmp_path):
    path = tmp_path / "p.parm"
    path.write_text(
        "# a comment\n"
        "FC_RATE_HZ 400   # trailing comment\n"
        "FC_POS_K2_Z,3.5\n"  # Mission Planner's separator
        "NO_SUCH 1\n"
        "FC_POS_K1_X -5\n"
        "FC_MAX_THR notanumber\n"
        "JUST_A_NAME\n"
        "\n")
    v = Vehicle(persist_path=path)
    warnings = v.proto.load()
    assert len(warnings) == 4
    assert any("NO_SUCH" in w for w in warnings)
    assert any("FC_POS_K1_X" in w and "must be > 0" in w for w in warnings)
    assert any("notanumber" in w for w in warnings)
    assert v.current.rate_hz == 400.0 and v.current.pos_k2_1_s[2] == 3.5
    assert v.current.pos_k1_1_s[0] == 1.6
    assert v.take() == []
    assert Vehicle(persist_path=tmp_path / "missing.parm").proto.load() == []


def test_save_replaces_the_file_atomically(tmp_path):
    path = tmp_path / "sub" / "p.parm"
    v = Vehicle(persist_path=path)
    v.set("FC_CMDF_HZ", 8.0)
    assert v.proto.flush()
    first_inode = path.stat().st_ino
    v.set("FC_CMDF_HZ", 9.0)
    assert v.proto.flush()
    assert path.stat().st_ino != first_inode  # a new file renamed over the old one
    assert "FC_CMDF_HZ       9.0" in path.read_text()
    assert sorted(os.listdir(path.parent)) == ["p.parm"]


# ---------------------------------------------------------------------- MAVFTP
def ftp_request(seq, session, opcode, size=0, offset=0, data=b""):
    header = struct.pack("<HBBBBBBI", seq, session, opcode, size, 0, 0, 0, offset)
    payload = (header + data).ljust(251, b"\0")
    return mavlink2.MAVLink_file_transfer_protocol_message(0, 1, 1, list(payload))


def ftp_reply(v: Vehicle, request):
    assert v.rx(request)
    ((peer, m),) = v.take()
    assert peer == PEER and m.get_type() == "FILE_TRANSFER_PROTOCOL"
    assert (m.target_network, m.target_system, m.target_component) == (0, GCS_SYS, GCS_COMP)
    return bytes(m.payload)


def test_ftp_open_of_the_param_file_gets_an_immediate_file_not_found_nak():
    """Byte by byte against the MAVLink FTP payload definition: seq_number u16 (0-1), session
    (2), opcode (3), size (4), req_opcode (5), burst_complete (6), padding (7), offset u32
    (8-11), data (12..)."""
    v = Vehicle()
    path = b"@PARAM/param.pck?withdefaults=1"
    p = ftp_reply(v, ftp_request(41, 3, 4, len(path), 0, path))
    assert len(p) == 251
    assert p[0] | p[1] << 8 == 42  # the reply's sequence number is the request's + 1
    assert p[2] == 3  # same session
    assert p[3] == 129  # NAK
    assert p[4] == 1  # one data byte
    assert p[5] == 4  # req_opcode: OpenFileRO
    assert p[6] == 0 and p[7] == 0
    assert p[8:12] == b"\0\0\0\0"
    assert p[12] == 10  # FileNotFound: QGC falls back to PARAM_REQUEST_LIST at once
    assert p[13:] == bytes(251 - 13)


@pytest.mark.parametrize("opcode,reply,error", [
    (3, 129, 10),  # ListDirectory -> FileNotFound
    (14, 129, 10),  # CalcFileCRC32 -> FileNotFound
    (6, 129, 10),  # CreateFile -> FileNotFound
    (5, 129, 4),  # ReadFile -> InvalidSession
    (15, 129, 4),  # BurstReadFile -> InvalidSession
    (7, 129, 4),  # WriteFile -> InvalidSession
    (0, 129, 7),  # None -> UnknownCommand
    (77, 129, 7),  # undefined -> UnknownCommand
    (1, 128, None),  # TerminateSession -> ACK
    (2, 128, None),  # ResetSessions -> ACK
])
def test_ftp_answers_per_opcode(opcode, reply, error):
    v = Vehicle()
    p = ftp_reply(v, ftp_request(65535, 7, opcode, 0))
    assert p[0:2] == b"\0\0"  # 65535 + 1 wraps to 0
    assert (p[2], p[3], p[5]) == (7, reply, opcode)
    if error is None:
        assert p[4] == 0 and p[12] == 0
    else:
        assert (p[4], p[12]) == (1, error)


def test_ftp_oversized_request_and_replies_addressed_to_us():
    v = Vehicle()
    p = ftp_reply(v, ftp_request(1, 0, 4, 240))
    assert (p[3], p[4], p[12]) == (129, 1, 3)  # InvalidDataSize
    for opcode in (128, 129):  # never answer an answer
        assert v.rx(ftp_request(5, 0, opcode, 1, 0, b"\x0a"))
    assert v.take() == []
    assert not v.rx(mavlink2.MAVLink_file_transfer_protocol_message(0, 1, 50, [4] + [0] * 250))


# ------------------------------------------------ a real pymavlink client (UDP)
class UdpVehicle:
    """A minimal UDP transport around ParamProtocol, for a real mavutil client."""

    def __init__(self, defs):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.005)
        self.port = self.sock.getsockname()[1]
        self.mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
        self.parser = mavlink2.MAVLink(None)
        self.peers: set = set()
        self.proto = ParamProtocol(defs, self.send, lambda s, t: None)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self.run, daemon=True)

    def send(self, peer, msg):
        for addr in (self.peers if peer is None else [peer]):
            self.sock.sendto(msg.pack(self.mav), addr)

    def run(self):
        while not self.stop.is_set():
            try:
                data, addr = self.sock.recvfrom(2048)
            except TimeoutError:
                data, addr = b"", None
            if addr is not None:
                self.peers.add(addr)
                for m in self.parser.parse_buffer(data) or []:
                    self.proto.handle(addr, m, time.monotonic())
            self.proto.tick(time.monotonic())


def test_mavutil_param_fetch_all_gets_every_parameter_over_udp():
    values = {f"PRM_{i:04d}": float(i) * 0.5 for i in range(600)}
    defs = [ParamDef(n, REAL32, (lambda n=n: values[n]), lambda x: None) for n in values]
    vehicle = UdpVehicle(defs)
    vehicle.thread.start()
    client = mavutil.mavlink_connection(f"udpout:127.0.0.1:{vehicle.port}",
                                        source_system=255, source_component=190,
                                        dialect="ardupilotmega")   # (mavutil's dialect is
    # process-wide: "common" here left every later connection of the suite unable to
    # decode ArduPilot's own messages, EKF_STATUS_REPORT among them)
    try:
        client.target_system, client.target_component = 1, 1
        client.param_fetch_all()
        seen = {}
        deadline = time.monotonic() + 10.0
        while len(seen) < len(values) and time.monotonic() < deadline:
            m = client.recv_match(type="PARAM_VALUE", blocking=True, timeout=0.5)
            if m is not None:
                seen[m.param_index] = (m.param_id, m.param_value, m.param_count)
                time.sleep(0.0005)  # a client that is not fast
        assert len(seen) == len(values)
        for index, (name, value, count) in seen.items():
            assert defs[index].name == name and values[name] == value and count == 600
        assert client.param_state[(1, 1)].params == values  # mavutil's own parameter table
    finally:
        vehicle.stop.set()
        vehicle.thread.join(2.0)
        client.close()
        vehicle.sock.close()


def test_announce_broadcasts_the_current_value():
    v = Vehicle()
    {d.name: d for d in v.defs}["FC_CMDF_HZ"].set(7.5)
    v.proto.announce("FC_CMDF_HZ")
    ((peer, m),) = v.take()
    assert peer is None and (m.param_id, m.param_value) == ("FC_CMDF_HZ", 7.5)
    with pytest.raises(KeyError):
        v.proto.announce("NOPE")


_PARAM_MSGS = st.one_of(
    st.builds(mavlink2.MAVLink_param_set_message, st.just(1), st.sampled_from([0, 1]),
              st.binary(max_size=16), st.floats(width=32), st.integers(0, 255)),
    st.builds(mavlink2.MAVLink_param_request_read_message, st.just(1), st.just(1),
              st.binary(max_size=16), st.integers(-(2**15), 2**15 - 1)),
    st.builds(mavlink2.MAVLink_param_request_list_message, st.just(1), st.just(1)),
    st.builds(mavlink2.MAVLink_file_transfer_protocol_message, st.integers(0, 255),
              st.just(1), st.just(1), st.binary(min_size=251, max_size=251).map(list)),
)


@settings(max_examples=300, deadline=None)
@given(script=st.lists(st.tuples(_PARAM_MSGS, st.floats(0, 0.1)), max_size=20))
def test_never_raises_and_keeps_parameters_valid(script):
    """Random traffic: nothing raises, every reply packs, and the parameters stay a valid
    FlightControlParams (its own checks would have raised otherwise)."""
    v = Vehicle()
    t = 0.0
    for msg, dt in script:
        t += dt
        v.rx(msg, PEER, t)
        v.proto.tick(t)
    FlightControlParams(**{f.name: getattr(v.current, f.name)
                           for f in dataclasses.fields(FlightControlParams)})
    for _, m in v.take():
        assert m.get_type() in ("PARAM_VALUE", "FILE_TRANSFER_PROTOCOL")


def test_param_set_never_waits_for_the_disk(tmp_path, monkeypatch):
    """PARAM_SET is answered while the disk is stuck (fsync blocked here until released):
    the file is written by the writer's own thread, the newest values once the disk moves
    (the control loop once fsynced for every accepted PARAM_SET)."""
    import threading

    import companion.param_protocol as pp

    stuck = threading.Event()
    real_fsync = os.fsync

    def slow_fsync(fd):
        stuck.wait(30.0)
        real_fsync(fd)

    monkeypatch.setattr(pp.os, "fsync", slow_fsync)
    path = tmp_path / "p.parm"
    v = Vehicle(persist_path=path)
    for k in range(200):            # all answered with the disk stuck
        assert v.set("FC_CMDF_HZ", 5.0 + 0.01 * k)
    assert len(v.take()) == 200
    assert not v.proto.flush(timeout_s=0.2)
    stuck.set()
    assert v.proto.flush()
    assert "FC_CMDF_HZ       6.99" in path.read_text()
    v.proto.close()


def test_a_failed_write_is_said_from_the_control_loop(tmp_path):
    """The parameter file cannot be written (its folder is a file): the next tick says
    'Parameter save failed', the set itself stands."""
    blocker = tmp_path / "not-a-folder"
    blocker.write_text("")
    v = Vehicle(persist_path=blocker / "p.parm")
    assert v.set("FC_CMDF_HZ", 8.0)
    v.proto.flush()
    v.proto.tick(0.0)
    assert v.texts[-1] == (mavlink2.MAV_SEVERITY_ERROR, "Parameter save failed")
    assert v.current.command_filter_hz == 8.0
