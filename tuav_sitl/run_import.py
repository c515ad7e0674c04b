"""Importing a ``tuav-sitl up`` run folder, so that ``tuav-sitl plot`` draws it.

A run folder of ``tuav-sitl up`` (``runs/up-STAMP-I/``) holds what the three processes
recorded, not the offline runner's time series: ``truth.csv`` (the plant's truth, every 5th
control period), ``params.toml`` (the system parameters used), ``flight.tlog`` (every MAVLink
frame to and from the ground stations, wall-clock stamped), ``can.log`` (the winder's bus in
``candump -L`` format, wall-clock stamped) and the processes' logs. :func:`import_up_run`
turns these into the files :mod:`tuav_sitl.figures` and :mod:`tuav_sitl.animation` read:

- ``timeseries.npz`` with every column of :data:`tuav_sitl.offline.SERIES`, at the truth's
  instants (SI units, z-up frame, angles in rad), as :func:`tuav_sitl.up_series.build_series`
  makes them from the truth, with ``winder_torque`` [N m] from ``can.log``
  (:func:`tuav_sitl.up_series.read_can_torque`, held between frames, NaN without a CAN log).
  Extra columns: ``armed`` (0/1), and from the tlog's ``WINCH_STATUS`` (component 169)
  ``winch_length`` [m], ``winch_speed`` [m/s, + paying out], ``winch_tension`` [N]
  (the message's kilograms times gravity), held between messages, NaN before the first.
- ``metrics.json`` with what the run supports
  (:func:`tuav_sitl.up_series.compute_up_metrics`), and the import's wall time [s], the
  files it read and its notes;
- ``scenario.toml``: the run's parameters as a :class:`~tuav_sitl.scenario.ScenarioParams`
  (system parameters from ``params.toml``, the run's start as ``[initial]``) whose
  ``[trajectory]`` carries the goals the vehicle was sent to, for drawing: the waypoints of
  the mission it flew (``MISSION_ITEM_REACHED`` in the tlog), else the guided targets it
  accepted (``NAV_TAKEOFF``, ``DO_REPOSITION``, ``SET_POSITION_TARGET_*``;
  :mod:`tuav_sitl.tlog_read`). It describes the run; it is not an experiment the offline
  runner would reproduce.

The tlog's and the CAN log's wall-clock stamps are put on the truth's simulated clock
through the vehicle's telemetry (:mod:`tuav_sitl.clock_pairing`).
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from companion.navigation import NavigationParams
from sitl.truth_log import TRUTH_COLUMNS
from tuav_sitl.offline import _to_toml
from tuav_sitl.scenario import (
    InitialParams,
    ScenarioParams,
    TrajectoryParams,
    WaypointParams,
)
from tuav_sitl.tlog_read import Goal, TlogData, read_tlog
from tuav_sitl.up_series import build_series, compute_up_metrics, held, read_can_torque
from tuavdefs.params import SystemParams
from tuavdefs.paramspec import ParameterError, load_toml, to_dict

__all__ = [
    "SOURCES",
    "ImportResult",
    "RunImportError",
    "import_up_run",
    "is_up_run",
    "needs_import",
    "read_truth",
]

#: The files an up run's import reads (all but truth.csv optional).
SOURCES = ("truth.csv", "params.toml", "flight.tlog", "can.log", "companion.parm")


class RunImportError(RuntimeError):
    """An up run folder that cannot be imported, said in one line."""


# --------------------------------------------------------------------------------------
# Detection


def is_up_run(run_dir: Path) -> bool:
    """Whether ``run_dir`` is a ``tuav-sitl up`` run folder (it has ``truth.csv``)."""
    return (Path(run_dir) / "truth.csv").is_file()


def needs_import(run_dir: Path) -> bool:
    """Whether ``run_dir`` is an up run folder without an up-to-date ``timeseries.npz``
    (none yet, or older than one of its :data:`SOURCES`)."""
    run_dir = Path(run_dir)
    if not is_up_run(run_dir):
        return False
    npz = run_dir / "timeseries.npz"
    if not npz.is_file():
        return True
    made = npz.stat().st_mtime
    return any((run_dir / name).is_file() and (run_dir / name).stat().st_mtime > made
               for name in SOURCES)


# --------------------------------------------------------------------------------------
# truth.csv


def read_truth(path: Path) -> dict[str, np.ndarray]:
    """The plant's truth log as columns (the names of ``sitl.truth_log.TRUTH_COLUMNS``; SI
    units, z-up frame, angles [rad]). A last line cut short (the plant stopped while
    writing) and unreadable lines are left out."""
    path = Path(path)
    text = path.read_text()
    lines = text.splitlines()
    if not lines:
        raise RunImportError(f"{path} is empty")
    header = [h.strip() for h in lines[0].split(",")]
    missing = [c for c in TRUTH_COLUMNS if c not in header]
    if missing:
        raise RunImportError(f"{path}: no column(s) {', '.join(missing)}")
    body = lines[1:]
    if body and not text.endswith("\n"):
        body = body[:-1]  # written up to the flush, not to the end of the line
    rows: list[list[float]] = []
    for line in body:
        parts = line.split(",")
        if len(parts) != len(header):
            continue
        try:
            rows.append([float(p) for p in parts])
        except ValueError:
            continue
    if len(rows) < 2:
        raise RunImportError(f"{path}: needs at least two samples, has {len(rows)}")
    data = np.array(rows, dtype=float)
    cols = {name: np.ascontiguousarray(data[:, i]) for i, name in enumerate(header)}
    order = np.argsort(cols["t_s"], kind="stable")
    if np.any(np.diff(order) != 1):
        cols = {k: v[order] for k, v in cols.items()}
    return cols


# --------------------------------------------------------------------------------------
# The import


@dataclass
class ImportResult:
    """What :func:`import_up_run` wrote, and what it could not do."""

    written: list[Path]
    series: dict[str, np.ndarray]
    metrics: dict[str, Any]
    scenario: ScenarioParams
    tlog: TlogData | None
    notes: list[str]


def _acceptance_radius_m(run_dir: Path) -> float:
    """The companion's waypoint acceptance radius [m]: ``WPNAV_RADIUS`` [cm] of
    ``companion.parm`` if set there, else its default."""
    radius = NavigationParams().acceptance_radius_m
    parm = run_dir / "companion.parm"
    if parm.is_file():
        for line in parm.read_text().splitlines():
            parts = line.replace(",", " ").split()
            if len(parts) >= 2 and parts[0] == "WPNAV_RADIUS":
                try:
                    value = float(parts[1]) / 100.0
                except ValueError:
                    continue
                if value > 0 and math.isfinite(value):
                    radius = value
    return radius


def _scenario(run_dir: Path, s: dict[str, np.ndarray], params: SystemParams,
              goals: list[Goal], acceptance_m: float) -> ScenarioParams:
    """The run as a scenario, for drawing: its system parameters, its start (the first
    truth sample's position [m] and yaw [rad]), its duration [s] and a trajectory through
    ``goals`` (hold with none, a set point with one, waypoints with more) with the
    waypoint acceptance radius ``acceptance_m`` [m]."""
    t = s["t"]
    trajectory = TrajectoryParams(kind="hold", acceptance_radius_m=acceptance_m)
    if len(goals) == 1:
        trajectory = trajectory.replace(kind="setpoint", goal_m=goals[0].pos_m)
    elif goals:
        trajectory = trajectory.replace(kind="waypoints", waypoints=tuple(
            WaypointParams(position_m=g.pos_m) for g in goals))
    return ScenarioParams.nominal(
        name=run_dir.name,
        description=("a 'tuav-sitl up' run imported by tuav_sitl.run_import (truth.csv, "
                     "flight.tlog, can.log); the trajectory holds the goals the vehicle was "
                     "sent to, for drawing: not an experiment to run offline"),
        duration_s=max(float(t[-1]), 1e-3),
        initial=InitialParams(position_m=tuple(float(v) for v in s["pos"][0]),
                              yaw_rad=float(s["euler"][0, 2])),
        trajectory=trajectory,
        environment=params.environment, vehicle=params.vehicle, tether=params.tether,
        winder=params.winder, wind=params.wind)


def import_up_run(run_dir: Path) -> ImportResult:
    """Build ``timeseries.npz``, ``metrics.json`` and ``scenario.toml`` in the up run folder
    ``run_dir`` from its ``truth.csv``, ``params.toml``, ``flight.tlog`` and ``can.log``
    (all but ``truth.csv`` optional: what is missing is said in the notes)."""
    run_dir = Path(run_dir)
    t0 = time.perf_counter()
    notes: list[str] = []
    truth = read_truth(run_dir / "truth.csv")
    params_file = run_dir / "params.toml"
    if params_file.is_file():
        try:
            params = load_toml(SystemParams, params_file)
        except ParameterError as exc:
            raise RunImportError(f"{params_file}: bad parameter: {exc}") from None
    else:
        params = SystemParams()
        notes.append("no params.toml: the default system parameters are assumed")
    s = build_series(truth, params)
    g = params.environment.gravity_m_s2

    tlog: TlogData | None = None
    tlog_file = run_dir / "flight.tlog"
    if tlog_file.is_file():
        tlog = read_tlog(tlog_file, s["t"], s["pos"])
        notes += tlog.notes
        s["winch_length"] = held(s["t"], tlog.winch_t_s, tlog.winch_length_m)
        s["winch_speed"] = held(s["t"], tlog.winch_t_s, tlog.winch_speed_m_s)
        s["winch_tension"] = held(s["t"], tlog.winch_t_s, tlog.winch_tension_kg * g)
    else:
        notes.append("no flight.tlog: no goals, waypoints reached or winch status")

    can_file = run_dir / "can.log"
    if not can_file.is_file():
        notes.append("no can.log: no winder torque")
    elif tlog is None or len(tlog.clock) < 2:
        notes.append("can.log not used: its frames cannot be timed without the tlog's "
                     "telemetry")
    else:
        t_can, torque, untimed = read_can_torque(can_file, tlog.clock)
        if len(t_can):
            s["winder_torque"] = held(s["t"], t_can, torque)
        else:
            notes.append("can.log has no Set_Input_Torque frame within the telemetry's span")
        if untimed:
            notes.append(f"{untimed} Set_Input_Torque frames outside the telemetry's span "
                         "left out")

    goals: list[Goal] = []
    if tlog is not None:
        goals = tlog.mission_goals or tlog.guided_goals
    scenario = _scenario(run_dir, s, params, goals, _acceptance_radius_m(run_dir))
    metrics = compute_up_metrics(s, params, tlog, scenario.name)
    metrics["wall_time_s"] = round(time.perf_counter() - t0, 3)
    metrics["imported_from"] = [n for n in SOURCES if (run_dir / n).is_file()]
    metrics["notes"] = notes

    written = []
    npz = run_dir / "timeseries.npz"
    np.savez_compressed(npz, **s)
    written.append(npz)
    mj = run_dir / "metrics.json"
    mj.write_text(json.dumps(metrics, indent=2) + "\n")
    written.append(mj)
    sc_file = run_dir / "scenario.toml"
    sc_file.write_text(_to_toml(to_dict(scenario)))
    written.append(sc_file)
    return ImportResult(written, s, metrics, scenario, tlog, notes)


def main(argv: list[str] | None = None) -> int:
    """``python -m tuav_sitl.run_import RUN_DIR``: import an up run folder, list the files."""
    import argparse

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("run_dir", type=Path)
    a = p.parse_args(argv)
    res = import_up_run(a.run_dir)
    for path in res.written:
        print(path)
    for note in res.notes:
        print(f"note: {note}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
