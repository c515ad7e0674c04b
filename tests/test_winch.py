"""The winch component's logic (groundstation/winch.py) without sockets: DO_WINCH answers,
the length reference against its analytic ramp, the taut-floor clamp against the straight-line
distance, the brake, encoder loss, WINCH_STATUS contents and rate; then the same class
closing the loop around the plant's own simulated ODrive axis and drum model."""

from __future__ import annotations

import math

import pytest
from chunk_socket import ChunkSocket
from hypothesis import given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import common as mavlink2

from groundstation import winch as wm
from groundstation import winch_link
from groundstation.lbar import TS_LEAD, TS_OFFSET, TS_WEIGHT, LBarParams
from groundstation.winch import (
    JOIN_MARGIN_M,
    REJOIN_ACC_M_S2,
    CommandRequest,
    Winch,
    WinchMode,
    WinchOutput,
)
from groundstation.winch_link import WinchLinkClient, local_positions
from groundstation.winch_sensors import TensionSource
from groundstation.winder_control import WinderControlParams
from groundstation.winder_host import WinderHost
from sitl.odrive_axis import OdriveAxis, WinchSensors
from sitl.winder import WinderModel
from tuavdefs import can_protocol as cp
from tuavdefs import component_link as cl
from tuavdefs.params import SystemParams

NAN = math.nan
PARAMS = SystemParams()
G = PARAMS.environment.gravity_m_s2
R_W = PARAMS.winder.drum_radius_m
MIN_SLACK = LBarParams().min_slack_m
DT = 1.0 / WinderControlParams().rate_hz
UAV = ((3.0, 4.0, 12.0), (0.0, 0.0, 0.0))     # 13 m from the winder's exit
GCS = (255, 190)
ACK = mavlink2.MAV_RESULT_ACCEPTED
ENC_ID = cp.frame_id(0, cp.Cmd.GET_ENCODER_ESTIMATES)
#: The paper's length law: what these tests check the winch's modes, L-bar's following,
#: its trims and its faults against (the default, the tension law, has
#: tests/test_tension_law.py).
PAPER = WinderControlParams(law="paper")


def make_winch(lbar: LBarParams | None = None) -> Winch:
    """The winch; without the tension trim unless ``lbar`` says otherwise: these tests
    feed it made-up tensions (a constant, or none), not a catenary's."""
    lbar = lbar if lbar is not None else LBarParams(tension_trim_rate_m_s=0.0)
    host = WinderHost(PAPER, lbar, PARAMS.winder, PARAMS.tether, G)
    return Winch(host, PARAMS.winder, PARAMS.tether, G)


def request(action: float, length: float = NAN, rate: float = NAN, *, instance: float = 0,
            target: int = 169, command: int = mavlink2.MAV_CMD_DO_WINCH,
            target_system: int = 1, confirmation: int = 0) -> CommandRequest:
    return CommandRequest(command, target_system, target, *GCS, instance, action, length, rate,
                          confirmation)


def encoder(w: Winch, wall: float, length_m: float, speed_m_s: float = 0.0) -> WinchOutput:
    """Feed an encoder frame for a drum at ``length_m`` turning at ``speed_m_s`` of line."""
    k = 2.0 * math.pi * R_W
    return w.on_frame(wall, ENC_ID, cp.encode_encoder_estimates(length_m / k, speed_m_s / k))


def decoded(frames: list[cp.Frame]) -> list[tuple[str, object]]:
    """(message name, decoded payload) of the host's frames, through the message table."""
    out = []
    for f in frames:
        spec = cp.spec_for_id(f.arbitration_id)
        out.append((spec.name, "RTR" if f.is_remote else spec.decode(f.data)))
    return out


def ready(length_m: float = 20.0, uav=UAV) -> Winch:
    w = make_winch()
    w.set_uav(uav)
    encoder(w, 0.0, length_m)
    return w


def track(w: Winch, frames: int, wall0: float = 1.0) -> list[tuple[float, float]]:
    """Step ``frames`` encoder frames with the drum exactly on the reference (perfect
    tracking); returns the reference (length, rate) after each."""
    refs = []
    for k in range(frames):
        encoder(w, wall0 + k * DT, w.reference()[0])
        refs.append(w.reference())
    return refs


# --------------------------------------------------------------------------------- ACKs

EXPECTED = {
    mavlink2.WINCH_RELAXED: ACK,
    mavlink2.WINCH_RELATIVE_LENGTH_CONTROL: ACK,
    mavlink2.WINCH_RATE_CONTROL: ACK,
    mavlink2.WINCH_LOCK: ACK,
    mavlink2.WINCH_DELIVER: mavlink2.MAV_RESULT_UNSUPPORTED,
    mavlink2.WINCH_HOLD: ACK,
    mavlink2.WINCH_RETRACT: ACK,
    mavlink2.WINCH_LOAD_LINE: mavlink2.MAV_RESULT_UNSUPPORTED,
    mavlink2.WINCH_ABANDON_LINE: mavlink2.MAV_RESULT_UNSUPPORTED,
    mavlink2.WINCH_LOAD_PAYLOAD: mavlink2.MAV_RESULT_UNSUPPORTED,
}


def test_every_winch_action_of_the_dialect_has_an_expected_answer():
    actions = {v for v, e in mavlink2.enums["WINCH_ACTIONS"].items()
               if not e.name.endswith("ENUM_END")}
    assert actions == set(EXPECTED)


@pytest.mark.parametrize("action", sorted(EXPECTED))
@pytest.mark.parametrize("target", [169, 1, 0])
def test_ack_result_per_action_and_addressed_to_the_sender(action, target):
    w = ready()
    reply = w.command(request(action, 1.0, 0.2, target=target), 2.0)
    assert reply is not None
    assert reply.command == 42600
    assert reply.result == EXPECTED[action]
    assert (reply.target_system, reply.target_component) == GCS
    if reply.result == ACK:
        assert w.mode == action
    else:
        assert w.mode == WinchMode.RELAXED
        assert reply.notices      # a STATUSTEXT says why


@pytest.mark.parametrize("req, why", [
    (request(mavlink2.WINCH_HOLD, instance=2), "instance"),
    (request(mavlink2.WINCH_HOLD, instance=NAN), "instance"),
    (request(mavlink2.WINCH_RELATIVE_LENGTH_CONTROL, NAN, 0.5), "NaN"),
    (request(mavlink2.WINCH_RATE_CONTROL, 1.0, NAN), "NaN"),
    (request(NAN), "action"),
    (request(1.5, 1.0, 1.0), "action"),
    (request(42), "action"),
])
def test_bad_parameters_are_denied_with_a_statustext(req, why):
    w = ready()
    reply = w.command(req, 2.0)
    assert reply.result == mavlink2.MAV_RESULT_DENIED
    assert len(reply.notices) == 1 and why in reply.notices[0].text
    assert reply.notices[0].text.startswith("winch: ")
    assert w.mode == WinchMode.RELAXED


def test_instance_1_is_accepted_too():
    assert ready().command(request(mavlink2.WINCH_HOLD, instance=1), 2.0).result == ACK


def test_commands_for_others_get_no_answer_and_unknown_ones_for_us_unsupported():
    w = ready()
    assert w.command(request(mavlink2.WINCH_HOLD, target=42), 2.0) is None
    assert w.command(request(mavlink2.WINCH_HOLD, target_system=7), 2.0) is None
    other = mavlink2.MAV_CMD_DO_SET_MODE
    assert w.command(request(0, command=other, target=1), 2.0) is None
    assert w.command(request(0, command=other, target=0), 2.0) is None
    reply = w.command(request(0, command=other, target=169), 2.0)
    assert reply.result == mavlink2.MAV_RESULT_UNSUPPORTED and reply.command == other
    assert w.mode == WinchMode.RELAXED


def test_motion_needs_an_encoder_and_retract_a_uav_position():
    w = make_winch()
    w.set_uav(UAV)
    r = w.command(request(mavlink2.WINCH_RELATIVE_LENGTH_CONTROL, 1.0, 0.5), 0.0)
    assert r.result == mavlink2.MAV_RESULT_TEMPORARILY_REJECTED
    assert w.command(request(mavlink2.WINCH_HOLD), 0.0).result == ACK   # no motion: fine
    w = ready(uav=None)
    r = w.command(request(mavlink2.WINCH_RETRACT), 1.0)
    assert r.result == mavlink2.MAV_RESULT_TEMPORARILY_REJECTED and "UAV" in r.notices[0].text


def test_a_retransmission_is_acknowledged_again_but_not_executed_again():
    w = ready(20.0)
    first = w.command(request(1, 1.0, NAN, confirmation=0), 1.0)
    again = w.command(request(1, 1.0, NAN, confirmation=1), 1.5)
    assert first.result == again.result == ACK
    refs = track(w, 400, 2.0)
    assert refs[-1][0] == pytest.approx(21.0, abs=1e-5)   # 1 m, not 2 m
    w.command(request(1, 1.0, NAN, confirmation=0), 9.0)  # a new command (confirmation 0)
    assert track(w, 400, 10.0)[-1][0] == pytest.approx(22.0, abs=1e-5)


# ------------------------------------------------------------------------ the reference

@pytest.mark.parametrize("length, rate", [(2.0, 0.4), (-3.0, 0.5), (-3.0, -0.5), (1.0, NAN),
                                          (1.0, 0.0)])
def test_relative_length_ramps_at_the_commanded_rate_then_holds(length, rate):
    start = 20.0
    w = ready(start)
    assert w.command(request(1, length, rate), 1.0).result == ACK
    speed = abs(rate) if math.isfinite(rate) and rate != 0.0 else wm.WinchParams().default_rate_m_s
    n_ramp = round(abs(length) / speed / DT)
    refs = track(w, n_ramp + 100)
    for k in (0, n_ramp // 3, n_ramp - 2):
        t = (k + 1) * DT                               # simulated time after frame k
        assert refs[k][0] == pytest.approx(start + math.copysign(speed * t, length), abs=1e-5)
        assert refs[k][1] == pytest.approx(math.copysign(speed, length))
    assert refs[n_ramp - 1][0] == pytest.approx(start + length, abs=1e-5)
    for ref, ref_rate in refs[n_ramp:]:
        assert ref == pytest.approx(start + length, abs=1e-5) and ref_rate == 0.0


def test_rate_control_runs_until_another_command():
    w = ready(20.0)
    assert w.command(request(2, NAN, 0.3), 1.0).result == ACK
    refs = track(w, 300)
    assert refs[-1] == (pytest.approx(20.0 + 0.3 * 3.0, abs=1e-5), 0.3)
    w.command(request(2, NAN, 0.0), 5.0)        # stop: hold the length last measured
    held = track(w, 50, 5.0)
    assert held[-1] == (pytest.approx(20.9 - 0.3 * DT, abs=1e-5), 0.0)


def test_a_length_below_the_taut_floor_is_clamped_to_it():
    w = ready(14.0)
    floor = math.dist(UAV[0], (0, 0, 0)) + MIN_SLACK           # 13.05 m
    reply = w.command(request(1, -5.0, 0.5), 1.0)
    assert reply.result == ACK
    assert "13.05" in reply.notices[0].text and "clamped" in reply.notices[0].text
    refs = track(w, 400)
    assert min(r for r, _ in refs) == pytest.approx(floor, abs=1e-5)
    assert refs[-1] == (pytest.approx(floor, abs=1e-5), 0.0)


def test_rate_control_stops_at_the_taut_floor_and_follows_it_out():
    w = ready(14.0)
    floor = math.dist(UAV[0], (0, 0, 0)) + MIN_SLACK
    reply = w.command(request(2, NAN, -1.0), 1.0)
    assert reply.result == ACK and not reply.notices
    notices = []
    for k in range(200):
        notices += encoder(w, 1.0 + k * DT, w.reference()[0]).notices
    assert w.reference()[0] == pytest.approx(floor, abs=1e-5)
    assert [n.text for n in notices] == [f"winch: stopped at taut limit {floor:.2f} m"]
    # the UAV moves out at 1 m/s radially: the reference rises with the floor, at its rate
    pos = (6.0, 8.0, 24.0)                                      # 26 m out
    w.set_uav((pos, (6 / 26, 8 / 26, 24 / 26)))
    encoder(w, 5.0, w.reference()[0])
    assert w.reference() == (pytest.approx(26.0 + MIN_SLACK), pytest.approx(1.0))


def test_rates_above_the_laws_limit_are_clamped():
    w = ready(20.0)
    vmax = WinderControlParams().speed_margin * PARAMS.winder.motor_speed_limit_rad_s * R_W
    reply = w.command(request(2, NAN, 100.0), 1.0)
    assert reply.result == ACK and f"{vmax:.2f}" in reply.notices[0].text
    refs = track(w, 10)
    assert refs[-1][1] == pytest.approx(vmax)
    assert refs[-1][0] == pytest.approx(20.0 + 10 * DT * vmax)


def test_the_drum_end_limits_paying_out():
    w = ready(45.0)
    end = PARAMS.tether.total_length_m - wm.WinchParams().end_margin_m
    reply = w.command(request(1, 30.0, 1.0), 1.0)
    assert reply.result == ACK and f"{end:.2f}" in reply.notices[0].text
    assert track(w, 600)[-1][0] == pytest.approx(end)


def test_retract_winds_in_to_the_straight_line_distance_plus_min_slack():
    w = ready(20.0)
    floor = math.dist(UAV[0], (0, 0, 0)) + MIN_SLACK
    reply = w.command(request(6), 1.0)
    assert reply.result == ACK and f"{floor:.2f}" in reply.notices[0].text
    rate = wm.WinchParams().retract_rate_m_s
    n = math.ceil((20.0 - floor) / rate / DT)
    refs = track(w, n + 50)
    assert refs[n // 2] == (pytest.approx(20.0 - rate * (n // 2 + 1) * DT), -rate)
    assert refs[-1] == (pytest.approx(floor, abs=1e-5), 0.0)
    assert w.status_flags() & wm.FLAG_FULLY_RETRACTED
    # then it holds: the UAV coming closer does not wind further
    w.set_uav(((3.0, 4.0, 10.0), (0.0, 0.0, 0.0)))
    assert track(w, 50, 30.0)[-1][0] == pytest.approx(floor, abs=1e-5)


def test_relaxed_follows_lbar_and_holds_its_length_without_a_uav_position():
    w = ready(20.0, uav=None)
    for k in range(20):
        encoder(w, k * DT, 20.0 + 0.001 * k)
    assert w.reference() == (pytest.approx(20.0, abs=1e-5), 0.0)   # its first length
    w.set_uav(UAV)
    encoder(w, 1.0, 20.0)
    host = WinderHost(PAPER, LBarParams(), PARAMS.winder, PARAMS.tether, G)
    assert w.reference()[0] == pytest.approx(host.lbar.length(UAV[0])[0], abs=1e-5)


# ------------------------------------------------------------------------- the brake

def test_hold_brakes_the_drum_and_leaving_it_rearms_closed_loop():
    w = ready(20.0)
    assert w.command(request(mavlink2.WINCH_HOLD), 1.0).result == ACK
    out = encoder(w, 1.0, 20.0)
    names = decoded(out.frames)
    assert names[0] == ("Set_Axis_State", cp.AxisState.IDLE)
    assert "Set_Input_Torque" not in [n for n, _ in names]
    for k in range(1, 6):                        # every frame is answered with IDLE again
        frames = encoder(w, 1.0 + k * DT, 20.0).frames
        assert decoded(frames)[0] == ("Set_Axis_State", cp.AxisState.IDLE)
    assert w.status_flags() & mavlink2.MAV_WINCH_STATUS_CLUTCH_ENGAGED
    assert w.status_flags() & mavlink2.MAV_WINCH_STATUS_HEALTHY
    assert w.command(request(mavlink2.WINCH_RELAXED), 2.0).result == ACK
    names = decoded(encoder(w, 2.0, 20.0).frames)
    assert names[:4] == [
        ("Clear_Errors", False),
        ("Set_Controller_Mode", (cp.ControlMode.TORQUE, cp.InputMode.PASSTHROUGH)),
        ("Set_Axis_State", cp.AxisState.CLOSED_LOOP_CONTROL),
        ("Set_Input_Torque", pytest.approx(names[3][1])),
    ]
    assert not w.status_flags() & mavlink2.MAV_WINCH_STATUS_CLUTCH_ENGAGED
    # LOCK is the same hold
    w.command(request(mavlink2.WINCH_LOCK), 3.0)
    assert decoded(encoder(w, 3.0, 20.0).frames)[0] == ("Set_Axis_State", cp.AxisState.IDLE)


def test_the_first_encoder_frame_arms_the_axis():
    w = make_winch()
    names = [n for n, _ in decoded(encoder(w, 0.0, 20.0).frames)]
    assert names == ["Clear_Errors", "Set_Controller_Mode", "Set_Axis_State", "Set_Input_Torque"]
    assert [n for n, _ in decoded(encoder(w, DT, 20.0).frames)] == ["Set_Input_Torque"]


def test_encoder_loss_brakes_and_its_return_rearms_and_resumes():
    w = ready(20.0)
    w.command(request(2, NAN, 0.5), 0.0)
    track(w, 50, 0.0)                            # last frame at wall 0.49 s
    last = 0.49
    ref_before = w.reference()[0]
    assert not w.poll(last + 0.05).frames
    out = w.poll(last + 0.11)
    assert decoded(out.frames) == [("Set_Axis_State", cp.AxisState.IDLE)]
    assert [(n.severity, n.text) for n in out.notices] == [
        (mavlink2.MAV_SEVERITY_CRITICAL, "winch: encoder lost, drum braked")]
    flags = out.status.flags
    assert not flags & mavlink2.MAV_WINCH_STATUS_HEALTHY
    assert flags & mavlink2.MAV_WINCH_STATUS_CLUTCH_ENGAGED
    # while lost: WINCH_STATUS by the wall clock, no more frames or notices
    sent = [last + 0.11]
    for k in range(1, 101):                      # the process polls at least every 10 ms
        o = w.poll(last + 0.11 + 0.01 * k)
        assert not o.frames and not o.notices
        if o.status is not None:
            sent.append(last + 0.11 + 0.01 * k)
            assert o.status.flags == out.status.flags
    assert len(sent) >= 11                        # >= 10 Hz
    assert max(b - a for a, b in zip(sent, sent[1:], strict=False)) <= 0.1 + 1e-9
    out = encoder(w, last + 1.5, ref_before)
    assert [n.text for n in out.notices] == ["winch: encoder back"]
    assert [n for n, _ in decoded(out.frames)][:4] == [
        "Clear_Errors", "Set_Controller_Mode", "Set_Axis_State", "Set_Input_Torque"]
    assert decoded(out.frames)[2][1] == cp.AxisState.CLOSED_LOOP_CONTROL
    # the rate mode resumes where its reference stood
    assert w.reference() == (pytest.approx(ref_before + 0.5 * DT), 0.5)
    assert w.poll(last + 1.5).status is None or w.status_flags() & wm.FLAG_HEALTHY
    assert w.status_flags() & wm.FLAG_HEALTHY


def test_encoder_back_during_hold_keeps_the_brake():
    w = ready(20.0)
    w.command(request(mavlink2.WINCH_HOLD), 0.0)
    encoder(w, 0.0, 20.0)
    w.poll(0.2)
    out = encoder(w, 0.5, 20.0)
    assert [n.text for n in out.notices] == ["winch: encoder back"]
    assert decoded(out.frames)[0] == ("Set_Axis_State", cp.AxisState.IDLE)
    assert "Clear_Errors" not in [n for n, _ in decoded(out.frames)]


# ----------------------------------------------------------------------------- status

def test_status_flag_bits_are_the_dialects():
    enum = {e.name: v for v, e in mavlink2.enums["MAV_WINCH_STATUS_FLAG"].items()}
    assert wm.FLAG_HEALTHY == enum["MAV_WINCH_STATUS_HEALTHY"] == 1
    assert wm.FLAG_FULLY_RETRACTED == enum["MAV_WINCH_STATUS_FULLY_RETRACTED"] == 2
    assert wm.FLAG_MOVING == enum["MAV_WINCH_STATUS_MOVING"] == 4
    assert wm.FLAG_CLUTCH_ENGAGED == enum["MAV_WINCH_STATUS_CLUTCH_ENGAGED"] == 8
    assert enum.get("MAV_WINCH_STATUS_LOCKED", 0) == wm.FLAG_LOCKED
    assert enum.get("MAV_WINCH_STATUS_RETRACTING", 0) == wm.FLAG_RETRACTING


def test_status_every_fifth_encoder_frame_with_the_measurements():
    w = ready(20.0)
    sensor = cp.WINCH_SENSOR_NODE_ID_DEFAULT
    w.on_frame(0.0, cp.frame_id(sensor, cp.SensorCmd.WINCH_TENSION),
               cp.encode_winch_tension(9.81, False))
    w.on_frame(0.0, cp.frame_id(sensor, cp.SensorCmd.WINCH_LENGTH),
               cp.encode_winch_length(20.25, 0.5))
    outs = [encoder(w, 0.001 * k, 20.0, 0.5) for k in range(1, 100)]   # 100 frames in all
    statuses = [o.status for o in outs if o.status is not None]
    assert len(statuses) == 20                   # 20 Hz of simulated time
    requests = [f for o in outs for f in o.frames if f.is_remote]
    assert len(requests) == 20
    assert {f.arbitration_id for f in requests} == {cp.frame_id(0, cp.Cmd.GET_BUS_VOLTAGE_CURRENT)}
    st = statuses[0]
    assert st.line_length_m == pytest.approx(20.25)
    assert st.speed_m_s == pytest.approx(0.5)
    assert st.tension_kg == pytest.approx(9.81 / G, rel=1e-6)
    assert math.isnan(st.voltage_v) and math.isnan(st.current_a)
    assert st.temperature_c == 32767
    assert st.flags == (mavlink2.MAV_WINCH_STATUS_HEALTHY | mavlink2.MAV_WINCH_STATUS_MOVING)
    w.on_frame(1.0, cp.frame_id(0, cp.Cmd.GET_BUS_VOLTAGE_CURRENT),
               cp.encode_bus_voltage_current(48.0, -1.5))
    st = w.poll(2.0).status
    assert (st.voltage_v, st.current_a) == (48.0, -1.5)


def test_status_by_the_wall_clock_when_frames_are_slow():
    w = ready(20.0)
    sent = []
    for k in range(100):                          # a frame every 0.25 s, polls every 10 ms
        wall = 0.01 * (k + 1)
        out = encoder(w, wall, 20.0) if k % 25 == 0 else WinchOutput()
        out.extend(w.poll(wall))
        if out.status is not None:
            sent.append(wall)
    gaps = [b - a for a, b in zip([0.0] + sent, sent, strict=False)]
    assert max(gaps) <= 0.1 + 1e-9 and len(sent) >= 10


def test_no_status_before_any_length_is_known():
    w = make_winch()
    assert w.poll(0.0).status is None and w.poll(1.0).status is None


def test_unhealthy_on_axis_errors_and_a_bad_load_cell():
    w = ready(20.0)
    out = w.on_frame(0.1, cp.frame_id(0, cp.Cmd.HEARTBEAT), cp.encode_heartbeat(
        cp.ODriveError.WATCHDOG_TIMER_EXPIRED, cp.AxisState.IDLE))
    assert out.notices[0].severity == mavlink2.MAV_SEVERITY_CRITICAL
    assert "0x01000000" in out.notices[0].text
    assert not w.status_flags() & wm.FLAG_HEALTHY
    # a command that needs closed loop re-arms the axis that disarmed itself
    w.command(request(mavlink2.WINCH_RELAXED), 0.2)
    assert decoded(encoder(w, 0.2, 20.0).frames)[0][0] == "Clear_Errors"
    w.on_frame(0.3, cp.frame_id(0, cp.Cmd.HEARTBEAT), cp.encode_heartbeat(
        0, cp.AxisState.CLOSED_LOOP_CONTROL))
    assert w.status_flags() & wm.FLAG_HEALTHY
    w.on_frame(0.4, cp.frame_id(cp.WINCH_SENSOR_NODE_ID_DEFAULT, cp.SensorCmd.WINCH_HEARTBEAT),
               cp.encode_winch_heartbeat(False, False, False, False, 1))
    assert not w.status_flags() & wm.FLAG_HEALTHY


def test_polling_only_from_next_poll_s_on_changes_nothing():
    """The process calls poll only once ``next_poll_s`` has come: the same outputs as
    polling at every turn of its loop, through frames, their loss and their return."""
    every, gated = ready(20.0), ready(20.0)
    k = 2.0 * math.pi * R_W
    for step in range(1, 800):
        wall = 0.0005 * step
        frame = step % 20 == 0 and not 300 <= step < 600        # 10 ms apart, then lost
        outs = []
        for w, gate in ((every, False), (gated, True)):
            out = WinchOutput()
            if frame:
                out.extend(w.on_frame(wall, ENC_ID, cp.encode_encoder_estimates(20.0 / k, 0.0)))
            if not gate or wall >= w.next_poll_s():
                out.extend(w.poll(wall))
            outs.append(out)
        assert repr(outs[0]) == repr(outs[1])                  # (NaN tensions)
    assert every.lost is False and every.encoder_frames == gated.encoder_frames


def test_handle_frame_is_on_frame_with_none_for_nothing_to_send():
    a, b = ready(20.0), ready(20.0)
    frames = [(ENC_ID, cp.encode_encoder_estimates(3.0, 0.1), False), (ENC_ID, b"\x00", False),
              (ENC_ID, bytes(8), True), (0x7FF, b"\xff" * 8, False),
              (cp.frame_id(0, cp.Cmd.HEARTBEAT), cp.encode_heartbeat(0x40, 1), False),
              (cp.frame_id(cp.WINCH_SENSOR_NODE_ID_DEFAULT, cp.SensorCmd.WINCH_TENSION),
               cp.encode_winch_tension(5.0, False, 7), False)]
    for fid, data, remote in frames * 6:
        out = b.handle_frame(1.0, fid, data, remote)
        expected = WinchOutput() if out is None else out
        assert repr(a.on_frame(1.0, fid, data, remote)) == repr(expected)   # (NaN tensions)
    assert a.bad_frames == b.bad_frames == 6 and a.encoder_frames == b.encoder_frames


def test_garbage_never_crashes():
    w = ready(20.0)
    for fid, data in [(ENC_ID, b"\x00"), (ENC_ID, cp.encode_encoder_estimates(NAN, 0.0)),
                      (cp.frame_id(0, cp.Cmd.HEARTBEAT), b""), (0x7FF, b"\xff" * 8),
                      (cp.frame_id(cp.WINCH_SENSOR_NODE_ID_DEFAULT, 2), b"\x01")]:
        assert w.on_frame(0.5, fid, data) == WinchOutput()
    assert w.bad_frames == 4
    w.set_uav(((NAN, 0.0, 0.0), (0.0, 0.0, 0.0)))
    assert w.uav == UAV


# ------------------------------------------- closed loop around the plant's axis and drum

class Bench:
    """The winch against the plant's simulated ODrive axis, winch sensors and drum model
    (sitl/), in one process: 1 kHz drum physics, the axis and sensors ticked on a 4 ms grid
    as the plant does, a constant line tension at the drum; simulated time is the winch's
    wall time."""

    def __init__(self, length_m: float, tension_n: float = 5.0, uav=UAV) -> None:
        wp = PARAMS.winder
        self.model = WinderModel(wp, PARAMS.tether)
        self.axis = OdriveAxis(torque_limit_nm=wp.motor_torque_limit_n_m,
                               vel_limit_rev_s=wp.motor_speed_limit_rad_s / (2 * math.pi))
        self.sensors = WinchSensors()
        self.winch = make_winch()
        self.winch.set_uav(uav)
        self.theta = length_m / R_W
        self.omega = 0.0
        self.tension = tension_n
        self.t = 0.0
        self.n = 0
        self.host_frames: list[tuple[float, str, object]] = []
        self.statuses: list[tuple[float, wm.WinchStatusReport]] = []
        self.notices: list[str] = []
        self.encoder_on = True
        self.load_cell_on = True     # False: no Winch_Tension reaches the winch
        self.load_cell_bias_n = 0.0  # what the load cell reads beyond the true tension
        self.host_on = True          # False: the winch's frames never reach the axis
        self.last_encoder_t = math.nan

    @property
    def length(self) -> float:
        return self.theta * R_W

    def _handle(self, out: WinchOutput) -> None:
        for f in out.frames:
            spec = cp.spec_for_id(f.arbitration_id)
            self.host_frames.append((self.t, spec.name,
                                     None if f.is_remote else spec.decode(f.data)))
            if not self.host_on:
                continue
            for reply in self.axis.handle(self.t, f.arbitration_id, f.data, f.is_remote):
                self._handle(self.winch.on_frame(self.t, reply.arbitration_id, reply.data))
        self.notices += [n.text for n in out.notices]
        if out.status is not None:
            self.statuses.append((self.t, out.status))

    def run(self, seconds: float) -> None:
        for _ in range(round(seconds * 1000)):
            braked = not self.axis.enabled
            applied = self.model.motor_torque_n_m(self.axis.torque_command_nm, self.omega,
                                                  self.axis.enabled)
            acc = self.model.acceleration(self.theta, self.omega, applied, self.tension, braked)
            before = self.omega
            self.omega += acc * 1e-3
            self.theta += self.omega * 1e-3
            self.theta, self.omega = self.model.project(self.theta, self.omega, before, braked)
            self.n += 1
            self.t = self.n * 1e-3
            if self.n % 4 == 0:
                two_pi = 2 * math.pi
                frames = self.axis.tick(self.t, self.theta / two_pi, self.omega / two_pi,
                                        applied, 48.0)
                frames += self.sensors.tick(self.t, self.length, self.omega * R_W,
                                            self.tension + self.load_cell_bias_n, braked,
                                            False, False)
                for f in frames:
                    if f.arbitration_id == TENSION_ID and not self.load_cell_on:
                        continue
                    if f.arbitration_id == ENC_ID:
                        if not self.encoder_on:
                            continue
                        self.last_encoder_t = self.t
                    self._handle(self.winch.on_frame(self.t, f.arbitration_id, f.data))
            self._handle(self.winch.poll(self.t))

    def command(self, req: CommandRequest) -> wm.CommandReply:
        reply = self.winch.command(req, self.t)
        self.notices += [n.text for n in reply.notices]
        return reply

    def other_host(self, cmd: cp.Cmd, data: bytes) -> None:
        """A frame from a second host on the bus: the axis and the winch both hear it."""
        fid = cp.frame_id(0, cmd)
        self.axis.handle(self.t, fid, data)
        self._handle(self.winch.on_frame(self.t, fid, data))

    def healthy(self, since_s: float) -> list[bool]:
        """HEALTHY in each WINCH_STATUS since ``since_s`` [s]."""
        return [bool(st.flags & wm.FLAG_HEALTHY) for t, st in self.statuses if t >= since_s]


def test_relaxed_after_a_long_pay_out_winds_back_in_at_a_bounded_rate():
    """DO_WINCH pays out 10 m, then RELAXED: the line goes back to L-bar no faster than
    rejoin_rate_m_s (full speed, 5.4 m/s, jerked the UAV), then follows L-bar's law."""
    b = Bench(14.0)
    b.run(2.0)
    lbar = b.winch.host.lbar.length(UAV[0])[0]
    assert b.command(request(1, 10.0, 2.0)).result == ACK
    b.run(7.0)
    assert b.length == pytest.approx(lbar + 10.0, abs=0.05)
    assert b.command(request(mavlink2.WINCH_RELAXED)).result == ACK
    rate = b.winch.p.rejoin_rate_m_s
    fastest = 0.0
    for _ in range(140):       # 14 s: 10 m at 1 m/s and the settling
        b.run(0.1)
        fastest = max(fastest, -b.omega * R_W)
    assert fastest <= rate * 1.05 + 0.02
    assert fastest >= 0.8 * rate                       # it did wind in, at that rate
    assert b.length == pytest.approx(lbar, abs=0.02)   # and is back on L-bar


def test_an_axis_that_disarmed_itself_is_re_armed_and_reported_truthfully():
    """The ground station's frames lost for half a second (a stall): the axis's watchdog
    trips it to IDLE. WINCH_STATUS says unhealthy while it is, and the winch re-arms it as
    soon as its frames get through (it kept sending torque into an IDLE axis)."""
    b = Bench(14.0)
    b.run(2.0)
    assert b.axis.enabled and all(b.healthy(1.0))
    b.host_on = False
    b.run(0.5)
    assert not b.axis.enabled
    assert b.axis.active_errors & cp.ODriveError.WATCHDOG_TIMER_EXPIRED
    t_back = b.t
    b.host_on = True
    b.run(0.2)
    assert not all(b.healthy(t_back))                  # said while it was IDLE
    # re-armed within a re-arm interval (an attempt while its frames were lost failed)
    b.run(wm.REARM_S)
    assert b.axis.enabled and b.axis.active_errors == 0
    assert any("re-arming" in n for n in b.notices)
    b.run(0.5)
    assert all(b.healthy(b.t - 0.5))
    lbar = b.winch.host.lbar.length(UAV[0])[0]
    b.run(2.0)
    assert b.length == pytest.approx(lbar, abs=0.02)   # back on L-bar


@pytest.mark.parametrize("quiet_first", [False, True])
def test_an_estop_from_another_host_is_said_and_only_a_command_re_arms(quiet_first):
    b = Bench(14.0)
    b.run(2.0)
    b.other_host(cp.Cmd.ESTOP, b"")
    b.run(1.5)
    assert not b.axis.enabled                            # not re-armed by itself
    assert any("another CAN host sends ESTOP" in n for n in b.notices)
    assert not any(b.healthy(b.t - 1.0))
    if quiet_first:     # the other host silent long enough: still the operator's to undo
        b.run(wm.FOREIGN_NOTICE_S)
        assert not b.axis.enabled and not b.winch.foreign_brake
        assert any("estopped" in n for n in b.notices)
    assert b.command(request(mavlink2.WINCH_RELAXED)).result == ACK
    b.run(0.5)
    assert b.axis.enabled


def test_a_second_host_sending_torque_is_noticed_and_the_drum_braked_against_it():
    """+/-4 N m from another host (the attack of issue 34): said once, the drum braked at
    once and held (the axis applies no torque in IDLE, whoever sends it), WINCH_STATUS
    braked and not HEALTHY; FOREIGN_NOTICE_S without such a frame re-arm the axis and
    the line goes back to L-bar."""
    b = Bench(14.0)
    b.run(2.0)
    held = b.length
    lengths = []
    for k in range(50):     # +/-4 N m at 50 Hz for a second, as the attack did
        b.other_host(cp.Cmd.SET_INPUT_TORQUE, cp.encode_set_input_torque(4.0 * (-1) ** k))
        assert not b.axis.enabled                       # IDLE from its first frame on
        b.run(0.02)
        lengths.append(b.length)
    assert b.winch.foreign_commands == 50
    said = [n for n in b.notices if "another CAN host sends SET_INPUT_TORQUE" in n]
    assert len(said) == 1                                # once per 5 s, not per frame
    assert b.notices.count("winch: drum braked against another CAN host") == 1
    assert not any(b.healthy(b.t - 0.9))
    assert max(abs(x - held) for x in lengths) < 1e-3   # the brake holds the line
    assert all(st.flags & wm.FLAG_CLUTCH_ENGAGED for t, st in b.statuses if t > 2.05)
    b.run(wm.FOREIGN_NOTICE_S - 0.5)
    assert not b.axis.enabled                            # quiet for less than 5 s
    b.run(1.0)
    assert b.axis.enabled and "winch: no other CAN host for 5 s, re-armed" in b.notices
    b.run(3.0)
    assert all(b.healthy(b.t - 1.0))
    assert b.length == pytest.approx(b.winch.host.lbar.length(UAV[0])[0], abs=0.02)


def test_another_host_re_arming_the_axis_is_answered_with_idle():
    """A second host that arms the axis before each torque (Clear_Errors, closed loop, a
    wind-in of 4 N m) is answered with IDLE after each of its arming frames: its torque
    finds the axis idle, and the drum does not move."""
    b = Bench(14.0)
    b.run(2.0)
    held = b.length
    for _ in range(100):
        b.other_host(cp.Cmd.CLEAR_ERRORS, cp.encode_clear_errors())
        b.other_host(cp.Cmd.SET_AXIS_STATE,
                     cp.encode_set_axis_state(cp.AxisState.CLOSED_LOOP_CONTROL))
        b.other_host(cp.Cmd.SET_INPUT_TORQUE, cp.encode_set_input_torque(-4.0))
        assert not b.axis.enabled
        b.run(0.01)
        assert abs(b.length - held) < 1e-3


def test_an_operators_do_winch_releases_the_brake_against_another_host():
    b = Bench(14.0)
    b.run(2.0)
    b.other_host(cp.Cmd.SET_INPUT_TORQUE, cp.encode_set_input_torque(4.0))
    b.run(0.5)
    assert not b.axis.enabled and b.winch.foreign_brake
    assert b.command(request(mavlink2.WINCH_RELAXED)).result == ACK
    b.run(0.1)
    assert b.axis.enabled and not b.winch.foreign_brake
    b.other_host(cp.Cmd.SET_INPUT_TORQUE, cp.encode_set_input_torque(4.0))  # it goes on
    assert not b.axis.enabled and b.winch.foreign_brake


def test_closed_loop_on_the_plants_axis_and_drum():
    b = Bench(14.0)
    b.run(3.0)
    lbar = b.winch.host.lbar.length(UAV[0])[0]
    assert b.axis.enabled
    assert b.length == pytest.approx(lbar, abs=0.01)            # relaxed: on L-bar
    # pay out 1 m at 0.4 m/s: mid-ramp line speed, then the length held
    start = b.length
    assert b.command(request(1, 1.0, 0.4)).result == ACK
    b.run(1.25)
    assert b.omega * R_W == pytest.approx(0.4, abs=0.02)
    b.run(2.75)
    assert b.length == pytest.approx(start + 1.0, abs=0.01)
    assert abs(b.omega * R_W) < 0.01
    # hold: the axis idles, the brake holds the drum under the line's pull
    assert b.command(request(mavlink2.WINCH_HOLD)).result == ACK
    b.run(0.05)
    assert not b.axis.enabled
    held = b.length
    b.run(1.0)
    assert b.length == pytest.approx(held, abs=1e-4)
    assert b.statuses[-1][1].flags & mavlink2.MAV_WINCH_STATUS_CLUTCH_ENGAGED
    # retract: to the taut floor, never below it
    assert b.command(request(mavlink2.WINCH_RETRACT, NAN, 0.5)).result == ACK
    b.run(0.05)
    assert b.axis.enabled
    b.run(6.0)
    floor = math.dist(UAV[0], (0, 0, 0)) + MIN_SLACK
    assert b.length == pytest.approx(floor, abs=0.01)
    assert b.statuses[-1][1].flags & mavlink2.MAV_WINCH_STATUS_FULLY_RETRACTED
    # WINCH_STATUS at 20 Hz of simulated time
    times = [t for t, _ in b.statuses if t > 1.0]
    assert (len(times) - 1) / (times[-1] - times[0]) == pytest.approx(20.0, rel=0.02)


def test_closed_loop_encoder_loss_brakes_and_recovers():
    b = Bench(14.0)
    b.run(1.0)
    assert b.command(request(2, NAN, 0.2)).result == ACK
    b.run(1.0)
    b.encoder_on = False
    t_off = b.last_encoder_t
    b.run(0.5)
    idles = [t for t, name, v in b.host_frames
             if t > t_off and name == "Set_Axis_State" and v == cp.AxisState.IDLE]
    assert idles and t_off + 0.1 - 1e-9 < idles[0] <= t_off + 0.102
    assert not b.axis.enabled
    assert "winch: encoder lost, drum braked" in b.notices
    lost = [s for t, s in b.statuses if t > idles[0]]
    assert len(lost) >= 4
    assert all(not s.flags & mavlink2.MAV_WINCH_STATUS_HEALTHY for s in lost)
    assert all(s.flags & mavlink2.MAV_WINCH_STATUS_CLUTCH_ENGAGED for s in lost)
    held = b.length
    b.encoder_on = True
    t_on = b.t
    b.run(1.0)
    assert b.notices[-1] == "winch: encoder back"
    rearm = [name for t, name, _ in b.host_frames if t > t_on][:3]
    assert rearm == ["Clear_Errors", "Set_Controller_Mode", "Set_Axis_State"]
    assert b.axis.enabled and b.axis.active_errors == 0
    assert b.omega * R_W == pytest.approx(0.2, abs=0.02)        # the rate mode resumed
    assert b.length > held + 0.1


def test_the_uav_position_is_carried_to_the_winch_sample_time():
    w = make_winch()
    state = ((3.0, 4.0, 10.0), (2.0, -1.0, 0.5))
    w.set_uav(state, time_ms=65_530)
    assert w.uav_now() == state                     # no sample time yet: as reported
    w.on_frame(0.0, cp.frame_id(cp.WINCH_SENSOR_NODE_ID_DEFAULT, cp.SensorCmd.WINCH_TENSION),
               cp.encode_winch_tension(9.0, False, 65_530 + 40))   # 40 ms later, wrapped
    (px, py, pz), vel = w.uav_now()
    assert (px, py, pz) == pytest.approx((3.08, 3.96, 10.02)) and vel == state[1]
    w.set_uav(state, time_ms=100)                   # newer than the sample: as reported
    assert w.uav_now() == state
    w.set_uav(state, time_ms=65_530 + 40 - 500)     # too old to carry forward
    assert w.uav_now() == state


# ------------------------------------------------- the component link's fast position path

def _component_stream() -> list[bytes]:
    """Frames as the companion sends them on the component link: positions (one with a
    zero tail, which MAVLink 2 truncates), a command, a heartbeat."""
    mav = cl.new_mavlink(cl.AUTOPILOT_COMPONENT_ID)
    return [bytes(m.pack(mav)) for m in (
        mav.local_position_ned_encode(1000, 1.0, 2.0, -10.0, 0.1, 0.2, 0.3),
        mav.local_position_ned_encode(1010, 1.5, 2.5, -10.5, 0.4, 0.0, 0.0),
        mav.local_position_ned_encode(0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
        mav.command_long_encode(1, 169, mavlink2.MAV_CMD_DO_WINCH, 1, 0, 1, 2.0, 0.5, 0, 0, 0),
        mav.heartbeat_encode(2, 3, 0, 0, 4),
        mav.local_position_ned_encode(1020, -3.0, 4.0, -12.0, -0.1, 0.2, -0.3),
    )]


def _pymavlink_positions(data: bytes) -> list[tuple]:
    msgs = cl.new_mavlink(cl.WINCH_COMPONENT_ID).parse_buffer(data) or []
    return [(m.time_boot_ms, m.x, m.y, m.z, m.vx, m.vy, m.vz) for m in msgs
            if m.get_type() == "LOCAL_POSITION_NED"]


def test_local_positions_is_pymavlinks_decoding_or_declines():
    frames = _component_stream()
    positions = [f for f in frames if f[7] == 32]
    assert local_positions(positions[0]) == _pymavlink_positions(positions[0])
    both = positions[1] + positions[2]                       # truncated payloads among them
    assert local_positions(both) == _pymavlink_positions(both)
    assert len(local_positions(both)) == 2
    bad_crc = positions[0][:-1] + bytes((positions[0][-1] ^ 1,))
    signed = positions[0][:2] + b"\x01" + positions[0][3:]
    for declined in (frames[3], frames[4], positions[0] + frames[4], positions[0][:-1],
                     positions[0] + b"\x00", bad_crc, signed, b"\xfe" + positions[0][1:]):
        assert local_positions(declined) is None


@settings(max_examples=60, deadline=None)
@given(st.lists(st.integers(0, 5), min_size=1, max_size=14), st.data())
def test_the_client_reads_the_same_with_and_without_the_fast_path(order, data):
    frames = _component_stream()
    stream = b"".join(frames[i] for i in order)
    cuts = sorted(data.draw(st.lists(st.integers(1, len(stream) - 1), max_size=4)))
    if data.draw(st.booleans()):                                  # a damaged byte
        pos = data.draw(st.integers(0, len(stream) - 1))
        stream = stream[:pos] + bytes((stream[pos] ^ 0x55,)) + stream[pos + 1:]
    chunks = [stream[a:b] for a, b in zip([0, *cuts], [*cuts, len(stream)], strict=True)
              if a < b]
    clients = []
    for fast in (True, False):
        c = WinchLinkClient("127.0.0.1:9")
        c.sock, c._last_heartbeat = ChunkSocket(list(chunks)), 1e18
        seen = []
        for _ in chunks:
            if fast:
                c.poll()
            else:
                with pytest.MonkeyPatch.context() as mp:
                    mp.setattr(winch_link, "local_positions", lambda data: None)
                    c.poll()
            seen.append((c.uav_state(), c.uav_state_time_ms(), c.take_commands(),
                         c.bad_frames, c.positions_received))
        clients.append(seen)
    assert clients[0] == clients[1]


def test_tension_trim_rides_out_a_snapping_load_cell():
    """A dynamic tether snapping at 25 Hz between slack and twice the model's tension (its
    mean the model's): the trim compares the low-passed tension and pays nothing out; on
    the raw samples it would have paid out at its full rate at every snap."""
    from groundstation.lbar import expected_drum_tension_n

    pos, vel = UAV
    paid = {}
    for tau in (LBarParams().tension_trim_filter_s, 0.0):
        lp = LBarParams(tension_trim_filter_s=tau)
        host = WinderHost(PAPER, lp, PARAMS.winder, PARAMS.tether, G)
        lbar, a = host.lbar.length(pos)
        expected = expected_drum_tension_n(a, math.hypot(pos[0], pos[1]), pos[2], host.lbar.w)
        for _ in range(100):
            host.update(lbar, 0.0, expected, pos, vel)
        for k in range(300):      # 3 s at the winder's 100 Hz: 2 periods slack, 2 at 2x
            host.update(lbar, 0.0, 2.0 * expected if k % 4 >= 2 else 0.0, pos, vel)
        paid[tau] = host.lbar.trim_state[TS_OFFSET]
    assert tau == 0.0 and paid[0.0] > 0.3
    assert paid[LBarParams().tension_trim_filter_s] < 0.01


def test_tension_trim_pays_out_when_the_tether_is_tighter_than_its_model_says():
    """L-bar's tension trim: a drum tension matching the model catenary's for the reported
    position leaves L-bar alone; 1.2 times that (the UAV is farther than reported) pays
    extra tether out at the trim's rate, bounded; back at the model's tension the extra
    is kept; well below it the extra is taken back, never below L-bar."""
    from groundstation.lbar import expected_drum_tension_n

    lp = LBarParams(tension_trim_filter_s=0.0)    # the law on the tension as it comes
    host = WinderHost(PAPER, lp, PARAMS.winder, PARAMS.tether, G)
    lb = host.lbar
    pos, vel = UAV
    lbar, a = lb.length(pos)
    expected = expected_drum_tension_n(a, math.hypot(pos[0], pos[1]), pos[2], lb.w)
    assert 0.5 < expected < 20.0
    for _ in range(100):
        step = host.update(lbar, 0.0, expected, pos, vel)
    assert step.lbar_m == pytest.approx(lbar, abs=1e-9) and lb.trim_state[TS_OFFSET] == 0.0
    for _ in range(50):   # 0.5 s at 1.2x the expected tension
        step = host.update(lbar, 0.0, 1.2 * expected, pos, vel)
    rate = lp.tension_trim_rate_m_s * (math.log(1.2) - lp.tension_trim_band)
    assert step.lbar_rate_m_s == pytest.approx(rate) and rate < lp.tension_trim_max_rate_m_s
    assert step.lbar_m - lbar == pytest.approx(0.5 * rate, rel=0.03)
    extra = step.lbar_m - lbar
    for _ in range(100):
        step = host.update(lbar, 0.0, 1.05 * expected, pos, vel)   # within the band
    assert step.lbar_m - lbar == pytest.approx(extra)
    for _ in range(300):
        step = host.update(lbar, 0.0, 0.1 * expected, pos, vel)    # far slacker: back
    assert step.lbar_m == pytest.approx(lbar) and step.lbar_rate_m_s == 0.0
    step = host.update(lbar, 0.0, 100.0 * expected, pos, vel)   # taut: at the rate limit
    assert step.lbar_rate_m_s == lp.tension_trim_max_rate_m_s
    for _ in range(3000):   # taut for 30 s: bounded
        step = host.update(lbar, 0.0, 100.0 * expected, pos, vel)
    assert step.lbar_m - lbar == pytest.approx(lp.tension_trim_max_m)


# ------------------------------------------------------------- on the ground, the clock

TENSION_ID = cp.frame_id(cp.WINCH_SENSOR_NODE_ID_DEFAULT, cp.SensorCmd.WINCH_TENSION)


def tension(w: Winch, wall: float, tension_n: float, stamp_ms: int = 0) -> None:
    w.on_frame(wall, TENSION_ID, cp.encode_winch_tension(tension_n, False, stamp_ms))


def test_relaxed_holds_a_ground_pre_tension_while_the_uav_is_unknown_or_on_the_ground():
    """No UAV position, or one on its gear: the length reference winds in while the load
    cell reads less than ground_tension_n and pays out while it reads more, at k (T - T_g)
    up to ground_tension_rate_m_s; never below the taut floor; L-bar once it has flown."""
    w = make_winch()
    p = w.p
    tension(w, 0.0, 0.0)
    encoder(w, 0.0, 5.0)
    refs = track(w, 100)              # slack line (0 N): wound in
    speed = min(p.ground_tension_gain_m_s_n * p.ground_tension_n, p.ground_tension_rate_m_s)
    assert refs[-1][1] == pytest.approx(-speed)
    assert refs[-1][0] == pytest.approx(5.0 - 101 * DT * speed, abs=1e-6)  # (+ the first)
    tension(w, 1.0, p.ground_tension_n + 0.1)   # above it, no position known: held
    assert track(w, 1, 2.0)[-1][1] == 0.0
    # the UAV on its gear 2 m out, reported: above it paid out in proportion, far above
    # it as fast as the law goes; below it wound in down to its taut floor, no further
    gear = ((2.0, 0.0, 0.2), (0.0, 0.0, 0.0))
    w.set_uav(gear)
    assert track(w, 1, 2.0)[-1][1] == pytest.approx(p.ground_tension_gain_m_s_n * 0.1)
    tension(w, 1.0, p.ground_tension_n + 100.0)
    assert track(w, 1, 2.0)[-1][1] == pytest.approx(w.max_rate_m_s)
    tension(w, 3.0, 0.0)
    floor, _ = w.taut_floor()
    last = track(w, 8000, 3.0)[-1]     # (80 s: at ground_tension_rate_m_s)
    assert last[0] == pytest.approx(floor, abs=1e-9) and last[1] == 0.0
    # taking off: climbing, still so low that L-bar would ask for more than twice its
    # tension (a nearly straight line): the pre-tension goes on; higher up, L-bar's law
    host = WinderHost(PAPER, LBarParams(), PARAMS.winder, PARAMS.tether, G)
    low = (2.0, 0.0, 0.3)
    assert host.lbar.length(low)[1] > p.ground_lbar_tension_ratio * host.lbar.a_target
    w.set_uav((low, (0.0, 0.0, 0.5)))
    encoder(w, 30.0, floor)
    assert w.reference() != (pytest.approx(host.lbar.length(low)[0], abs=1e-5), 0.0)
    assert w.reference()[0] >= w.taut_floor()[0]
    high = (2.0, 0.0, 3.0)
    assert host.lbar.length(high)[1] < p.ground_lbar_tension_ratio * host.lbar.a_target
    w.set_uav((high, (0.0, 0.0, 0.5)))
    encoder(w, 30.0, floor)
    # (L-bar, and the stop lead the climb at 0.5 m/s has begun to pay out ahead) less the
    # join's gap: the line, shorter than L-bar by more than JOIN_MARGIN_M, is paid out to
    # it on a trapezoid, not in a step; the gap closes, its speed rising at most at
    # REJOIN_ACC_M_S2, and L-bar's law holds once it has (the old step set the drum paying
    # out faster than a lumped line takes it: slack at the exit, then a snap)
    lbar_high = host.lbar.length(high)[0]
    lead = float(w.host.lbar.trim_state[TS_LEAD])
    assert 0.0 <= lead < 0.1
    assert lbar_high - floor > JOIN_MARGIN_M
    gap = lbar_high + lead - w.reference()[0]
    assert 0.0 < gap <= lbar_high - floor
    gaps = [gap]
    for k in range(600):
        encoder(w, 30.0 + k * DT, w.reference()[0])
        gaps.append(lbar_high + float(w.host.lbar.trim_state[TS_LEAD]) - w.reference()[0])
    closing = [(a - b) / DT for a, b in zip(gaps, gaps[1:], strict=False)]
    assert max(closing) <= p.rejoin_rate_m_s + 1e-9
    assert max(b - a for a, b in zip(closing, closing[1:], strict=False)) <= (
        REJOIN_ACC_M_S2 * DT + 1e-9)      # (it slows down on sqrt(2 a gap))
    assert gaps[1] > 0.0 and gaps[-1] == pytest.approx(0.0, abs=1e-9)
    lead = float(w.host.lbar.trim_state[TS_LEAD])
    assert w.reference()[0] == pytest.approx(lbar_high + lead, abs=1e-5)
    tension(w, 36.0, 2.0)       # (pulled: 10 m more out is no slack for the guard)
    w.set_uav(UAV)
    encoder(w, 36.0, 13.5)
    lead = float(w.host.lbar.trim_state[TS_LEAD])      # the stop lead, as above
    assert w.reference()[0] == pytest.approx(host.lbar.length(UAV[0])[0] + lead, abs=1e-5)
    # without a pre-tension (or a load cell: the earlier test) it holds its length
    w2 = Winch(w.host, PARAMS.winder, PARAMS.tether, G, w.p.replace(ground_tension_n=0.0))
    tension(w2, 0.0, 0.0)
    encoder(w2, 0.0, 5.0)
    assert track(w2, 50)[-1] == (pytest.approx(5.0, abs=1e-6), 0.0)


RUNAWAYS = {
    # a diverged estimate: climbing away, flying away, sliding away on the ground
    "up": lambda t: ((4.0, 1.0, 0.3 + 6.0 * t), (0.0, 0.0, 6.0)),
    "out": lambda t: ((4.0 + 6.0 * t, 1.0, 2.0), (6.0, 0.0, 0.0)),
    "on the ground": lambda t: ((4.0 + 6.0 * t, 1.0, 0.2), (6.0, 0.0, 0.0)),
}


@pytest.mark.parametrize("runaway", sorted(RUNAWAYS))
def test_a_slack_line_is_not_paid_out_to_a_report_that_runs_away(runaway):
    """The ground side of a crash (issue 35): a vehicle on the ground 4.1 m out, the line
    slack to it (nothing pulls: the load cell reads 0), its reported position running
    away at 6 m/s. The winch pays out at most slack_payout_max_m more, says so once and
    holds; the report coming back with the line pulled ends it, and L-bar's law takes up
    again. Before, the law followed the report to the drum's end (2.4 -> 49.5 m in 8 s)."""
    report = RUNAWAYS[runaway]
    start = math.hypot(4.0, 1.0) + 0.5
    b = Bench(start, tension_n=0.0, uav=((4.0, 1.0, 0.2), (0.0, 0.0, 0.0)))
    b.run(1.0)
    first = b.length
    limit = b.winch.p.slack_payout_max_m
    lengths = []
    for k in range(1000):          # 10 s of a runaway
        b.winch.set_uav(report(k * 0.01))
        b.run(0.01)
        lengths.append(b.length)
    # (and stops from the law's full speed, 5.4 m/s: under a metre more)
    assert max(lengths) < first + limit + 1.0
    assert b.winch.slack_hold
    said = [n for n in b.notices if "paid out slack, pay-out held" in n]
    assert len(said) == 1
    held = b.length
    b.run(2.0)
    assert b.length == pytest.approx(held, abs=0.01)      # held, not wound in onto it
    # a report near the winder, the line pulled: not followed (it would wind the line in
    # onto a vehicle that may be elsewhere); the pull is paid out, slowly
    b.winch.set_uav(((4.0, 1.0, 3.0), (0.0, 0.0, 0.0)))
    b.tension = wm.WinchParams().ground_tension_n + 0.1
    b.run(1.0)
    assert b.winch.slack_hold and held <= b.length < held + 0.2
    # a report that agrees with the line pulled straight to it: the law takes up again
    k = (b.length - 0.3) / math.dist((4.0, 1.0, 3.0), (0, 0, 0))
    b.winch.set_uav(((4.0 * k, 1.0 * k, 3.0 * k), (0.0, 0.0, 0.0)))
    b.run(0.2)
    assert not b.winch.slack_hold and "winch: line pulled, following L-bar again" in b.notices
    # and an operator's DO_WINCH RELAXED ends it too: the line rejoins L-bar
    b.winch.set_uav(((4.0, 1.0, 3.0), (0.0, 0.0, 0.0)))
    b.winch.relaxed.slack_hold = True
    assert b.command(request(mavlink2.WINCH_RELAXED)).result == ACK
    assert not b.winch.slack_hold
    b.tension = 1.0
    b.run(10.0)                    # (rejoining from the longer line at 1 m/s)
    lbar = b.winch.host.lbar.length((4.0, 1.0, 3.0))[0]
    assert b.winch.reference()[0] >= lbar              # L-bar's law (with its lead)
    assert b.length == pytest.approx(b.winch.reference()[0], abs=0.01)
    assert b.length < lbar + 0.3


def test_a_slack_line_pulled_again_counts_afresh_and_a_pulled_line_is_paid_out():
    """The count is of line paid out while nothing pulls it: a pull resets it, so a real
    vehicle moving away on a line that pulls (the tether governor's moves, a climb on the
    catenary's 0.3-0.7 N) is followed as far as it goes."""
    b = Bench(5.0, tension_n=0.0, uav=((4.0, 1.0, 3.0), (0.0, 0.0, 0.0)))
    b.run(1.0)
    for k in range(1000):          # 10 s of a climb at 2 m/s: 20 m of line
        b.tension = 0.0 if (k // 50) % 2 else 0.5      # slack half the time, 0.5 s each
        b.winch.set_uav(((4.0, 1.0, 3.0 + 0.02 * k), (0.0, 0.0, 2.0)))
        b.run(0.01)
    assert not b.winch.slack_hold
    assert b.length > b.winch.host.lbar.length((4.0, 1.0, 22.98))[0] - 0.05


def test_a_join_never_winds_the_line_in():
    """A join's gap defers a pay-out; it never winds the line in. A vehicle found in the
    air first reports a height 2.5 m too high (a just-aligned estimate on a consumer
    receiver), which opens a gap; as its reports settle 3 m lower over a second, L-bar's
    law falls into the gap: the reference holds the line it has until L-bar's law is
    below it, then follows the law (before, it followed the law down with the whole gap
    still open, a metre short of the true distance: the line taut)."""
    w = make_winch()
    host = w.host
    high = (20.0, 0.0, 22.0)
    lbar_high = host.lbar.length(high)[0]
    start = lbar_high - 2.0                   # the line the winder has: the true one's
    tension(w, 0.0, 3.0)                      # an in-air pull, no position yet
    encoder(w, 0.0, start)
    for k in range(101):                      # 1 s of reports sinking at 3 m/s
        pos = (high[0], high[1], high[2] - 3.0 * k * DT)
        w.set_uav((pos, (0.0, 0.0, -3.0 if k < 100 else 0.0)))
        encoder(w, 0.01 + k * DT, w.reference()[0] if k else start)
        lbar = host.lbar.length(pos)[0]
        ref = w.reference()[0]
        assert ref >= min(start, lbar) - 1e-6, (k, ref, start, lbar)
    assert lbar < start - 0.1 and w.join_gap_m == 0.0
    lead = float(host.lbar.trim_state[TS_LEAD])
    assert ref == pytest.approx(lbar + lead, abs=1e-6)


def test_the_sensor_clock_unwraps_the_sample_time_and_serves_as_the_winchs_time():
    """Winch_Tension's 16-bit Sample_Time unwrapped into the sensor node's clock; handed
    that as its time (a lockstep plant), the winch brakes on an encoder silent for 0.1 s
    of it while the sensors go on, however long the host took between frames."""
    w = make_winch()
    assert w.sensor_clock_s is None
    for k, stamp in enumerate((65_500, 65_530, 24, 54)):      # wraps after 65.535 s
        tension(w, 100.0 * k, 1.0, stamp)
    assert w.sensor_clock_s == pytest.approx(65.590)
    clock = w.sensor_clock_s
    encoder(w, clock, 10.0)
    for ms in range(10, 200, 10):     # the sensors on, the encoder silent
        tension(w, clock, 1.0, (54 + ms) & 0xFFFF)
        out = w.poll(w.sensor_clock_s)
        assert w.lost == (ms > 100)
        if ms == 110:
            assert "winch: encoder lost, drum braked" in [n.text for n in out.notices]


# ----- the over-tension pay-out and a stuck drum, against the plant's axis and drum


def test_over_tension_pays_out_then_the_line_rejoins_lbar():
    """RELAXED on L-bar, then the load cell reads 40 N (above the 30 N limit) for 2 s: the
    winch says so within 0.1 s and pays out at 0.5 m/s; below the limit again, it says so
    and winds back to L-bar no faster than its rejoin rate."""
    b = Bench(14.0)
    b.run(2.0)
    lbar = b.winch.host.lbar.length(UAV[0])[0]
    assert b.length == pytest.approx(lbar, abs=0.02)
    b.tension = 40.0
    b.run(0.2)
    said = [n for n in b.notices if "over-tension" in n]
    assert said == ["winch: over-tension 40 N > 30 N, paying out"]
    start = b.length
    b.run(2.0)
    assert b.length - start == pytest.approx(2.0 * 0.5, abs=0.1)
    b.tension = 10.0
    b.run(0.1)
    assert b.notices[-1] == "winch: tension back below 30 N"
    fastest = 0.0
    for _ in range(40):
        b.run(0.1)
        fastest = max(fastest, -b.omega * R_W)
    assert 0.5 < fastest <= b.winch.p.rejoin_rate_m_s * 1.05 + 0.02
    assert b.length == pytest.approx(lbar, abs=0.02)


def test_over_tension_stops_a_wind_in_and_pays_out():
    b = Bench(14.0, uav=((2.0, 2.0, 6.0), (0.0, 0.0, 0.0)))    # the taut floor near 7 m
    b.run(0.5)
    assert b.command(request(mavlink2.WINCH_RATE_CONTROL, rate=-0.3)).result == ACK
    b.run(1.0)
    assert b.omega * R_W == pytest.approx(-0.3, abs=0.05)
    b.tension = 35.0                  # (the motor holds up to 40 N: 4 N m on 0.1 m)
    b.run(1.0)
    assert b.omega * R_W == pytest.approx(0.5, abs=0.05)      # paying out now
    b.tension = 5.0
    b.run(1.0)
    assert abs(b.omega * R_W) < 0.02                          # and holds: no wind-in again


def test_a_stuck_drum_is_reported_braked_and_unhealthy():
    """The drum jammed (its stops closed on its angle, as a snagged tether closes them) and
    the UAV moving away: the reference runs ahead, the winch says the drum is stuck within
    0.2 s and reports it braked (CLUTCH_ENGAGED) and not HEALTHY; freed, it follows again
    and is healthy."""
    b = Bench(14.0)
    b.run(2.0)
    assert all(b.healthy(1.0))
    theta = b.theta
    b.model.set_stops(theta, theta)
    far = ((4.5, 6.0, 12.0), (0.0, 0.0, 0.0))     # 14.2 m from the exit: L-bar 0.9 m longer
    b.winch.set_uav(far)
    b.run(0.3)
    stuck = [n for n in b.notices if "stuck" in n]
    assert stuck == [f"winch: drum stuck at {b.length:.1f} m, no pay-out"]
    t_stuck = next(t for t, st in b.statuses if st.flags & wm.FLAG_CLUTCH_ENGAGED)
    assert t_stuck <= 2.2 + 0.05
    last = b.statuses[-1][1]
    assert last.flags & wm.FLAG_CLUTCH_ENGAGED and not last.flags & wm.FLAG_HEALTHY
    b.model.set_stops(b.model.theta_min, b.model.theta_max)
    b.run(3.0)
    assert "winch: drum no longer behind its reference" in b.notices
    assert b.healthy(b.t - 0.5) and all(b.healthy(b.t - 0.5))
    # a drum catching up with a jump of L-bar (it moves) is not stuck
    b.winch.set_uav(((7.0, 9.0, 12.0), (0.0, 0.0, 0.0)))
    n = len(b.notices)
    b.run(3.0)
    assert not [x for x in b.notices[n:] if "stuck" in x]


def test_the_bus_check_counts_lost_and_late_load_cell_frames():
    """The load cell's stamps judge the bus: a plant on a 20 ms grid (its frames 20 ms
    apart) loses nothing; every other frame of a 10 ms stream gone is 50 % lost; frames
    80 ms older than the UAV's position are late; each brakes the drum (IDLE on the next
    encoder frame) and is said, and 10 good windows end it."""
    tension_id = cp.frame_id(cp.WINCH_SENSOR_NODE_ID_DEFAULT, cp.SensorCmd.WINCH_TENSION)

    def feed(w: Winch, stamps, uav_ahead_ms: int | None = None) -> list[str]:
        said = []
        for ms in stamps:
            if uav_ahead_ms is not None:
                w.set_uav(UAV, (ms + uav_ahead_ms) & 0xFFFF)
            w.on_frame(ms * 1e-3, tension_id, cp.encode_winch_tension(5.0, False, ms & 0xFFFF))
            out = encoder(w, ms * 1e-3, 14.0)
            said += [n.text for n in out.notices]
            if w.bus_degraded:
                assert ("Set_Axis_State", cp.AxisState.IDLE) in decoded(out.frames)
        return said

    slow = ready(14.0)
    assert feed(slow, range(0, 2000, 20)) == [] and not slow.bus_degraded
    lossy = ready(14.0)
    said = feed(lossy, [*range(0, 1000, 10), *range(1000, 2000, 20)])
    assert lossy.bus_degraded and said == ["winch: CAN bad (50% lost, 0 ms), braked"]
    assert not lossy.status_flags() & wm.FLAG_HEALTHY
    assert lossy.status_flags() & wm.FLAG_CLUTCH_ENGAGED
    said = feed(lossy, range(2000, 3200, 10))
    assert said == ["winch: CAN bus good again"] and not lossy.bus_degraded
    late = ready(14.0)
    assert feed(late, range(0, 1000, 10), uav_ahead_ms=5) == []
    said = feed(late, range(1000, 1500, 10), uav_ahead_ms=80)
    assert said == ["winch: CAN bad (0% lost, 80 ms), braked"]


@pytest.mark.parametrize(("a", "x0", "h"), [(6.0, 0.5, 12.0), (20.0, 3.0, 15.0),
                                            (3.0, 0.1, 4.0)])
def test_line_weight_from_exit_tension_and_angle_is_the_catenarys(a, x0, h):
    """An inextensible catenary y = a cosh(x/a) leaving the exit at x0 (upward) and
    reaching the UAV h further: its exit tension, exit angle, arc length and rise give
    back its weight per metre, whatever the weight."""
    from groundstation.lbar import line_weight_n_m

    for w in (0.2, 0.33, 1.1):
        x1 = x0 + h
        z = a * (math.cosh(x1 / a) - math.cosh(x0 / a))
        length = a * (math.sinh(x1 / a) - math.sinh(x0 / a))
        tension = w * a * math.cosh(x0 / a)
        elevation = math.atan(math.sinh(x0 / a))
        assert line_weight_n_m(tension, elevation, length, z) == pytest.approx(w, rel=1e-9)
    # no tension, a vertical or a straight line: nothing to say
    assert math.isnan(line_weight_n_m(0.0, 0.3, 10.0, 5.0))
    assert math.isnan(line_weight_n_m(5.0, 0.3, 10.0, 10.0))


def test_a_heavier_line_than_the_model_does_not_trip_the_tension_trim():
    """The drum tension of a line twice the model's weight, at the geometry the model
    expects (exit angle and all): the trim pays out nothing once the weight estimate has
    it, and it still pays out for a tension above what that weight explains."""
    from groundstation.lbar import LBarParams, catenary_length_m, exit_slope

    lp = LBarParams(tension_trim_filter_s=0.0)
    host = WinderHost(PAPER, lp, PARAMS.winder, PARAMS.tether, G)
    lb = host.lbar
    pos = (12.0, 0.0, 20.0)
    _, a = lb.length(pos)
    h, v = math.hypot(pos[0], pos[1]), pos[2]
    length = catenary_length_m(a, h, v)    # the model's catenary, paid out
    slope = exit_slope(a, h, v)
    heavy = 2.0 * lb.w
    tension = heavy * a * math.sqrt(1.0 + slope * slope)
    for _ in range(2000):   # 20 s at 100 Hz
        host.update(length, 0.0, tension, pos, (0.0, 0.0, 0.0), math.atan(slope))
    assert lb.trim_state[TS_WEIGHT] == pytest.approx(heavy, rel=1e-3)
    assert lb.estimated_weight_n_m == lb.trim_state[TS_WEIGHT]
    assert lb.trim_state[TS_OFFSET] == 0.0
    # without the exit angle the model's weight is all it has: the heavy line reads tight
    blind = WinderHost(PAPER, lp, PARAMS.winder, PARAMS.tether, G)
    for _ in range(200):
        blind.update(length, 0.0, tension, pos, (0.0, 0.0, 0.0))
    assert blind.lbar.trim_state[TS_OFFSET] > 0.3   # 2 s at the trim's 0.2 m/s
    # a UAV farther than reported pulls harder than the heavy line explains: it pays out
    for _ in range(100):
        host.update(length, 0.0, 1.6 * tension, pos, (0.0, 0.0, 0.0), math.atan(slope))
    assert lb.trim_state[TS_OFFSET] > 0.1


def test_the_raw_reading_carries_the_winders_weight_estimate():
    """The raw reading the winch sends with a tether fix (DEBUG_FLOAT_ARRAY "TETHER")
    carries L-bar's weight estimate: none (NaN) before it has one, then the estimate of a
    line twice the model's weight (its catenary at the geometry the model expects),
    through the message the vehicle parses."""
    from groundstation.lbar import catenary_length_m, exit_slope
    from groundstation.tether_fix import TetherFix

    winch = Winch(WinderHost(PAPER, LBarParams(tension_trim_filter_s=0.0), PARAMS.winder,
                             PARAMS.tether, G), PARAMS.winder, PARAMS.tether, G)
    sensors, lb = winch.sensors, winch.host.lbar
    sensors.load_cell_n = 2.5
    sensors.exit_angle = (0.1, 0.6, 0, True)
    fix = TetherFix((10.0, 1.0, 12.0), ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)),
                    4200, False)
    assert math.isnan(sensors.tether_reading(fix, 16.0, lb).weight_n_m)
    pos = (12.0, 0.0, 20.0)
    _, a = lb.length(pos)
    h, v = math.hypot(pos[0], pos[1]), pos[2]
    slope = exit_slope(a, h, v)
    tension = 2.0 * lb.w * a * math.sqrt(1.0 + slope * slope)
    for _ in range(2000):   # 20 s at 100 Hz
        winch.host.update(catenary_length_m(a, h, v), 0.0, tension, pos, (0.0, 0.0, 0.0),
                          math.atan(slope))
    reading = sensors.tether_reading(fix, 16.0, lb)
    assert reading.weight_n_m == pytest.approx(2.0 * lb.w, rel=1e-3)
    companion = cl.new_mavlink(cl.AUTOPILOT_COMPONENT_ID)
    msg, = companion.parse_buffer(cl.tether_reading_message(reading).pack(
        cl.new_mavlink(cl.WINCH_COMPONENT_ID)))
    assert cl.tether_reading(msg).weight_n_m == pytest.approx(2.0 * lb.w, rel=1e-6)


# ------------------------------------------------- the motor's current, a second source

TENSION_ID = cp.frame_id(cp.WINCH_SENSOR_NODE_ID_DEFAULT, cp.SensorCmd.WINCH_TENSION)


def _current_tension(b: Bench, seconds: float) -> list[float]:
    out = []
    for _ in range(round(seconds / 0.1)):
        b.run(0.1)
        out.append(b.winch.sensors.current.tension_n)
    return out


@pytest.mark.parametrize("tension_n", [2.0, 8.0])
def test_the_motor_current_gives_the_drum_tension(tension_n):
    """Against the plant's drum model (its inertia, friction and speed cut-back; the axis's
    Get_Iq from the torque it applied), the drum holding a line at a constant tension: the
    current's estimate (T = (I dw/dt + beta w - Kt Iq) / r_w on the station's own drum
    model) is that tension within 0.3 N once settled, and it is the plant's frames that
    bring it (a Get_Iq every 50 ms)."""
    b = Bench(14.0, tension_n=tension_n)
    b.run(2.0)
    est = _current_tension(b, 1.0)
    assert b.winch.sensors.current.iq_frames >= 2.9 * 20 * 0.98     # 20 Hz
    assert max(abs(t - tension_n) for t in est) < 0.3
    assert b.winch.sensors.source is TensionSource.LOAD_CELL   # the load cell agrees
    assert b.winch.tension_n == pytest.approx(tension_n, abs=0.2)


def test_a_silent_load_cell_hands_the_tension_to_the_motor_current_and_back():
    """No Winch_Tension for 0.1 s: the winch takes the current's tension (said), follows
    the line's true tension with it (a pull raised from 5 to 9 N while the load cell is
    silent: the over-tension and WINCH_STATUS see it), and takes the load cell back when it
    speaks again (said)."""
    b = Bench(14.0, tension_n=5.0)
    b.run(2.0)
    b.load_cell_on = False
    b.run(0.3)
    assert "winch: load cell silent, tension from current" in b.notices
    assert b.winch.sensors.source is TensionSource.CURRENT
    b.tension = 9.0
    b.run(1.0)
    assert b.winch.tension_n == pytest.approx(9.0, abs=0.5)
    assert b.statuses[-1][1].tension_kg == pytest.approx(9.0 / G, abs=0.05)
    b.load_cell_on = True
    b.run(0.2)
    assert "winch: load cell back, tension from load cell" in b.notices
    assert b.winch.sensors.source is TensionSource.LOAD_CELL
    assert b.winch.tension_n == pytest.approx(9.0, abs=0.2)


def test_a_load_cell_that_disagrees_for_a_second_is_overruled_by_the_current():
    """A load cell reading 12 N over the truth (a shifted zero): after tension_disagree_s
    the current's tension takes over (said), within its model of the truth; a short
    disagreement changes nothing."""
    b = Bench(14.0, tension_n=5.0)
    b.run(2.0)
    b.load_cell_bias_n = 12.0
    b.run(0.5)
    assert b.winch.sensors.source is TensionSource.LOAD_CELL   # not yet: 0.5 s < 1 s
    b.run(1.0)
    assert "winch: load cell disagrees, tension from current" in b.notices
    assert b.winch.sensors.source is TensionSource.CURRENT
    assert b.winch.tension_n == pytest.approx(5.0, abs=1.0)


def test_a_braked_drum_leaves_the_tension_to_the_load_cell():
    """HOLD: the brake takes the pull and the motor's current (0 A) says nothing of it: no
    current's tension while braked, no disagreement, the load cell's 8 N kept; back in
    RELAXED the current's tension returns with the closed loop."""
    b = Bench(14.0, tension_n=8.0)
    b.run(2.0)
    assert b.command(request(mavlink2.WINCH_HOLD)).result == ACK
    b.run(2.5)
    assert math.isnan(b.winch.sensors.current.tension_n)
    assert b.winch.sensors.source is TensionSource.LOAD_CELL
    assert b.winch.tension_n == pytest.approx(8.0, abs=0.2)
    assert not any("tension from current" in n for n in b.notices)
    assert b.command(request(mavlink2.WINCH_RELAXED)).result == ACK
    b.run(2.0)
    assert b.winch.sensors.current.tension_n == pytest.approx(8.0, abs=0.3)


def test_a_landing_hands_the_tension_law_over_to_the_pre_tension_without_a_bump():
    """The UAV reports itself on the ground while the tension law holds the line at 2.5 N:
    the pre-tension's loop starts from the tension the law held (its rate continuous: no
    pay-out at k (T - T_g), 2.2 m/s, at once, which left the lumped line slack and snapped
    it at 26 N when the drum wound it back) and reaches its own target on the law's
    set-point filter; with the paper's law, it starts at its own target as before."""
    for law, bumpless in (("tension", True), ("paper", False)):
        host = WinderHost(WinderControlParams(law=law), LBarParams(tension_trim_rate_m_s=0.0),
                          PARAMS.winder, PARAMS.tether, G)
        w = Winch(host, PARAMS.winder, PARAMS.tether, G)
        p = w.p
        air = ((6.0, 0.0, 2.0), (0.0, 0.0, -0.5))
        w.set_uav(air)
        wall = 0.0
        for k in range(300):            # 3 s at 2.5 N in the air: the law's
            wall = k * DT               # low-pass has it
            tension(w, wall, 2.5)
            encoder(w, wall, 6.4)
        assert not w.relaxed.pretension.holding
        w.set_uav(((6.0, 0.0, 0.4), (0.0, 0.0, -0.5)))
        rates = []
        for k in range(1, 301):
            tension(w, wall + k * DT, 2.5)
            encoder(w, wall + k * DT, w.reference()[0])
            rates.append(w.reference()[1])
        assert w.relaxed.pretension.holding
        full = min(p.ground_tension_gain_m_s_n * (2.5 - p.ground_tension_n), w.max_rate_m_s)
        if bumpless:
            assert rates[0] < 0.05 * full
            # the target falls on the set-point filter (0.5 s): after 3 s nearly all of it
            tau = WinderControlParams().tension_setpoint_filter_s
            assert rates[-1] == pytest.approx(full * (1.0 - math.exp(-300 * DT / tau)),
                                              rel=0.01)
        else:
            assert rates[0] == pytest.approx(full)
