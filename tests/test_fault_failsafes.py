"""The failsafes against the plant's faults, offline in closed loop (the plant's truth, the
onboard software and the ground station's winch, as tuav-sitl run steps them): a tether
snag met by an outward move, a lossy CAN bus, a lost winder bus while paying out; and the
winch's own checks (a stuck drum, a late bus) against the plant's axis and drum. Each
failsafe acts within its timeout, says so, and ends with the vehicle landed within the
tether's reach; the tether is never taut (the truth's slack, paid-out length less the
distance, stays positive)."""

from __future__ import annotations

import numpy as np
import pytest
from netns_util import netns_available, run_session

from companion.navigation import NavEvent
from groundstation.winch import WinchParams
from tuav_sitl.offline import OfflineRunner
from tuav_sitl.scenario import ScenarioParams
from tuavdefs.paramspec import load_toml

#: The companion's tether governor for a length law and the winder's stop lead, on, with
#: the paper's length law on the catenary truth these failsafes were measured with (said
#: here so that they are tested with them whatever the defaults are: the tension law on
#: the lumped line by default; docs/control.md §3, §8).
_SAFETY = """[navigation]
tether_governor = 1
[lbar]
stop_lead_acc_m_s2 = 2.5
[winder_control]
law = "paper"
[tether]
model = 'catenary'"""


def _run(tmp_path, fault: str, goal=(8.0, 4.0, 10.0), duration_s: float = 60.0,
         start_s: float = 5.0):
    """A hover at (8, 4, 10) m on the EKF, a setpoint move to ``goal`` from 10 s, the fault
    (a [[faults]] table's body) from ``start_s``; the runner and its result."""
    p = tmp_path / "fault.toml"
    p.write_text(f'''name = "fault"
description = "a hover, a fault, a move"
duration_s = {duration_s}
metrics_after_s = 2.0
[initial]
position_m = [8.0, 4.0, 10.0]
[trajectory]
kind = "setpoint"
start_s = 10.0
goal_m = [{goal[0]}, {goal[1]}, {goal[2]}]
{_SAFETY}
[[faults]]
start_s = {start_s}
{fault}
''')
    runner = OfflineRunner(load_toml(ScenarioParams, p))
    return runner, runner.run()


def _said(runner) -> tuple[list[tuple[float, str]], list[tuple[float, str]]]:
    """(the vehicle's FAILSAFE texts, the winch's notices), each with its time [s]."""
    nav = [(t, str(v)) for k, v, t in runner.nav_events if k is NavEvent.FAILSAFE]
    return nav, list(runner.ground.notices)


def _slack(res) -> np.ndarray:
    s = res.series
    return s["length"] - np.linalg.norm(s["pos"], axis=1)


def test_a_snagged_tether_stops_the_vehicle_short_of_taut_and_brings_it_down(tmp_path):
    """Snagged at the exit at 5 s (invisible while hovering), then told to fly 8 m outward
    at 10 s: the winch finds its drum stuck within 0.1 s of lagging 0.1 m, reports it
    braked (the vehicle holds within the snagged length) and unhealthy; 2 s later the
    winder failsafe flies RTL within the tether and lands. Without the check the line went
    taut (slack -2 cm, 160 N); with it, before the tether governor and the winder's stop
    lead, the stop came 1.4 cm too late (-0.014 m, 84 N)."""
    runner, res = _run(tmp_path, 'kind = "tether_snag"', goal=(16.0, 4.0, 10.0))
    nav, winch = _said(runner)
    s, t = res.series, res.series["t"]
    lagging = t[np.nonzero((s["lbar"] - s["length"] > 0.1) & (t > 1.0))[0][0]]
    stuck = [(ts, n) for ts, n in winch if "stuck" in n]
    assert len(stuck) == 1 and lagging < stuck[0][0] <= lagging + 0.1 + 0.02
    assert stuck[0][1].startswith("winch: drum stuck at 13.")
    fs = [(ts, v) for ts, v in nav if v.startswith("Winch Failsafe")]
    assert len(fs) == 1 and fs[0][0] - stuck[0][0] == pytest.approx(2.0, abs=0.1)
    assert runner.companion.nav.landed and not runner.companion.nav.armed
    assert _slack(res)[t > 1.0].min() > 0.0
    assert res.metrics["max_drum_tension_n"] < 30.0


def test_a_lossy_can_bus_brakes_the_drum_and_the_vehicle_comes_down(tmp_path):
    """Half of the winder's CAN exchanges lost from 5 s: the winch judges the bus degraded
    at its first whole window (0.1 s; within two), brakes the drum and reports it
    unhealthy; the vehicle's winder failsafe flies RTL within the braked length 2 s later
    and lands. (With the bus at half and 100 ms late, the winder's loop went unstable:
    1488 N, taut.)"""
    runner, res = _run(tmp_path, 'kind = "can"\ndrop_probability = 0.5',
                       goal=(16.0, 4.0, 10.0))
    nav, winch = _said(runner)
    bad = [(ts, n) for ts, n in winch if "CAN bad" in n]
    window = runner.ground.winch.p.bus_window_s
    assert len(bad) == 1 and 5.0 < bad[0][0] <= 5.0 + 2 * window + 0.1
    assert "lost" in bad[0][1] and bad[0][1].endswith("braked")
    # 2 s after the last healthy report (which may be a lost exchange before the notice)
    fs = [(ts, v) for ts, v in nav if v.startswith("Winch Failsafe")]
    assert len(fs) == 1 and 2.0 - 2 * window <= fs[0][0] - bad[0][0] <= 2.0 + 0.1
    assert runner.companion.nav.landed and not runner.companion.nav.armed
    t = res.series["t"]
    assert _slack(res)[t > 1.0].min() > 0.0


def test_a_can_bus_lost_after_a_move_leaves_the_line_slack(tmp_path):
    """The bus lost (drop probability 1) once the vehicle holds 16 m out: the axis's
    watchdog brakes the drum at the length it had, the winch hears nothing; the vehicle
    takes the drum as braked 0.3 s after the last report and, 2 s after it, flies RTL
    within that length and lands. (Lost during the outward move at 1.3 m/s, 0.5 m of
    slack is not enough to stop in: the line is taut for a moment, slack -2 cm, 150 N;
    docs/usage.md says so.)"""
    runner, res = _run(tmp_path, 'kind = "can"\ndrop_probability = 1.0',
                       goal=(16.0, 4.0, 10.0), start_s=25.0, duration_s=80.0)
    nav, _ = _said(runner)
    fs = [(ts, v) for ts, v in nav if v.startswith("Winch Failsafe")]
    assert len(fs) == 1 and 26.9 <= fs[0][0] <= 27.1
    assert runner.companion.failsafes.winch_silent
    assert runner.companion.nav.landed and not runner.companion.nav.armed
    t = res.series["t"]
    assert _slack(res)[t > 1.0].min() > 0.0


#: (fault, fault start [s], start position [m], goal [m], move's top speed [m/s]): the
#: drum stopped mid-move, outward at different speeds, directions and heights
_DRAWS = [
    ('kind = "can"\ndrop_probability = 1.0', 11.5, (8.0, 4.0, 10.0), (16.0, 4.0, 10.0), 4.0),
    ('kind = "can"\ndrop_probability = 1.0', 10.9, (8.0, 4.0, 10.0), (16.0, 4.0, 10.0), 1.3),
    ('kind = "can"\ndrop_probability = 1.0', 12.3, (-6.0, 3.0, 6.0), (-14.0, 9.0, 18.0), 3.0),
    ('kind = "can"\ndrop_probability = 1.0', 11.0, (0.0, -10.0, 15.0), (3.0, -3.0, 25.0), 2.0),
    ('kind = "can"\ndrop_probability = 1.0', 13.7, (5.0, 0.0, 20.0), (20.0, 0.0, 8.0), 2.5),
    ('kind = "tether_snag"', 11.2, (-6.0, 3.0, 6.0), (-14.0, 9.0, 18.0), 3.0),
    ('kind = "tether_snag"', 12.0, (5.0, 0.0, 20.0), (20.0, 0.0, 8.0), 2.5),
    ('kind = "tether_snag"', 10.6, (0.0, -10.0, 15.0), (3.0, -3.0, 25.0), 1.0),
]


@pytest.mark.parametrize("fault,start_s,initial,goal,speed", _DRAWS)
def test_a_drum_stopped_during_an_outward_move_never_pulls_the_line_taut(
        tmp_path, fault, start_s, initial, goal, speed):
    """The winder's bus lost, or the tether snagged, while the vehicle moves outward
    (different speeds, directions, heights, moments): the drum stops at what it had paid
    out. The winder had paid out the vehicle's stopping distance ahead (its stop lead), and
    the vehicle's tether governor brakes as soon as its stopping point would pass the
    last length the winch reported; then the winder failsafe brings it down. The truth's
    tether is never taut (slack > 0, drum tension under 30 N) and the vehicle lands."""
    p = tmp_path / "draw.toml"
    p.write_text(f'''name = "draw"
description = "a drum stopped during an outward move"
duration_s = 70.0
metrics_after_s = 2.0
[initial]
position_m = [{initial[0]}, {initial[1]}, {initial[2]}]
[trajectory]
kind = "setpoint"
start_s = 10.0
goal_m = [{goal[0]}, {goal[1]}, {goal[2]}]
max_speed_m_s = {speed}
{_SAFETY}
[[faults]]
start_s = {start_s}
{fault}
''')
    runner = OfflineRunner(load_toml(ScenarioParams, p))
    res = runner.run()
    t = res.series["t"]
    nav, _ = _said(runner)
    assert any(v.startswith("Winch Failsafe") for _, v in nav), nav
    assert _slack(res)[t > 1.0].min() > 0.0
    assert res.metrics["max_drum_tension_n"] < 30.0
    assert runner.companion.nav.landed and not runner.companion.nav.armed


def test_over_tension_brings_the_tension_back_before_the_line_is_taut(tmp_path):
    """The backstop behind the tether governor and the stuck-drum check (both switched off
    here): the tether snagged,
    the vehicle creeping outward at 0.2 m/s. As the slack runs out the load cell's tension
    climbs past the 20 N limit (TUAV_TENS_MAX, the winch's tension_limit_n): the vehicle,
    once every report has said so for TUAV_TENS_TIME, says so and moves 2 m towards the
    winder, the winch says so and pays out (it cannot:
    snagged); the tension falls back under 1 N and the vehicle holds there, the tether
    never taut (its slack at the worst a few millimetres: a catenary's tension climbs that
    steeply near taut)."""
    p = tmp_path / "creep.toml"
    p.write_text('''name = "creep"
description = "a slow outward creep against a snagged tether"
duration_s = 50.0
metrics_after_s = 2.0
[initial]
position_m = [8.0, 4.0, 10.0]
[trajectory]
kind = "setpoint"
start_s = 10.0
goal_m = [16.0, 4.0, 10.0]
max_speed_m_s = 0.2
[winch]
stuck_error_m = 100.0
tension_limit_n = 20.0
[navigation]
tension_limit_n = 20.0
tether_governor = 0
[winder_control]
law = "paper"
[tether]
model = "catenary"
[[faults]]
kind = "tether_snag"
start_s = 5.0
''')
    runner = OfflineRunner(load_toml(ScenarioParams, p))
    res = runner.run()
    nav, winch = _said(runner)
    s, t = res.series, res.series["t"]
    over = np.nonzero(s["drum_tension"] > 20.0)[0]
    first = t[over[0]]
    moves = [(ts, v) for ts, v in nav if "over-tension" in v]
    # every WINCH_STATUS above the limit for TUAV_TENS_TIME, then the next one
    hold = runner.companion.nav.p.tension_time_s
    assert moves and first + hold <= moves[0][0] <= first + hold + 0.06
    assert moves[0][1].endswith("> 20 N): moving towards the winder")
    said = [(ts, n) for ts, n in winch if "tension" in n]
    assert said[0][1].startswith("winch: over-tension") and said[0][1].endswith("paying out")
    assert said[1][1] == "winch: tension back below 20 N"
    assert 0.0 < said[0][0] - first <= 0.15
    late = t > t[over[-1]] + 2.0
    assert late.any() and s["drum_tension"][late].max() < 1.0
    assert np.linalg.norm(s["vel"][t > t[-1] - 5.0], axis=1).max() < 0.1   # holding
    assert _slack(res)[t > 1.0].min() > 0.0
    assert runner.companion.nav.armed and not runner.companion.nav.landed


@pytest.mark.skipif(not netns_available(),
                    reason="needs root (unshare) for a private network namespace")
def test_a_late_can_bus_in_up_brakes_the_drum_and_the_vehicle_comes_down(tmp_path):
    """``tuav-sitl up --faults``: every winder CAN frame 100 ms late from 8 s while the
    vehicle hovers at (4, 0, 8) m. The winch finds its load cell's frames late against the
    UAV's position within two windows (0.1 s each), brakes the drum and says so; the vehicle's
    winder failsafe flies RTL within the braked length 2 s later, lands and disarms; the
    truth's tether is never taut. (The delay's onset alone trips the axis's 0.1 s watchdog:
    100 ms without a command; the winch re-arms it.)"""
    s = run_session("tests.netns.can_delay_session", str(tmp_path), timeout_s=900)
    assert s["rc"] == 0, s["stderr"]
    assert "fault can begins at 8.000 s" in s["plant_log"]
    bad = [(t, text) for t, comp, text in s["texts"] if comp == 169 and "CAN bad" in text]
    window = WinchParams().bus_window_s
    assert bad and 8.0 < bad[0][0] <= 8.0 + 2 * window + 0.15, s["texts"]
    late_ms = int(bad[0][1].split("lost, ")[1].split(" ms")[0])
    assert 50 < late_ms <= 100 and bad[0][1].endswith("braked")
    fs = [t for t, comp, text in s["texts"] if comp == 1 and text.startswith("Winch Failsafe")]
    assert fs and bad[0][0] < fs[0] <= bad[0][0] + 2.0 + 0.15
    assert s["disarmed_s"] > fs[0] and s["last"]["z_m"] < 0.3 and s["last"]["armed"] == 0.0
    assert s["min_slack_m"] > 0.0
