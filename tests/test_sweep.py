"""``tuav-sitl sweep``: a small sweep on a Dask LocalCluster of two workers against the same
runs made directly, resuming an interrupted sweep, reproducibility, the summary's counts
and interval against scipy, and bad sweep files refused by field."""

from __future__ import annotations

import json
import math
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import binomtest

from tuav_sitl import sweep as sw
from tuav_sitl.cli import main
from tuav_sitl.offline import run_scenario
from tuav_sitl.scenario import ScenarioParams, load_scenario
from tuavdefs.paramspec import ParameterError

SMALL = """\
name = "small"
scenario = "circle"
runs = 4
seed = 7
duration_s = 7.0

[targets]
position_rmse_m = 0.04

[[vary]]
parameter = "mass_factor"
distribution = "uniform"
low = 0.8
high = 1.2

[[vary]]
parameter = "tether_density_factor"
distribution = "normal"
mean = 1.0
std = 0.5

[[vary]]
parameter = "wind_speed_m_s"
distribution = "choice"
values = [0.0, 6.0]

[[vary]]
parameter = "turbulence"
distribution = "choice"
labels = ["none", "light"]
"""


def _write(tmp_path: Path, text: str, name: str = "small.toml") -> Path:
    p = tmp_path / name
    p.write_text(textwrap.dedent(text))
    return p


@pytest.fixture(scope="module")
def small_sweep(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("sweep")
    sweep, sc = sw.load_sweep(_write(tmp, SMALL))
    rows, summary = sw.run_sweep(sweep, sc, tmp / "out", workers=2, progress=None)
    return sweep, sc, rows, summary, tmp / "out"


def test_the_table_holds_what_single_runs_give(small_sweep):
    sweep, sc, rows, _, _ = small_sweep
    assert [r["index"] for r in rows] == list(range(sweep.runs))
    for row in rows:
        seed, drawn = sw.draw(sweep, row["index"])
        assert row["seed"] == seed
        for name, value in drawn.items():
            assert row[name] == value
        # the run made here, directly, from the drawn parameters
        direct = sw.apply(sc, seed, drawn)
        assert direct.plant.vehicle.mass_kg == pytest.approx(
            sc.plant.vehicle.mass_kg * drawn["mass_factor"])
        assert direct.vehicle == sc.vehicle   # the controllers' model stays nominal
        assert direct.sensors.seed == seed and direct.wind.seed == seed
        m = run_scenario(direct, progress=None).metrics
        for c in sw.METRIC_COLUMNS:
            if c == "wall_time_s" or c in sw.OWN_COLUMNS:
                continue
            v = m.get(c)
            if v is None or (isinstance(v, float) and math.isnan(v)):
                assert row[c] is None or math.isnan(row[c]), c
            else:
                assert row[c] == v, c
    # the draws differ between runs (the table is not one run repeated)
    assert len({r["mass_factor"] for r in rows}) == sweep.runs


def test_the_summary_counts_the_table(small_sweep):
    sweep, _, rows, summary, out = small_sweep
    assert summary["runs"] == len(rows) == sweep.runs
    k = sum(r["failed"] for r in rows)
    assert summary["failed"] == k
    for kind in sw.FailureKind:
        assert summary["failures_by_kind"][kind.value] == sum(
            kind.value in r["failures"].split(";") for r in rows)
    # a tracking failure is exactly an RMSE above the sweep's target
    for r in rows:
        assert ("tracking" in r["failures"]) == (r["position_rmse_m"] > 0.04)
    lo, hi = summary["failure_rate_95ci"]
    ci = binomtest(k, len(rows)).proportion_ci(0.95, method="exact")
    assert (lo, hi) == pytest.approx((ci.low, ci.high), abs=1e-9)
    p95 = np.percentile([r["position_rmse_m"] for r in rows], 95)
    assert summary["percentiles"]["position_rmse_m"]["p95"] == pytest.approx(p95)
    assert (out / "runs.json").is_file() and (out / "summary.md").is_file()
    assert sorted(sw.read_table(out / "runs.csv", sweep), key=lambda r: r["index"]) == rows


def test_an_interrupted_sweep_resumes_where_it_stopped(small_sweep, tmp_path):
    sweep, sc, rows, _, out = small_sweep
    # the table as a sweep killed after two runs, in the middle of its third row, left it
    lines = (out / "runs.csv").read_text().splitlines(keepends=True)
    (tmp_path / "runs.csv").write_text("".join(lines[:3]) + lines[3][:17])
    ran: list[int] = []
    again, _ = sw.run_sweep(sweep, sc, tmp_path, workers=1, progress=None,
                            on_row=lambda r: ran.append(r["index"]))
    kept = {int(line.split(",")[0]) for line in lines[1:3]}
    # the two finished runs are not run again, the torn one is
    assert sorted(ran) == sorted(set(range(sweep.runs)) - kept)
    strip = [{k: v for k, v in r.items() if k != "wall_time_s"} for r in again]
    assert strip == [{k: v for k, v in r.items() if k != "wall_time_s"} for r in rows]
    # nothing left to do: nothing runs
    ran.clear()
    sw.run_sweep(sweep, sc, tmp_path, workers=1, progress=None,
                 on_row=lambda r: ran.append(r["index"]))
    assert ran == []


def test_draws_are_reproducible_and_follow_their_distributions(tmp_path):
    sweep, _ = sw.load_sweep(_write(tmp_path, SMALL))
    assert sw.draw(sweep, 3) == sw.draw(sweep, 3)
    assert sw.draw(sweep, 3) != sw.draw(sweep, 4)
    draws = [sw.draw(sweep, i)[1] for i in range(2000)]
    mass = np.array([d["mass_factor"] for d in draws])
    assert mass.min() >= 0.8 and mass.max() <= 1.2
    assert mass.mean() == pytest.approx(1.0, abs=0.01)   # 4 sigma of the mean
    dens = np.array([d["tether_density_factor"] for d in draws])
    assert dens.min() >= sw.Quantity.TETHER_DENSITY_FACTOR.bounds[0]
    assert dens.std() == pytest.approx(0.5, rel=0.1)
    assert {d["wind_speed_m_s"] for d in draws} == {0.0, 6.0}
    assert {d["turbulence"] for d in draws} == {"none", "light"}


def test_wind_direction_is_where_it_blows_from():
    sc = load_scenario("circle")
    north = sw.apply(sc, None, {"wind_speed_m_s": 4.0, "wind_direction_deg": 0.0})
    assert north.wind.steady_m_s == pytest.approx((0.0, -4.0, 0.0), abs=1e-12)
    west = sw.apply(sc, None, {"wind_speed_m_s": 4.0, "wind_direction_deg": 270.0})
    assert west.wind.steady_m_s == pytest.approx((4.0, 0.0, 0.0), abs=1e-12)


def test_the_truths_line_model_is_drawn_and_the_controllers_keep_theirs():
    """tether_model sets the truth's line model only (the plant's [tether]); the
    controllers' model, and robustness-gnss's scenario file, stay as they are; the shipped
    robustness-gnss flies the lumped line whatever the default truth."""
    sc = ScenarioParams.from_dict({"tether": {"model": "catenary"}})   # a file's pin
    assert sc.plant.tether.model == "catenary"
    lumped = sw.apply(sc, None, {"tether_model": "lumped"})
    assert lumped.plant.tether.model == "lumped"
    assert lumped.tether == sc.tether
    sc = load_scenario("circle-gnss")             # the default truth: the lumped line
    catenary = sw.apply(sc, None, {"tether_model": "catenary"})
    assert catenary.plant.tether.model == "catenary" and catenary.tether == sc.tether
    sweep, base = sw.load_sweep("robustness-gnss")
    assert base.plant.tether.model == "lumped"
    assert {sw.run_scenario_of(sweep, base, i).plant.tether.model for i in range(3)} == {
        "lumped"}
    with pytest.raises(ValueError):
        sw.VaryParams(parameter="tether_model", distribution="choice", labels=("rope",))


FAULTS = """\
name = "faulty"
scenario = "hover"
runs = 6
seed = 3
duration_s = 12.0

[[vary]]
parameter = "mass_factor"
distribution = "uniform"
low = 0.95
high = 1.05

[[faults]]
probability = 0.5
start_low_s = 6.0
start_high_s = 8.0

[faults.fault]
kind = "motor"
motor = 1
thrust_multiplier = 0.0

[[faults]]
probability = 0.25
start_low_s = 2.0
start_high_s = 4.0
duration_low_s = 1.0
duration_high_s = 3.0

[faults.fault]
kind = "gnss_loss"
"""


def test_fault_draws_follow_their_probability_and_times(tmp_path):
    sweep, sc = sw.load_sweep(_write(tmp_path, FAULTS, "faulty.toml"))
    motor, gnss = (f.columns(i) for i, f in enumerate(sweep.faults))
    assert motor == ("fault0_motor_start_s", "fault0_motor_end_s")
    # adding faults leaves the quantities' draws as they were
    plain = sw.load_sweep(_write(tmp_path, FAULTS.split("[[faults]]")[0], "plain.toml"))[0]
    assert sw.draw(sweep, 5)[1]["mass_factor"] == sw.draw(plain, 5)[1]["mass_factor"]
    n = 4000
    draws = [sw.draw(sweep, i)[1] for i in range(n)]
    for (start, end), p, lo, hi, dur in ((motor, 0.5, 6.0, 8.0, None),
                                         (gnss, 0.25, 2.0, 4.0, (1.0, 3.0))):
        had = [d for d in draws if d[start] is not None]
        assert all(d[end] is None for d in draws if d[start] is None)
        assert binomtest(len(had), n, p).pvalue > 1e-4
        t0 = np.array([d[start] for d in had])
        assert t0.min() >= lo and t0.max() <= hi
        length = np.array([d[end] for d in had]) - t0
        if dur is None:
            assert np.all(np.array([d[end] for d in had]) == sw.NEVER_S)
        else:
            assert length.min() >= dur[0] and length.max() <= dur[1]
    # the faults a run has are its scenario's [[faults]] entries at the drawn times
    i = next(i for i, d in enumerate(draws) if d[motor[0]] is not None and d[gnss[0]] is None)
    run = sw.run_scenario_of(sweep, sc, i)
    assert run.faults == (sweep.faults[0].fault.replace(start_s=draws[i][motor[0]],
                                                         end_s=sw.NEVER_S),)


def test_a_drawn_dead_motor_brings_the_runs_that_have_it_down(tmp_path):
    """On a LocalCluster: the hovering runs that draw a rotor at zero thrust come down
    (the plant's own physics); the others hold their hover."""
    sweep, sc = sw.load_sweep(_write(tmp_path, FAULTS, "faulty.toml"))
    rows, summary = sw.run_sweep(sweep, sc, tmp_path / "out", workers=2, progress=None)
    start = sweep.faults[0].columns(0)[0]
    dead = [r for r in rows if r[start] is not None]
    alive = [r for r in rows if r[start] is None]
    assert dead and alive
    assert all(r["failed"] and r["position_max_error_m"] > 2.0 for r in dead)
    assert all(r["position_max_error_m"] < 0.5 for r in alive)
    by = summary["failures_against"]["fault0_motor"]["failure_rate_by_value"]
    assert by["with"] == 1.0
    # the table read back holds the same drawn times
    again = sw.read_table(tmp_path / "out" / "runs.csv", sweep)
    # (the table is appended as runs finish, in any order: compared run by run)
    assert ({r["index"]: r[start] for r in again} == {r["index"]: r[start] for r in rows})


@pytest.mark.parametrize(("patch", "field"), [
    (SMALL.replace("high = 1.2", "high = 0.5"), "bad.vary[0].high"),
    (SMALL.replace('"mass_factor"', '"mass_fraction"'), "bad.vary[0].parameter"),
    (SMALL.replace("std = 0.5", "std = 0.0"), "bad.vary[1].std"),
    (SMALL.replace('labels = ["none", "light"]', 'labels = ["gale"]'),
     "bad.vary[3].labels[0]"),
    (SMALL.replace("runs = 4", "runs = 0"), "bad.runs"),
    (SMALL.replace("position_rmse_m = 0.04", "position_rmse_m = -1"),
     "bad.targets.position_rmse_m"),
    (SMALL + '\n[[vary]]\nparameter = "mass_factor"\nlow = 0.9\nhigh = 1.0\n',
     "bad.vary[4].parameter"),
    (FAULTS.replace("start_high_s = 8.0", "start_high_s = 5.0"), "bad.faults[0].start_high_s"),
    (FAULTS.replace("probability = 0.25", "probability = 1.5"), "bad.faults[1].probability"),
    (FAULTS.replace('kind = "gnss_loss"', 'kind = "meteor"'), "bad.faults[1].fault.kind"),
])
def test_a_bad_sweep_file_fails_naming_the_field(tmp_path, capsys, patch, field):
    path = _write(tmp_path, patch, "bad.toml")
    with pytest.raises(ParameterError) as exc:
        sw.load_sweep(path)
    assert exc.value.field == field
    assert main(["sweep", str(path), "--out", str(tmp_path / "o")]) == 2
    assert field in capsys.readouterr().err


def test_the_sweep_figures_are_drawn(small_sweep, tmp_path):
    from tuav_sitl.sweep_figures import make_sweep_figures

    sweep, _, rows, _, _ = small_sweep
    written = make_sweep_figures(sweep, rows, tmp_path)
    assert [p.name for p in written] == ["cdfs.png", "failures.png"]
    for p in written:
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_killed_sweep_resumes_and_loses_nothing(tmp_path):
    """``tuav-sitl sweep`` killed (SIGKILL, the whole process group: the command and its
    Dask workers) part-way: started again, it runs only the runs its table lacks. (16
    runs: the kill comes within 20 ms of the second row, one 7 s run takes a Dask worker
    about a quarter of a second; what is left is run again here, in this process.)"""
    import os
    import signal
    import subprocess
    import sys
    import time

    path = _write(tmp_path, SMALL)
    out = tmp_path / "out"
    table = out / "runs.csv"
    runs = 16
    proc = subprocess.Popen(
        [sys.executable, "-m", "tuav_sitl", "sweep", str(path), "--runs", str(runs),
         "--workers", "1", "--out", str(out), "--quiet", "--no-figures"],
        start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        while proc.poll() is None:
            if table.is_file() and table.read_text().count("\n") >= 3:   # header + 2 rows
                break
            time.sleep(0.02)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    sweep, sc = sw.load_sweep(path)
    sweep = sweep.replace(runs=runs)
    before = sw.read_table(table, sweep)
    if len(before) >= runs:
        pytest.skip("the sweep finished before it could be killed")
    assert len(before) >= 2
    ran: list[int] = []
    rows, _ = sw.run_sweep(sweep, sc, out, workers=1, progress=None,
                           on_row=lambda r: ran.append(r["index"]))
    done = {r["index"] for r in before}
    assert sorted(ran) == sorted(set(range(runs)) - done)
    assert [r["index"] for r in rows] == list(range(runs))
    by_index = {r["index"]: r for r in rows}
    for r in before:   # what was stored before the kill is kept as it was
        assert by_index[r["index"]] == r


def test_results_show_a_shipped_sweeps_summary_or_how_to_run_it(small_sweep, tmp_path):
    from tuav_sitl.results import shipped_sweeps, sweep_section

    _, _, _, summary, out = small_sweep
    names = sorted(shipped_sweeps())
    assert {"robustness", "wind-envelope-hover", "wind-envelope-circle"} <= set(names)
    for name in names:   # every shipped sweep file loads
        sw.load_sweep(shipped_sweeps()[name])
    text = "\n".join(sweep_section(tmp_path, {"circle-rtk": {"wall_time_s": 1.5}}))
    assert "### sweep robustness: not run" in text
    import os

    assert f"about {200 * 1.5 / (os.cpu_count() or 1) / 60:.0f} min" in text
    # a sweep run there: its summary, headings one level down
    import shutil

    shutil.copytree(out, tmp_path / "sweeps" / "robustness")
    text = "\n".join(sweep_section(tmp_path, {}))
    assert f"### sweep small over circle: {summary['runs']} runs" in text


def test_shipped_sweeps_by_name_from_any_folder_and_a_refusal_naming_them(
        tmp_path, monkeypatch, capsys):
    from tuav_sitl.cli import build_parser

    names = sorted(sw.shipped_sweeps())
    assert "robustness" in names
    monkeypatch.chdir(tmp_path)        # no sweep files here: the names are the package's
    for name in names:
        by_name, sc = sw.load_sweep(name)
        by_path, sc_path = sw.load_sweep(str(sw.shipped_sweeps()[name]))
        assert by_name == by_path and sc == sc_path
    # a file path still works, and a file whose stem is not a shipped name is a file
    path = _write(tmp_path, SMALL)
    assert sw.load_sweep(path)[0].name == "small"
    assert sw.load_sweep("small.toml")[0].name == "small"
    args = build_parser().parse_args(["sweep", "robustness", "--runs", "3"])
    assert args.sweep == "robustness" and args.runs == 3
    # a name that is neither: refused with every shipped name
    assert main(["sweep", "robustnes", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "robustnes: no such sweep" in err
    for name in names:
        assert name in err
    assert not (tmp_path / "o").exists()
    with pytest.raises(SystemExit):
        build_parser().parse_args(["sweep", "--help"])
    help_text = " ".join(capsys.readouterr().out.split())
    for name in names:
        assert name in help_text.replace("- ", "-")


def test_results_writes_where_it_says_whatever_the_current_folder(
        tmp_path, monkeypatch, capsys):
    import tuav_sitl.results as res
    import tuav_sitl.warmup as warmup
    from tuav_sitl.cli import build_parser

    repo = Path(__file__).resolve().parent.parent
    monkeypatch.chdir(tmp_path)
    # run from this checkout (an editable install): its docs/results.md, not ./docs
    assert res.checkout_results_path() == repo / "docs" / "results.md"
    args = build_parser().parse_args(["results"])
    assert args.out is None and args.runs == "runs"
    # the run of every scenario (minutes) is not what this checks: where it goes is
    written: list[tuple[Path, Path]] = []
    monkeypatch.setattr(res, "write_results",
                        lambda out, runs, **kw: written.append((out, runs)) or {})
    monkeypatch.setattr(warmup, "compile_if_cold", lambda *a, **kw: None)
    assert main(["results", "--quiet", "--no-figures"]) == 0
    assert written == [(repo / "docs" / "results.md", tmp_path / "runs")]
    assert f"writing {repo / 'docs' / 'results.md'}" in capsys.readouterr().out
    written.clear()
    assert main(["results", "--quiet", "--no-figures", "--out", "r/results.md"]) == 0
    out = capsys.readouterr().out
    assert written == [(tmp_path / "r" / "results.md", tmp_path / "runs")]
    assert f"writing {tmp_path / 'r' / 'results.md'}" in out
    assert f"wrote {tmp_path / 'r' / 'results.md'}" in out
    # an installed package (no checkout): --out is required, said, nothing written
    monkeypatch.setattr(res, "checkout_results_path", lambda: None)
    written.clear()
    assert main(["results", "--quiet"]) == 2
    assert "give --out FILE" in capsys.readouterr().err
    assert written == [] and not (tmp_path / "docs").exists()


def test_a_sweep_meeting_a_run_that_cannot_fly_records_it_and_goes_on(tmp_path, capsys):
    """A drawn system no rotor can hold (a 1000 m/s wind: no hover trim) used to end the
    sweep with its exception; it is a failed row (kind "error", why in runs.json and on the
    progress stream) and the other runs fly."""
    sweep, sc = sw.load_sweep(_write(tmp_path, """\
        name = "gale"
        scenario = "hover"
        runs = 2
        seed = 1
        duration_s = 11.0

        [[vary]]
        parameter = "wind_speed_m_s"
        distribution = "choice"
        values = [1000.0, 0.0]
        """, "gale.toml"))
    out = tmp_path / "out"
    rows, summary = sw.run_sweep(sweep, sc, out, workers=1, progress=sys.stderr)
    by_wind = {r["wind_speed_m_s"]: r for r in rows}
    assert set(by_wind) == {0.0, 1000.0}
    bad, good = by_wind[1000.0], by_wind[0.0]
    assert bad["failed"] and bad["failures"] == "error"
    assert "cannot hold" in bad["error"] and bad["position_rmse_m"] is None
    assert good["position_rmse_m"] is not None and good["position_rmse_m"] < 0.1
    assert summary["failures_by_kind"]["error"] == 1 and summary["runs"] == 2
    assert "did not fly: ValueError" in capsys.readouterr().err
    again = sw.read_table(out / "runs.csv", sweep)          # the table holds both rows
    assert sorted(r["index"] for r in again) == [0, 1]
    kept = json.loads((out / "runs.json").read_text())
    assert any("cannot hold" in (r.get("error") or "") for r in kept)


def test_a_sweep_keeps_its_worst_failed_runs_as_run_folders(tmp_path, capsys):
    """``tuav-sitl sweep --keep 1``: of two failed runs (a tracking target no hover
    meets), the one with the larger position error is flown again into
    OUT/runs/run-INDEX/, the run its row counted (a run depends only on the sweep and its
    index), with its recording.rrd; the other is not kept."""
    path = _write(tmp_path, """\
        name = "keep"
        scenario = "hover"
        runs = 2
        seed = 3
        duration_s = 12.0

        [[vary]]
        parameter = "wind_speed_m_s"
        distribution = "uniform"
        low = 0.0
        high = 6.0

        [targets]
        position_rmse_m = 1e-6
        """, "keep.toml")
    out = tmp_path / "o"
    assert main(["sweep", str(path), "--out", str(out), "--workers", "1", "--quiet",
                 "--no-figures", "--keep", "1"]) == 0
    sweep, sc = sw.load_sweep(path)
    rows = sw.read_table(out / "runs.csv", sweep)
    failed = sorted((r for r in rows if r["failed"]), key=lambda r: -r["position_max_error_m"])
    assert len(failed) == 2, rows
    kept = sorted((out / "runs").iterdir())
    assert kept == [out / "runs" / f"run-{failed[0]['index']:04d}"]
    metrics = json.loads((kept[0] / "metrics.json").read_text())
    assert metrics["position_rmse_m"] == pytest.approx(failed[0]["position_rmse_m"], rel=1e-9)
    from tuav_sitl.view import available
    if available():
        assert (kept[0] / "recording.rrd").stat().st_size > 0
    assert f"kept a failed run: {kept[0]}" in capsys.readouterr().out
    assert main(["sweep", str(path), "--out", str(out), "--keep", "-1"]) == 2
