"""The real ground-station process as the winch component, in a private network namespace:

- against the plant's simulated ODrive axis and sensors (``sitl.odrive_axis`` objects around
  the plant's drum model, in real time) on a real python-can udp_multicast bus, and a real
  pymavlink TCP server standing where the companion is (tests/netns/groundstation_session.py):
  DO_WINCH answers, the drum following each mode, the brake, encoder loss and return,
  WINCH_STATUS rate and contents;
- in the whole stack: the plant process (lockstep), the companion and the ground station,
  with DO_WINCH commands injected on the component link (tests/netns/stack_winch_session.py):
  the real drum follows the modes, the tether is never taut, lockstep is kept.
"""

import math

import pytest
from netns_util import netns_available, run_session
from pymavlink.dialects.v20 import common as mavlink2

from groundstation.lbar import LBarEstimator, LBarParams
from tuavdefs.params import SystemParams

ACCEPTED = mavlink2.MAV_RESULT_ACCEPTED
HEALTHY = mavlink2.MAV_WINCH_STATUS_HEALTHY
FULLY_RETRACTED = mavlink2.MAV_WINCH_STATUS_FULLY_RETRACTED
MOVING = mavlink2.MAV_WINCH_STATUS_MOVING
CLUTCH = mavlink2.MAV_WINCH_STATUS_CLUTCH_ENGAGED
MIN_SLACK = LBarParams().min_slack_m
PARAMS = SystemParams()
G = PARAMS.environment.gravity_m_s2
LBAR = LBarEstimator(LBarParams(), PARAMS.tether.weight_per_length_n_m(G))

pytestmark = pytest.mark.skipif(not netns_available(),
                                reason="needs root (unshare) for a private network namespace")


def _session(module: str, *args: str, timeout_s: float = 240) -> dict:
    return run_session(module, *args, timeout_s=timeout_s)


@pytest.fixture(scope="module")
def gs() -> dict:
    return _session("tests.netns.groundstation_session", timeout_s=480)


def _acked(ack: dict | None, result: int = ACCEPTED) -> None:
    assert ack is not None, "no COMMAND_ACK"
    assert ack["command"] == 42600 and ack["result"] == result
    assert ack["src"] == [1, 169]                                  # from the winch
    assert (ack["target_system"], ack["target_component"]) == (255, 190)   # to the sender
    # (how soon is the wall clock's, which a busy machine stretches: the session waits 5 s)


# ----------------------------------------------------------- the process on its own links

def test_it_connects_arms_the_axis_and_follows_lbar(gs):
    assert gs["gs_rc"] == 0
    hb = gs["heartbeat"]
    assert hb["src"] == [1, 169] and hb["type"] == mavlink2.MAV_TYPE_WINCH
    assert hb["autopilot"] == mavlink2.MAV_AUTOPILOT_INVALID
    assert [n for n, _ in gs["first_host_frames"]] == [
        "Clear_Errors", "Set_Controller_Mode", "Set_Axis_State", "Set_Input_Torque"]
    assert gs["armed_state"] == 8
    uav = (10.0, 0.0, 5.0)
    assert gs["relaxed_length_m"] == pytest.approx(LBAR.length(uav)[0], abs=0.005)


def test_winch_status_rate_and_contents(gs):
    assert gs["status_rate_hz"] == pytest.approx(20.0, rel=0.05)   # of simulated time
    st = gs["status_sample"]
    assert st["src"] == [1, 169]
    assert st["line_length"] == pytest.approx(gs["relaxed_length_m"], abs=0.005)
    assert st["tension"] == pytest.approx(5.0 / G, rel=1e-5)       # kg, as defined
    assert st["voltage"] == pytest.approx(48.0)                    # Get_Bus_Voltage_Current
    assert math.isfinite(st["current"])
    assert st["temperature"] == 32767
    assert st["status"] == HEALTHY


def test_relative_length_pays_out_at_the_commanded_rate(gs):
    _acked(gs["length_ack"])
    assert gs["length_mid_speed_m_s"] == pytest.approx(0.5, abs=0.02)
    assert gs["length_paid_m"] == pytest.approx(1.0, abs=0.01)


def test_a_length_below_the_taut_floor_is_clamped_and_said(gs):
    _acked(gs["clamp_ack"])                          # COMMAND_INT to the autopilot's id
    floor = math.dist((10.0, 0.0, 5.0), (0, 0, 0)) + MIN_SLACK
    # (on a busy machine the axis's watchdog may trip meanwhile, said, and re-armed)
    assert [t for t in gs["clamp_texts"] if "clamped" in t[1]] == [
        [mavlink2.MAV_SEVERITY_WARNING, f"winch: length clamped to {floor:.2f} m"]]
    assert gs["clamp_length_m"] == pytest.approx(floor, abs=0.005)


def test_rate_control(gs):
    _acked(gs["rate_ack"])                           # to component 0
    assert gs["rate_paid_m"] == pytest.approx(0.5, abs=0.02)
    assert gs["rate_status_flags"] == HEALTHY | MOVING


def test_retract_to_the_straight_line_distance_plus_min_slack(gs):
    _acked(gs["retract_ack"])
    floor = math.dist((10.0, 0.0, 5.0), (0, 0, 0)) + MIN_SLACK
    assert gs["retract_length_m"] == pytest.approx(floor, abs=0.005)
    assert gs["retract_status"]["status"] == HEALTHY | FULLY_RETRACTED


def test_hold_idles_the_axis_and_the_brake_holds(gs):
    _acked(gs["hold_ack"])
    assert gs["hold_frames"][0] == ["Set_Axis_State", "1"]
    assert gs["hold_state"] == 1
    assert abs(gs["hold_drift_m"]) < 1e-4
    assert gs["hold_status_flags"] & CLUTCH and gs["hold_status_flags"] & HEALTHY
    _acked(gs["relax_ack"])
    frames = [n for n, _ in gs["relax_frames"]]
    i = frames.index("Clear_Errors")
    assert gs["relax_frames"][i:i + 3] == [
        ["Clear_Errors", "False"],
        ["Set_Controller_Mode", "ControllerMode(control_mode=1, input_mode=1)"],
        ["Set_Axis_State", "8"]]
    assert gs["relax_state"] == 8
    assert gs["relax_length_m"] == pytest.approx(gs["relaxed_length_m"], abs=0.005)


def test_refused_commands(gs):
    r = gs["refused"]
    for name in ("deliver", "load_payload"):
        _acked(r[name]["ack"], mavlink2.MAV_RESULT_UNSUPPORTED)
    for name, why in (("instance", "instance"), ("nan_length", "NaN"), ("nan_rate", "NaN")):
        _acked(r[name]["ack"], mavlink2.MAV_RESULT_DENIED)
        assert len(r[name]["texts"]) == 1 and why in r[name]["texts"][0][1]
    assert r["other_component"]["ack"] is None and not r["other_component"]["texts"]
    assert gs["state_after_refused"] == 8            # nothing changed


def test_encoder_loss_brakes_the_drum_and_its_return_rearms(gs):
    # braked once the encoder has been silent for its timeout, never before (how much
    # after is the wall clock's, which a busy machine stretches)
    assert gs["lost_idle_after_s"] >= 0.1
    texts = gs["lost_texts"]
    lost = [t for t in texts if t[1] == "winch: encoder lost, drum braked"]
    assert len(lost) == 1, texts
    sev, _, after = lost[0]
    assert sev == mavlink2.MAV_SEVERITY_CRITICAL
    assert after >= 0.1
    assert texts[-1][:2] == [mavlink2.MAV_SEVERITY_NOTICE, "winch: encoder back"]
    # beside it at most the axis's own watchdog (no torque frames without encoder frames to
    # answer), which races the encoder's timeout and the IDLE request, both on the wall
    # clock (on a machine busy on every core it came first); Clear_Errors clears it on the
    # way back
    assert all(t[:2] == [mavlink2.MAV_SEVERITY_CRITICAL, "winch: axis error 0x01000000"]
               for t in texts[:-1] if t is not lost[0] and "re-arming" not in t[1])
    # WINCH_STATUS by the wall clock while lost (every 0.09 s of it: a dozen in the 1.35 s
    # on an idle machine; a busy one wakes the process less often), without HEALTHY,
    # clutch engaged
    times = gs["lost_status_times"]
    assert len(times) >= 5
    assert gs["lost_status_flags"] == [CLUTCH]
    assert gs["lost_heartbeats"] >= 1
    # back: Clear_Errors, torque mode, closed loop, then torques
    assert [n for n, _, _ in gs["back_frames"]] == [
        "Clear_Errors", "Set_Controller_Mode", "Set_Axis_State", "Set_Input_Torque"]
    assert gs["back_frames"][2][1] == "8"
    assert gs["back_state"] == 8 and gs["back_errors"] == 0
    assert gs["back_status_flags"] == HEALTHY
    assert gs["back_length_m"] == pytest.approx(gs["relaxed_length_m"], abs=0.005)
    assert gs["axis_dropped"] == {}                  # never a malformed frame
    assert "encoder lost" in gs["gs_out"] and "encoder back" in gs["gs_out"]


# ----------------------------------------------------------------------- the whole stack

@pytest.fixture(scope="module")
def stack(tmp_path_factory) -> dict:
    return _session("tests.netns.stack_winch_session",
                    str(tmp_path_factory.mktemp("winch_stack")), timeout_s=480)


def _row(rows: list[dict], t: float) -> dict:
    return min(rows, key=lambda r: abs(r["t_s"] - t))


def _floor(r: dict) -> float:
    return math.dist((r["x_m"], r["y_m"], r["z_m"]), (0, 0, 0)) + MIN_SLACK


def test_stack_commands_are_acknowledged_through_the_link(stack):
    assert set(stack["sent"]) == {"length", "hold", "relax", "retract", "relax2"}
    acks = [d for _, k, d in stack["seen"] if k == "COMMAND_ACK"]
    assert len(acks) == 5
    for a in acks:
        assert (a["result"], a["src"], a["target_system"], a["target_component"]) == (
            ACCEPTED, [1, 169], 255, 190)


def test_stack_drum_follows_the_modes(stack):
    rows, sent = stack["rows"], stack["sent"]
    # +1 m at 0.5 m/s: done 2 s later, held until HOLD
    t = sent["length"]
    assert (_row(rows, sent["hold"])["tether_length_m"] - _row(rows, t)["tether_length_m"]
            == pytest.approx(1.0, abs=0.01))
    mid = _row(rows, t + 1.0)
    assert mid["drum_rate_rad_s"] * PARAMS.winder.drum_radius_m == pytest.approx(0.5, abs=0.03)
    # HOLD: the brake holds the drum
    held = [r["tether_length_m"] for r in rows if sent["hold"] + 0.1 <= r["t_s"] <= sent["relax"]]
    assert max(held) - min(held) < 1e-3
    # RELAXED: back on L-bar
    r = _row(rows, sent["retract"])
    assert r["tether_length_m"] == pytest.approx(LBAR.length((r["x_m"], r["y_m"], r["z_m"]))[0],
                                                 abs=0.01)
    # RETRACT: the straight-line distance plus min slack
    r = _row(rows, sent["relax2"])
    assert r["tether_length_m"] == pytest.approx(_floor(r), abs=0.01)
    flags = [f for t, _, f in stack["status"] if sent["relax2"] - 0.5 <= t <= sent["relax2"]]
    assert flags and all(f & FULLY_RETRACTED for f in flags)


def test_stack_never_taut_and_lockstep_kept(stack):
    for r in stack["rows"]:
        assert r["tether_length_m"] > math.dist((r["x_m"], r["y_m"], r["z_m"]), (0, 0, 0))
    assert stack["rows"][-1]["t_s"] >= 19.9
    assert "0 late answers" in stack["plant"] and "0 bad frames" in stack["plant"]
    start = stack["rows"][0]
    worst = max(math.dist((r["x_m"], r["y_m"], r["z_m"]),
                          (start["x_m"], start["y_m"], start["z_m"])) for r in stack["rows"])
    assert worst < 0.2                               # the UAV holds its place meanwhile


def test_stack_status_rate_in_simulated_time(stack):
    times = [t for t, _, _ in stack["status"] if 1.0 <= t <= 19.0]
    assert len(times) / 18.0 == pytest.approx(20.0, rel=0.05)


# ------------------------------------------------- the ground station's own parameters

def test_ground_params_are_checked_and_default_to_the_defaults(tmp_path):
    """``up --ground-params``: a scenario's tables, each field checked; none: defaults."""
    import argparse

    from groundstation.station_params import GroundStationParams
    from groundstation.winder_control import WinderControlParams
    from tuav_sitl.up import add_arguments, ground_params
    from tuavdefs.paramspec import ParameterError

    ap = argparse.ArgumentParser()
    add_arguments(ap)
    assert ground_params(ap.parse_args([])) == GroundStationParams()
    good = tmp_path / "gs.toml"
    good.write_text('[winder_control]\nlaw = "tension"\n[winch]\ntension_limit_n = 25.0\n')
    got = ground_params(ap.parse_args(["--ground-params", str(good)]))
    assert got.winder_control == WinderControlParams(law="tension")
    assert got.winch.tension_limit_n == 25.0
    bad = tmp_path / "bad.toml"
    bad.write_text('[winder_control]\nlaw = "rope"\n')
    with pytest.raises(ParameterError, match="law"):
        ground_params(ap.parse_args(["--ground-params", str(bad)]))
