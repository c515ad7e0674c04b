"""The winder's CAN bus between real processes: a CAN host (standing in for the ground
station) drives the plant's simulated ODrive axis over python-can's udp_multicast bus,
inside a private network namespace (the suite creates it itself when run as root)."""


import pytest
from netns_util import netns_available, run_session

from tuavdefs.can_protocol import ODriveError

pytestmark = pytest.mark.skipif(not netns_available(),
                                reason="needs root (unshare) for a private network namespace")


@pytest.fixture(scope="module")
def session() -> dict:
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
