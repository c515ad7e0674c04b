"""The companion's mission micro-service against real pymavlink messages.

Every message a test sends is packed by a GCS-side pymavlink encoder (255/190) and parsed
back, and every reply of the vehicle is packed as system 1 / component 1 and parsed by the
GCS side, so the tests see exactly what would cross the wire. The truths checked are the
MAVLink mission-protocol rules (sequence, ACK results, targets, the MISSION_ITEM <->
MISSION_ITEM_INT scaling) and ArduPilot's observable behaviour.
"""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import common as mavlink2

from companion.mission_protocol import (
    INT32_MAX,
    MissionItem,
    MissionItemError,
    MissionProtocol,
    check_item,
    degrees_to_e7,
    e7_to_degrees,
    from_message,
    home_item,
    to_message,
)

GCS_SYS, GCS_COMP = 255, 190
PEER_A = ("tcp", 3)
PEER_B = ("udp", ("127.0.0.1", 14550))
WP = mavlink2.MAV_CMD_NAV_WAYPOINT
REL_ALT_INT = mavlink2.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
REL_ALT = mavlink2.MAV_FRAME_GLOBAL_RELATIVE_ALT
MISSION = mavlink2.MAV_MISSION_TYPE_MISSION
FENCE = mavlink2.MAV_MISSION_TYPE_FENCE
RALLY = mavlink2.MAV_MISSION_TYPE_RALLY
HOME = home_item(47.3977419, 8.5455938, 488.0)


def f32(x: float) -> float:
    """``x`` rounded to float32, as the wire carries it (computed with struct, not numpy)."""
    return struct.unpack("<f", struct.pack("<f", x))[0]


def wire(msg, src_system: int = GCS_SYS, src_component: int = GCS_COMP):
    """Pack ``msg`` as (src_system, src_component) and parse it back."""
    packer = mavlink2.MAVLink(None, srcSystem=src_system, srcComponent=src_component)
    parser = mavlink2.MAVLink(None)
    out = parser.parse_buffer(msg.pack(packer))
    assert out is not None and len(out) == 1
    return out[0]


class Vehicle:
    """A MissionProtocol with recording callbacks; replies are put through the wire too."""

    def __init__(self, validate=None, **kw):  # kw: MissionProtocol's keywords
        self.sent: list[tuple[object, object]] = []
        self.texts: list[tuple[int, str]] = []
        self.changes: list[list[MissionItem]] = []
        self.validated: list[int] = []
        self._validate = validate
        self.proto = MissionProtocol(self._send, self._text, self._check, self.changes.append,
                                     **kw)
        self.proto.set_home(HOME)

    def _send(self, peer, msg):
        self.sent.append((peer, wire(msg, 1, 1)))

    def _text(self, severity, text):
        assert len(text) <= 50
        self.texts.append((severity, text))

    def _check(self, seq, item):
        self.validated.append(seq)
        return None if self._validate is None else self._validate(seq, item)

    def rx(self, msg, peer=PEER_A, now=0.0, sysid=GCS_SYS, compid=GCS_COMP) -> bool:
        return self.proto.handle(peer, wire(msg, sysid, compid), now)

    def take(self):
        out, self.sent = self.sent, []
        return out


def item_msg(seq, item: MissionItem, *, int_variant=True, current=0, mission_type=MISSION,
             target=(1, 1)):
    return to_message(seq, item, int_variant, target[0], target[1], current, mission_type)


def waypoint(lat, lon, alt, **kw) -> MissionItem:
    return MissionItem(command=WP, frame=REL_ALT_INT, x=degrees_to_e7(lat),
                       y=degrees_to_e7(lon), z=alt, **kw)


MISSION_A = [
    MissionItem(command=mavlink2.MAV_CMD_NAV_TAKEOFF, frame=REL_ALT_INT, z=10.0,
                param4=math.nan, x=473977419, y=85455938),
    waypoint(47.3980, 8.5460, 20.0, param1=2.0),
    waypoint(47.3985, 8.5450, 25.0),
    MissionItem(command=mavlink2.MAV_CMD_DO_CHANGE_SPEED, frame=mavlink2.MAV_FRAME_MISSION,
                param1=1.0, param2=3.5, param3=-1.0),
    MissionItem(command=mavlink2.MAV_CMD_NAV_RETURN_TO_LAUNCH, frame=REL_ALT_INT),
]


def same(a: MissionItem, b: MissionItem) -> bool:
    """Equality with NaN == NaN (a NaN param4 is a legal 'default')."""
    for name in MissionItem.__dataclass_fields__:
        u, v = getattr(a, name), getattr(b, name)
        if not (u == v or (isinstance(u, float) and math.isnan(u) and math.isnan(v))):
            return False
    return True


def assert_ack(entry, result, peer=PEER_A, mission_type=MISSION, target=(GCS_SYS, GCS_COMP)):
    p, m = entry
    assert p == peer
    assert m.get_type() == "MISSION_ACK", m
    assert (m.type, m.mission_type) == (result, mission_type), m
    assert (m.target_system, m.target_component) == target
    assert (m.get_srcSystem(), m.get_srcComponent()) == (1, 1)


def assert_request(entry, seq, peer=PEER_A, kind="MISSION_REQUEST_INT"):
    p, m = entry
    assert p == peer
    assert m.get_type() == kind, m
    assert (m.seq, m.mission_type) == (seq, MISSION)
    assert (m.target_system, m.target_component) == (GCS_SYS, GCS_COMP)


def upload(v: Vehicle, items: list[MissionItem], *, int_variant=True, peer=PEER_A,
           gcs_home: MissionItem | None = None, now=0.0):
    """A well-behaved GCS upload (home + items); returns the final reply."""
    seq0 = gcs_home or home_item(1.0, 2.0, 3.0)
    full = [seq0, *items]
    assert v.rx(mavlink2.MAVLink_mission_count_message(1, 1, len(full), MISSION), peer, now)
    for _ in range(len(full)):
        (entry,) = v.take()
        p, req = entry
        assert p == peer
        if req.get_type() == "MISSION_ACK":
            return entry
        assert req.get_type() in ("MISSION_REQUEST_INT", "MISSION_REQUEST")
        assert v.rx(item_msg(req.seq, full[req.seq], int_variant=int_variant), peer, now)
    (entry,) = v.take()
    return entry


# --------------------------------------------------------------- conversions
def test_float_item_converted_as_the_spec_says():
    """Global frames: degrees x 1e7; local frames: metres x 1e4; MAV_FRAME_MISSION: as is."""
    assert degrees_to_e7(47.3977419) == 473977419
    assert degrees_to_e7(-122.0841231) == -1220841231
    assert e7_to_degrees(473977419) == pytest.approx(47.3977419, abs=1e-12)

    m = wire(mavlink2.MAVLink_mission_item_message(
        1, 1, 1, REL_ALT, WP, 0, 1, 0, 0, 0, 0, 47.3977419, -8.5455938, 30.0))
    item = from_message(m)
    # the float32 on the wire, converted exactly: round(float32(lat) * 1e7)
    assert item.x == round(f32(47.3977419) * 1e7)
    assert item.y == round(f32(-8.5455938) * 1e7)
    # ... which is within one float32 step of the decimal the GCS meant (and not closer:
    # MISSION_ITEM_INT exists because float32 cannot carry 1e-7 deg)
    ulp_units = float(np.spacing(np.float32(47.3977419))) * 1e7
    assert 0 < abs(item.x - 473977419) <= ulp_units
    assert (item.frame, item.command, item.z) == (REL_ALT, WP, 30.0)

    local = from_message(wire(mavlink2.MAVLink_mission_item_message(
        1, 1, 1, mavlink2.MAV_FRAME_LOCAL_NED, WP, 0, 1, 0, 0, 0, 0, 12.25, -5.5, -3.0)))
    assert (local.x, local.y) == (122500, -55000)
    enu = from_message(wire(mavlink2.MAVLink_mission_item_message(
        1, 1, 1, mavlink2.MAV_FRAME_LOCAL_ENU, WP, 0, 1, 0, 0, 0, 0, 0.0001, 100.0, 3.0)))
    assert (enu.x, enu.y) == (1, 1000000)
    raw = from_message(wire(mavlink2.MAVLink_mission_item_message(
        1, 1, 1, mavlink2.MAV_FRAME_MISSION, mavlink2.MAV_CMD_DO_DIGICAM_CONTROL, 0, 1,
        0, 0, 0, 0, 1.0, 7.0, 0.0)))
    assert (raw.x, raw.y) == (1, 7)
    # NaN means "default": INT32_MAX in the integer message
    nan = from_message(wire(mavlink2.MAVLink_mission_item_message(
        1, 1, 1, REL_ALT, WP, 0, 1, 0, 0, 0, 0, math.nan, math.nan, 5.0)))
    assert (nan.x, nan.y) == (INT32_MAX, INT32_MAX)


def test_item_int_is_taken_verbatim():
    m = wire(mavlink2.MAVLink_mission_item_int_message(
        1, 1, 3, REL_ALT_INT, WP, 0, 1, 1.5, 2.0, 0.0, 90.0, 473977419, 85455938, 12.5))
    item = from_message(m)
    assert item == MissionItem(WP, REL_ALT_INT, 1.5, 2.0, 0.0, 90.0, 473977419, 85455938,
                               12.5, 1)


@pytest.mark.parametrize("frame,x,y,result", [
    (REL_ALT, math.inf, 8.0, mavlink2.MAV_MISSION_INVALID_PARAM5_X),
    (REL_ALT, 47.0, -math.inf, mavlink2.MAV_MISSION_INVALID_PARAM6_Y),
    (mavlink2.MAV_FRAME_LOCAL_NED, 300000.0, 0.0, mavlink2.MAV_MISSION_INVALID_PARAM5_X),
    (99, 1.0, 1.0, mavlink2.MAV_MISSION_UNSUPPORTED_FRAME),
])
def test_unconvertible_float_items_raise(frame, x, y, result):
    m = wire(mavlink2.MAVLink_mission_item_message(
        1, 1, 1, frame, WP, 0, 1, 0, 0, 0, 0, x, y, 0.0))
    with pytest.raises(MissionItemError) as info:
        from_message(m)
    assert info.value.result == result


def test_float_reply_undoes_the_scaling():
    item = MissionItem(WP, mavlink2.MAV_FRAME_LOCAL_NED, x=-122500, y=55000, z=-3.0)
    m = wire(to_message(4, item, False, GCS_SYS, GCS_COMP, 0), 1, 1)
    assert m.get_type() == "MISSION_ITEM"
    assert (m.seq, m.x, m.y, m.z) == (4, -12.25, 5.5, -3.0)
    glob = wire(to_message(1, HOME, False, GCS_SYS, GCS_COMP, 1), 1, 1)
    assert glob.x == f32(473977419e-7) and glob.y == f32(85455938e-7)
    assert glob.current == 1
    dflt = wire(to_message(1, MissionItem(WP, REL_ALT_INT, x=INT32_MAX, y=INT32_MAX), False,
                           1, 1, 0), 1, 1)
    assert math.isnan(dflt.x) and math.isnan(dflt.y)


@given(lat=st.floats(-90, 90), lon=st.floats(-180, 180))
def test_float_round_trip_is_stable(lat, lon):
    """int -> MISSION_ITEM -> int returns the same integers whenever float32 can hold them
    (and never moves them by more than half a float32 step)."""
    item = MissionItem(WP, REL_ALT_INT, x=degrees_to_e7(lat), y=degrees_to_e7(lon))
    back = from_message(wire(to_message(1, item, False, 1, 1, 0)))
    for original, got in ((item.x, back.x), (item.y, back.y)):
        step = float(np.spacing(np.float32(abs(original) * 1e-7))) * 1e7
        assert abs(got - original) <= step / 2 + 1


# -------------------------------------------------------------------- checks
@pytest.mark.parametrize("item,result", [
    (MissionItem(WP, REL_ALT_INT, param1=math.nan), mavlink2.MAV_MISSION_INVALID_PARAM1),
    (MissionItem(WP, REL_ALT_INT, param2=math.inf), mavlink2.MAV_MISSION_INVALID_PARAM2),
    (MissionItem(WP, REL_ALT_INT, param4=-math.inf), mavlink2.MAV_MISSION_INVALID_PARAM4),
    (MissionItem(mavlink2.MAV_CMD_DO_CHANGE_SPEED, mavlink2.MAV_FRAME_MISSION,
                 param4=math.nan), mavlink2.MAV_MISSION_INVALID_PARAM4),
    (MissionItem(WP, REL_ALT_INT, z=math.nan), mavlink2.MAV_MISSION_INVALID_PARAM7),
    (MissionItem(WP, REL_ALT_INT, z=math.inf), mavlink2.MAV_MISSION_INVALID_PARAM7),
    (MissionItem(WP, REL_ALT_INT, x=900000001), mavlink2.MAV_MISSION_INVALID_PARAM5_X),
    (MissionItem(WP, REL_ALT_INT, y=-1800000001), mavlink2.MAV_MISSION_INVALID_PARAM6_Y),
    (MissionItem(WP, 22), mavlink2.MAV_MISSION_UNSUPPORTED_FRAME),
    (MissionItem(0, REL_ALT_INT), mavlink2.MAV_MISSION_INVALID),
    (MissionItem(WP, REL_ALT_INT, autocontinue=2), mavlink2.MAV_MISSION_INVALID),
])
def test_generic_checks_reject(item, result):
    problem = check_item(item)
    assert problem is not None and problem[0] == result


@pytest.mark.parametrize("item", [
    *MISSION_A,
    MissionItem(WP, REL_ALT_INT, param4=math.nan),  # "keep the current yaw"
    MissionItem(mavlink2.MAV_CMD_NAV_VTOL_LAND, REL_ALT_INT, param3=math.nan,
                param4=math.nan),
    MissionItem(WP, REL_ALT_INT, x=INT32_MAX, y=INT32_MAX),  # "current position"
    MissionItem(WP, REL_ALT_INT, x=900000000, y=-1800000000),
    MissionItem(mavlink2.MAV_CMD_DO_DIGICAM_CONTROL, mavlink2.MAV_FRAME_MISSION, z=math.nan),
    MissionItem(WP, mavlink2.MAV_FRAME_LOCAL_NED, x=10**9, y=-(10**9)),
])
def test_generic_checks_accept(item):
    assert check_item(item) is None


# -------------------------------------------------------------------- upload
def test_upload_int_variant():
    v = Vehicle()
    final = upload(v, MISSION_A)
    assert_ack(final, mavlink2.MAV_MISSION_ACCEPTED)
    got = v.proto.items
    # ArduPilot never takes seq 0 of an upload as home: home stays the vehicle's
    assert got[0] == HOME
    assert len(got) == 1 + len(MISSION_A)
    assert all(same(a, b) for a, b in zip(got[1:], MISSION_A, strict=True))
    assert v.validated == list(range(1, 1 + len(MISSION_A)))
    assert len(v.changes) == 1 and v.changes[0][0] == HOME
    assert (mavlink2.MAV_SEVERITY_INFO, "Flight plan received") in v.texts
    assert not v.proto.upload_in_progress


def test_upload_requests_each_item_in_order_with_request_int():
    v = Vehicle()
    v.rx(mavlink2.MAVLink_mission_count_message(1, 1, 3, MISSION))
    (req,) = v.take()
    assert_request(req, 0)
    assert v.proto.upload_in_progress
    v.rx(item_msg(0, HOME))
    (req,) = v.take()
    assert_request(req, 1)


def test_upload_float_variant_is_answered_in_kind():
    v = Vehicle()
    items = [waypoint(47.3980, 8.5460, 20.0), waypoint(47.3985, 8.5450, 25.0)]
    assert v.rx(mavlink2.MAVLink_mission_count_message(1, 1, 3, MISSION))
    (req,) = v.take()
    assert_request(req, 0)  # the first request is MISSION_REQUEST_INT ...
    v.rx(item_msg(0, HOME, int_variant=False))
    (req,) = v.take()
    assert_request(req, 1, kind="MISSION_REQUEST")  # ... then in kind
    v.rx(item_msg(1, items[0], int_variant=False))
    (req,) = v.take()
    assert_request(req, 2, kind="MISSION_REQUEST")
    v.rx(item_msg(2, items[1], int_variant=False))
    (ack,) = v.take()
    assert_ack(ack, mavlink2.MAV_MISSION_ACCEPTED)
    for stored, sent in zip(v.proto.items[1:], items, strict=True):
        assert stored.x == round(f32(sent.x * 1e-7) * 1e7)
        assert stored.y == round(f32(sent.y * 1e-7) * 1e7)
        assert stored.z == sent.z and stored.frame == sent.frame


def test_upload_mixed_int_and_float_items():
    v = Vehicle()
    final = upload(v, MISSION_A[:2], int_variant=False)
    assert_ack(final, mavlink2.MAV_MISSION_ACCEPTED)
    v2 = Vehicle()
    assert_ack(upload(v2, MISSION_A), mavlink2.MAV_MISSION_ACCEPTED)


def test_count_zero_clears_and_count_one_keeps_only_home():
    v = Vehicle()
    upload(v, MISSION_A)
    v.rx(mavlink2.MAVLink_mission_count_message(1, 1, 0, MISSION))
    (ack,) = v.take()
    assert_ack(ack, mavlink2.MAV_MISSION_ACCEPTED)
    assert v.proto.items == [HOME] and v.changes[-1] == [HOME]
    upload(v, MISSION_A)
    assert_ack(upload(v, []), mavlink2.MAV_MISSION_ACCEPTED)
    assert v.proto.items == [HOME]


def test_count_above_the_limit_is_no_space():
    v = Vehicle(max_items=700)
    v.rx(mavlink2.MAVLink_mission_count_message(1, 1, 701, MISSION))
    (ack,) = v.take()
    assert_ack(ack, mavlink2.MAV_MISSION_NO_SPACE)
    assert not v.proto.upload_in_progress
    assert v.texts and v.texts[-1][0] == mavlink2.MAV_SEVERITY_WARNING
    v.rx(mavlink2.MAVLink_mission_count_message(1, 1, 700, MISSION))
    (req,) = v.take()
    assert_request(req, 0)


# ------------------------------------------------------ lost items and retries
def test_rerequest_after_a_lost_item():
    v = Vehicle(timeout_s=1.5)
    full = [home_item(0, 0, 0), *MISSION_A[:3]]
    v.rx(mavlink2.MAVLink_mission_count_message(1, 1, 4, MISSION), now=100.0)
    v.take()
    v.rx(item_msg(0, full[0]), now=100.1)
    (req,) = v.take()
    assert_request(req, 1)
    # the item the GCS sends for this request is lost; nothing happens before timeout_s
    for t in (100.2, 100.9, 101.59):
        v.proto.tick(t)
    assert v.take() == []
    v.proto.tick(101.6)
    (req,) = v.take()
    assert_request(req, 1)  # the same seq again
    v.proto.tick(102.0)
    assert v.take() == []
    for seq in (1, 2, 3):
        v.rx(item_msg(seq, full[seq]), now=102.1)
    replies = v.take()
    assert_request(replies[0], 2)
    assert_request(replies[1], 3)
    assert_ack(replies[2], mavlink2.MAV_MISSION_ACCEPTED)
    assert len(v.proto.items) == 4


def test_upload_given_up_after_max_retries():
    v = Vehicle(timeout_s=1.5, max_retries=5)
    upload(v, MISSION_A[:2])
    before = v.proto.items
    changes = len(v.changes)
    v.rx(mavlink2.MAVLink_mission_count_message(1, 1, 3, MISSION), now=0.0)
    sent = v.take()
    t = 0.0
    while t < 30.0 and v.proto.upload_in_progress:
        t = round(t + 0.05, 2)
        v.proto.tick(t)
        sent += v.take()
    requests, rest = sent[:-1], sent[-1]
    assert len(requests) == 1 + 5
    for r in requests:
        assert_request(r, 0)
    assert_ack(rest, mavlink2.MAV_MISSION_OPERATION_CANCELLED)
    # 1 request + 5 repeats, each after 1.5 s of silence: given up 6 x 1.5 s after the count
    assert t == pytest.approx(9.0, abs=0.06)
    assert (mavlink2.MAV_SEVERITY_WARNING, "Mission upload timeout") in v.texts
    assert v.proto.items == before and len(v.changes) == changes
    v.proto.tick(60.0)
    assert v.take() == []


def test_stalled_upload_gives_up_even_if_items_keep_coming_out_of_order():
    v = Vehicle(timeout_s=1.0, max_retries=2)
    v.rx(mavlink2.MAVLink_mission_count_message(1, 1, 3, MISSION), now=0.0)
    t = 0.0
    while t < 10.0 and v.proto.upload_in_progress:
        t = round(t + 0.25, 2)
        v.rx(item_msg(2, MISSION_A[0]), now=t)  # never the expected seq 0
        v.proto.tick(t)
    assert not v.proto.upload_in_progress
    assert t <= 3.5
    assert_ack(v.take()[-1], mavlink2.MAV_MISSION_OPERATION_CANCELLED)


def test_out_of_order_item_is_dropped_and_the_expected_one_re_requested():
    v = Vehicle()
    full = [HOME, *MISSION_A[:3]]
    v.rx(mavlink2.MAVLink_mission_count_message(1, 1, 4, MISSION), now=0.0)
    v.take()
    v.rx(item_msg(0, full[0]), now=0.5)
    v.take()
    v.rx(item_msg(2, full[2]), now=0.7)  # skipped seq 1
    (req,) = v.take()
    assert_request(req, 1)  # re-requested, no error ACK
    v.rx(item_msg(3, full[3]), now=0.72)  # within the hold-off: not requested again
    assert v.take() == []
    for seq in (1, 2, 3):
        v.rx(item_msg(seq, full[seq]), now=1.0)
    replies = v.take()
    assert_ack(replies[-1], mavlink2.MAV_MISSION_ACCEPTED)
    assert all(same(a, b) for a, b in zip(v.proto.items[1:], full[1:], strict=True))


def test_duplicate_item_does_not_break_the_transfer():
    """The GCS answers a repeated request twice: the second copy arrives after the vehicle
    has moved on. It must neither be stored twice nor end the upload with an error."""
    v = Vehicle(timeout_s=1.0)
    full = [HOME, *MISSION_A[:3]]
    v.rx(mavlink2.MAVLink_mission_count_message(1, 1, 4, MISSION), now=0.0)
    v.rx(item_msg(0, full[0]), now=0.1)
    v.proto.tick(1.2)  # request 1 repeated (the answer was only slow)
    v.rx(item_msg(1, full[1]), now=1.25)  # answer to the first request
    v.rx(item_msg(1, full[1]), now=1.26)  # answer to the repeat: a duplicate
    v.rx(item_msg(2, full[2]), now=1.3)
    v.rx(item_msg(2, full[2]), now=1.6)  # GCS re-sent it: our request for 3 was lost
    v.rx(item_msg(3, full[3]), now=1.7)
    sent = v.take()
    acks = [m for _, m in sent if m.get_type() == "MISSION_ACK"]
    assert [a.type for a in acks] == [mavlink2.MAV_MISSION_ACCEPTED]
    requests = [m.seq for _, m in sent if m.get_type() == "MISSION_REQUEST_INT"]
    assert requests == [0, 1, 1, 2, 3, 3]
    assert len(v.proto.items) == 4
    assert all(same(a, b) for a, b in zip(v.proto.items[1:], full[1:], strict=True))
    assert v.validated == [1, 2, 3]


def test_last_item_repeated_after_a_lost_final_ack_gets_the_ack_again():
    v = Vehicle()
    final = upload(v, MISSION_A[:2], now=5.0)
    assert_ack(final, mavlink2.MAV_MISSION_ACCEPTED)
    v.rx(item_msg(2, MISSION_A[1]), now=6.0)
    (again,) = v.take()
    assert_ack(again, mavlink2.MAV_MISSION_ACCEPTED)
    assert len(v.changes) == 1
    # any other stray item outside an upload is an error, as in ArduPilot
    v.rx(item_msg(1, MISSION_A[0]), now=6.1)
    (err,) = v.take()
    assert_ack(err, mavlink2.MAV_MISSION_ERROR)


# ------------------------------------------------------------ concurrent GCSs
def test_second_uploader_is_denied_and_the_first_completes():
    v = Vehicle()
    full = [HOME, *MISSION_A[:2]]
    v.rx(mavlink2.MAVLink_mission_count_message(1, 1, 3, MISSION), PEER_A)
    v.take()
    # another link, same ids (QGC and MAVProxy both default to 255)
    v.rx(mavlink2.MAVLink_mission_count_message(1, 1, 5, MISSION), PEER_B)
    (deny,) = v.take()
    assert_ack(deny, mavlink2.MAV_MISSION_DENIED, peer=PEER_B)
    # same link, another system
    v.rx(mavlink2.MAVLink_mission_count_message(1, 1, 5, MISSION), PEER_A, sysid=250)
    (deny,) = v.take()
    assert_ack(deny, mavlink2.MAV_MISSION_DENIED, target=(250, GCS_COMP))
    # its items are refused too, without disturbing the upload
    v.rx(item_msg(0, full[0]), PEER_B)
    (deny,) = v.take()
    assert_ack(deny, mavlink2.MAV_MISSION_DENIED, peer=PEER_B)
    # downloads and clears wait for the upload, as in ArduPilot
    v.rx(mavlink2.MAVLink_mission_request_list_message(1, 1, MISSION), PEER_B)
    assert_ack(v.take()[0], mavlink2.MAV_MISSION_DENIED, peer=PEER_B)
    v.rx(mavlink2.MAVLink_mission_request_int_message(1, 1, 0, MISSION), PEER_B)
    assert_ack(v.take()[0], mavlink2.MAV_MISSION_DENIED, peer=PEER_B)
    v.rx(mavlink2.MAVLink_mission_clear_all_message(1, 1, MISSION), PEER_B)
    assert_ack(v.take()[0], mavlink2.MAV_MISSION_ERROR, peer=PEER_B)
    for seq in range(3):
        v.rx(item_msg(seq, full[seq]), PEER_A)
    assert_ack(v.take()[-1], mavlink2.MAV_MISSION_ACCEPTED)
    assert len(v.proto.items) == 3
    # now B may upload
    assert_ack(upload(v, MISSION_A, peer=PEER_B), mavlink2.MAV_MISSION_ACCEPTED, peer=PEER_B)
    assert len(v.proto.items) == 1 + len(MISSION_A)


def test_the_uploader_may_restart_with_a_new_count():
    v = Vehicle()
    v.rx(mavlink2.MAVLink_mission_count_message(1, 1, 4, MISSION))
    v.rx(item_msg(0, HOME))
    v.take()
    assert_ack(upload(v, MISSION_A[:1]), mavlink2.MAV_MISSION_ACCEPTED)
    assert len(v.proto.items) == 2


def test_gcs_cancel_and_vanished_peer_leave_the_mission_untouched():
    v = Vehicle()
    upload(v, MISSION_A)
    before = v.proto.items
    v.rx(mavlink2.MAVLink_mission_count_message(1, 1, 3, MISSION))
    v.rx(item_msg(0, HOME))
    v.rx(mavlink2.MAVLink_mission_ack_message(
        1, 1, mavlink2.MAV_MISSION_OPERATION_CANCELLED, MISSION))
    assert not v.proto.upload_in_progress
    v.rx(mavlink2.MAVLink_mission_count_message(1, 1, 3, MISSION), PEER_B)
    v.take()
    v.proto.peer_closed(PEER_B)
    assert not v.proto.upload_in_progress
    v.proto.tick(100.0)
    assert v.take() == []
    assert v.proto.items == before


# ---------------------------------------------------------------- validation
def test_validation_failure_aborts_and_keeps_the_old_mission():
    def validate(seq, item):
        if item.command == mavlink2.MAV_CMD_NAV_LOITER_TURNS:
            return mavlink2.MAV_MISSION_UNSUPPORTED, f"item {seq}: loiter unsupported"
        return None

    v = Vehicle(validate=validate)
    assert_ack(upload(v, MISSION_A), mavlink2.MAV_MISSION_ACCEPTED)
    old = v.proto.items
    bad = [waypoint(47.4, 8.5, 30.0),
           MissionItem(mavlink2.MAV_CMD_NAV_LOITER_TURNS, REL_ALT_INT, param1=2.0),
           waypoint(47.5, 8.5, 30.0)]
    v.validated.clear()
    final = upload(v, bad)
    assert_ack(final, mavlink2.MAV_MISSION_UNSUPPORTED)
    assert v.validated == [1, 2]  # aborted right away
    assert v.texts[-1] == (mavlink2.MAV_SEVERITY_WARNING, "item 2: loiter unsupported")
    assert not v.proto.upload_in_progress
    new = v.proto.items
    assert len(new) == len(old) and all(same(a, b) for a, b in zip(new, old, strict=True))
    assert len(v.changes) == 1
    # the rest of that GCS's upload is refused
    v.rx(item_msg(3, bad[2]))
    assert_ack(v.take()[0], mavlink2.MAV_MISSION_ERROR)


def test_generic_check_failure_aborts_without_asking_the_validator():
    v = Vehicle()
    upload(v, MISSION_A[:1])
    v.validated.clear()
    final = upload(v, [waypoint(47.4, 8.5, 30.0),
                       MissionItem(WP, REL_ALT_INT, param1=math.nan, x=1, y=1)])
    assert_ack(final, mavlink2.MAV_MISSION_INVALID_PARAM1)
    assert v.validated == [1]
    assert v.texts[-1][0] == mavlink2.MAV_SEVERITY_WARNING and "param1" in v.texts[-1][1]
    assert len(v.proto.items) == 2


def test_unconvertible_float_item_aborts():
    v = Vehicle()
    v.rx(mavlink2.MAVLink_mission_count_message(1, 1, 2, MISSION))
    v.rx(item_msg(0, HOME))
    v.take()
    v.rx(mavlink2.MAVLink_mission_item_message(1, 1, 1, REL_ALT, WP, 0, 1, 0, 0, 0, 0,
                                               math.inf, 8.0, 10.0))
    (ack,) = v.take()
    assert_ack(ack, mavlink2.MAV_MISSION_INVALID_PARAM5_X)
    assert v.proto.items == [HOME]


def test_a_validator_that_raises_rejects_the_item():
    def validate(seq, item):
        raise ZeroDivisionError("oops")

    v = Vehicle(validate=validate)
    assert_ack(upload(v, MISSION_A[:1]), mavlink2.MAV_MISSION_ERROR)
    assert v.proto.items == [HOME]


# ------------------------------------------------------------------- download
def download(v: Vehicle, int_variant=True, peer=PEER_A):
    v.rx(mavlink2.MAVLink_mission_request_list_message(1, 1, MISSION), peer)
    (entry,) = v.take()
    p, count = entry
    assert p == peer and count.get_type() == "MISSION_COUNT"
    assert (count.target_system, count.target_component) == (GCS_SYS, GCS_COMP)
    assert count.mission_type == MISSION
    out = []
    for seq in range(count.count):
        cls = (mavlink2.MAVLink_mission_request_int_message if int_variant
               else mavlink2.MAVLink_mission_request_message)
        v.rx(cls(1, 1, seq, MISSION), peer)
        (entry,) = v.take()
        p, m = entry
        assert p == peer
        assert m.get_type() == ("MISSION_ITEM_INT" if int_variant else "MISSION_ITEM")
        assert (m.seq, m.target_system, m.target_component) == (seq, GCS_SYS, GCS_COMP)
        out.append(m)
    v.rx(mavlink2.MAVLink_mission_ack_message(1, 1, mavlink2.MAV_MISSION_ACCEPTED, MISSION),
         peer)
    assert v.take() == []  # the GCS's closing ACK is consumed silently
    return out


def test_download_int_variant_returns_what_was_uploaded():
    v = Vehicle()
    upload(v, MISSION_A)
    got = [from_message(m) for m in download(v)]
    assert got[0] == HOME
    assert all(same(a, b) for a, b in zip(got[1:], MISSION_A, strict=True))


def test_download_float_variant_scales_back():
    v = Vehicle()
    upload(v, MISSION_A)
    msgs = download(v, int_variant=False)
    for m, item in zip(msgs, v.proto.items, strict=True):
        scale = 1e-7 if item.frame in (0, 3, 5, 6, 10, 11) else 1.0
        assert m.x == f32(item.x * scale) and m.y == f32(item.y * scale)
        assert m.command == item.command and m.frame == item.frame


def test_download_before_home_is_set_gives_count_1_with_a_zero_home():
    sent = []
    proto = MissionProtocol(lambda p, m: sent.append(wire(m, 1, 1)), lambda s, t: None,
                            lambda s, i: None, lambda items: None)
    proto.handle(PEER_A, wire(mavlink2.MAVLink_mission_request_list_message(1, 1)), 0.0)
    assert sent[-1].count == 1
    proto.handle(PEER_A, wire(mavlink2.MAVLink_mission_request_int_message(1, 1, 0)), 0.0)
    home = sent[-1]
    assert (home.command, home.frame, home.x, home.y, home.z) == (WP, 0, 0, 0, 0.0)


def test_set_home_shows_in_downloads_and_current_flag():
    v = Vehicle()
    upload(v, MISSION_A[:2])
    v.proto.set_home(home_item(-33.8688, 151.2093, 12.0))
    v.proto.current_seq = 2
    msgs = download(v)
    assert (msgs[0].x, msgs[0].y, msgs[0].z) == (-338688000, 1512093000, 12.0)
    assert [m.current for m in msgs] == [0, 0, 1]


def test_out_of_range_request_is_invalid_sequence():
    v = Vehicle()
    upload(v, MISSION_A[:2])
    v.rx(mavlink2.MAVLink_mission_request_int_message(1, 1, 3, MISSION))
    (ack,) = v.take()
    assert_ack(ack, mavlink2.MAV_MISSION_INVALID_SEQUENCE)
    v.rx(mavlink2.MAVLink_mission_request_message(1, 1, 65535, MISSION))
    (ack,) = v.take()
    assert_ack(ack, mavlink2.MAV_MISSION_INVALID_SEQUENCE)


# ---------------------------------------------------------- clear, types, targets
@pytest.mark.parametrize("mission_type", [MISSION, mavlink2.MAV_MISSION_TYPE_ALL])
def test_clear_all(mission_type):
    v = Vehicle()
    upload(v, MISSION_A)
    v.rx(mavlink2.MAVLink_mission_clear_all_message(1, 1, mission_type))
    (ack,) = v.take()
    assert_ack(ack, mavlink2.MAV_MISSION_ACCEPTED, mission_type=mission_type)
    assert v.proto.items == [HOME] and v.changes[-1] == [HOME]


def fence_items() -> list[MissionItem]:
    """An inclusion polygon of four vertices and an exclusion circle of 5 m (MAVLink's
    fence commands, as QGC and MAVProxy upload them)."""
    corners = [(47.3975, 8.5452), (47.3975, 8.5460), (47.3981, 8.5460), (47.3981, 8.5452)]
    poly = [MissionItem(command=mavlink2.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION,
                        frame=mavlink2.MAV_FRAME_GLOBAL_INT, param1=4, x=degrees_to_e7(la),
                        y=degrees_to_e7(lo)) for la, lo in corners]
    circle = MissionItem(command=mavlink2.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION,
                         frame=mavlink2.MAV_FRAME_GLOBAL_INT, param1=5.0,
                         x=degrees_to_e7(47.3978), y=degrees_to_e7(8.5456))
    return [*poly, circle]


@pytest.mark.parametrize("mission_type", [FENCE, RALLY])
def test_fence_and_rally_are_stores_of_their_own(mission_type):
    """Uploaded from seq 0 (no home), checked by validate_other, downloaded back as sent,
    cleared; the mission is untouched."""
    others: list = []
    checked: list = []
    v = Vehicle(validate_other=lambda t, seq, item: checked.append((t, seq)),
                on_other_changed=lambda t, items: others.append((t, items)))
    upload(v, MISSION_A)
    before, changes = v.proto.items, len(v.changes)
    items = fence_items() if mission_type == FENCE else [
        MissionItem(command=mavlink2.MAV_CMD_NAV_RALLY_POINT, frame=REL_ALT_INT, z=12.0,
                    x=degrees_to_e7(47.3979), y=degrees_to_e7(8.5457))]
    v.rx(mavlink2.MAVLink_mission_count_message(1, 1, len(items), mission_type))
    for seq in range(len(items)):
        (entry,) = v.take()
        req = entry[1]
        assert (req.get_type(), req.seq, req.mission_type) == ("MISSION_REQUEST_INT", seq,
                                                               mission_type)
        v.rx(item_msg(seq, items[seq], mission_type=mission_type))
    assert_ack(v.take()[0], mavlink2.MAV_MISSION_ACCEPTED, mission_type=mission_type)
    assert checked == [(mission_type, i) for i in range(len(items))]
    assert others[-1] == (mission_type, items) and v.proto.stored(mission_type) == items
    v.rx(mavlink2.MAVLink_mission_request_list_message(1, 1, mission_type))
    assert v.take()[0][1].count == len(items)
    for seq, item in enumerate(items):
        v.rx(mavlink2.MAVLink_mission_request_int_message(1, 1, seq, mission_type))
        got = v.take()[0][1]
        assert (got.command, got.x, got.y, got.mission_type) == (item.command, item.x,
                                                                 item.y, mission_type)
    v.rx(mavlink2.MAVLink_mission_request_int_message(1, 1, len(items), mission_type))
    assert_ack(v.take()[0], mavlink2.MAV_MISSION_INVALID_SEQUENCE, mission_type=mission_type)
    v.rx(mavlink2.MAVLink_mission_clear_all_message(1, 1, mission_type))
    assert_ack(v.take()[0], mavlink2.MAV_MISSION_ACCEPTED, mission_type=mission_type)
    assert v.proto.stored(mission_type) == [] and others[-1] == (mission_type, [])
    assert v.proto.items == before and len(v.changes) == changes


def test_a_refused_fence_item_aborts_its_upload_only():
    v = Vehicle(validate_other=lambda t, seq, item: (mavlink2.MAV_MISSION_INVALID_PARAM1,
                                                     "bad vertex count") if seq == 2 else None)
    items = fence_items()
    v.rx(mavlink2.MAVLink_mission_count_message(1, 1, len(items), FENCE))
    for seq in range(3):
        v.take()
        v.rx(item_msg(seq, items[seq], mission_type=FENCE))
    assert_ack(v.take()[0], mavlink2.MAV_MISSION_INVALID_PARAM1, mission_type=FENCE)
    assert v.proto.stored(FENCE) == [] and not v.proto.upload_in_progress


@pytest.mark.parametrize("msg", [
    mavlink2.MAVLink_mission_request_list_message(1, 1, 7),
    mavlink2.MAVLink_mission_count_message(1, 1, 3, 7),
    mavlink2.MAVLink_mission_count_message(1, 1, 3, mavlink2.MAV_MISSION_TYPE_ALL),
    mavlink2.MAVLink_mission_clear_all_message(1, 1, 3),
    mavlink2.MAVLink_mission_request_int_message(1, 1, 0, 9),
    mavlink2.MAVLink_mission_write_partial_list_message(1, 1, 1, 2, MISSION),
])
def test_unknown_mission_types_and_partial_lists_are_unsupported(msg):
    v = Vehicle()
    assert v.rx(msg)
    (ack,) = v.take()
    assert_ack(ack, mavlink2.MAV_MISSION_UNSUPPORTED, mission_type=msg.mission_type)
    assert not v.proto.upload_in_progress


@pytest.mark.parametrize("target", [(2, 1), (1, 190), (255, 0)])
def test_messages_for_others_are_not_consumed(target):
    v = Vehicle()
    msgs = [mavlink2.MAVLink_mission_request_list_message(*target, MISSION),
            mavlink2.MAVLink_mission_count_message(*target, 3, MISSION),
            mavlink2.MAVLink_mission_clear_all_message(*target, MISSION),
            item_msg(0, HOME, target=target)]
    for m in msgs:
        assert v.rx(m) is False
    assert v.take() == [] and not v.proto.upload_in_progress


def test_broadcast_target_is_served():
    v = Vehicle()
    assert v.rx(mavlink2.MAVLink_mission_request_list_message(0, 0, MISSION))
    assert v.take()[0][1].count == 1


def test_guided_items_and_other_messages_are_left_to_the_caller():
    v = Vehicle()
    for current in (2, 3):
        assert v.rx(item_msg(0, waypoint(47.4, 8.5, 20.0), current=current)) is False
    assert v.rx(mavlink2.MAVLink_mission_set_current_message(1, 1, 2)) is False
    assert v.rx(mavlink2.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3)) is False
    assert v.take() == []


def test_tolerates_a_mavlink1_peer_and_unpacked_messages():
    v = Vehicle()
    packer = mavlink2.MAVLink(None, srcSystem=GCS_SYS, srcComponent=GCS_COMP)
    packer.WIRE_PROTOCOL_VERSION = "1.0"
    buf = mavlink2.MAVLink_mission_request_list_message(1, 1).pack(packer,
                                                                    force_mavlink1=True)
    m = mavlink2.MAVLink(None).parse_buffer(buf)[0]
    assert v.proto.handle(PEER_A, m, 0.0)
    assert v.take()[0][1].count == 1
    # a message never packed has no source ids: replies then target 0 (broadcast)
    assert v.proto.handle(PEER_A, mavlink2.MAVLink_mission_request_list_message(1, 1), 0.0)
    assert v.take()[0][1].target_system == 0


# ------------------------------------------------------------------ robustness
_MISSION_MSGS = st.one_of(
    st.builds(mavlink2.MAVLink_mission_count_message, st.sampled_from([0, 1]),
              st.sampled_from([0, 1]), st.integers(0, 800), st.integers(0, 255)),
    st.builds(mavlink2.MAVLink_mission_request_list_message, st.sampled_from([0, 1]),
              st.sampled_from([0, 1]), st.integers(0, 255)),
    st.builds(mavlink2.MAVLink_mission_request_int_message, st.just(1), st.just(1),
              st.integers(0, 65535), st.integers(0, 255)),
    st.builds(mavlink2.MAVLink_mission_request_message, st.just(1), st.just(1),
              st.integers(0, 65535), st.integers(0, 255)),
    st.builds(mavlink2.MAVLink_mission_ack_message, st.just(1), st.just(1),
              st.integers(0, 255), st.integers(0, 255)),
    st.builds(mavlink2.MAVLink_mission_clear_all_message, st.just(1), st.just(1),
              st.integers(0, 255)),
    st.builds(mavlink2.MAVLink_mission_item_int_message, st.just(1), st.just(1),
              st.integers(0, 6), st.integers(0, 255), st.integers(0, 65535),
              st.integers(0, 255), st.integers(0, 255), st.floats(width=32),
              st.floats(width=32), st.floats(width=32), st.floats(width=32),
              st.integers(-(2**31), 2**31 - 1), st.integers(-(2**31), 2**31 - 1),
              st.floats(width=32), st.integers(0, 255)),
    st.builds(mavlink2.MAVLink_mission_item_message, st.just(1), st.just(1),
              st.integers(0, 6), st.integers(0, 255), st.integers(0, 65535),
              st.integers(0, 255), st.integers(0, 255), st.floats(width=32),
              st.floats(width=32), st.floats(width=32), st.floats(width=32),
              st.floats(width=32), st.floats(width=32), st.floats(width=32),
              st.integers(0, 255)),
)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(script=st.lists(st.tuples(st.sampled_from([PEER_A, PEER_B]), _MISSION_MSGS,
                                 st.floats(0, 3)), max_size=25))
def test_never_raises_and_every_reply_is_valid_mavlink(script):
    """Random traffic from two links: nothing raises, every reply packs (Vehicle._send
    round-trips it), a NaN/inf item is never stored, and home never moves."""
    v = Vehicle()
    t = 0.0
    for peer, msg, dt in script:
        t += dt
        v.rx(msg, peer, t)
        v.proto.tick(t)
    assert v.proto.items[0] == HOME
    for item in v.proto.items:
        assert check_item(item) is None
