"""The tension-regulating winder law (groundstation/tension_law.py, docs/control.md §8)
against independent truths: its Lyapunov identity on the drum and line model it was derived
on, the dynamic (lumped) line's pull in the snap cases, MoorPy's catenary at the regulated
tension in a steady hover; the plant's load cell against its own definition; and the
vehicle's governor against the fence speed of the room each winder law gives."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import brentq
from test_winch import PARAMS as BENCH_PARAMS
from test_winch import R_W, Bench
from test_winch import UAV as BENCH_UAV
from test_winch import G as BENCH_G

from companion.governor import (
    GOVERNOR_SLOW_MARGIN_M,
    GOVERNOR_SLOW_RAMP_S,
    GovernorMode,
    TetherGovernor,
)
from companion.navigation import NavigationParams
from companion.reference import RefSample
from groundstation import tension_law as tl
from groundstation.lbar import LBarParams, lbar_kernel
from groundstation.winch import Winch
from groundstation.winder_control import WinderController, WinderControlParams, WinderLaw
from groundstation.winder_host import WinderHost
from sitl.load_cell import LoadCell, LoadCellParams
from sitl.winder import WinderModel
from tuav_sitl.offline import OfflineRunner, run_scenario
from tuav_sitl.scenario import load_scenario
from tuavdefs.params import TetherParams, WinderParams

try:
    from moorpy.Catenary import catenary as moorpy_catenary
except ImportError:  # pragma: no cover - the test extras install it
    moorpy_catenary = None


# ---------------------------------------------------------------- the design model
@pytest.mark.parametrize("ell_rate", [0.0, 0.6, -0.8])
def test_tension_law_lyapunov_identity_on_the_drum_and_line_model(ell_rate):
    """On the model it was derived for (the drum with its varying inertia, the line a spring
    of stiffness kappa towards the length the UAV asks, moving at ``ell_rate``, fed forward
    exactly), V = e^2/(2 kappa) + I_w e_w^2/2 changes as
    dV/dt = -e sigma(T) - k_w e_w^2 - e (v_c - v0), to the accuracy of the 10 ms hold, and
    the tension settles on the set-point."""
    kappa = 8.0
    wp, tp = WinderParams(), TetherParams()
    gains = WinderControlParams(law="tension", tension_filter_s=0.0, line_stiffness_n_m=kappa)
    ctl = WinderController(gains, wp, tp)
    p = ctl.tension_params()
    drum = WinderModel(wp, tp)
    r = wp.drum_radius_m
    dt_c, n_fine = 0.01, 20
    dt = dt_c / n_fine
    theta, omega = drum.theta_rad(20.0), 0.0
    setpoint = 4.0
    tension = 1.5                       # a slack line to start from
    ell = 20.0 - 0.3
    values, rates, scale = [], [], []
    for _ in range(800):
        length = drum.length_m(theta)
        cmd = ctl.update_tension(dt_c, length, omega, tension, setpoint, ell_rate,
                                 0.0, 0.0, 1e3)
        s = ctl.tension_state
        e = tension - setpoint
        v0 = tl.tension_speed(p, tension, setpoint, ell_rate)
        values.append(cmd.lyapunov)
        terms = (-e * (v0 - ell_rate), -gains.k_speed_n_m_s * cmd.e_rate_rad_s ** 2,
                 -e * (s[tl.Z_SPEED] - v0))
        rates.append(sum(terms))
        scale.append(sum(abs(x) for x in terms))
        assert not cmd.saturated
        for _ in range(n_fine):        # the drum and the line, integrated finely
            acc = drum.acceleration(theta, omega, cmd.torque_n_m, tension, braked=False)
            tension += -kappa * (r * omega - ell_rate) * dt
            omega += acc * dt
            theta += omega * dt
            ell += ell_rate * dt
    values, rates, scale = np.array(values), np.array(rates), np.array(scale)
    num = np.diff(values)
    pred = 0.5 * (rates[1:] + rates[:-1]) * dt_c
    size = 0.5 * (scale[1:] + scale[:-1]) * dt_c      # the terms' magnitudes (they cancel)
    sig = size > 1e-3 * values[:-1]                   # a change the 10 ms hold can resolve
    assert sig.sum() > 400
    assert np.all(np.abs(num[sig] - pred[sig]) <= 0.1 * size[sig])
    assert abs(tension - setpoint) < 1e-3
    assert values[-1] < 1e-6 * values[0]


def test_tension_law_renders_to_a_snap_at_once():
    """The torque holds the set-point, not the measured tension: a pull far above it (a
    snap) accelerates the drum paying out before any filter has seen it."""
    wp, tp = WinderParams(), TetherParams()
    ctl = WinderController(WinderControlParams(law="tension"), wp, tp)
    cmd = ctl.update_tension(0.01, 20.0, 0.0, 3.0, 3.0, 0.0, 0.0, 0.0, 1e3)
    drum = WinderModel(wp, tp)
    theta = drum.theta_rad(20.0)
    acc_snap = drum.acceleration(theta, 0.0, cmd.torque_n_m, 30.0, braked=False)
    # the line's 27 N over the set-point, on the drum's inertia alone
    assert acc_snap * wp.drum_radius_m == pytest.approx(
        27.0 * wp.drum_radius_m ** 2 / ctl.inertia_kg_m2(20.0), rel=0.05)


# ---------------------------------------------------------------- the lumped line
_TAIL = """
[tether]
model = "lumped"
[winch]
status_rate_hz = 100.0
[estimator]
kind = "truth"
[winder_control]
law = "{law}"
"""


def _moorpy_at_exit_tension(h: float, z: float, ea: float, w: float, tension_n: float,
                            upper: float) -> tuple[float, tuple[float, ...]]:
    """MoorPy's catenary from the exit to (``h``, ``z``) [m] of the length [m] whose tension
    at the exit is ``tension_n`` [N] (between 1.0001 and ``upper`` times the chord): that
    length and the end forces ``moorpy_catenary`` returns for it."""
    def exit_tension(length: float) -> float:
        f = moorpy_catenary(h, z, length, ea, w, CB=0)
        return math.hypot(f[0], f[1]) - tension_n

    chord = math.hypot(h, z)
    length = brentq(exit_tension, chord * 1.0001, chord * upper)
    return length, moorpy_catenary(h, z, length, ea, w, CB=0)


def _radial(start, goal, speed, acc, duration, extra=""):
    return f"""name = "snap"
description = "a snap case"
duration_s = {duration}
metrics_after_s = 1.0
[initial]
position_m = [{start[0]}, {start[1]}, {start[2]}]
[trajectory]
kind = "line"
start_s = 4.0
goal_m = [{goal[0]}, {goal[1]}, {goal[2]}]
speed_m_s = {speed}
max_acc_m_s2 = {acc}
{extra}"""


_SNAG = """
[[faults]]
kind = "tether_snag"
start_s = 4.0
end_s = 6.0
"""

SNAP_CASES = {
    # a step of the UAV's radial speed (0 -> +-2 m/s at 8 m/s^2, 10 m along the radius)
    "radial-out": (_radial((9.0, 0.0, 12.0), (15.0, 0.0, 20.0), 2.0, 8.0, 14.0), 3.0),
    "radial-in": (_radial((15.0, 0.0, 20.0), (9.0, 0.0, 12.0), 2.0, 8.0, 14.0), 3.0),
    # the drum stalled (snagged) during an outward or an inward move at 1 m/s, released
    # 2 s later: the peak counted from the release
    "stall-released": (_radial((9.0, 0.0, 12.0), (15.0, 0.0, 20.0), 1.0, 2.0, 16.0, _SNAG),
                       6.0),
    "stall-released-in": (_radial((15.0, 0.0, 20.0), (9.0, 0.0, 12.0), 1.0, 2.0, 16.0,
                                  _SNAG), 6.0),
}


def _peak_ratio(series, from_s):
    t, top = series["t"], series["top_tension"]
    before = np.median(top[(t > 1.0) & (t < 3.0)])
    after = np.median(top[t > t[-1] - 3.0])
    return top[t >= from_s].max() / max(before, after)


#: The shipped line's 2 m segments snap where the law and the vehicle do not: a slack
#: exit segment (up to 4 m, no mass between its ends, no sag stiffness) lets the node
#: above it run free until it is caught taut (docs/control.md §8.5). Measured on the 2 m
#: line: the inward stall 1.93x with either governor (19.1 N, 1 s after the release, the
#: exit segment lying on the ground and caught taut with no node change; 1.18x with 1 m
#: segments). Asserted on 1 m segments; on 2 m known to fail (strict: a mended line or
#: law makes it pass, and then this mark goes). (The step out, 3.03x here with the
#: set-point's acceleration limit at 8 m/s^2, passes since it is 10: 1.37x; docs/control.md §8.2.)
_LINE_RESOLUTION = pytest.mark.xfail(strict=True, reason="the line's 2 m segments: "
                                     "docs/control.md §8.5")
#: (case, the vehicle's governor, the line's segments over its 50 m: 25 is the shipped
#: 2 m). With governor 1 (a length law's room) the step out never flies: the reported
#: length less its margin brakes the streamed step at 4.1 s and ends it, 15.1 m out.
SNAP_RUNS = [("radial-out", 1, 25), ("radial-in", 1, 25), ("stall-released", 1, 25),
             ("radial-in", 2, 25), ("stall-released", 2, 25), ("radial-out", 2, 50),
             ("stall-released-in", 2, 50), ("radial-out", 2, 25),
             pytest.param("stall-released-in", 1, 25, marks=_LINE_RESOLUTION),
             pytest.param("stall-released-in", 2, 25, marks=_LINE_RESOLUTION)]


@pytest.mark.parametrize(("case", "governor", "segments"), SNAP_RUNS)
def test_no_snap_on_the_lumped_line(case, governor, segments, tmp_path):
    """The pull at the UAV peaks at most 1.5 times its steady value (before or after), and
    the line is never taut."""
    text, from_s = SNAP_CASES[case]
    path = tmp_path / "snap.toml"
    path.write_text(text + _TAIL.format(law="tension")
                    + f"[navigation]\ntether_governor = {governor}\n"
                    + f"[plant.tether]\nsegments = {segments}\n")
    res = run_scenario(load_scenario(str(path)), None, progress=None)
    assert _peak_ratio(res.series, from_s) <= 1.5
    assert res.metrics["min_tether_slack_m"] > 0.0


def _tension_bench():
    """The winch on the tension law against the plant's axis and drum (test_winch's
    bench: a constant line tension at the drum), settled at its set-point; and that
    set-point [N]."""
    b = Bench(14.0)
    host = WinderHost(WinderControlParams(law="tension"), LBarParams(), BENCH_PARAMS.winder,
                      BENCH_PARAMS.tether, BENCH_G)
    b.winch = Winch(host, BENCH_PARAMS.winder, BENCH_PARAMS.tether, BENCH_G)
    b.winch.set_uav(BENCH_UAV)
    b.run(3.0)
    setpoint = float(host.controller.tension_state[tl.Z_SETPOINT])
    b.tension = setpoint
    b.run(2.0)
    return b, setpoint


def test_a_stuck_drum_is_told_by_the_pull_it_does_not_render_to():
    """The tension law's drum jammed (its stops closed, as a snag closes them): at the
    set-point's pull nothing is said (a jam nothing pulls against is no danger); the pull
    3 N above it, which a free drum renders to at once, is said stuck within 0.25 s, while
    the law's lag behind its speed set-point is still far below stuck_error_m. Meanwhile
    the law's speed set-point stays at the drum's (anti-windup): freed, the drum starts
    from rest under the excess pull, not from the speed the law would have run on to, and
    is said free once it has moved."""
    b, setpoint = _tension_bench()
    winch = b.winch
    theta = b.theta
    b.model.set_stops(theta, theta)
    b.run(2.0)
    assert not [n for n in b.notices if "stuck" in n] and not winch.drum_stuck
    t0, n0 = b.t, len(b.notices)
    b.tension = setpoint + 3.0
    lag_at = None
    while not winch.drum_stuck and b.t - t0 < 1.0:
        lag_at = float(winch.host.controller.tension_state[tl.Z_LAG])
        b.run(0.01)
    assert winch.drum_stuck and b.t - t0 <= 0.25
    assert lag_at is not None and lag_at < 0.2 * winch.p.stuck_error_m
    assert b.notices[n0:] == [f"winch: drum stuck at {b.length:.1f} m, no pay-out"]
    b.run(1.0)
    assert abs(winch.last_command.rate_cmd_rad_s * R_W) < winch.p.stuck_speed_m_s
    b.model.set_stops(b.model.theta_min, b.model.theta_max)
    fastest = 0.0
    for _ in range(10):
        b.run(0.01)
        fastest = max(fastest, b.omega * R_W)
    assert 0.0 < fastest < 0.2
    b.run(1.0)
    assert "winch: drum no longer behind its reference" in b.notices[n0:]
    assert not winch.drum_stuck


def test_the_paper_law_snaps_where_the_tension_law_does_not(tmp_path):
    """The check can fail: the paper's length law on the radial step out (53.7 N)."""
    text, from_s = SNAP_CASES["radial-out"]
    path = tmp_path / "snap.toml"
    path.write_text(text + _TAIL.format(law="paper") + "[navigation]\ntether_governor = 1\n")
    res = run_scenario(load_scenario(str(path)), None, progress=None)
    assert _peak_ratio(res.series, from_s) > 1.5


def test_no_snap_in_a_crosswind_gust_on_the_lumped_line():
    """gust-lumped (25 m up, a 6 m/s gust across the line) on the tension law."""
    sc = load_scenario("gust-lumped")
    sc = sc.replace(winder_control=sc.winder_control.replace(law="tension"))
    res = run_scenario(sc, None, progress=None)
    assert _peak_ratio(res.series, 4.0) <= 1.5


@pytest.mark.skipif(moorpy_catenary is None, reason="MoorPy is not installed")
@pytest.mark.parametrize(("h", "v", "tension", "rel"), [
    (2.0, 10.0, 1.0, 0.15), (1.86, 20.0, 1.0, 0.2), (2.0, 3.5, 1.5, 0.15),
    (2.0, 10.0, 3.0, 0.15), (12.0, 20.0, 5.0, 0.4), (4.0, 10.0, 1.0, 0.45)])
def test_the_gain_schedule_s_line_stiffness_against_moorpy(h, v, tension, rel):
    """The law's estimate of dT/dL at fixed ends (its set-point gain falls with it) against
    MoorPy's elastic catenary through the same ends, differentiated in its length: close
    where the line is stiff (near the vertical), the order where it sags."""
    tp = TetherParams()
    ea, w = tp.axial_stiffness_n, tp.weight_per_length_n_m(9.81)

    def exit_tension(length):
        f = moorpy_catenary(h, v, length, ea, w, CB=0)
        return math.hypot(f[0], f[1])

    chord = math.hypot(h, v)
    length = brentq(lambda x: exit_tension(x) - tension, chord * (1 + 1e-6), chord * 1.05)
    dl = 1e-4 * (length - chord)
    truth = (exit_tension(length - dl) - exit_tension(length + dl)) / (2.0 * dl)
    assert tl.taut_line_stiffness_n_m(tension, w, h, v) == pytest.approx(truth, rel=rel)


# ---------------------------------------------------------------- a steady hover
@pytest.mark.skipif(moorpy_catenary is None, reason="MoorPy is not installed")
def test_steady_hover_holds_the_set_point_and_moorpy_agrees_on_the_exit_angle():
    """hover (12 m out, 20 m up, catenary truth) on the tension law: the drum's tension
    equals the law's set-point within the load cell's noise, and MoorPy's catenary through
    the UAV at that exit tension leaves the winder at the angle the guide arm measures."""
    # on the catenary truth (hover's is the lumped line): MoorPy's static catenary is the
    # line's shape only there
    sc = load_scenario("hover").with_tether_model("catenary")
    sc = sc.replace(duration_s=25.0,
                    winder_control=sc.winder_control.replace(law="tension"))
    runner = OfflineRunner(sc)
    assert runner.winder_host.controller.law is WinderLaw.TENSION
    res = runner.run(progress=None)
    winch = runner.ground.winch
    setpoint = float(winch.host.controller.tension_state[tl.Z_SETPOINT])
    t, drum = res.series["t"], res.series["drum_tension"]
    held = drum[t > t[-1] - 5.0]
    noise = LoadCellParams().noise_n
    assert abs(held.mean() - setpoint) <= 3.0 * noise
    assert held.std() <= 3.0 * noise
    # MoorPy's catenary with that exit tension through the UAV's (true) position
    x, y, z = res.series["pos"][-1]
    h = math.hypot(x, y)
    ea = TetherParams().axial_stiffness_n
    w = TetherParams().weight_per_length_n_m(sc.model().environment.gravity_m_s2)
    length, f = _moorpy_at_exit_tension(h, z, ea, w, setpoint, 1.2)
    elevation = math.atan2(f[1], f[0])
    measured = winch.exit_angle[1]
    assert measured == pytest.approx(elevation, abs=0.01)   # the arm's bias is 2 mrad (1 sigma)
    assert elevation > sc.lbar.min_exit_angle_rad            # suspended, with margin
    assert winch.length_m == pytest.approx(length, abs=0.01)


# ---------------------------------------------------------------- the load cell
def test_load_cell_lags_filters_and_is_noisy_as_specified():
    """A step of tension read at 100 Hz: the reading is the step through the first-order
    low-pass, ``latency_s`` late; the noise's spread is ``noise_n``."""
    p = LoadCellParams(noise_n=0.0, filter_s=0.05, latency_s=0.02)
    cell = LoadCell(p)
    got = [cell.read(k * 0.01, 0.0 if k < 10 else 10.0) for k in range(60)]
    for k in range(60):
        lagged = k - 2                   # 20 ms late
        want = 0.0 if lagged < 10 else 10.0 * (1.0 - math.exp(-(lagged - 9) * 0.01 / 0.05))
        assert got[k] == pytest.approx(want, abs=1e-9)
    noisy = LoadCell(LoadCellParams(noise_n=0.2))
    reads = np.array([noisy.read(k * 0.01, 5.0) for k in range(4000)])
    assert reads[100:].mean() == pytest.approx(5.0, abs=0.02)
    assert reads[100:].std() == pytest.approx(0.2, rel=0.1)


# ---------------------------------------------------------------- the vehicle's governor
@pytest.mark.parametrize("mode", [GovernorMode.LENGTH, GovernorMode.TENSION])
def test_the_governor_counts_on_what_the_winder_guarantees(mode):
    """A leg outward at 2 m/s near the vertical (2, 0, 10) m with the drum's reported
    length 5 cm beyond the vehicle's distance: the length law's governor slows it to the
    speed it can stop from in those 5 cm less its margins (ArduPilot's fence speed,
    ``v t + v^2/2a <= r``); the tension law's does not (a free drum pays out what the
    vehicle pulls), and both stop it at a braked drum's length."""
    nav = NavigationParams(tether_governor=int(mode))
    gov = TetherGovernor(nav, 50.0, 0.1)
    pos = (2.0, 0.0, 10.0)
    dist = math.dist(pos, (0.0, 0.0, 0.0))
    u = tuple(x / dist for x in pos)
    vel = tuple(2.0 * x for x in u)
    leg = RefSample(pos, vel, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.0, 0.0)
    gov.report(dist + 0.05, braked=False, speed_m_s=0.0)
    rate, speed = gov.slow_rate(leg, 1.0, None, pos, vel, 0.0)
    assert speed == pytest.approx(2.0)
    # the stop from v inside r = 5 cm less the margins: v t + v^2 / 2a <= r
    r = 0.05 - nav.tether_margin_m - GOVERNOR_SLOW_MARGIN_M
    t_s = nav.tether_latency_s + GOVERNOR_SLOW_RAMP_S
    a = nav.tether_brake_acc_m_s2
    v_fence = a * (-t_s + math.sqrt(t_s * t_s + 2.0 * max(r, 0.0) / a))
    if mode is GovernorMode.LENGTH:
        assert rate * 2.0 <= v_fence + 0.02
    else:
        assert rate == 1.0
    gov.report(dist + 0.05, braked=True, speed_m_s=0.0)
    braked_rate, _ = gov.slow_rate(leg, 1.0, None, pos, vel, 0.0)
    assert braked_rate * 2.0 <= v_fence + 0.02


# ---------------------------------------------------------------- the line in wind
def _circle_in_crosswind(fix: bool):
    """The paper's circle on the lumped line in 8 m/s from 190 deg (across the line at the
    circle's far side) with light turbulence: the sweep wind-envelope-circle's run 118,
    flown to 31 s (its line first touched the ground at 28.4 s). Without ``fix`` the
    exit-elevation loop is off."""
    from tuav_sitl.sweep import shipped_sweeps

    sweeps = shipped_sweeps()["wind-envelope-circle"].parent
    sc = load_scenario(str(sweeps / "scenarios" / "circle-lumped-tension.toml"))
    wind = sc.wind.replace(steady_m_s=(1.3806629580231529, 7.890164213646648, 0.0),
                           turbulence="light", seed=1181423110)
    wc = sc.winder_control
    if not fix:
        wc = wc.replace(exit_lift_gain_n_s_rad=0.0)
    sc = sc.replace(duration_s=31.0, wind=wind, winder_control=wc,
                    sensors=sc.sensors.replace(seed=1181423110))
    return run_scenario(sc, None, progress=None).series


def test_the_exit_elevation_loop_keeps_the_line_off_the_ground_in_a_crosswind():
    """The guide arm's elevation raises the force loop's set-point (docs/control.md §8.4):
    the line stays off the ground in flight; without it, the drag
    across the line raises the tension, the law pays out to hold its windless set-point,
    and the line lies on the ground (2.2 s from 28.4 s). The pull stays under 35 N."""
    from tuav_sitl.offline import GROUND_REGIMES

    touched = []
    for fix in (True, False):
        s = _circle_in_crosswind(fix)
        t = s["t"]
        on_ground = np.isin(s["regime"], GROUND_REGIMES) & (t > 5.0)
        touched.append(float(on_ground.sum() * (t[1] - t[0])))
        if fix:
            assert s["top_tension"][t > 5.0].max() < 35.0
    assert touched[0] == 0.0
    assert touched[1] > 0.5


@pytest.mark.skipif(moorpy_catenary is None, reason="MoorPy is not installed")
def test_the_exit_elevation_loop_s_lyapunov_function_on_moorpy_s_catenary():
    """The outer loop on its design model (docs/control.md §8.4): the tension loop
    converged (T = T* + dT), the exit elevation MoorPy's catenary's at that tension
    through the UAV (12 m out, 20 m up) for a line loaded at twice its weight (a drag
    pressing it down), from a set-point of 3 N at which it lies on the ground: W =
    (dT - dT_e)^2 / (2 k) never rises and dT settles where the line leaves at the
    reference angle; with the line's own weight it leaves above it at 3 N and the raise
    stays 0."""
    tp = TetherParams()
    ea, w = tp.axial_stiffness_n, tp.weight_per_length_n_m(9.81)
    h, v = 12.0, 20.0
    chord = math.hypot(h, v)
    gains = WinderControlParams(law="tension")
    p = WinderController(gains, WinderParams(), tp).tension_params()
    ref = math.radians(8.0)

    def elevation(tension, load):
        def excess(length):
            f = moorpy_catenary(h, v, length, ea, load, CB=0)
            return math.hypot(f[0], f[1]) - tension
        length = brentq(excess, chord * (1 + 1e-7), chord * 1.5)
        f = moorpy_catenary(h, v, length, ea, load, CB=0)
        return math.atan2(f[1], f[0])

    base = 3.0
    grid = np.linspace(base, base + gains.exit_lift_max_n, 61)
    for load, raised in ((2.0 * w, True), (w, False)):
        table = np.array([elevation(x, load) for x in grid])
        # E(T) nondecreasing, the proof's premise (flat at 0 while the heavy line lies on
        # the ground, below 3.9 N)
        assert np.all(np.diff(table) >= 0) and table[-1] > table[0]
        s = np.zeros(tl.N_TENSION_STATE)
        s[tl.Z_LIFTED] = 1.0        # the line has flown (the loop is armed)
        lift, values = [], []
        if raised:
            assert table[0] < ref < table[-1]
            target = brentq(lambda x, e=table: np.interp(x, grid, e) - ref, base, grid[-1]) - base
        else:
            assert table[0] > ref
            target = 0.0
        for _ in range(1500):
            eps = float(np.interp(base + s[tl.Z_LIFT], grid, table))
            tl.exit_lift(p, s, 0.01, eps, ref)
            lift.append(s[tl.Z_LIFT])
            values.append((s[tl.Z_LIFT] - target) ** 2)
        assert np.all(np.diff(values) <= 1e-12)
        assert lift[-1] == pytest.approx(target, abs=0.05)


def test_the_exit_elevation_loop_waits_for_a_flown_line_and_a_following_drum():
    """The loop's raise (docs/control.md §8.4) at a flat exit: none before the guide arm
    has read the line leaving at twice the reference (the take-off's line on the ground),
    none while the drum lags its speed set-point by more than ``exit_lift_lag_m`` (a
    snag: the cascade's windup); then ``k_eps eps_r`` per second."""
    gains = WinderControlParams(law="tension")
    p = WinderController(gains, WinderParams(), TetherParams()).tension_params()
    ref = math.radians(8.0)
    s = np.zeros(tl.N_TENSION_STATE)
    for _ in range(100):
        tl.exit_lift(p, s, 0.01, 0.0, ref)
    assert s[tl.Z_LIFT] == 0.0
    tl.exit_lift(p, s, 0.01, 2.0 * ref, ref)        # the line leaves steeply: armed
    for _ in range(100):
        tl.exit_lift(p, s, 0.01, 0.0, ref, 1.5 * gains.exit_lift_lag_m)
    assert s[tl.Z_LIFT] == 0.0
    for _ in range(100):
        tl.exit_lift(p, s, 0.01, 0.0, ref, 0.5 * gains.exit_lift_lag_m)
    assert s[tl.Z_LIFT] == pytest.approx(gains.exit_lift_gain_n_s_rad * ref, rel=1e-9)


def test_a_line_that_reads_slack_is_not_paid_out_into():
    """Below the slack floor, once flown and within L-bar (docs/control.md §8.2): the drum
    pays out no faster than the length law ``L_lo' - k_p s`` on the slack ``s`` above the
    lower bound and never winds in for it while the vehicle goes away, so the slack the
    vehicle takes at 1 m/s is not paid out again at L-bar's rate (the sweep's run 186: the
    exit at 0 N, the drum at L-bar's 0.83 m/s, 0.74 m piled up in the exit segment).
    The truth: the ideal law's slack on a drum that follows its speed set-point,
    ``s' = -L_lo'`` down to ``L_lo'/k_p``, then ``-k_p s``, within the command filter's
    lag."""
    gains = WinderControlParams(law="tension")
    wp, tp = WinderParams(), TetherParams()
    p = WinderController(gains, wp, tp).tension_params()
    r, dt, radial, ff = wp.drum_radius_m, 0.01, 1.0, 0.83
    s = np.zeros(tl.N_TENSION_STATE)
    length, low, lbar = 26.0, 25.0, 26.01
    speeds, slacks = [], []
    for k in range(400):
        tl.tension_law(p, s, dt, length, ff / r if k == 0 else speeds[-1] / r, 0.0, 5.0,
                       ff, low, radial, lbar + 3.0, lbar)
        s[tl.Z_LIFTED] = 1.0                          # the line has flown
        speeds.append(s[tl.Z_SPEED])
        length += dt * s[tl.Z_SPEED]
        low += dt * radial
        lbar += dt * ff
        slacks.append(length - low)
    speeds, slacks = np.array(speeds), np.array(slacks)
    assert speeds.min() >= 0.0                        # never wound in
    assert np.all(np.diff(slacks) <= 1e-12)           # the slack only falls
    t = dt * np.arange(1, 401)
    k_p = gains.slack_payout_gain_1_s
    knee = (1.0 - radial / k_p) / radial              # the ideal law's slack reaches L_lo'/k_p
    ideal = np.where(t < knee, 1.0 - radial * t,
                     radial / k_p * np.exp(-k_p * (t - knee)))
    # the command filter pays out its 0.3 s lag at the start: 0.83 m/s * 0.3 s at most
    assert np.all(slacks - ideal <= ff * gains.speed_filter_s)
    assert slacks[-1] < 0.05
    # without the bound (the law before), L-bar's rate is paid out into the slack line
    p_old = p.copy()
    p_old[tl.Q_PAYOUT] = 1e-9
    s = np.zeros(tl.N_TENSION_STATE)
    tl.tension_law(p_old, s, dt, 26.0, ff / r, 0.0, 5.0, ff, 25.0, radial, 29.0, 26.01)
    s[tl.Z_LIFTED] = 1.0
    for _ in range(100):
        tl.tension_law(p_old, s, dt, 26.0, ff / r, 0.0, 5.0, ff, 25.0, radial, 29.0, 26.01)
    assert s[tl.Z_SPEED] > 0.8


# ---------------------------------------------------------------- low and far
def test_the_string_slack_inverts_the_slack_tension():
    """:func:`string_slack_m` is :func:`slack_tension_n`'s inverse, and the lay-down share
    falls linearly in the chord's elevation from 1 at twice the least exit angle to 0."""
    for h, v, s in [(8.5, 1.5, 0.05), (12.0, 6.0, 0.3), (3.0, 20.0, 0.01)]:
        t = tl.slack_tension_n(0.33, h, v, s)
        assert tl.string_slack_m(0.33, h, v, t) == pytest.approx(s, rel=1e-9)
    eps = math.radians(8.0)
    p = WinderController(WinderControlParams(law="tension", lay_down_height_m=1.5),
                         WinderParams(), TetherParams()).tension_params()
    # low: only the chord's elevation says
    assert tl.lay_down_share(p, eps, 5.0, 5.0 * math.tan(2.5 * eps)) == 1.0
    assert tl.lay_down_share(p, eps, 5.0, 5.0 * math.tan(0.5 * eps)) == 0.0
    assert tl.lay_down_share(p, eps, 5.0, 5.0 * math.tan(1.5 * eps)) == pytest.approx(0.5)
    # low and far, but up at 2.25 m or 3 m: half held, held
    assert tl.lay_down_share(p, eps, 30.0, 2.25) == pytest.approx(0.5)
    assert tl.lay_down_share(p, eps, 30.0, 3.0) == 1.0


def test_a_landing_low_and_far_lays_the_line_down(tmp_path):
    """Coming down 8.5 m out (docs/control.md §8.4): below the chord's 16 deg the station
    lays the line down instead of holding it up on its least slack. Before, below 1.5 m
    (10 deg) the line pulled 8 N nearly level at the UAV and leaned it 0.2 rad; now the pull
    there stays under 3 N over 0.1 s, the lean under 0.1 rad, and the line is never
    taut."""
    text = _radial((8.0, 3.0, 3.0), (8.0, 3.0, 0.6), 0.4, 1.0, 12.0)
    path = tmp_path / "land.toml"
    path.write_text(text + _TAIL.format(law="tension"))
    res = run_scenario(load_scenario(str(path)), None, progress=None)
    s = res.series
    t, z = s["t"], s["pos"][:, 2]
    band = (t > 4.0) & (z < 8.5 * math.tan(math.radians(10.0))) & (z > 0.8)
    assert band.sum() > 100
    # the pull over 0.1 s (single 4 ms samples of the 2 m line touching down reach 9 N:
    # docs/control.md §8.5)
    mean = np.convolve(s["top_tension"], np.ones(25) / 25.0, mode="same")
    assert mean[band].max() < 3.0
    assert np.abs(s["euler"][band, :2]).max() < 0.1
    assert res.metrics["min_tether_slack_m"] > 0.0


@pytest.mark.skipif(moorpy_catenary is None, reason="MoorPy is not installed")
@pytest.mark.parametrize("ratio", [1.0, 1.5, 2.0])
def test_the_set_point_holds_a_heavier_line_off_the_ground(ratio):
    """A line ``ratio`` times as heavy as the model's, its weight estimated right, with the
    UAV at the far side of the robustness circle (22, 0, 20) m: MoorPy's catenary through
    the UAV that pulls the law's set-point at the exit leaves the winder at L-bar's least
    exit angle or above (the cap and the ceiling follow the weight: at the model's 8 N a
    2x line lay on the ground)."""
    q = WinderController(WinderControlParams(law="tension"), WinderParams(),
                         TetherParams()).tension_params()
    lbar = LBarParams()
    w_model = TetherParams().weight_per_length_n_m(9.81)
    w = ratio * w_model
    x, z = 22.0, 20.0
    _, _, a, _ = lbar_kernel(x, 0.0, z, 0.0, 0.0, 0.0, lbar.target_horizontal_tension_n
                             / w_model, math.tan(lbar.min_exit_angle_rad),
                             lbar.min_slack_m, math.nan)
    heavy = tl.heavy_scale(q, w, w_model)
    setpoint = tl.tension_setpoint_n(q, a, x, z, w, lbar.min_slack_m, 1.0, heavy)
    assert setpoint <= 2.0 * q[tl.Q_SP_MAX] + 1e-9
    ea = TetherParams().axial_stiffness_n
    _, f = _moorpy_at_exit_tension(x, z, ea, w, setpoint, 1.5)
    assert math.atan2(f[1], f[0]) >= lbar.min_exit_angle_rad
