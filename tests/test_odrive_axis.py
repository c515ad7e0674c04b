"""The simulated ODrive axis and winch sensors (sitl.odrive_axis), checked through their CAN
frames; replies are decoded with cantools from the DBC, independently of our decoders."""

import math
import struct

import cantools
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sitl.odrive_axis import Frame, OdriveAxis, WinchSensors
from tuavdefs import can_protocol as cp
from tuavdefs.can_protocol import (
    AxisState,
    Cmd,
    ControlMode,
    InputMode,
    ODriveError,
    ProcedureResult,
    frame_id,
)

DB = cantools.database.load_file(cp.dbc_path(), strict=True)
KT = 0.1  # torque constant used below [N m/A]


def f32(x: float) -> float:
    return struct.unpack("<f", struct.pack("<f", x))[0]


def decode(frame: Frame) -> dict:
    """Decode a reply with cantools (by name, so any node id works)."""
    assert not frame.is_remote
    node, cmd = cp.split_id(frame.arbitration_id)
    name = {m.cmd_id: m.name for m in cp.MESSAGES if m.node == "axis"}[cmd]
    return DB.get_message_by_name(name).decode(frame.data, decode_choices=False)


class Host:
    """A minimal CAN host talking to one axis, in simulated time."""

    def __init__(self, axis: OdriveAxis, node_id: int = 0):
        self.axis, self.node = axis, node_id

    def send(self, t, cmd, data=b"", rtr=False):
        return self.axis.handle(t, frame_id(self.node, cmd), data, rtr)

    def request(self, t, cmd):
        replies = self.send(t, cmd, bytes(8), rtr=True)
        assert len(replies) == 1 and replies[0].arbitration_id == frame_id(self.node, cmd)
        return decode(replies[0])

    def arm(self, t):
        self.send(t, Cmd.SET_CONTROLLER_MODE,
                  cp.encode_set_controller_mode(ControlMode.TORQUE, InputMode.PASSTHROUGH))
        self.send(t, Cmd.SET_AXIS_STATE, cp.encode_set_axis_state(AxisState.CLOSED_LOOP_CONTROL))

    def torque(self, t, tau):
        self.send(t, Cmd.SET_INPUT_TORQUE, cp.encode_set_input_torque(tau))


def make(**kw):
    kw.setdefault("torque_constant_nm_a", KT)
    kw.setdefault("torque_limit_nm", 5.0)
    axis = OdriveAxis(**kw)
    return axis, Host(axis, axis.node_id)


def run_ticks(axis, t0, t1, dt=0.001):
    """Tick from t0 (inclusive) to t1 (exclusive); return [(t, frames)]."""
    out = []
    n = round((t1 - t0) / dt)
    for k in range(n):
        t = t0 + k * dt
        out.append((t, axis.tick(t, 0.0, 0.0, 0.0, 48.0)))
    return out


def test_state_machine_idle_closed_loop_idle():
    axis, host = make()
    assert axis.state == AxisState.IDLE and not axis.enabled
    assert host.request(0.0, Cmd.HEARTBEAT)["Axis_State"] == AxisState.IDLE
    host.send(0.0, Cmd.SET_AXIS_STATE, cp.encode_set_axis_state(8))
    assert axis.enabled
    hb = host.request(0.01, Cmd.HEARTBEAT)
    assert hb["Axis_State"] == AxisState.CLOSED_LOOP_CONTROL and hb["Axis_Error"] == 0
    assert hb["Procedure_Result"] == ProcedureResult.BUSY
    host.send(0.02, Cmd.SET_AXIS_STATE, struct.pack("<I", 1))  # 4-byte form, as ODrive's examples
    assert not axis.enabled
    assert host.request(0.03, Cmd.HEARTBEAT)["Axis_State"] == AxisState.IDLE


def test_torque_acts_only_in_closed_loop_and_torque_mode():
    axis, host = make()
    host.torque(0.0, 2.0)
    assert axis.input_torque_nm == 2.0 and axis.torque_command_nm == 0.0  # IDLE
    host.send(0.0, Cmd.SET_AXIS_STATE, cp.encode_set_axis_state(8))
    assert axis.enabled and axis.torque_command_nm == 0.0  # position mode (power-up default)
    host.send(0.01, Cmd.SET_CONTROLLER_MODE, cp.encode_set_controller_mode(1, 1))
    assert axis.torque_command_nm == 2.0
    host.send(0.02, Cmd.SET_CONTROLLER_MODE, cp.encode_set_controller_mode(2, 1))
    assert axis.torque_command_nm == 0.0  # velocity control is not simulated
    host.send(0.03, Cmd.SET_CONTROLLER_MODE, cp.encode_set_controller_mode(1, 1))
    host.send(0.04, Cmd.SET_AXIS_STATE, cp.encode_set_axis_state(1))
    assert axis.torque_command_nm == 0.0


def test_torque_clamped_to_limit_and_set_limits():
    axis, host = make(torque_limit_nm=5.0)
    host.arm(0.0)
    host.torque(0.0, 10.0)
    assert axis.torque_command_nm == 5.0
    host.torque(0.0, -10.0)
    assert axis.torque_command_nm == -5.0
    host.send(0.0, Cmd.SET_LIMITS, cp.encode_set_limits(12.5, 20.0))  # 20 A * 0.1 N m/A
    assert axis.torque_limit_nm == pytest.approx(2.0)
    assert axis.vel_limit_rev_s == 12.5
    assert axis.torque_command_nm == pytest.approx(-2.0)
    host.torque(0.0, 1.5)
    assert axis.torque_command_nm == 1.5


def test_torque_ramp_input_mode():
    axis, host = make(torque_ramp_rate_nm_s=10.0, watchdog_timeout_s=0.0)
    host.send(0.0, Cmd.SET_CONTROLLER_MODE, cp.encode_set_controller_mode(1, 6))
    host.send(0.0, Cmd.SET_AXIS_STATE, cp.encode_set_axis_state(8))
    host.torque(0.0, 2.0)
    run_ticks(axis, 0.0, 0.101)
    assert axis.torque_command_nm == pytest.approx(1.0, abs=1e-6)  # 10 N m/s for 0.1 s
    run_ticks(axis, 0.101, 0.5)
    assert axis.torque_command_nm == pytest.approx(2.0)


def _trip_time(axis, t0, t1, feed=None):
    """Tick at 1 kHz; ``feed(t)`` is called before each tick; return when the axis fell out of
    closed loop (or None)."""
    n = round((t1 - t0) * 1000)
    for k in range(n):
        t = t0 + k * 0.001
        if feed is not None:
            feed(t)
        axis.tick(t, 0.0, 0.0, 0.0, 48.0)
        if not axis.enabled:
            return t
    return None


@pytest.mark.parametrize("timeout", [0.1, 0.25])
def test_watchdog_trips_after_timeout_without_host_frames(timeout):
    axis, host = make(watchdog_timeout_s=timeout)
    host.arm(0.0)
    host.torque(0.0, 1.0)
    assert axis.torque_command_nm == 1.0
    t_trip = _trip_time(axis, 0.0, 1.0)
    assert t_trip is not None and timeout < t_trip <= timeout + 0.0015
    assert axis.torque_command_nm == 0.0
    assert axis.active_errors & ODriveError.WATCHDOG_TIMER_EXPIRED
    hb = host.request(t_trip, Cmd.HEARTBEAT)
    assert hb["Axis_Error"] & 0x01000000 and hb["Axis_State"] == AxisState.IDLE
    err = host.request(t_trip, Cmd.GET_ERROR)
    assert err["Active_Errors"] == err["Disarm_Reason"] == 0x01000000


def test_watchdog_fed_by_any_host_data_frame_to_this_node():
    axis, host = make(watchdog_timeout_s=0.1)
    host.arm(0.0)
    feeders = [
        lambda t: host.torque(t, 1.0),
        lambda t: host.send(t, Cmd.SET_LIMITS, cp.encode_set_limits(10.0, 40.0)),
        lambda t: host.send(t, 0x0D, cp.encode_encoder_estimates(0, 0)),  # unknown here
        lambda t: host.send(t, Cmd.SET_INPUT_TORQUE, b"\x00"),  # malformed, still a feed
    ]
    k = iter(range(10**6))

    def feed(t):
        if round(t * 1000) % 50 == 0:
            feeders[next(k) % len(feeders)](t)

    assert _trip_time(axis, 0.0, 1.0, feed) is None
    assert axis.enabled and axis.active_errors == 0


@pytest.mark.parametrize("source", ["other_axis_node", "sensor_node", "own_echo"])
def test_watchdog_not_fed_by_other_nodes_or_echoes(source):
    axis, host = make(watchdog_timeout_s=0.1)
    sensors = WinchSensors()
    other = Host(axis, node_id=1)
    host.arm(0.0)

    def feed(t):
        if source == "other_axis_node":
            other.torque(t, 1.0)
            other.send(t, Cmd.SET_AXIS_STATE, cp.encode_set_axis_state(8))
        elif source == "sensor_node":
            for f in sensors.tick(t, 10.0, 0.0, 50.0, False, False, False):
                axis.handle(t, f.arbitration_id, f.data, f.is_remote)
        else:  # the axis's own transmissions heard back on a loop-back bus
            for f in axis.tick(t, 0.0, 0.0, 0.0, 48.0):
                axis.handle(t, f.arbitration_id, f.data, f.is_remote)

    t_trip = _trip_time(axis, 0.0, 1.0, feed)
    assert t_trip is not None and t_trip <= 0.1015
    assert axis.active_errors & ODriveError.WATCHDOG_TIMER_EXPIRED
    if source != "own_echo":
        assert sum(axis.counters.values()) == 0  # other nodes are ignored, not "bad"
        assert axis.rx_frames == 2  # only the host's arm() frames


def test_watchdog_not_fed_by_a_bystanders_polls():
    """A node polling the axis by remote request at 50 Hz while the host is silent: the
    polls are answered, and the axis still disarms on its watchdog (it kept its last
    torque before)."""
    axis, host = make(watchdog_timeout_s=0.1)
    host.arm(0.0)
    host.torque(0.0, 3.0)
    answers = []

    def poll(t):
        if round(t * 1000) % 20 == 0:
            for cmd in (Cmd.GET_ENCODER_ESTIMATES, Cmd.HEARTBEAT, Cmd.GET_TORQUES):
                answers.extend(axis.handle(t, (axis.node_id << 5) | cmd, b"", True))

    t_trip = _trip_time(axis, 0.0, 1.0, poll)
    assert t_trip is not None and t_trip <= 0.1015
    assert axis.active_errors & ODriveError.WATCHDOG_TIMER_EXPIRED
    assert axis.torque_command_nm == 0.0
    assert len(answers) >= 3 * 5           # every poll answered


def test_watchdog_recovery_needs_clear_errors_then_closed_loop():
    axis, host = make(watchdog_timeout_s=0.1)
    host.arm(0.0)
    host.torque(0.0, 1.0)
    t = _trip_time(axis, 0.0, 1.0)
    assert t is not None
    host.send(t + 0.01, Cmd.SET_AXIS_STATE, cp.encode_set_axis_state(8))
    assert not axis.enabled  # refused while the error is latched
    assert host.request(t + 0.01, Cmd.HEARTBEAT)["Procedure_Result"] == ProcedureResult.DISARMED
    host.send(t + 0.02, Cmd.CLEAR_ERRORS, cp.encode_clear_errors())
    assert not axis.enabled and axis.active_errors == 0  # still IDLE after clearing
    assert host.request(t + 0.02, Cmd.GET_ERROR) == {"Active_Errors": 0, "Disarm_Reason": 0}
    host.send(t + 0.03, Cmd.SET_AXIS_STATE, cp.encode_set_axis_state(8))
    assert axis.enabled and axis.torque_command_nm == 1.0


def test_late_frame_does_not_revive_an_expired_axis():
    axis, host = make(watchdog_timeout_s=0.1)
    host.arm(0.0)
    host.torque(0.5, 1.0)  # no tick in between: the expiry is noticed on this frame
    assert not axis.enabled
    assert axis.active_errors & ODriveError.WATCHDOG_TIMER_EXPIRED


def test_watchdog_disabled():
    axis, host = make(watchdog_timeout_s=0.0)
    host.arm(0.0)
    assert _trip_time(axis, 0.0, 1.0) is None


def test_estop():
    axis, host = make()
    host.arm(0.0)
    host.torque(0.0, 3.0)
    host.send(0.01, Cmd.ESTOP, cp.encode_estop())
    assert not axis.enabled and axis.torque_command_nm == 0.0
    err = host.request(0.02, Cmd.GET_ERROR)
    assert err["Active_Errors"] & 0x02000000 and err["Disarm_Reason"] & 0x02000000
    host.send(0.03, Cmd.SET_AXIS_STATE, cp.encode_set_axis_state(8))
    assert not axis.enabled
    host.send(0.04, Cmd.CLEAR_ERRORS, cp.encode_clear_errors(identify=True))
    host.send(0.05, Cmd.SET_AXIS_STATE, cp.encode_set_axis_state(8))
    assert axis.enabled and axis.torque_command_nm == 3.0


def test_rtr_replies_carry_the_right_values():
    axis, host = make(torque_limit_nm=5.0)
    host.arm(0.0)
    host.torque(0.0, 2.0)
    axis.tick(0.001, 12.5, -3.25, 1.75, 48.0)
    enc = host.request(0.002, Cmd.GET_ENCODER_ESTIMATES)
    assert enc == {"Pos_Estimate": 12.5, "Vel_Estimate": -3.25}
    tq = host.request(0.002, Cmd.GET_TORQUES)
    assert tq == {"Torque_Target": 2.0, "Torque_Estimate": 1.75}
    iq = host.request(0.002, Cmd.GET_IQ)
    assert iq == {"Iq_Setpoint": f32(2.0 / KT), "Iq_Measured": f32(1.75 / KT)}
    bus = host.request(0.002, Cmd.GET_BUS_VOLTAGE_CURRENT)
    assert bus["Bus_Voltage"] == 48.0
    # lossless power balance: tau * omega / V; negative here (the drum winds in against a
    # paying-out torque: the motor brakes the motion and regenerates)
    assert bus["Bus_Current"] == f32(1.75 * 2 * math.pi * -3.25 / 48.0)
    assert host.request(0.002, Cmd.GET_ERROR) == {"Active_Errors": 0, "Disarm_Reason": 0}
    hb = host.request(0.002, Cmd.HEARTBEAT)
    assert hb == {"Axis_Error": 0, "Axis_State": 8, "Procedure_Result": 1,
                  "Trajectory_Done_Flag": 1}
    # a zero-length data frame is also a request (ODrive accepts both)
    (reply,) = host.send(0.003, Cmd.GET_TORQUES, b"")
    assert decode(reply)["Torque_Target"] == 2.0
    assert sum(axis.counters.values()) == 0


def test_cyclic_frame_timing_over_one_second():
    axis, _ = make()
    frames = [f for _, fs in run_ticks(axis, 0.0, 1.0) for f in fs]
    ids = [f.arbitration_id for f in frames]
    assert ids.count(frame_id(0, Cmd.HEARTBEAT)) == 10
    assert ids.count(frame_id(0, Cmd.GET_ENCODER_ESTIMATES)) == 100
    assert ids.count(frame_id(0, Cmd.GET_IQ)) == 20      # the winder's second tension source
    assert len(frames) == 130
    # each Get_Iq comes just before the encoder frame of its instant (the host answers that)
    iq = frame_id(0, Cmd.GET_IQ)
    assert all(ids[i + 1] == frame_id(0, Cmd.GET_ENCODER_ESTIMATES)
               for i, f in enumerate(ids) if f == iq)
    assert not any(f.is_remote for f in frames)
    for f in frames:  # every cyclic frame decodes with the DBC
        decode(f)


def test_cyclic_frames_are_evenly_spaced_and_configurable():
    axis, _ = make(heartbeat_period_s=0.05, iq_period_s=None,
                   cyclic={Cmd.GET_TORQUES: 0.02, Cmd.GET_ENCODER_ESTIMATES: None})
    times = {}
    for t, fs in run_ticks(axis, 0.0, 1.0):
        for f in fs:
            times.setdefault(cp.split_id(f.arbitration_id)[1], []).append(t)
    assert set(times) == {Cmd.HEARTBEAT, Cmd.GET_TORQUES}
    assert len(times[Cmd.HEARTBEAT]) == 20 and len(times[Cmd.GET_TORQUES]) == 50
    gaps = [b - a for a, b in zip(times[Cmd.GET_TORQUES], times[Cmd.GET_TORQUES][1:],
                                  strict=False)]
    assert all(abs(g - 0.02) < 1e-6 for g in gaps)
    with pytest.raises(ValueError):
        OdriveAxis(cyclic={Cmd.SET_INPUT_TORQUE: 0.01})


def test_coarse_ticks_skip_missed_slots_without_bursts():
    axis, _ = make()
    counts = [len(axis.tick(t, 0, 0, 0, 48)) for t in (0.0, 0.5, 0.5005, 1.0)]
    assert counts == [3, 3, 0, 3]            # heartbeat, Get_Iq, encoder


@pytest.mark.parametrize(
    "cmd, data, rtr, reason",
    [
        (Cmd.SET_INPUT_TORQUE, b"\x00\x00", False, "bad_dlc"),
        (Cmd.SET_INPUT_TORQUE, bytes(9), False, "bad_dlc"),
        (Cmd.SET_INPUT_TORQUE, cp.encode_set_input_torque(math.nan), False, "non_finite"),
        (Cmd.SET_INPUT_TORQUE, cp.encode_set_input_torque(math.inf), False, "non_finite"),
        (Cmd.SET_INPUT_TORQUE, cp.encode_set_input_torque(-math.inf), False, "non_finite"),
        (Cmd.SET_INPUT_TORQUE, bytes(8), True, "not_requestable"),
        (0x0D, bytes(8), False, "unknown_cmd"),  # Set_Input_Vel: not simulated
        (0x1F, b"", True, "unknown_cmd"),
        (Cmd.HEARTBEAT, cp.encode_heartbeat(0, 8), False, "wrong_direction"),
        (Cmd.SET_CONTROLLER_MODE, cp.encode_set_controller_mode(99, 1), False, "bad_value"),
        (Cmd.SET_CONTROLLER_MODE, b"\x01\x00\x00\x00", False, "bad_dlc"),
        (Cmd.SET_LIMITS, cp.encode_set_limits(-1.0, 10.0), False, "bad_value"),
        (Cmd.SET_LIMITS, cp.encode_set_limits(1.0, math.nan), False, "non_finite"),
        (Cmd.SET_AXIS_STATE, cp.encode_set_axis_state(3), False, "unsupported_state"),
        (Cmd.SET_AXIS_STATE, b"\x01", False, "bad_dlc"),
        (Cmd.CLEAR_ERRORS, b"", False, "bad_dlc"),
    ],
)
def test_bad_frames_dropped_counted_and_harmless(cmd, data, rtr, reason):
    axis, host = make()
    host.arm(0.0)
    host.torque(0.0, 1.25)
    before = (axis.state, axis.torque_command_nm, axis.input_torque_nm, axis.torque_limit_nm,
              axis.vel_limit_rev_s, axis.control_mode, axis.input_mode, axis.active_errors)
    replies = host.send(0.01, cmd, data, rtr)
    assert replies == []
    assert dict(axis.counters) == {reason: 1}
    after = (axis.state, axis.torque_command_nm, axis.input_torque_nm, axis.torque_limit_nm,
             axis.vel_limit_rev_s, axis.control_mode, axis.input_mode, axis.active_errors)
    assert after == before


_COMMANDS_THAT_ACT = {Cmd.ESTOP, Cmd.SET_AXIS_STATE, Cmd.SET_CONTROLLER_MODE,
                      Cmd.SET_INPUT_TORQUE, Cmd.SET_LIMITS, Cmd.CLEAR_ERRORS}


@settings(max_examples=300, deadline=None)
@given(cmd=st.integers(0, 0x1F).filter(lambda c: c not in _COMMANDS_THAT_ACT),
       data=st.binary(max_size=8), rtr=st.booleans(), node=st.integers(0, 0x3F))
def test_garbage_never_moves_the_set_point_or_state(cmd, data, rtr, node):
    axis, host = make()
    host.arm(0.0)
    host.torque(0.0, -0.75)
    axis.handle(0.01, frame_id(node, cmd), data, rtr)
    axis.handle(0.01, frame_id(0, Cmd.SET_INPUT_TORQUE), data[:3], False)  # too short
    assert axis.enabled and axis.torque_command_nm == -0.75 and axis.active_errors == 0


def test_frames_for_other_nodes_are_ignored_and_node_id_is_honoured():
    axis, host = make(node_id=5)
    Host(axis, 0).arm(0.0)  # node 0 is someone else
    assert not axis.enabled and axis.rx_frames == 0 and not axis.counters
    host.arm(0.0)
    assert axis.enabled
    frames = axis.tick(0.0, 1.0, 2.0, 0.0, 48.0)
    assert {f.arbitration_id for f in frames} == {0x0A1, 0x0B4, 0x0A9}
    assert decode(axis.handle(0.0, 0x0B4, bytes(8), True)[0])["Iq_Setpoint"] == 0.0
    assert axis.handle(0.0, 0x0A1, bytes(8), True, is_extended=True) == []


def test_winch_sensor_frames():
    sensors = WinchSensors()
    frames = []
    for k in range(1000):
        t = k / 1000
        frames += sensors.tick(t, 10.0 + t, 1.0, 80.0, k >= 500, False, k >= 900)
    by_id = {}
    for f in frames:
        by_id.setdefault(f.arbitration_id, []).append(DB.decode_message(f.arbitration_id, f.data,
                                                                        decode_choices=False))
    assert {k: len(v) for k, v in by_id.items()} == {0x602: 100, 0x603: 100, 0x601: 10}
    assert by_id[0x602][0] == {"Line_Length": 10.0, "Line_Speed": 1.0}
    assert by_id[0x602][-1]["Line_Length"] == f32(10.99)
    assert by_id[0x603][0] == {"Tension": 80.0, "Brake_Engaged": 0, "Sample_Time": 0}
    assert by_id[0x603][-1]["Brake_Engaged"] == 1
    assert [m["Sample_Time"] for m in by_id[0x603]] == [10 * k for k in range(100)]
    hb = by_id[0x601]
    assert [h["Counter"] for h in hb] == list(range(10))
    assert hb[0] == {"Brake_Engaged": 0, "Load_Cell_Healthy": 1, "At_Full_Stop": 0,
                     "At_Empty_Stop": 0, "Counter": 0}
    assert hb[-1]["Brake_Engaged"] == 1 and hb[-1]["At_Empty_Stop"] == 1


def test_winch_sensor_faults_and_counter_wrap():
    sensors = WinchSensors(node_id=0x31, period_s=0.01, heartbeat_period_s=0.01)
    decoded = []
    for k in range(260):
        for f in sensors.tick(k * 0.01, 1.0, 0.0, math.nan, True, True, False):
            if f.arbitration_id == frame_id(0x31, 1):
                decoded.append(cp.decode_winch_heartbeat(f.data))
            elif f.arbitration_id == frame_id(0x31, 3):
                assert math.isnan(cp.decode_winch_tension(f.data).tension_n)
    assert decoded[255].counter == 255 and decoded[256].counter == 0
    assert not decoded[0].load_cell_healthy and decoded[0].at_full_stop


def _reference_due(state: dict, period: float, t: float) -> bool:
    """A fixed-rate schedule by its definition: slots at t0 + k period, t0 the first poll;
    a poll serves the latest slot at or before it (1 ns tolerance), once."""
    if state.get("t0") is None:
        state["t0"], state["n"] = t, 1
        return True
    if t + 1e-9 < state["t0"] + state["n"] * period:
        return False
    state["n"] = max(state["n"] + 1, math.floor((t + 1e-9 - state["t0"]) / period) + 1)
    return True


@settings(max_examples=100, deadline=None)
@given(st.lists(st.floats(0.0, 0.05), min_size=1, max_size=200),
       st.sampled_from([0.004, 0.01, 0.0125]))
def test_cyclic_outputs_are_the_schedules_by_their_definition(steps, enc_period):
    """OdriveAxis.tick and WinchSensors.tick (which skip the schedules while nothing is
    due) send exactly what the schedules' definition says, and WinchSensors.due tells."""
    axis = OdriveAxis(encoder_period_s=enc_period)
    sensors = WinchSensors()
    ref: dict[str, dict] = {"hb": {}, "iq": {}, "enc": {}, "data": {}, "whb": {}}
    t = 0.0
    for dt in steps:
        t += dt
        expected = [frame_id(0, cmd) for cmd, key, period in (
            (Cmd.HEARTBEAT, "hb", 0.1), (Cmd.GET_IQ, "iq", 0.05),
            (Cmd.GET_ENCODER_ESTIMATES, "enc", enc_period))
            if _reference_due(ref[key], period, t)]
        assert [f.arbitration_id for f in axis.tick(t, 1.0, 0.0, 0.0, 48.0)] == expected
        data_due = _reference_due(ref["data"], 0.01, t)
        hb_due = _reference_due(ref["whb"], 0.1, t)
        assert sensors.due(t) == (data_due or hb_due)
        assert len(sensors.tick(t, 10.0, 0.0, 5.0, False, False, False)) == (
            2 * data_due + hb_due)


def test_winder_node_sends_each_instants_sensor_frames_before_its_encoder_frame():
    from sitl.plant import Plant
    from sitl.winder_node import WinderCanNode
    from tuavdefs.canbus import CanLink
    from tuavdefs.params import SystemParams

    node_link, host = CanLink("virtual:node_order"), CanLink("virtual:node_order")
    try:
        node = WinderCanNode(node_link, Plant(SystemParams()))
        bursts = []
        for k in range(250):                       # 1 s of 4 ms control periods
            t = k * 0.004
            node.tick(t)
            assert node.inputs(t) == (0.0, False)
            burst = []
            while (rx := host.recv(0.0)) is not None:
                burst.append(cp.split_id(rx.arbitration_id))
            bursts.append(burst)
    finally:
        node_link.close()
        host.close()
    sensor = cp.WINCH_SENSOR_NODE_ID_DEFAULT
    encoder = (0, Cmd.GET_ENCODER_ESTIMATES)
    with_encoder = [b for b in bursts if encoder in b]
    assert len(with_encoder) == 100                            # 100 Hz of simulated time
    for b in with_encoder:
        assert b[:2] == [(sensor, cp.SensorCmd.WINCH_LENGTH), (sensor, cp.SensorCmd.WINCH_TENSION)]
    # 100 Hz length, tension, encoder; 10 Hz two heartbeats; 50 Hz the exit angle; 20 Hz
    # Get_Iq
    assert sum(len(b) for b in bursts) == node.frames_sent == 100 * 3 + 10 * 2 + 50 + 20


def test_winder_node_ignores_29_bit_frames_of_other_protocols():
    """An extended-id frame (another protocol sharing the bus) is received, counted and
    ignored: no reply, no effect on the axis, and the node keeps serving CAN Simple."""
    from sitl.plant import Plant
    from sitl.winder_node import WinderCanNode
    from tuavdefs.canbus import CanLink
    from tuavdefs.params import SystemParams

    node_link, host = CanLink("virtual:node_ext"), CanLink("virtual:node_ext")
    try:
        node = WinderCanNode(node_link, Plant(SystemParams()))
        for fid in (0x18FF50E5, 0x7FF + 1, 0x00000001):
            host.send(fid, bytes(8), is_extended=True)
        host.send(cp.frame_id(0, Cmd.GET_ENCODER_ESTIMATES), b"", is_remote=True, dlc=8)
        node.service(0.0)
        replies = []
        while (rx := host.recv(0.0)) is not None:
            replies.append(rx.arbitration_id)
    finally:
        node_link.close()
        host.close()
    assert node.frames_received == 4
    assert replies == [cp.frame_id(0, Cmd.GET_ENCODER_ESTIMATES)]
    assert node.axis.rx_frames == 1


def _lockstep_torques(channel: str, delays_s: tuple[float, ...]) -> list[tuple[float, bool]]:
    """(torque the node returns, whether it sent an encoder frame) per control period, over
    0.4 s of lockstep against a host thread that answers the n-th encoder frame with
    0.01 n N m after ``delays_s[n % len]`` [s] of wall time."""
    import threading
    import time

    from sitl.plant import Plant
    from sitl.winder_node import WinderCanNode
    from tuavdefs.canbus import CanLink
    from tuavdefs.params import SystemParams

    node_link, host = CanLink(f"virtual:{channel}"), CanLink(f"virtual:{channel}")
    node = WinderCanNode(node_link, Plant(SystemParams()), lockstep=True)
    encoder_id = cp.frame_id(0, Cmd.GET_ENCODER_ESTIMATES)
    stop = threading.Event()

    def answer() -> None:
        n = 0
        while not stop.is_set():
            rx = host.recv(0.01)
            if rx is None or rx.arbitration_id != encoder_id or rx.is_remote:
                continue
            time.sleep(delays_s[n % len(delays_s)])
            n += 1
            host.send(cp.frame_id(0, Cmd.SET_INPUT_TORQUE), cp.encode_set_input_torque(0.01 * n))

    # armed before the first period, so the node waits for the host from the start
    host.send(cp.frame_id(0, Cmd.CLEAR_ERRORS), cp.encode_clear_errors())
    host.send(cp.frame_id(0, Cmd.SET_CONTROLLER_MODE), cp.encode_set_controller_mode(
        cp.ControlMode.TORQUE, cp.InputMode.PASSTHROUGH))
    host.send(cp.frame_id(0, Cmd.SET_AXIS_STATE),
              cp.encode_set_axis_state(cp.AxisState.CLOSED_LOOP_CONTROL))
    thread = threading.Thread(target=answer, daemon=True)
    thread.start()
    out = []
    try:
        for k in range(100):
            t = k * 0.004
            node.service(t)
            node.tick(t)
            torque, enabled = node.inputs(t)
            assert enabled
            out.append((torque, node._encoder_t == t))
    finally:
        stop.set()
        thread.join()
        node_link.close()
        host.close()
    assert node.late_answers == 0
    return out


def test_in_lockstep_a_hosts_torque_applies_from_the_next_period_whatever_its_delay():
    """Real time's timing, kept exactly: the torque answering the encoder frame of one
    control period is what the plant gets from the next period on, never in the period
    that sent the frame, and the sequence does not depend on how long the host takes."""
    quick = _lockstep_torques("lockstep_quick", (0.0,))
    slow = _lockstep_torques("lockstep_slow", (0.003, 0.0, 0.0015, 0.0005))
    assert quick == slow
    sent = 0
    for torque, sent_now in quick:
        # the frames sent before this period have all been answered, this one's not yet
        assert torque == pytest.approx(0.01 * sent, abs=1e-6)
        sent += sent_now
    assert sent == 40                       # 100 Hz of simulated time over 0.4 s
