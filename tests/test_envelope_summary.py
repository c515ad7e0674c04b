"""The sweep summary's envelope (``[envelope]`` of a sweep file): the values where each limit
is first passed and the table by bins, against hand-made rows whose answers are known; the
sweep's own flight metrics against a hand-made series; a bad envelope refused by field."""

from __future__ import annotations

import math
import textwrap

import numpy as np
import pytest

from sitl.catenary import CatenaryRegime
from tuav_sitl import sweep as sw
from tuav_sitl import sweep_summary as ss
from tuav_sitl.scenario import load_scenario
from tuavdefs.paramspec import ParameterError

ENV = sw.EnvelopeParams(over="wind_speed_m_s", bin_width=1.0, pull_limit_n=35.0,
                        saturation_limit_fraction=0.01)
SWEEP = sw.SweepParams(
    name="tiny", scenario="hover", runs=9, envelope=ENV,
    vary=(sw.VaryParams(parameter="wind_speed_m_s", distribution="uniform", low=0.0,
                        high=15.0),))


def _row(index: int, wind: float, *, pull: float | None = 10.0, sat: float | None = 0.0,
         slack: float | None = 0.5, taut: float | None = 0.0, ground: float | None = 0.0,
         rmse: float | None = 0.05, tilt: float | None = 5.0, failures: str = ""
         ) -> dict:
    """A sweep row with the given metrics (the others None)."""
    row = {"index": index, "seed": index, "wind_speed_m_s": wind,
           **dict.fromkeys(sw.METRIC_COLUMNS)}
    row |= {"tension_peak_flying_n": pull, "tension_p99_flying_n": None if pull is None
            else 0.8 * pull, "motor_saturation_fraction": sat, "min_tether_slack_m": slack,
            "taut_time_s": taut, "ground_flying_s": ground, "position_rmse_m": rmse,
            "position_max_error_m": None if rmse is None else 3 * rmse, "max_tilt_deg": tilt,
            "position_loop_saturation_fraction": None if tilt is None else tilt / 100,
            "failed": bool(failures), "failures": failures}
    return row


#: Nine runs: the pull passes 35 N first at 7.9 m/s (exactly 35 N at 5.0 does not pass),
#: the rotors 1 % at 12.4 (exactly 1 % at 11.0 does not), the line taut at 14.9 only and
#: on the ground at 8.1 only, control lost at 13.0 (a run that raised: no metrics) and 14.9.
ROWS = [
    _row(0, 0.5),
    _row(1, 3.2, pull=12.0),
    _row(2, 5.0, pull=35.0),
    _row(3, 7.9, pull=36.0, failures="tracking"),
    _row(4, 8.1, pull=30.0, ground=0.4, slack=0.2, failures="ground_contact"),
    _row(5, 11.0, pull=40.0, sat=0.01),
    _row(6, 12.4, pull=50.0, sat=0.011, tilt=20.0, failures="saturation"),
    _row(7, 13.0, pull=None, sat=None, slack=None, taut=None, ground=None, rmse=None,
         tilt=None, failures="error"),
    _row(8, 14.9, pull=60.0, sat=0.03, slack=-0.01, taut=0.25, rmse=0.9, tilt=50.0,
         failures="taut;saturation;diverged;tilted"),
]


def test_the_thresholds_are_the_least_wind_that_passes_each_limit():
    t = ss.thresholds(ENV, ROWS)
    assert t["pull"] == {"first": 7.9, "runs": 4, "fraction_from_first": pytest.approx(4 / 6)}
    assert t["saturation"] == {"first": 12.4, "runs": 2,
                               "fraction_from_first": pytest.approx(2 / 3)}
    assert t["taut"] == {"first": 14.9, "runs": 1, "fraction_from_first": 1.0}
    assert t["ground"] == {"first": 8.1, "runs": 1, "fraction_from_first": pytest.approx(1 / 5)}
    assert t["lost_control"] == {"first": 13.0, "runs": 2, "fraction_from_first": 1.0}


def test_a_limit_never_passed_has_no_threshold():
    calm = [r for r in ROWS if r["wind_speed_m_s"] < 7.0]
    t = ss.thresholds(ENV, calm)
    for limit in ss.Limit:
        assert t[limit.value] == {"first": None, "runs": 0, "fraction_from_first": None}
    # a higher pull limit moves the threshold to the first run above it
    t = ss.thresholds(ENV.replace(pull_limit_n=45.0), ROWS)
    assert t["pull"]["first"] == 12.4 and t["pull"]["runs"] == 2


def test_the_table_holds_the_worst_run_of_each_bin():
    table = ss.envelope_table(ENV, ROWS)
    # 1 m/s bins from 0; the empty ones (1-3, 4, 6, 9-10, 14) left out
    assert [(b["low"], b["high"]) for b in table] == [
        (0, 1), (3, 4), (5, 6), (7, 8), (8, 9), (11, 12), (12, 13), (13, 14), (14, 15)]
    assert [b["runs"] for b in table] == [1] * 9
    by_low = {b["low"]: b for b in table}
    assert by_low[13]["controlled"] == 0 and by_low[13]["pull_peak_n"] is None
    assert by_low[14]["controlled"] == 0 and by_low[14]["least_slack_m"] == -0.01
    assert by_low[12]["controlled"] == 1 and by_low[12]["passed"] == 0
    # 5 m/s bins: several runs each, the worst of each metric (least slack: the least)
    wide = ss.envelope_table(ENV.replace(bin_width=5.0), ROWS)
    assert [(b["low"], b["runs"], b["controlled"], b["passed"]) for b in wide] == [
        (0, 2, 2, 2), (5, 3, 3, 1), (10, 4, 2, 1)]
    assert wide[1]["pull_peak_n"] == 36.0 and wide[1]["pull_p99_n"] == pytest.approx(28.8)
    assert wide[1]["least_slack_m"] == 0.2 and wide[1]["ground_s"] == 0.4
    assert wide[2]["pull_peak_n"] == 60.0 and wide[2]["saturation_fraction"] == 0.03
    assert wide[2]["taut_s"] == 0.25 and wide[2]["max_tilt_deg"] == 50.0
    assert wide[2]["position_max_error_m"] == pytest.approx(2.7)
    assert wide[2]["position_loop_saturation_fraction"] == pytest.approx(0.5)


def test_the_summary_writes_the_envelope():
    s = ss.summarise(SWEEP, ROWS)
    assert s["envelope"]["range"] == [0.5, 14.9]
    assert s["envelope"]["thresholds"] == ss.thresholds(ENV, ROWS)
    text = ss.summary_text(s)
    assert "- the pull at the UAV above 35 N: from 7.9 (4 runs; 66.7 % of the runs" in text
    assert "- the rotors saturated above 1 % of the flight: from 12.4 (2 runs" in text
    assert "- the tether taut: from 14.9 (1 runs" in text
    assert "- the vehicle not controlled: from 13 (2 runs" in text
    assert "| 7–8 | 1 | 1 | 0 | 36.0 | 28.8 | 0.00 % | 0.500 |" in text
    assert "| 13–14 | 1 | 0 | 0 | – | – |" in text
    assert ("| 14–15 | 1 | 0 | 0 | 60.0 | 48.0 | 3.00 % | -0.010 | 0.25 | 0.00 | 0.900 | 2.70 "
            "| 50.0 | 50.0 % |") in text
    # a sweep without an envelope writes none
    plain = ss.summarise(SWEEP.replace(envelope=sw.EnvelopeParams()), ROWS)
    assert "envelope" not in plain and "Envelope" not in ss.summary_text(plain)


def test_flight_metrics_of_a_hand_made_series():
    sc = load_scenario("hover")
    gear = sc.plant.vehicle.gear_height_m
    dt = 0.01
    t = np.arange(0.0, 40.0, dt)
    n = len(t)
    pos = np.tile([12.0, 0.0, 20.0], (n, 1))
    dist = np.linalg.norm(pos, axis=1)
    length = dist + 0.5
    length[(t >= 20.0) & (t < 21.0)] = dist[0] - 0.01        # taut for 1 s
    regime = np.full(n, int(CatenaryRegime.SUSPENDED))
    regime[(t >= 30.0) & (t < 30.5)] = int(CatenaryRegime.TOUCHDOWN)   # 0.5 s on the ground
    regime[t < 2.0] = int(CatenaryRegime.TOUCHDOWN)          # before take-off: not flying
    pos[t < 2.0, 2] = gear
    euler = np.zeros((n, 3))
    euler[t >= 25.0, :2] = math.radians(20.0)                 # tilt arccos(cos^2 20 deg)
    euler[t < 5.0, 0] = math.radians(80.0)                    # before metrics_after_s
    pull = np.full(n, 10.0)
    pull[t < 5.0] = 500.0                                     # before metrics_after_s
    pull[(t >= 15.0) & (t < 15.3)] = 40.0                     # 30 samples of 3000 flying
    series = {"t": t, "pos": pos, "ref_pos": np.tile([12.0, 0.0, 20.0], (n, 1)),
              "length": length, "regime": regime, "euler": euler, "top_tension": pull}
    m = sw.flight_metrics(sc, sw.TargetParams(), series)
    assert m["taut_time_s"] == pytest.approx(1.0, abs=1.5 * dt)
    assert m["ground_flying_s"] == pytest.approx(0.5, abs=1.5 * dt)
    assert m["tension_peak_flying_n"] == 40.0
    assert sc.metrics_after_s == 10.0
    # 30 of 3000 samples at 40 N: the 99th percentile lies on the step's edge
    assert 10.0 <= m["tension_p99_flying_n"] <= 40.0
    assert m["max_tilt_deg"] == pytest.approx(
        math.degrees(math.acos(math.cos(math.radians(20.0)) ** 2)))
    assert m["min_height_flying_m"] == pytest.approx(gear)
    # the tilt over the sweep's bound fails as tilted, with the vehicle not controlled
    row = {**dict.fromkeys(sw.METRIC_COLUMNS, 0.0), **m, "max_tilt_deg": 50.0,
           "min_tether_slack_m": 0.5, "min_height_flying_m": 20.0}
    assert sw.failures(sc, sw.TargetParams(), row) == [sw.FailureKind.TILTED]


def test_an_envelope_over_a_quantity_not_drawn_is_refused(tmp_path):
    p = tmp_path / "bad.toml"
    p.write_text(textwrap.dedent("""\
        name = "bad"
        scenario = "hover"
        [envelope]
        over = "mass_factor"
        [[vary]]
        parameter = "wind_speed_m_s"
        distribution = "uniform"
        low = 0.0
        high = 5.0
        """))
    with pytest.raises(ParameterError, match="envelope.over"):
        sw.load_sweep(p)


def test_the_envelope_figure_draws_every_run_and_its_limit(tmp_path):
    from tuav_sitl.sweep_figures import ENVELOPE_PANELS, fig_envelope, make_sweep_figures

    fig = fig_envelope(SWEEP, ROWS)
    pull = fig.axes[0]
    good, bad = (c.get_offsets() for c in pull.collections)
    # the runs that flew, split by control: 14.9 m/s lost it, 13.0 did not fly (no pull)
    assert sorted(map(tuple, good.tolist())) == sorted(
        (r["wind_speed_m_s"], r["tension_peak_flying_n"]) for r in ROWS[:7])
    assert bad.tolist() == [[14.9, 60.0]]
    assert [ln.get_ydata()[0] for ln in pull.get_lines()] == [35.0]
    sat = fig.axes[[p[0] for p in ENVELOPE_PANELS].index("motor_saturation_fraction")]
    assert [ln.get_ydata()[0] for ln in sat.get_lines()] == [pytest.approx(1.0)]   # in %
    names = {p.name for p in make_sweep_figures(SWEEP, ROWS, tmp_path)}
    assert names == {"cdfs.png", "failures.png", "envelope.png"}
