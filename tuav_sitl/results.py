"""``tuav-sitl results``: run every shipped experiment and write the results file (by
default the source checkout's docs/results.md, :func:`checkout_results_path`).

Runs the scenarios in parallel (one process per core), writes each run folder (time series,
metrics, figures, animation) under ``--runs``, copies a selection of figures next to the
results file, and writes the table of metrics against the project's targets. Every shipped
scenario flies the default truth, the lumped line (:data:`DEFAULT_TRUTH_TETHER`); each is
flown again on the other truth, the catenary (:func:`other_truth`), beside it.
"""

from __future__ import annotations

import math
import os
import platform
import shutil
import time
from multiprocessing import get_context
from pathlib import Path
from typing import Any, TextIO

from tuav_sitl.offline import run_scenario
from tuav_sitl.scenario import load_scenario, shipped_scenarios
from tuav_sitl.sweep import shipped_sweeps
from tuavdefs.params import DEFAULT_TRUTH_TETHER, TetherModel

#: (scenario, metric, comparison, limit, description) — the targets of the issue.
TARGETS: list[tuple[str, str, str, float, str]] = [
    ("circle", "position_rmse_m", "<=", 0.05, "calm circle: position RMSE after the lead-in"),
    ("circle", "tether_length_rmse_m", "<=", 0.02, "calm circle: tether-length RMSE"),
    ("circle-windy", "position_rmse_m", "<=", 0.25, "windy circle: position RMSE"),
    ("setpoint", "settling_time_s", "<=", 10.0, "set-point: within 5 cm in"),
    ("setpoint", "overshoot_percent", "<=", 5.0, "set-point: overshoot"),
    ("circle-rtk", "position_rmse_m", "<=", 0.05, "circle on the EKF, RTK: position RMSE"),
    ("circle-rtk", "estimate_position_rmse_m", "<=", 0.03, "circle on the EKF, RTK: "
     "estimate - truth"),
    ("circle-gnss", "position_rmse_m", "<=", 1.0, "circle on the EKF, consumer GNSS: "
     "position RMSE"),
    ("circle-gnss", "estimate_position_rmse_m", "<=", 1.0, "circle on the EKF, consumer "
     "GNSS: estimate - truth"),
    ("circle-windy-gnss", "position_rmse_m", "<=", 1.5, "windy circle on the EKF, consumer "
     "GNSS: position RMSE"),
    ("hover-gnss-loss-calm", "gnss_loss_horizontal_error_max_m", "<=", 0.5, "hover in calm "
     "air, GNSS lost for 60 s, tether fix: horizontal truth error during the loss"),
    ("hover-gnss-loss", "gnss_loss_horizontal_error_max_m", "<=", 0.5, "hover, GNSS lost "
     "for 60 s, tether fix: horizontal truth error during the loss"),
    ("hover-gnss-loss-windy", "gnss_loss_horizontal_error_max_m", "<=", 1.0, "hover on the "
     "lumped line in 6 m/s, GNSS lost for 60 s, the raw tether reading fused tightly: "
     "horizontal truth error during the loss"),
    ("mission-gnss-denied", "min_tether_slack_m", ">=", 1e-9, "mission without GNSS, on the "
     "tether fix: never taut"),
    *((name, "estimate_attitude_rmse_rad", "<=", math.radians(0.5), f"{label}: attitude "
       "estimate - truth (0.5 deg)")
      for name, label in (("circle-rtk", "circle on the EKF, RTK"),
                          ("circle-gnss", "circle on the EKF, consumer GNSS"),
                          ("circle-windy-gnss", "windy circle on the EKF, consumer GNSS"))),
]
FIGURES_FOR_DOCS = {
    "setpoint": ["states.png", "errors.png", "lyapunov.png"],
    "linear": ["position_tracking.png", "attitude_tracking.png"],
    "circle": ["path_3d.png"],
    "tether-length": ["tether_length.png"],
    "single-position": ["snapshots.png"],
    "multi-position": ["snapshots.png"],
    "mission": ["path_3d.png"],
    "circle-gnss": ["estimate.png"],
}


#: Runs beside the shipped scenarios: (label, scenario, its [estimator] tether_aid).
TETHER_AID_VARIANTS = (("hover-gnss-loss, tether_aid = false", "hover-gnss-loss", False),
                       ("circle-gnss, tether_aid = false", "circle-gnss", False))


def _other(model: TetherModel) -> TetherModel:
    """The truth tether that is not ``model``."""
    return TetherModel.CATENARY if model is TetherModel.LUMPED else TetherModel.LUMPED


def other_truth(name: str) -> TetherModel:
    """The truth tether shipped scenario ``name`` is not flown on: the catenary for one on
    the lumped line (every shipped scenario: the default truth), the lumped line for one
    on the catenary."""
    return _other(TetherModel(load_scenario(name).plant.tether.model))


def _truths_text(names: list[str]) -> str:
    """Which truth the tables of shipped scenarios ``names`` show and which is beside
    them, in words."""
    main, other = DEFAULT_TRUTH_TETHER, _other(DEFAULT_TRUTH_TETHER)
    what = {TetherModel.LUMPED: "the lumped-mass line (the dynamic tether with drag)",
            TetherModel.CATENARY: "the catenary (quasi-static, the controllers' model of "
                                  "the line and the paper's truth)"}
    pinned = [n for n in names if load_scenario(n).plant.tether.model != main.value]
    flies = (f"Every shipped scenario flies the default truth tether, {what[main]}, and "
             "every number here is flown on it unless it says otherwise" if not pinned else
             f"The shipped scenarios fly the default truth tether, {what[main]}, but for "
             f"{', '.join(pinned)} (the `truth` column)")
    return (f"{flies}; beside it, the same run on the other truth, {what[other]}, an option "
            f"(`tuav-sitl run NAME --tether-model {other.value}`; § On the other truth "
            "tether). The controllers keep their catenary model either way (docs/model.md).")


def other_truth_label(name: str) -> str:
    """The label of shipped scenario ``name``'s run on its :func:`other_truth`."""
    return f"{name}{OTHER_TRUTH_SEP}{other_truth(name).value} truth"


#: Between a scenario's name and its other truth in a run's label.
OTHER_TRUTH_SEP = ", on the "


def _one(args: tuple[str, str, bool]) -> tuple[str, dict[str, Any]]:
    name, runs, figures = args
    variant = {label: (sc, aid) for label, sc, aid in TETHER_AID_VARIANTS}.get(name)
    if variant is not None:      # a variant: metrics only
        sc = load_scenario(variant[0])
        sc = sc.replace(estimator=sc.estimator.replace(tether_aid=variant[1]))
        return name, run_scenario(sc, None, progress=None).metrics
    if OTHER_TRUTH_SEP in name:
        base = name.split(OTHER_TRUTH_SEP)[0]
        sc = load_scenario(base).with_tether_model(other_truth(base).value)
        return name, run_scenario(sc, None, progress=None).metrics
    out = Path(runs) / name
    result = run_scenario(load_scenario(name), out, progress=None)
    if figures:
        from tuav_sitl.render import draw_run

        draw_run(out, workers=0)     # the pool's processes already use the cores
    return name, result.metrics


def _fmt(v: Any) -> str:
    if v is None:
        return "–"
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


def _check(value: Any, op: str, limit: float) -> bool:
    return value is not None and (value <= limit if op == "<=" else value >= limit)


def checkout_results_path() -> Path | None:
    """``docs/results.md`` of the source checkout this package runs from (an editable
    install or a clone on the path: the folder above ``tuav_sitl/`` holds this project's
    ``pyproject.toml`` and ``docs/``), wherever the command is run; None for an installed
    package, which has no docs to write into."""
    root = Path(__file__).resolve().parent.parent
    project = root / "pyproject.toml"
    try:
        ours = project.is_file() and 'name = "tuav-sitl"' in project.read_text()
    except OSError:
        return None
    return root / "docs" / "results.md" if ours and (root / "docs").is_dir() else None


def run_sweeps(runs_dir: Path, workers: int | None = None, figures: bool = True) -> None:
    """Run every shipped sweep into ``runs_dir/sweeps/NAME`` (resuming what is there), and
    draw its figures there (``figures``) as ``tuav-sitl sweep`` does: the failures'
    figure goes into the results file."""
    import sys

    from tuav_sitl.sweep import load_sweep, run_sweep

    for name, path in sorted(shipped_sweeps().items()):
        sweep, sc = load_sweep(path)
        print(f"tuav-sitl results: sweep {name}, {sweep.runs} runs", file=sys.stderr)
        out = runs_dir / "sweeps" / name
        rows, _ = run_sweep(sweep, sc, out, workers=workers)
        if figures:
            from tuav_sitl.sweep_figures import make_sweep_figures

            make_sweep_figures(sweep, rows, out)


def sweep_section(runs_dir: Path, metrics: dict[str, dict[str, Any]],
                  fig_dir: Path | None = None) -> list[str]:
    """The shipped sweeps' summaries found in ``runs_dir/sweeps/NAME`` (a sweep not run
    there: the command and about how long it takes, from the scenario's wall time); with
    ``fig_dir``, each sweep's failures figure copied there and shown."""
    import json

    from tuav_sitl.sweep import load_sweep
    from tuav_sitl.sweep_summary import summary_text

    lines = ["", "## Sweeps", "",
             "Monte Carlo sweeps (`tuav-sitl sweep`, docs/usage.md): each run draws the "
             "plant's truth, the wind and the seeds; the controllers keep their nominal "
             "model. `tuav-sitl results --sweeps` runs them into `RUNS/sweeps/`."]
    for name, path in sorted(shipped_sweeps().items()):
        summary = runs_dir / "sweeps" / name / "summary.json"
        sweep, sc = load_sweep(path)
        if summary.is_file():
            text = summary_text(json.loads(summary.read_text()))
            lines += ["", *("##" + ln if ln.startswith("# ") else ln
                            for ln in text.rstrip("\n").split("\n"))]
            for kind, what in (("failures", "failures against the drawn parameters"),
                               ("envelope", "the envelope")):
                fig = summary.parent / "figures" / f"{kind}.png"
                if fig_dir is not None and fig.is_file():
                    fig_dir.mkdir(parents=True, exist_ok=True)
                    shutil.copyfile(fig, fig_dir / f"sweep-{name}-{kind}.png")
                    lines += ["", f"![sweep {name}: {what}](figures/sweep-{name}-{kind}.png)"]
            continue
        wall = metrics.get(sc.name, {}).get("wall_time_s")
        cores = os.cpu_count() or 1
        took = (f", about {sweep.runs * wall / cores / 60:.0f} min on {cores} cores (a "
                f"nominal run's {wall:.1f} s; failing runs take longer)" if wall else "")
        lines += ["", f"### sweep {name}: not run", "",
                  f"`tuav-sitl sweep {name} --out {runs_dir}/sweeps/{name}`: "
                  f"{sweep.runs} runs of {sc.name}{took}."]
    return lines


def _tether_aid_section(metrics: dict[str, dict[str, Any]]) -> list[str]:
    """The tether-aided navigation runs beside the same without tether aid."""
    lines = ["", "## Tether-aided navigation", "",
             "The winch's tether fix fused by the onboard filter (docs/estimation.md §10), "
             "beside the same runs with `[estimator] tether_aid = false`. During the GNSS "
             "loss: the truth's horizontal distance from its reference (max) and the "
             "estimate's from the truth (max); a failsafe is the EKF failsafe landing.", "",
             "| run | position RMSE [m] | estimate position RMSE [m] | loss: truth off "
             "reference, max [m] | loss: estimate off truth, max [m] | min slack [m] | "
             "items reached | landed and disarmed |", "|---|---|---|---|---|---|---|---|"]
    runs = ["hover-gnss-loss-calm", "hover-gnss-loss", "hover-gnss-loss, tether_aid = false",
            "mission-gnss-denied",
            "circle-gnss", "circle-gnss, tether_aid = false"]
    for n in runs:
        m = metrics.get(n)
        if m is None:
            continue
        items = m.get("items_reached")
        landed = m.get("landed_disarmed")
        lines.append("| " + " | ".join([
            n, _fmt(m["position_rmse_m"]), _fmt(m.get("estimate_position_rmse_m")),
            _fmt(m.get("gnss_loss_horizontal_error_max_m")),
            _fmt(m.get("gnss_loss_estimate_horizontal_error_max_m")),
            _fmt(m["min_tether_slack_m"]),
            "–" if items is None else ", ".join(f"#{i}" for i in items),
            "–" if landed is None else ("yes" if landed else "**no**")]) + " |")
    return lines


def _other_truth_section(metrics: dict[str, dict[str, Any]], names: list[str]) -> list[str]:
    """Each shipped scenario on its own truth beside the same on the other truth
    (:func:`other_truth`), with what fails there: the targets of :data:`TARGETS` and the
    every-scenario criteria (taut, on the ground, rotor saturation >= 1 %)."""
    lines = ["", "## On the other truth tether", "",
             "Each scenario again with the plant's other truth tether, the controllers "
             "unchanged: the catenary for a scenario on the lumped-mass line (the default "
             f"truth is the {DEFAULT_TRUTH_TETHER.value} line), the lumped line for one its "
             "file pins to the catenary (docs/model.md); the last column lists what fails "
             "there. On the catenary the paper's experiments fly the paper's own truth.", "",
             "| scenario | truth: shipped → other | position RMSE [m] | min slack [m] | "
             "on ground | max tension [N] | rotor saturation | fails on the other truth |",
             "|---|---|---|---|---|---|---|---|"]
    for n in names:
        label = other_truth_label(n)
        a, b = metrics[n], metrics[label]
        fails = [f"`{key}` {_fmt(b.get(key))}" for sc, key, op, limit, _ in TARGETS
                 if sc == n and not _check(b.get(key), op, limit)]
        if not b["min_tether_slack_m"] > 0.0:
            fails.append("taut")
        if b["tether_ground_contact_fraction"] > 0.0 and "items_reached" not in b:
            fails.append("on the ground")
        if b["motor_saturation_fraction"] >= 0.01:
            fails.append("saturation")
        if "items_reached" in b and not b.get("landed_disarmed"):
            fails.append("mission not landed")
        pairs = [f"{_fmt(a.get(k))} → {_fmt(b.get(k))}" for k in (
            "position_rmse_m", "min_tether_slack_m", "tether_ground_contact_fraction",
            "max_tension_n", "motor_saturation_fraction")]
        truths = f"{load_scenario(n).plant.tether.model} → {other_truth(n).value}"
        lines.append(f"| {n} | {truths} | {' | '.join(pairs)} | {', '.join(fails) or '–'} |")
    return lines


def write_results(out_md: Path, runs_dir: Path, figures: bool = True,
                  processes: int | None = None,
                  progress: TextIO | None = None) -> dict[str, dict[str, Any]]:
    """Run all shipped scenarios and write ``out_md``; returns the metrics by scenario
    (with the shipped sweeps' summaries found under ``runs_dir/sweeps``). A line on
    ``progress`` as each run (simulation, figures and animation) is done."""
    names = sorted(shipped_scenarios())
    wall = time.perf_counter()
    jobs = [*names, *(label for label, _, _ in TETHER_AID_VARIANTS),
            *(other_truth_label(n) for n in names)]
    metrics: dict[str, dict[str, Any]] = {}
    if progress is not None:
        progress.write(f"tuav-sitl results: {len(jobs)} runs"
                       f"{' with their figures and animations' if figures else ''}\n")
    with get_context("fork").Pool(processes or min(len(names), os.cpu_count() or 1)) as pool:
        for name, m in pool.imap_unordered(_one, [(n, str(runs_dir), figures) for n in jobs]):
            metrics[name] = m
            if progress is not None:
                progress.write(f"  [{len(metrics):2d}/{len(jobs)}] {name} done, "
                               f"{time.perf_counter() - wall:5.0f} s elapsed\n")
                progress.flush()
        # the workers leave on their own, not by the pool's SIGTERM (a SIGTERM handler in
        # this process, inherited by them, would keep one waiting on the queue's lock)
        pool.close()
        pool.join()
    wall = time.perf_counter() - wall
    fig_dir = out_md.parent / "figures"
    if figures:
        fig_dir.mkdir(parents=True, exist_ok=True)
        for name, files in FIGURES_FOR_DOCS.items():
            for f in files:
                src = runs_dir / name / "figures" / f
                if src.is_file():
                    shutil.copyfile(src, fig_dir / f"{name}-{f}")
    lines = [
        "# Results",
        "",
        "Produced by `tuav-sitl results` (runs every shipped scenario with `tuav-sitl run`",
        f"and writes this file); its {len(names)} scenarios, {len(jobs)} runs with the "
        f"variants below, took {wall:.0f} s of wall time on "
        f"{os.cpu_count()} cores ({platform.python_implementation()} "
        f"{platform.python_version()}, {platform.machine()}).",
        "Metric definitions: `docs/usage.md` and `tuav_sitl/offline_metrics.py: compute_metrics`.",
        "",
        _truths_text(names),
        "",
        "## Targets",
        "",
        "Each on the scenario's truth tether (the `truth` column), and beside it the same "
        "run on the other truth.",
        "",
        "| scenario | truth | target | value | limit | met | on the other truth |",
        "|---|---|---|---|---|---|---|",
    ]
    for sc, key, op, limit, text in TARGETS:
        v = metrics[sc].get(key)
        o = metrics[other_truth_label(sc)].get(key)
        lines.append(f"| {sc} | {load_scenario(sc).plant.tether.model} | {text} (`{key}`) | "
                     f"{_fmt(v)} | {op} {limit:g} | "
                     f"{'yes' if _check(v, op, limit) else '**no**'} | "
                     f"{other_truth(sc).value}: {_fmt(o)} "
                     f"({'met' if _check(o, op, limit) else '**not met**'}) |")
    lines += [
        "",
        "In every scenario: the tether is never taut (`min_tether_slack_m` > 0), never lies "
        "on the ground (`tether_ground_contact_fraction` = 0; a mission starts and ends on "
        "the ground, where it lies), and the rotors saturate less than 1 % of the time in "
        "flight:",
        "",
        "| scenario | truth | position RMSE [m] | max error [m] | attitude RMSE [rad] | "
        "tether-length RMSE [m] | min slack [m] | on ground | max tension [N] | "
        "rotor saturation | settling [s] | overshoot [%] | sim [s] | wall [s] |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for n in names:
        m = metrics[n]
        lines.append("| " + " | ".join([
            n, load_scenario(n).plant.tether.model, _fmt(m["position_rmse_m"]),
            _fmt(m["position_max_error_m"]),
            _fmt(m["attitude_rmse_rad"]), _fmt(m["tether_length_rmse_m"]),
            _fmt(m["min_tether_slack_m"]), _fmt(m["tether_ground_contact_fraction"]),
            _fmt(m["max_tension_n"]), _fmt(m["motor_saturation_fraction"]),
            _fmt(m["settling_time_s"]), _fmt(m["overshoot_percent"]),
            _fmt(m["sim_time_s"]), _fmt(m["wall_time_s"])]) + " |")
    lines += ["", "## Lyapunov functions once the reference is constant", "",
              "From docs/control.md §5, for each subsystem from when its reference is "
              "constant: the function's value then, its resolution floor, how long it "
              "stays above the floor (the span the count covers: a count over 0 s is no "
              "evidence), how often it rose above the floor and at all; beside it the "
              "same for the raw (uncompensated) errors' function, and the rises above the "
              "floor on the other truth. The proofs model the line as the quasi-static "
              "catenary: on the lumped line its waves, which they do not model, make the "
              "functions rise.", "",
              "| scenario | truth | loop | from [s] | V then | floor | above floor [s] | "
              "rises above floor | rises at all | raw V then | raw above floor [s] | raw "
              "rises above floor | on the other truth: rises above floor |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    loops = {"v_pos": "position", "v_att": "attitude", "v_win": "winder"}
    for n in names:
        ly = metrics[n].get("lyapunov")
        if not ly:
            continue
        other = metrics[other_truth_label(n)].get("lyapunov") or {}
        truths = f"{load_scenario(n).plant.tether.model} ({other_truth(n).value})"
        for k, loop in loops.items():
            r = ly[k]
            lines.append(f"| {n} | {truths} | {loop} | " + " | ".join(_fmt(r.get(c)) for c in (
                "from_s", "value_then", "floor", "above_floor_s", "increases",
                "increases_any", "raw_value_then", "raw_above_floor_s", "raw_increases"))
                + f" | {_fmt(other.get(k, {}).get('increases'))} |")
    wp = {n: metrics[n].get("waypoints_reached") for n in names
          if metrics[n].get("waypoints_reached")}
    if wp:
        lines += ["", "## Waypoints reached", ""]
        for n, items in wp.items():
            lines.append(f"- {n}: " + ", ".join(f"#{w['index']} at {w['t_s']:.1f} s"
                                                for w in items))
    est = [n for n in names if "estimate_position_rmse_m" in metrics[n]]
    if est:
        lines += ["", "## Flown on the onboard estimate", "",
                  "The companion's EKF on the plant's sensors (docs/estimation.md), beside "
                  "the same flight on the truth: tracking is truth minus reference, the "
                  "estimate's errors are estimate minus truth.", "",
                  "| scenario | GNSS | position RMSE [m] | estimate position RMSE [m] | "
                  "estimate velocity RMSE [m/s] | estimate attitude RMSE [rad] | "
                  "rotor saturation | min slack [m] |", "|---|---|---|---|---|---|---|---|"]
        shown: set[str] = set()
        for n in est:
            m = metrics[n]
            base = n.removesuffix("-rtk").removesuffix("-gnss")
            if (base in metrics and base not in shown
                    and "estimate_position_rmse_m" not in metrics[base]):
                shown.add(base)
                b = metrics[base]
                lines.append(f"| {base} | truth | {_fmt(b['position_rmse_m'])} | – | – | – | "
                             f"{_fmt(b['motor_saturation_fraction'])} | "
                             f"{_fmt(b['min_tether_slack_m'])} |")
            lines.append(f"| {n} | {m.get('gnss', '?')} | {_fmt(m['position_rmse_m'])} | "
                         f"{_fmt(m['estimate_position_rmse_m'])} | "
                         f"{_fmt(m['estimate_velocity_rmse_m_s'])} | "
                         f"{_fmt(m['estimate_attitude_rmse_rad'])} | "
                         f"{_fmt(m['motor_saturation_fraction'])} | "
                         f"{_fmt(m['min_tether_slack_m'])} |")
    lines += _tether_aid_section(metrics)
    lines += _other_truth_section(metrics, names)
    missions = {n: metrics[n] for n in names if "items_reached" in metrics[n]}
    if missions:
        lines += ["", "## Missions", "",
                  "Flown through the navigator from the ground, armed in AUTO "
                  "(docs/usage.md):", ""]
        for n, m in missions.items():
            reached = ", ".join(f"#{seq} at {t:.1f} s" for seq, t in
                                zip(m["items_reached"], m["items_reached_t_s"], strict=True))
            end = "landed and disarmed" if m["landed_disarmed"] else "NOT landed and disarmed"
            lines.append(f"- {n}: items reached {reached}; {end}")
    lines += sweep_section(runs_dir, metrics, fig_dir if figures else None)
    if figures:
        lines += ["", "## Figures", ""]
        from tuav_sitl.figures import FIGURE_CAPTIONS

        for name, files in FIGURES_FOR_DOCS.items():
            for f in files:
                if (fig_dir / f"{name}-{f}").is_file():
                    cap = FIGURE_CAPTIONS.get(f.removesuffix(".png"), f)
                    lines += [f"**{name}** — {cap}", "",
                              f"![{name} {f}](figures/{name}-{f})", ""]
    out_md.parent.mkdir(parents=True, exist_ok=True)
    out_md.write_text("\n".join(lines) + "\n")
    return metrics
