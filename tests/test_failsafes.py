"""The link failsafes (companion/failsafes.py) in closed loop on the plant's truth model:
a lost ground station (ArduCopter's FS_GCS_ENABLE / FS_GCS_TIMEOUT) and a lost or failed
winder, each within its timeout, said once, ending landed with the tether never taut; and
offline, a CAN-loss fault the ground station cannot see through."""

from __future__ import annotations

import math

import pytest
from nav_harness import Loop

from companion.failsafes import FailsafeParams, GcsAction, WinchAction
from companion.navigation import FlightMode, NavEvent, NavigationParams
from tuav_sitl.offline import OfflineRunner
from tuav_sitl.scenario import ScenarioParams
from tuavdefs.paramspec import ParameterError, load_toml


def flying_at(pos, failsafes: FailsafeParams) -> Loop:
    """Taken off and holding at ``pos`` in GUIDED, a ground station heard every period."""
    loop = Loop(nav=NavigationParams())
    loop.companion.failsafes.params = failsafes
    nav = loop.nav
    assert nav.set_mode(FlightMode.GUIDED) is None and nav.arm() is None
    assert nav.takeoff(pos[2]) is None

    def heard(lp: Loop) -> bool:
        lp.companion.gcs_heard(lp.t)
        return NavEvent.TAKEOFF_DONE in lp.kinds()
    assert loop.run_until(heard, 30.0)
    assert nav.goto(pos) is None

    def there(lp: Loop) -> bool:
        lp.companion.gcs_heard(lp.t)
        return math.dist(lp.pos, pos) < 0.1
    assert loop.run_until(there, 30.0)
    return loop


def failsafe_texts(loop: Loop) -> list[tuple[float, str]]:
    return [(t, str(v)) for t, k, v in loop.events if k is NavEvent.FAILSAFE]


@pytest.mark.parametrize("action, mode, text", [
    (GcsAction.RTL, FlightMode.RTL, "GCS Failsafe: RTL"),
    (GcsAction.LAND, FlightMode.LAND, "GCS Failsafe: landing")])
def test_a_lost_ground_station_is_flown_home_or_down(action, mode, text):
    loop = flying_at((8.0, 3.0, 8.0), FailsafeParams(gcs_action=int(action),
                                                     gcs_timeout_s=3.0))
    t_lost = loop.t
    assert loop.run_until(lambda lp: lp.nav.mode == mode, 5.0)
    said = failsafe_texts(loop)
    assert [s for _, s in said] == [text]
    assert 3.0 <= said[0][0] - t_lost <= 3.0 + 0.05
    assert loop.run_until(lambda lp: not lp.nav.armed, 120.0)
    assert loop.nav.landed and loop.max_taut < 0.0
    assert len(failsafe_texts(loop)) == 1                 # said once per loss
    if mode == FlightMode.RTL:
        assert math.dist(loop.pos[:2], (2.0, 0.0)) < 0.5   # home, the launch point


def test_no_ground_station_failsafe_when_disabled_or_never_heard():
    loop = flying_at((8.0, 3.0, 8.0), FailsafeParams())     # ArduCopter's default: off
    assert FailsafeParams().gcs == GcsAction.DISABLED
    loop.run_until(lambda lp: False, 8.0)
    assert loop.nav.mode == FlightMode.GUIDED and not failsafe_texts(loop)
    # enabled, but no ground station was ever heard (a script without heartbeats)
    quiet = Loop(nav=NavigationParams())
    quiet.companion.failsafes.params = FailsafeParams(gcs_action=1, gcs_timeout_s=2.0)
    nav = quiet.nav
    assert nav.set_mode(FlightMode.GUIDED) is None and nav.arm() is None
    assert nav.takeoff(6.0) is None
    quiet.run_until(lambda lp: False, 12.0)
    assert nav.mode == FlightMode.GUIDED and not failsafe_texts(quiet)


@pytest.mark.parametrize("how", ["silent", "unhealthy"])
def test_a_lost_winder_holds_the_reach_at_its_length_and_returns(how):
    loop = flying_at((12.0, 4.0, 8.0), FailsafeParams(winch_timeout_s=2.0))
    length = loop.plant.tether_length_m
    t_lost = loop.t
    if how == "silent":
        loop.winch_link = False
    else:
        loop.winch_healthy = False
    assert loop.run_until(lambda lp: lp.nav.mode == FlightMode.RTL, 4.0)
    said = failsafe_texts(loop)
    assert [s for _, s in said] == ["Winch Failsafe: RTL within the tether"]
    assert 2.0 - 0.02 <= said[0][0] - t_lost <= 2.0 + 0.05   # from the last report
    # the drum is taken as braked where it was: no target beyond that length's reach
    assert loop.nav.reach_m <= length + 1e-6
    assert loop.run_until(lambda lp: not lp.nav.armed, 120.0)
    assert loop.nav.landed and loop.max_taut < 0.0


def test_the_winder_failsafe_waits_for_a_first_report():
    loop = Loop(nav=NavigationParams())
    loop.winch_link = False                     # no winch at all (a companion alone)
    nav = loop.nav
    assert nav.set_mode(FlightMode.GUIDED) is None and nav.arm() is None
    assert nav.takeoff(6.0) is None
    loop.run_until(lambda lp: False, 10.0)
    assert nav.mode == FlightMode.GUIDED and not failsafe_texts(loop)


def test_bad_failsafe_parameters_name_the_field(tmp_path):
    f = tmp_path / "fs.toml"
    f.write_text("gcs_action = 2\n")            # ArduCopter's removed "continue in AUTO"
    with pytest.raises(ParameterError, match="gcs_action"):
        load_toml(FailsafeParams, f)
    f.write_text("gcs_timeout_s = 0.5\n")
    with pytest.raises(ParameterError, match="gcs_timeout_s"):
        load_toml(FailsafeParams, f)
    assert FailsafeParams().winch == WinchAction.RTL


def test_offline_a_can_loss_triggers_the_winder_failsafe(tmp_path):
    """The winder's CAN bus down from 10 s: the axis brakes, the winch goes silent and the
    vehicle, hovering on its EKF, returns within the braked tether's reach and lands."""
    p = tmp_path / "can-loss.toml"
    p.write_text('''name = "can-loss"
description = "hover, the winder's CAN bus lost"
duration_s = 60.0
metrics_after_s = 2.0
[initial]
position_m = [8.0, 4.0, 10.0]
[trajectory]
kind = "setpoint"
goal_m = [8.0, 4.0, 10.0]
[[faults]]
kind = "can_loss"
start_s = 10.0
''')
    runner = OfflineRunner(load_toml(ScenarioParams, p))
    res = runner.run()
    said = [(t, v) for k, v, t in runner.nav_events if k is NavEvent.FAILSAFE]
    assert [v for _, v in said] == ["Winch Failsafe: RTL within the tether"]
    assert 11.95 <= said[0][0] <= 12.2          # 2 s after the last report
    assert res.metrics["min_tether_slack_m"] > 0.0
    assert runner.companion.nav.landed
