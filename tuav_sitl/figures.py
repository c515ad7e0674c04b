"""Figures of an offline run: the paper's plots, drawn from a run folder.

A run folder (:mod:`tuav_sitl.run_data`) holds ``timeseries.npz``, ``metrics.json`` and
``scenario.toml``. :func:`make_figures` reads it and writes one PNG per figure into its
``figures/`` sub-folder (skipping those whose series the run lacks, :data:`FIGURE_NEEDS`);
:func:`build_figures` does the drawing from the arrays and the
scenario alone and returns matplotlib :class:`~matplotlib.figure.Figure` objects (no pyplot
global state and no backend switch: a bare Figure renders with Agg when saved).
:data:`FIGURE_CAPTIONS` gives each figure's caption for the documentation.

This module is the registry: the names, captions and needs, and the files. The figures are
drawn by :mod:`tuav_sitl.figures_series` (time series) and :mod:`tuav_sitl.figures_3d` (the
3-D path and snapshots, whose scene :mod:`tuav_sitl.figure_scene` shares with the
animation) in the look of :mod:`tuav_sitl.figure_style`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from tuav_sitl.figures_3d import fig_path_3d, fig_snapshots
from tuav_sitl.figures_series import (
    fig_attitude_tracking,
    fig_errors,
    fig_estimate,
    fig_lyapunov,
    fig_position_tracking,
    fig_states,
    fig_tension_and_winder,
    fig_tether_length,
)
from tuav_sitl.run_data import has_data, load_run
from tuav_sitl.scenario import ScenarioParams

__all__ = [
    "FIGURE_CAPTIONS",
    "FIGURE_NAMES",
    "FIGURE_NEEDS",
    "build_figures",
    "make_figures",
    "missing_series",
    "save_figures",
]

#: Figure name (file stem) -> caption.
FIGURE_CAPTIONS: dict[str, str] = {
    "states": (
        "State evolution: the UAV's position x, y, z, its attitude (roll, pitch, yaw, in "
        "degrees) and the paid-out tether length L over time; dashed lines are the references "
        "(position reference, attitude command, desired length L-bar)."),
    "errors": (
        "Errors over time: position error (actual minus reference) per axis, attitude error "
        "(measured minus the filtered command, yaw wrapped to +-180 deg) and tether length "
        "error L - L-bar, taken at the instants the ground station updates L-bar (between "
        "updates the logged L-bar is held while L moves on)."),
    "position_tracking": (
        "Position tracking: the UAV's x, y and z (solid) against the reference trajectory "
        "(dashed)."),
    "attitude_tracking": (
        "Attitude tracking: measured roll, pitch and yaw (solid) against the attitude command "
        "after the command filter (dashed) and the position loop's desired attitude before "
        "the filter (dotted)."),
    "path_3d": (
        "3-D path of the UAV (solid) against the reference path (dashed), with the winder at "
        "the origin, the ground plane z = 0 and the tether drawn at a few instants (the "
        "lumped line's nodes as the run recorded them, the catenary on the catenary truth); "
        "equal scale on all three axes."),
    "tether_length": (
        "Tether length tracking: the desired length L-bar, the paid-out length L, the "
        "straight-line distance |p| from the winder to the UAV and the altitude z; the lengths "
        "stay above the distance, which stays above the altitude."),
    "snapshots": (
        "Snapshots of the flight at four instants: the quadrotor (drawn enlarged, with its "
        "attitude; red arms at the front), the tether from the winder (the lumped line's "
        "recorded nodes, the catenary on the catenary truth), the path flown so far "
        "(trail), and the goal, waypoints (filled once reached) or circle to track."),
    "lyapunov": (
        "Lyapunov functions of the position loop, the attitude loop (both in the compensated "
        "errors of command-filtered backstepping) and the winder loop on a logarithmic scale "
        "over time; docs/control.md proves each decays, and §5 says when its reference "
        "counts as constant."),
    "tension_and_winder": (
        "Tether tension at the UAV (top) and at the winder drum, the winder motor torque "
        "(dotted lines: its limits, when approached) and the drum rate over time; shaded "
        "spans, if any, are "
        "times when part of the tether lies on the ground."),
    "estimate": (
        "The onboard navigation filter against the truth: its position error (estimate "
        "minus truth) per axis with the filter's own 3-sigma band, and the horizontal "
        "speed error; runs flown on the estimate only."),
}
#: The figures :func:`build_figures` draws, in order.
FIGURE_NAMES: tuple[str, ...] = tuple(FIGURE_CAPTIONS)
#: Series a figure cannot do without (all of them): a run folder imported from
#: ``tuav-sitl up`` (:mod:`tuav_sitl.run_import`) has no reference, attitude command or
#: Lyapunov functions, which stay NaN; :func:`make_figures` skips these figures there.
FIGURE_NEEDS: dict[str, tuple[str, ...]] = {
    "errors": ("ref_pos", "att_cmd"),
    "position_tracking": ("ref_pos",),
    "attitude_tracking": ("att_cmd",),
    "lyapunov": ("v_pos", "v_att", "v_win"),
    "estimate": ("est_pos", "est_pos_sigma"),
}



def missing_series(series: Mapping[str, np.ndarray], name: str) -> list[str]:
    """The series the figure ``name`` needs (:data:`FIGURE_NEEDS`) that the run lacks."""
    return [k for k in FIGURE_NEEDS.get(name, ()) if not has_data(series, k)]


#: Figure name -> the function drawing it from (series, scenario, metrics).
_BUILDERS: dict[str, Callable[..., Figure]] = {
    "states": fig_states,
    "errors": fig_errors,
    "position_tracking": fig_position_tracking,
    "attitude_tracking": fig_attitude_tracking,
    "path_3d": fig_path_3d,
    "tether_length": fig_tether_length,
    "snapshots": fig_snapshots,
    "lyapunov": fig_lyapunov,
    "tension_and_winder": fig_tension_and_winder,
    "estimate": fig_estimate,
}


def build_figures(series: Mapping[str, np.ndarray], scenario: ScenarioParams,
                  names: Iterable[str] | None = None,
                  metrics: Mapping[str, Any] | None = None) -> dict[str, Figure]:
    """Draw the figures ``names`` (default: all of :data:`FIGURE_NAMES`) from a run's
    arrays and its scenario (and its metrics, used for the instants waypoints were reached
    if given); returns name -> Figure, nothing written."""
    chosen = FIGURE_NAMES if names is None else tuple(names)
    unknown = [n for n in chosen if n not in _BUILDERS]
    if unknown:
        raise ValueError(f"unknown figure(s) {unknown}; known: {', '.join(FIGURE_NAMES)}")
    if len(series["t"]) < 2:
        raise ValueError("the time series needs at least two samples")
    return {n: _BUILDERS[n](series, scenario, metrics) for n in chosen}


def save_figures(figures: Mapping[str, Figure], out_dir: Path) -> list[Path]:
    """Write each figure as ``out_dir/<name>.png``; returns the paths."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, fig in figures.items():
        path = out_dir / f"{name}.png"
        # zlib level 1: a fifth of level 6's encoding time for ~10 % more bytes
        fig.savefig(path, dpi=fig.dpi, pil_kwargs={"compress_level": 1})
        paths.append(path)
    return paths


def make_figures(run_dir: Path, names: Iterable[str] | None = None,
                 skipped: list[str] | None = None) -> list[Path]:
    """Read the run folder ``run_dir`` and write its figures into ``run_dir/figures/``;
    returns the PNG paths in :data:`FIGURE_NAMES` order. A figure whose data the run does
    not have (:func:`missing_series`) is not drawn; a one-line note on it is appended to
    ``skipped`` if given."""
    run = load_run(Path(run_dir))
    out = Path(run_dir) / "figures"
    paths: list[Path] = []
    for name in FIGURE_NAMES if names is None else tuple(names):
        lacking = missing_series(run.series, name) if name in _BUILDERS else []
        if lacking:
            if skipped is not None:
                skipped.append(f"{name}: the run has no {', '.join(lacking)}")
            continue
        # one figure at a time keeps memory low for long runs
        paths += save_figures(build_figures(run.series, run.scenario, [name], run.metrics), out)
    return paths


def main(argv: list[str] | None = None) -> int:
    """``python -m tuav_sitl.figures RUN_DIR [NAME ...]``: write the figures, list them."""
    import argparse
    import time

    p = argparse.ArgumentParser(description="Write the figures of an offline run.")
    p.add_argument("run_dir", type=Path)
    p.add_argument("names", nargs="*", help=f"figures (default all): {', '.join(FIGURE_NAMES)}")
    a = p.parse_args(argv)
    t0 = time.perf_counter()
    skipped: list[str] = []
    for path in make_figures(a.run_dir, a.names or None, skipped):
        print(path)
    for note in skipped:
        print(f"skipped {note}")
    print(f"{time.perf_counter() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
