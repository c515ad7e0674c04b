"""The paper's experiments, run in full by the offline runner, against the project's
targets (issue: controllers and offline runner)."""

import math
from multiprocessing import get_context

import numpy as np
import pytest

from companion.navigation import NavEvent
from tuav_sitl.offline import OfflineRunner, RunResult, run_scenario, write_outputs
from tuav_sitl.scenario import ScenarioParams, load_scenario, shipped_scenarios
from tuavdefs.params import GustParams
from tuavdefs.paramspec import ParameterError, load_toml

NAMES = sorted(shipped_scenarios())


#: The paper's experiments whose Lyapunov functions are checked: on the catenary truth,
#: the line the proofs model (docs/control.md §5). On the shipped lumped line its waves,
#: which the proofs' quasi-static line has not, make the position loop's function rise
#: (regulation 2231 times, setpoint 1526, single-position 2117, tether-length 838 above
#: its floor once the reference is constant): docs/results.md shows both.
LYAPUNOV = ["regulation", "setpoint", "single-position", "tether-length"]


def _run(name: str) -> RunResult:
    return run_scenario(load_scenario(name), None, progress=None)


def _run_on_the_catenary(name: str) -> RunResult:
    return run_scenario(load_scenario(name).with_tether_model("catenary"), None,
                        progress=None)


def _pool_map(fn, names: list[str]) -> dict[str, RunResult]:
    with get_context("fork").Pool(2) as pool:
        runs = pool.map(fn, names)
        # the workers leave on their own (the pool's exit would SIGTERM them, which a
        # handler an earlier test installed in this process catches: the forked worker
        # then waits on the queue's lock forever, and so does the exit)
        pool.close()
        pool.join()
    return dict(zip(names, runs, strict=True))


@pytest.fixture(scope="module")
def results() -> dict[str, RunResult]:
    return _pool_map(_run, NAMES)


@pytest.fixture(scope="module")
def on_the_catenary() -> dict[str, RunResult]:
    """:data:`LYAPUNOV`'s scenarios on the catenary truth (an option: ``--tether-model``)."""
    return _pool_map(_run_on_the_catenary, LYAPUNOV)


def test_the_paper_experiments_are_shipped():
    assert {"setpoint", "linear", "circle", "tether-length", "single-position",
            "multi-position", "circle-windy", "multi-position-windy"} <= set(NAMES)


def test_the_defaults_are_a_stations_and_the_paper_experiments_keep_the_papers():
    """Issue 31: a scenario naming none flies the tension law, the governor's tension mode
    and the lumped truth line (the controllers' model stays the catenary); every shipped
    scenario flies the lumped truth, the paper's experiments with the paper's law and the
    governor off; `tuav-sitl results` flies each again on the catenary beside it."""
    from tuav_sitl.results import other_truth
    from tuavdefs.params import DEFAULT_TRUTH_TETHER, TetherModel

    bare = ScenarioParams.from_dict({})
    assert bare.plant.tether.model == "lumped" and bare.tether.model == "catenary"
    assert bare.winder_control.law == "tension" and bare.navigation.tether_governor == 2
    named = ScenarioParams.from_dict({"tether": {"model": "catenary"}})
    assert named.plant.tether.model == "catenary"
    truth = ScenarioParams.from_dict({"plant": {"tether": {"model": "catenary"}}})
    assert truth.plant.tether.model == "catenary" and truth.tether.model == "catenary"
    paper = {"setpoint", "linear", "circle", "circle-windy", "tether-length",
             "single-position", "multi-position", "multi-position-windy", "regulation"}
    assert DEFAULT_TRUTH_TETHER is TetherModel.LUMPED
    for name in shipped_scenarios():
        sc = load_scenario(name)
        if name in paper:
            assert (sc.winder_control.law, sc.navigation.tether_governor) == ("paper", 0)
        else:
            assert (sc.winder_control.law, sc.navigation.tether_governor) == ("tension", 2)
        assert sc.plant.tether.model == "lumped", name
        assert other_truth(name) is TetherModel.CATENARY


@pytest.mark.parametrize("name", NAMES)
def test_tether_never_taut_never_on_the_ground_rotors_rarely_saturate(results, name):
    m = results[name].metrics
    sc = results[name].scenario
    s = results[name].series
    if sc.flies_mission:
        # never taut in flight; before the take-off the winch's ground pre-tension may
        # pull a short lumped line straight once: without GNSS the only way to a fix on
        # the ground, and a line under two nominal segments (4 m) is one segment, which
        # pulls nothing until it is straight (mission-gnss-denied: 0.3 mm at 16.5 N)
        slack = s["length"] - np.linalg.norm(s["pos"], axis=1)
        assert slack[np.isfinite(s["ref_pos"]).all(axis=1)].min() > 0.0
        assert m["min_tether_slack_m"] > -1e-3
    else:
        assert m["min_tether_slack_m"] > 0.0
    # a mission starts and ends on the ground; above 8 m/s of mean wind the line's own
    # drag may lay it on the ground at the exit (issue 31: there it must stay controlled
    # and never taut; hover-windy-lumped, 12 m/s)
    if not sc.flies_mission and math.hypot(*sc.wind.steady_m_s) <= 8.0:
        assert m["tether_ground_contact_fraction"] == 0.0
    assert m["motor_saturation_fraction"] < 0.01
    # independent check of the slack metric from the raw series
    slack = s["length"] - np.linalg.norm(s["pos"], axis=1)
    assert slack.min() == pytest.approx(m["min_tether_slack_m"])


def test_circle_calm(results):
    m = results["circle"].metrics
    assert m["position_rmse_m"] <= 0.05
    assert m["tether_length_rmse_m"] <= 0.02
    # it really flew the circle: radius and height over the measured window
    s = results["circle"].series
    sc = results["circle"].scenario
    win = s["t"] >= 10.0
    r = np.hypot(s["pos"][win, 0] - sc.trajectory.centre_m[0],
                 s["pos"][win, 1] - sc.trajectory.centre_m[1])
    assert np.allclose(r, 10.0, atol=0.1)
    assert np.allclose(s["pos"][win, 2], 20.0, atol=0.1)
    speed = np.linalg.norm(s["vel"][(s["t"] > 10) & (s["t"] < 40)], axis=1)
    assert np.allclose(speed, 2.0, atol=0.05)


def test_circle_windy(results):
    m = results["circle-windy"].metrics
    assert m["position_rmse_m"] <= 0.25
    wind = results["circle-windy"].series["wind"]
    assert np.mean(wind[:, 0]) > 2.0 and np.std(wind[:, 0]) > 0.2   # the wind blew


def test_setpoint_settles_without_overshoot(results):
    m = results["setpoint"].metrics
    assert m["settling_time_s"] is not None and m["settling_time_s"] <= 10.0
    assert m["overshoot_percent"] <= 5.0
    s = results["setpoint"].series
    assert np.linalg.norm(s["pos"][-1] - np.array([5.0, 5.0, 20.0])) < 0.05


@pytest.mark.parametrize("name", ["multi-position", "multi-position-windy"])
def test_every_waypoint_is_reached_in_order(results, name):
    reached = results[name].metrics["waypoints_reached"]
    sc = results[name].scenario
    assert [w["index"] for w in reached] == list(range(len(sc.trajectory.waypoints)))
    s = results[name].series
    for w in reached:
        i = int(np.searchsorted(s["t"], w["t_s"]))
        goal = np.array(sc.trajectory.waypoints[w["index"]].position_m)
        assert np.linalg.norm(s["pos"][i] - goal) <= sc.trajectory.acceptance_radius_m


def test_tether_length_follows_lbar_and_exceeds_altitude(results):
    s = results["tether-length"].series
    assert results["tether-length"].metrics["tether_length_rmse_m"] <= 0.02
    assert np.all(s["length"] > s["pos"][:, 2])
    assert s["length"][-1] - s["length"][0] > 20.0      # it paid out as the UAV climbed


def test_outputs_round_trip(results, tmp_path):
    res = results["setpoint"]
    write_outputs(res, tmp_path)
    assert load_toml(ScenarioParams, tmp_path / "scenario.toml") == res.scenario
    data = np.load(tmp_path / "timeseries.npz")
    assert np.array_equal(data["pos"], res.series["pos"])
    import json

    metrics = json.loads((tmp_path / "metrics.json").read_text())
    assert math.isclose(metrics["position_rmse_m"], res.metrics["position_rmse_m"])


def test_bad_scenario_names_the_field(tmp_path):
    f = tmp_path / "bad.toml"
    f.write_text('name = "bad"\n[trajectory]\nkind = "spiral"\n')
    with pytest.raises(ParameterError, match="bad.trajectory.kind"):
        load_scenario(str(f))
    with pytest.raises(ParameterError, match="no such scenario"):
        load_scenario("no-such-scenario")


@pytest.mark.parametrize("name", LYAPUNOV)
def test_position_lyapunov_function_falls_from_far_above_its_floor(on_the_catenary, name):
    """Once the position reference is constant, the position loop's Lyapunov function
    (compensated errors) never rises, and the count covers a real decay: it starts well
    above its floor and stays above it for seconds (docs/results.md). On the catenary
    truth, the line the proof models (:data:`LYAPUNOV`)."""
    assert on_the_catenary[name].scenario.plant.tether.model == "catenary"
    r = on_the_catenary[name].metrics["lyapunov"]["v_pos"]
    assert r["from_s"] is not None and r["floor"] > 0.0
    assert r["value_then"] > 1e3 * r["floor"], r
    assert r["above_floor_s"] > 5.0, r
    assert r["increases_any"] == 0, r   # not even below the floor
    assert r["increases"] == 0, r


def test_regulation_lyapunov_count_starts_at_the_initial_error(on_the_catenary):
    """The regulation run's reference is constant from t = 0, so its count starts at the
    whole initial error: compensated and raw alike fall from there without a rise (on the
    catenary truth, :data:`LYAPUNOV`)."""
    r = on_the_catenary["regulation"].metrics["lyapunov"]["v_pos"]
    assert r["from_s"] == 0.0 and r["value_then"] > 1.0
    assert r["raw_value_then"] > 1.0 and r["raw_increases"] == 0


def test_the_rise_counter_sees_a_disturbance():
    """The counter can fail: a gust while the reference is constant makes the position
    loop's Lyapunov function rise above its floor (on the catenary truth, where without
    the gust it does not: :data:`LYAPUNOV`)."""
    base = load_scenario("regulation").with_tether_model("catenary")
    gust = GustParams(start_s=12.0, duration_s=2.0, amplitude_m_s=(4.0, 0.0, 0.0))
    sc = base.replace(wind=base.wind.replace(gusts=(gust,)), duration_s=16.0)
    r = run_scenario(sc, None, progress=None).metrics["lyapunov"]["v_pos"]
    assert r["value_then"] > 1.0
    assert r["increases"] > 0


def _regulation(start, goal, duration=12.0) -> RunResult:
    base = load_scenario("setpoint").with_tether_model("catenary")   # LYAPUNOV's why
    sc = base.replace(initial=base.initial.replace(position_m=start),
                      trajectory=base.trajectory.replace(kind="step", goal_m=goal),
                      duration_s=duration)
    return run_scenario(sc, None, progress=None)


@pytest.mark.parametrize("start", [(4.0, 4.0, 18.0), (2.0, 3.0, 16.0)])
def test_regulation_from_an_offset_position_lyapunov_decreases_throughout(start):
    """The paper's set-point experiment: the reference is the goal from t = 0, the UAV
    starts metres away (the thrust saturates in tilt at first); the position loop's
    Lyapunov function must fall at every sample, from its largest value on (on the
    catenary truth, :data:`LYAPUNOV`)."""
    res = _regulation(start, (5.0, 5.0, 20.0))
    s = res.series
    v = s["v_pos"]
    assert v[0] > 1.0                                      # a real initial error
    assert np.all(np.diff(v) <= 0.0)
    assert np.all(np.diff(s["v_pos_raw"]) <= 0.0)          # even without compensation
    assert v[-1] < 1e-4 * v[0]                             # the slow mode is adaptation's
    assert np.linalg.norm(s["pos"][-1] - np.array([5.0, 5.0, 20.0])) < 0.02
    assert res.metrics["position_loop_saturation_fraction"] > 0.0   # limits were hit
    assert res.metrics["min_tether_slack_m"] > 0.0


def test_the_mission_scenario_flies_every_item_to_landed_and_disarmed(results):
    """The shipped mission: from the ground, armed in AUTO, every item reached in order,
    landed and disarmed at the end; the circle was flown at its radius."""
    res = results["mission"]
    m = res.metrics
    assert m["items_reached"] == [1, 2, 3, 4, 5, 6]
    assert m["landed_disarmed"] is True
    s = res.series
    assert s["pos"][0, 2] == pytest.approx(s["pos"][-1, 2], abs=0.01)   # on its gear
    t2, t3 = m["items_reached_t_s"][0], m["items_reached_t_s"][1]
    circ = (s["t"] > t2 + 8.0) & (s["t"] < t3 - 3.0)
    r = np.hypot(s["pos"][circ, 0] - 4.0, s["pos"][circ, 1] - 4.0)
    assert np.allclose(r, 5.0, atol=0.1) and circ.sum() > 100
    # the waypoints, where they were reached
    for seq, goal in zip((3, 4, 5), ((10.0, 0.0, 12.0), (6.0, 8.0, 10.0), (-2.0, 6.0, 8.0)),
                         strict=True):
        t = m["items_reached_t_s"][seq - 1]
        here = s["pos"][int(np.searchsorted(s["t"], t))]
        assert math.dist(here, goal) <= 0.5


def test_a_mission_file_flies_as_the_same_items_in_the_toml(tmp_path):
    """The mission as ground stations save it (QGC WPL 110, home at item 0) flies exactly
    as the same items written as [[mission]]; latitude/longitude items as local ones."""
    from companion import mission_file

    sc = load_scenario("mission")
    home, items = sc.mission_items()
    wp = tmp_path / "m.waypoints"
    wp.write_text(mission_file.format_items(items))
    assert mission_file.load(wp) == items
    (tmp_path / "s.toml").write_text('name = "from-file"\nduration_s = 200.0\n'
                                     'mission_file = "m.waypoints"\n'
                                     '[initial]\nposition_m = [2.0, 0.0, 0.0]\n')
    from_file = load_scenario(str(tmp_path / "s.toml"))
    assert from_file.mission_items() == (pytest.approx(home), items)
    a = run_scenario(sc.replace(duration_s=20.0), progress=None)
    b = run_scenario(from_file.replace(duration_s=20.0), progress=None)
    assert np.array_equal(a.series["pos"], b.series["pos"])


def test_bad_missions_fail_at_load_or_upload_with_the_reason(tmp_path):
    from companion.mission_file import MissionFileError, parse
    from tuav_sitl.offline import MissionError, OfflineRunner

    with pytest.raises(MissionFileError, match="line 1"):
        parse("QGC WPL 100\n")
    with pytest.raises(MissionFileError, match="line 3: item 2 out of sequence"):
        parse("QGC WPL 110\n0\t1\t0\t16\t0\t0\t0\t0\t47\t8\t488\t1\n"
              "2\t0\t3\t16\t0\t0\t0\t0\t47\t8\t10\t1\n")
    far = ScenarioParams.from_dict({
        "name": "far", "initial": {"position_m": [2.0, 0.0, 0.0]},
        "mission": [{"command": "NAV_TAKEOFF", "altitude_m": 10.0},
                    {"command": "NAV_WAYPOINT", "position_m": [60.0, 0.0, 10.0]}]})
    with pytest.raises(MissionError, match="beyond tether reach"):
        OfflineRunner(far)
    with pytest.raises(ParameterError, match="mission\\[0\\].command"):
        ScenarioParams.from_dict({"mission": [{"command": "NAV_FLIP"}]})


def test_a_mission_s_do_winch_reaches_the_winch_offline():
    """DO_WINCH items offline go to the ground station's own winch logic (the
    groundstation.winch.Winch the process runs): relative length pays 2 m more out, relaxed
    follows L-bar again; the DO items are run, not reached, and the tether stays slack."""
    from tuav_sitl.offline import OfflineRunner

    item = {"command": "NAV_WAYPOINT", "param1": 8.0}
    sc = ScenarioParams.from_dict({
        "name": "winch", "duration_s": 120.0, "initial": {"position_m": [2.0, 0.0, 0.0]},
        "mission": [
            {"command": "NAV_TAKEOFF", "altitude_m": 10.0},
            {"command": "DO_WINCH", "param1": 1.0, "param2": 1.0, "param3": 2.0,
             "param4": 0.5},
            {**item, "position_m": [4.0, 0.0, 10.0]},
            {"command": "DO_WINCH", "param1": 1.0, "param2": 0.0},
            {**item, "position_m": [2.0, 0.0, 10.0]},
            {"command": "NAV_LAND"}]})
    runner = OfflineRunner(sc)
    res = runner.run()
    m, s = res.metrics, res.series
    assert m["items_reached"] == [1, 3, 5, 6] and m["landed_disarmed"]
    assert m["min_tether_slack_m"] > 0.0
    t_wp, t_back = m["items_reached_t_s"][1], m["items_reached_t_s"][2]
    slack = s["length"] - np.linalg.norm(s["pos"], axis=1)
    at = lambda when: int(np.searchsorted(s["t"], when))   # noqa: E731
    t_cmd = m["items_reached_t_s"][0]   # DO_WINCH runs as the take-off is reached
    i = at(t_wp + 6.0)   # held at the waypoint: 2 m more than when the command came
    assert s["length"][i] - s["length"][at(t_cmd)] == pytest.approx(2.0, abs=0.02)
    j = at(t_back + 4.0)   # relaxed again: the slack of L-bar
    assert slack[j] < 0.3 < slack[i]
    assert [k for k, _, _ in res.events].count(NavEvent.WINCH) == 2
    assert runner.ground.notices == []


@pytest.mark.parametrize(("name", "tracking_m", "estimate_m", "inside_3_sigma"), [
    ("circle-rtk", 0.05, 0.03, 0.9), ("circle-gnss", 1.0, 1.0, 0.7),
    ("circle-windy-gnss", 1.5, 1.0, 0.7)])
def test_the_circle_flown_on_the_onboard_estimate(results, name, tracking_m, estimate_m,
                                                  inside_3_sigma):
    """The circle on the companion's EKF (RTK-grade and consumer-grade GNSS, calm and in
    wind): the truth tracks the reference within the targets, the estimate is off the
    truth by at most its target, and the tether stays slack (the ground station's tension
    trim: its L-bar comes from the same estimate). Within 3 sigma of its own covariance the
    estimate is 90 % of the time with RTK, but only about 75 % with the consumer receiver,
    whose error wanders (Gauss-Markov, 8 s) where the filter takes each fix as independent:
    the filter is overconfident there (measured 75.5 %), as said in docs/estimation.md."""
    m = results[name].metrics
    assert results[name].scenario.estimator.kind == "ekf"
    assert m["position_rmse_m"] <= tracking_m
    assert m["estimate_position_rmse_m"] <= estimate_m
    assert m["estimate_velocity_rmse_m_s"] <= 0.1
    # the attitude estimate within its 0.5 deg target (docs/results.md): a wind-state
    # default once moved circle-gnss's from 0.0038 to 0.0095 rad with its position unmoved
    assert m["estimate_attitude_rmse_rad"] <= math.radians(0.5)
    assert m["min_tether_slack_m"] > 0.0
    s = results[name].series
    est = np.isfinite(s["est_pos"]).all(axis=1)
    assert est[s["t"] > 2.0].all()             # aligned within the first seconds
    # the estimate really is the estimate: off the truth, by about what it says
    err = np.abs(s["est_pos"][est] - s["pos"][est])
    assert err.max() > 1e-3
    inside = (err <= 3.0 * s["est_pos_sigma"][est] + 0.05).mean()
    assert inside > inside_3_sigma


def test_the_tether_fix_holds_a_gnss_loss_in_calm_air(results):
    """hover-gnss-loss-calm (no wind, GNSS lost 20-80 s, the winch's tether fix on the lumped
    line, its covariance widened by the line's sway): the truth within 0.5 m of the hold
    point horizontally throughout the loss, the estimate within 0.5 m of the truth, never
    taut, the line off the ground."""
    m = results["hover-gnss-loss-calm"].metrics
    assert m["gnss_loss_horizontal_error_max_m"] <= 0.5
    assert m["gnss_loss_estimate_horizontal_error_max_m"] <= 0.5
    assert m["min_tether_slack_m"] > 0.0
    assert m["tether_ground_contact_fraction"] == 0.0


@pytest.mark.xfail(strict=True, reason="on the lumped line the ground's tether fix holds the "
                   "hover to 0.662 m during the loss, over the 0.5 m target: the line's "
                   "drag biases the calm fix 0.25 m downwind (0.10 m on the catenary; 0.43 m "
                   "given the vehicle's wind, not the default: docs/estimation.md §10; "
                   "issue 33)")
def test_the_tether_fix_holds_a_gnss_loss(results):
    """hover-gnss-loss (3 m/s of light turbulence, GNSS lost 20-80 s, the winch's tether
    fix): the truth within 0.5 m of the hold point horizontally throughout the loss, the
    tether never taut."""
    m = results["hover-gnss-loss"].metrics
    assert m["min_tether_slack_m"] > 0.0
    assert m["gnss_loss_horizontal_error_max_m"] <= 0.5


def test_the_tight_tether_fusion_holds_a_gnss_loss_in_the_wind(results):
    """hover-gnss-loss-windy (the lumped line in 6 m/s of moderate turbulence, GNSS lost
    20-80 s, the raw tether reading fused tightly with the filter's wind and line states):
    the truth within 1 m of the hold point horizontally throughout the loss (4.3 m on the
    ground station's calm fix), the estimate within 1 m of the truth, never taut."""
    m = results["hover-gnss-loss-windy"].metrics
    assert m["gnss_loss_horizontal_error_max_m"] <= 1.0
    assert m["gnss_loss_estimate_horizontal_error_max_m"] <= 1.0
    assert m["min_tether_slack_m"] > 0.0


def test_an_unhealthy_filter_in_flight_lands_the_vehicle():
    """ArduCopter's EKF failsafe: the GNSS stops arriving mid-circle (no tether aid), the
    filter turns
    unhealthy (no GNSS for its timeout), and a second later the vehicle lands, said as a
    failsafe; before that the same filter armed only once healthy (the mission's pre-arm
    check is exercised by every mission run)."""
    from companion.navigation import FlightMode
    from tuav_sitl.offline import OfflineRunner

    sc = load_scenario("circle-rtk").replace(duration_s=30.0)
    # without the tether fix: with it the filter keeps a position source (tests/test_tether_aid)
    sc = sc.replace(estimator=sc.estimator.replace(tether_aid=False))
    runner = OfflineRunner(sc)
    read = runner.sensors.read

    def without_gnss_after_10_s(t_s: float):
        sim = read(t_s)
        return sim._replace(gps_updated=False) if t_s >= 10.0 else sim

    runner.sensors.read = without_gnss_after_10_s
    res = runner.run()
    failsafes = [(t, v) for k, v, t in res.events if k is NavEvent.FAILSAFE]
    assert failsafes, "no failsafe"
    t_fs, text = failsafes[0]
    assert "EKF" in text and 11.0 <= t_fs <= 13.0
    assert runner.companion.nav.mode == FlightMode.LAND
    s = res.series
    assert s["pos"][-1, 2] < s["pos"][np.searchsorted(s["t"], t_fs), 2] - 2.0   # descending
    # the unaided estimate wanders off by metres (7 m by 30 s) while the winch follows the
    # position the vehicle reports; its slack floor, from what the winder itself measures
    # (length, tension, exit angles), keeps the line slack all the same
    err = np.linalg.norm(s["est_pos"] - s["pos"], axis=1)
    slack = s["length"] - np.linalg.norm(s["pos"], axis=1)
    t = s["t"]
    assert np.nanmax(err[t >= t_fs + 10.0]) > 2.0          # it did wander
    assert (slack > 0.0).all(), slack.min()


def test_a_run_that_never_flies_has_metrics():
    # a mission cut off before its take-off (or a vehicle that never arms, as a sweep's
    # draw can leave it): nothing tracked, the maxima NaN, nothing saturated
    sc = load_scenario("mission").replace(duration_s=1.0, metrics_after_s=0.5)
    m = OfflineRunner(sc).run().metrics
    assert m["items_reached"] == []
    assert math.isnan(m["position_max_error_m"]) and math.isnan(m["position_rmse_m"])
    assert m["motor_saturation_fraction"] == 0.0


def test_the_slack_floor_keeps_a_dynamic_line_off_the_ground(results):
    """The winch's slack floor (docs/control.md §3) reads the winder's own fix from the
    tension low-passed as its trim does: on the lumped (dynamic) line in the windy circle
    the load cell sees axial waves and snaps, and a floor fed the raw tension (paying out
    fast, taking back slowly) ratcheted the line out onto the ground (98 % of the run).
    Truth: the plant's lumped line, its nodes against the ground."""
    sc = results["circle-windy"].scenario
    assert sc.plant.tether.model == "lumped"
    assert sc.winder_control.law == "paper"            # the floor is the length law's
    m = results["circle-windy"].metrics
    assert m["tether_ground_contact_fraction"] == 0.0
    assert m["min_tether_slack_m"] > 0.0
    assert m["position_rmse_m"] < 0.05


def test_an_in_air_start_joins_lbar_without_snapping_a_dynamic_line():
    """circle-gnss starts in the air with 0.4 m less line out than L-bar asks at its first
    report. Stepping the reference there set the drum paying out at its torque limit,
    faster than the lumped line takes it: the exit went slack, the line near it fell and
    snapped taut when the drum stopped (top 82 N, drum 72 N at 0.6 s). Joined on a
    trapezoid (docs/control.md §3): measured 28 N. The join is the paper's length law's
    (the tension law, the default, follows the pull, not L-bar). Truth: the plant's lumped
    line."""
    sc = load_scenario("circle-gnss").with_tether_model("lumped").replace(
        duration_s=3.0, metrics_after_s=0.0)
    sc = sc.replace(winder_control=sc.winder_control.replace(law="paper"),
                    navigation=sc.navigation.replace(tether_governor=1))
    runner = OfflineRunner(sc)
    gaps: list[float] = []
    r = runner.run(on_sample=lambda _t: gaps.append(runner.ground.winch.join_gap_m))
    s = r.series
    assert max(gaps) > 0.3 and gaps[-1] == 0.0         # a join of decimetres, done
    assert s["top_tension"].max() < 40.0
    assert s["drum_tension"].max() < 40.0
    assert r.metrics["min_tether_slack_m"] > 0.0
