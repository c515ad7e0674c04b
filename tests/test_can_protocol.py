"""The winder bus protocol (tuavdefs.can_protocol) against its DBC, decoded by cantools."""

import math
import struct

import cantools
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tuavdefs import can_protocol as cp
from tuavdefs.can_protocol import (
    MESSAGES,
    WINCH_SENSOR_NODE_ID_DEFAULT,
    CanFrameError,
    Cmd,
    ODriveError,
    decode_signals,
    encode_signals,
    frame_id,
    split_id,
)

SENDER = {cp.Direction.HOST_TO_AXIS: "Ground_Station",
          cp.Direction.AXIS_TO_HOST: "ODrive_Axis0",
          cp.Direction.SENSOR_TO_HOST: "Winch_Sensors"}
NAMES = [m.name for m in MESSAGES]


@pytest.fixture(scope="module")
def db():
    return cantools.database.load_file(cp.dbc_path(), strict=True)


def _signal_strategy(sig):
    if sig.is_float:
        assert sig.length == 32
        return st.floats(width=32, allow_nan=False, allow_infinity=False)
    lo = 0 if sig.minimum is None else int(sig.minimum)
    hi = (1 << sig.length) - 1 if sig.maximum is None else int(sig.maximum)
    return st.integers(lo, hi)


def test_dbc_is_packaged_and_loads_strictly(db):
    path = cp.dbc_path()
    assert path.is_file() and path.name == "tuav_winder.dbc"
    assert {n.name for n in db.nodes} == {"ODrive_Axis0", "Winch_Sensors", "Ground_Station"}


def test_dbc_and_message_table_agree(db):
    assert sorted(m.name for m in db.messages) == sorted(NAMES)
    for spec in MESSAGES:
        msg = db.get_message_by_name(spec.name)
        assert msg.frame_id == spec.frame_id(), spec.name
        assert not msg.is_extended_frame
        assert msg.length == spec.dlc, spec.name
        expected_cycle = None if spec.period_s is None else round(spec.period_s * 1000)
        assert msg.cycle_time == expected_cycle, spec.name
        assert [s.name for s in msg.signals] == list(spec.signals), spec.name
        assert msg.senders == [SENDER[spec.direction]], spec.name
        rtr = msg.dbc.attributes.get("TUAV_RtrRequestable")
        assert (rtr is not None and rtr.value == 1) == spec.rtr, spec.name
        for sig in msg.signals:
            assert sig.comment, f"{spec.name}.{sig.name} has no comment"
            assert sig.byte_order == "little_endian"
        # the shortest payload a decoder accepts covers exactly the signals
        extent = max((s.start + s.length for s in msg.signals), default=0)
        assert spec.min_len == math.ceil(extent / 8), spec.name
        assert spec.min_len <= spec.dlc <= 8


def test_message_table_facts():
    by = cp.MESSAGES_BY_NAME
    assert by["Heartbeat"].period_s == 0.1 and by["Heartbeat"].rtr
    assert by["Get_Encoder_Estimates"].period_s == 0.01
    assert by["Estop"].dlc == 0 and by["Clear_Errors"].dlc == 1
    assert by["Winch_Heartbeat"].dlc == 2 and by["Winch_Tension"].dlc == 8
    requestable = {m.name for m in MESSAGES if m.rtr}
    assert requestable == {"Heartbeat", "Get_Error", "Get_Encoder_Estimates", "Get_Iq",
                           "Get_Bus_Voltage_Current", "Get_Torques"}
    assert all(m.direction is cp.Direction.AXIS_TO_HOST for m in MESSAGES if m.rtr)
    assert {m.cmd_id for m in MESSAGES if m.node is cp.NodeKind.AXIS} == {int(c) for c in Cmd}
    assert ODriveError.WATCHDOG_TIMER_EXPIRED == 0x01000000
    assert ODriveError.ESTOP_REQUESTED == 0x02000000


@pytest.mark.parametrize("name", NAMES)
@settings(max_examples=150, deadline=None)
@given(data=st.data())
def test_ours_and_cantools_agree(db, name, data):
    msg = db.get_message_by_name(name)
    values = {s.name: data.draw(_signal_strategy(s), label=s.name) for s in msg.signals}
    spec = cp.message_spec(name)

    ours = encode_signals(name, values)
    theirs = msg.encode(values, scaling=True, strict=True)
    assert len(ours) == spec.dlc
    assert ours == bytes(theirs)  # same bits, same zero padding

    decoded_by_cantools = msg.decode(ours, decode_choices=False)
    decoded_by_us = decode_signals(name, bytes(theirs))
    for key, value in values.items():
        assert decoded_by_cantools[key] == value, key
        assert decoded_by_us[key] == value, key
        assert type(decoded_by_us[key]) in (int, float, bool)


def test_nan_and_inf_decode_as_such(db):
    for value in (math.nan, math.inf, -math.inf):
        payload = cp.encode_set_input_torque(value)
        ours = cp.decode_set_input_torque(payload)
        theirs = db.get_message_by_name("Set_Input_Torque").decode(payload)["Input_Torque"]
        if math.isnan(value):
            assert math.isnan(ours) and math.isnan(theirs)
        else:
            assert ours == theirs == value
    pos, vel = cp.decode_encoder_estimates(cp.encode_encoder_estimates(math.nan, 1.0))
    assert math.isnan(pos) and vel == 1.0


def test_known_payloads():
    # the reference's candump example: Set_Input_Torque 1.0 N m on node 0
    assert frame_id(0, Cmd.SET_INPUT_TORQUE) == 0x00E
    assert cp.encode_set_input_torque(1.0).hex() == "0000803f00000000"
    assert cp.encode_heartbeat(0x01000000, 1, 3, True).hex() == "0000000101030100"
    assert cp.decode_heartbeat(bytes.fromhex("0000000101030100")) == (0x01000000, 1, 3, True)
    assert cp.encode_set_axis_state(8) == b"\x08" + bytes(7)
    # ODrive's own examples send a 4-byte Set_Axis_State and unpack 7 heartbeat bytes
    assert cp.decode_set_axis_state(struct.pack("<I", 8)) == 8
    assert cp.decode_heartbeat(bytes.fromhex("00000000080001")).axis_state == 8
    assert cp.encode_estop() == b""
    assert cp.encode_clear_errors() == b"\x00"
    assert cp.encode_set_controller_mode(1, 6) == struct.pack("<II", 1, 6)
    assert cp.decode_winch_heartbeat(bytes([0b1011, 7])) == (True, True, False, True, 7)
    assert cp.encode_winch_tension(10.0, True) == struct.pack("<f", 10.0) + b"\x01\x00\x00\x00"
    assert cp.encode_winch_tension(10.0, False, 70_000) == (
        struct.pack("<fBHx", 10.0, 0, 70_000 - 65_536))           # the clock wraps
    assert cp.decode_winch_tension(cp.encode_winch_tension(1.5, True, 1234)) == (1.5, True, 1234)
    length, speed = cp.decode_winch_length(cp.encode_winch_length(12.25, -0.5))
    assert (length, speed) == (12.25, -0.5)


@pytest.mark.parametrize("spec", MESSAGES, ids=NAMES)
def test_wrong_length_raises_named_error(spec):
    assert issubclass(CanFrameError, ValueError)
    with pytest.raises(CanFrameError):
        spec.decode(bytes(9))
    if spec.min_len > 0:
        with pytest.raises(CanFrameError):
            spec.decode(bytes(spec.min_len - 1))
    spec.decode(bytes(spec.min_len))  # the shortest accepted payload
    spec.decode(bytes(8))


def test_encoders_reject_out_of_range():
    with pytest.raises(ValueError):
        cp.encode_set_axis_state(-1)
    with pytest.raises(ValueError):
        cp.encode_set_axis_state(1 << 32)
    with pytest.raises(ValueError):
        cp.encode_set_input_torque(1e39)  # beyond f32
    with pytest.raises(ValueError):
        cp.encode_winch_heartbeat(False, True, False, False, 256)
    with pytest.raises(KeyError):
        encode_signals("Set_Limits", {"Velocity_Limit": 1.0})


def test_frame_ids():
    assert frame_id(0, 0x01) == 0x001
    assert frame_id(1, 0x0D) == 0x02D
    assert frame_id(0x3F, 0x1F) == 0x7FF
    for node in range(0x40):
        for cmd in range(0x20):
            assert split_id(frame_id(node, cmd)) == (node, cmd)
    for bad in ((0x40, 0), (-1, 0), (0, 0x20), (0, -1)):
        with pytest.raises(ValueError):
            frame_id(*bad)
    with pytest.raises(ValueError):
        split_id(0x800)


def test_sensor_node_never_collides_with_an_axis_node():
    sensor_ids = {m.frame_id() for m in MESSAGES if m.node is cp.NodeKind.SENSOR}
    assert sensor_ids == {0x601, 0x602, 0x603, 0x604}
    whole_sensor_node = {frame_id(WINCH_SENSOR_NODE_ID_DEFAULT, c) for c in range(0x20)}
    for node in range(0x30):
        axis_ids = {frame_id(node, c) for c in range(0x20)}
        assert not axis_ids & whole_sensor_node, node
        assert all(split_id(i)[0] != node for i in sensor_ids)


def test_spec_for_id():
    assert cp.spec_for_id(0x00E).name == "Set_Input_Torque"
    assert cp.spec_for_id(0x602).name == "Winch_Length"
    assert cp.spec_for_id(0x0AE, axis_node_id=5).name == "Set_Input_Torque"
    assert cp.spec_for_id(0x00D) is None  # Set_Input_Vel: not used here
    assert cp.spec_for_id(0x02E) is None  # another node


def test_get_iq_from_the_plants_axis_on_a_real_bus_decodes_with_the_dbc(db):
    """The plant's winder node sends Get_Iq cyclic (the ground station's second tension
    source); the frame read off a python-can bus decodes with cantools to the motor's
    applied torque over the torque constant."""
    from sitl.odrive_axis import OdriveAxis
    from tuavdefs.canbus import CanLink

    node, host = CanLink("virtual:iq_frame"), CanLink("virtual:iq_frame")
    try:
        axis = OdriveAxis(torque_constant_nm_a=0.1)
        node.send_frames(axis.tick(0.0, 3.0, -0.5, -0.42, 48.0))
        frames = []
        while (rx := host.recv(0.1)) is not None:
            frames.append(rx)
    finally:
        node.close()
        host.close()
    iq = [f for f in frames if f.arbitration_id == cp.frame_id(0, cp.Cmd.GET_IQ)]
    assert len(iq) == 1 and not iq[0].is_remote and len(iq[0].data) == 8
    decoded = db.get_message_by_name("Get_Iq").decode(bytes(iq[0].data))
    assert decoded["Iq_Measured"] == pytest.approx(-4.2, rel=1e-6)      # -0.42 N m / 0.1
    assert decoded["Iq_Setpoint"] == 0.0                                # not armed
    assert cp.decode_iq(bytes(iq[0].data)).measured_a == decoded["Iq_Measured"]
