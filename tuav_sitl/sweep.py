"""``tuav-sitl sweep``: Monte Carlo over a scenario, on Dask distributed.

A sweep file names a scenario and draws, for each run, quantities of the plant's truth
(mass, inertia, thrust coefficient, tether density and drag, the tether's attachment), the
wind (speed, direction, turbulence, a gust), the sensors' preset and every run's seeds from
their distributions (uniform, normal, choice). Each run is one offline run
(:func:`tuav_sitl.offline.run_scenario`, as ``tuav-sitl run`` does, without figures) on a
Dask worker: a ``LocalCluster`` on this machine by default, or an existing cluster's
scheduler. The drawn values of run ``i`` depend only on the sweep's seed and ``i``, so a
sweep is reproducible and an interrupted one resumes: every finished run is appended to
``runs.csv`` as it arrives, and the runs already there are not run again. At the end the
table is also written as ``runs.json``, with ``summary.json`` (failures by kind, the failure
rate with its exact binomial confidence interval, the metrics' percentiles, what the
failures correlate with) and its text (``summary.md``). The file format is in
docs/usage.md.
"""

from __future__ import annotations

import csv
import enum
import json
import logging
import math
import sys
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from sitl.faults import NEVER_S, FaultParams
from tuav_sitl.offline_metrics import GROUND_REGIMES
from tuav_sitl.scenario import ScenarioParams, load_scenario
from tuavdefs.params import GustParams, TetherModel
from tuavdefs.paramspec import ParameterError, Params, load_toml, quantity, toml_line


class Quantity(enum.Enum):
    """What a sweep may draw. ``*_factor`` multiplies the scenario's truth; the others are
    absolute values."""

    MASS_FACTOR = "mass_factor"                    #: vehicle mass
    INERTIA_FACTOR = "inertia_factor"              #: all three moments of inertia
    THRUST_COEFF_FACTOR = "thrust_coeff_factor"    #: the rotors' thrust coefficient
    TETHER_DENSITY_FACTOR = "tether_density_factor"  #: the tether's mass per length
    TETHER_DRAG_FACTOR = "tether_drag_factor"      #: the tether's drag coefficients (lumped)
    ATTACHMENT_X_M = "attachment_x_m"              #: tether attachment, body x [m]
    ATTACHMENT_Y_M = "attachment_y_m"              #: tether attachment, body y [m]
    ATTACHMENT_Z_M = "attachment_z_m"              #: tether attachment, body z [m]
    WIND_SPEED_M_S = "wind_speed_m_s"              #: mean wind at its reference height [m/s]
    WIND_DIRECTION_DEG = "wind_direction_deg"      #: where it blows from, from north [deg]
    TURBULENCE = "turbulence"                      #: Dryden intensity (a label)
    GUST_SPEED_M_S = "gust_speed_m_s"              #: one (1 - cos) gust along the wind [m/s]
    GUST_START_S = "gust_start_s"                  #: when that gust begins [s]
    GNSS = "gnss"                                  #: the GNSS receiver's preset (a label)
    TETHER_MODEL = "tether_model"                  #: the truth's line model (a label)

    @property
    def is_label(self) -> bool:
        """Whether its values are labels (drawn only by ``choice``)."""
        return self in (Quantity.TURBULENCE, Quantity.GNSS, Quantity.TETHER_MODEL)

    @property
    def bounds(self) -> tuple[float, float]:
        """The values it may take (a normal draw outside them is drawn again)."""
        if self.value.endswith("_factor"):
            return (0.05, 20.0)
        if self in (Quantity.WIND_SPEED_M_S, Quantity.GUST_SPEED_M_S, Quantity.GUST_START_S):
            return (0.0, 1e6)
        if self is Quantity.WIND_DIRECTION_DEG:
            return (-1e6, 1e6)
        return (-2.0, 2.0)   # attachment offsets [m]


class Distribution(enum.Enum):
    """How a quantity is drawn."""

    UNIFORM = "uniform"   #: uniform in [low, high]
    NORMAL = "normal"     #: normal (mean, std), drawn again outside the quantity's bounds
    CHOICE = "choice"     #: one of values (numbers) or labels, equally likely


class FailureKind(enum.Enum):
    """Why a run fails its targets."""

    TAUT = "taut"                        #: the tether went straight (slack at or below target)
    GROUND_CONTACT = "ground_contact"    #: the tether touched the ground in flight
    SATURATION = "saturation"            #: the rotors saturated more often than allowed
    DIVERGED = "diverged"                #: the position error grew beyond bounds
    CRASHED = "crashed"                  #: the vehicle came down to the ground in flight
    TILTED = "tilted"                    #: the vehicle tilted beyond its bound (attitude lost)
    TRACKING = "tracking"                #: the position RMSE is above its target
    REFUSED = "refused"                  #: its drawn system was refused (a bad parameter)
    ERROR = "error"                      #: the run raised (e.g. no hover trim exists)


@dataclass(frozen=True)
class VaryParams(Params):
    """One drawn quantity: its distribution and the distribution's parameters."""

    parameter: str = quantity("mass_factor", "", "what is drawn",
                             choices=tuple(q.value for q in Quantity))
    distribution: str = quantity("uniform", "", "uniform, normal or choice",
                                 choices=tuple(d.value for d in Distribution))
    low: float = quantity(0.0, "", "uniform: lower bound (the quantity's unit)")
    high: float = quantity(0.0, "", "uniform: upper bound")
    mean: float = quantity(0.0, "", "normal: mean")
    std: float = quantity(0.0, "", "normal: standard deviation", ge=0)
    values: tuple[float, ...] = quantity((), "", "choice: the numbers drawn from")
    labels: tuple[str, ...] = quantity((), "", "choice: the labels drawn from (turbulence: "
                                       "none, light, moderate, severe; gnss: rtk, gnss)")

    @property
    def kind(self) -> Quantity:
        """:attr:`parameter` as its enum."""
        return Quantity(self.parameter)

    @property
    def dist(self) -> Distribution:
        """:attr:`distribution` as its enum."""
        return Distribution(self.distribution)

    def check(self) -> None:
        q, d = self.kind, self.dist
        lo, hi = q.bounds
        if q.is_label and d is not Distribution.CHOICE:
            raise ValueError(f"distribution: {q.value} is a label: only choice draws it")
        if d is Distribution.UNIFORM:
            if not self.low < self.high:
                raise ValueError("high: must be above low")
            if self.low < lo or self.high > hi:
                raise ValueError(f"low: {q.value} must stay within [{lo}, {hi}]")
        elif d is Distribution.NORMAL:
            if not self.std > 0:
                raise ValueError("std: must be > 0")
            if not lo <= self.mean <= hi:
                raise ValueError(f"mean: {q.value} must be within [{lo}, {hi}]")
        elif q.is_label:
            allowed = _LABELS[q]
            if not self.labels:
                raise ValueError("labels: a choice of labels needs at least one")
            for i, v in enumerate(self.labels):
                if v not in allowed:
                    raise ValueError(f"labels[{i}]: must be one of {', '.join(allowed)}; "
                                     f"got {v!r}")
        else:
            if not self.values:
                raise ValueError("values: a choice needs at least one value")
            for i, v in enumerate(self.values):
                if not lo <= v <= hi:
                    raise ValueError(f"values[{i}]: must be within [{lo}, {hi}], got {v}")

    def draw(self, rng: np.random.Generator) -> float | str:
        """One value."""
        d = self.dist
        if d is Distribution.UNIFORM:
            return float(rng.uniform(self.low, self.high))
        if d is Distribution.NORMAL:
            lo, hi = self.kind.bounds
            for _ in range(1000):
                v = float(rng.normal(self.mean, self.std))
                if lo <= v <= hi:
                    return v
            return min(max(self.mean, lo), hi)
        options = self.labels if self.kind.is_label else self.values
        return options[int(rng.integers(len(options)))]


_LABELS: dict[Quantity, tuple[str, ...]] = {
    Quantity.TURBULENCE: ("none", "light", "moderate", "severe"),
    Quantity.GNSS: ("rtk", "gnss"),
    Quantity.TETHER_MODEL: tuple(m.value for m in TetherModel),
}


@dataclass(frozen=True)
class FaultDrawParams(Params):
    """A fault a run may have: the fault (a scenario's ``[[faults]]`` entry: its kind and
    settings), the chance that a run has it, and its start and duration drawn uniformly."""

    fault: FaultParams = quantity(FaultParams(), "", "the fault: kind and settings (its "
                                  "start_s and end_s are drawn)")
    probability: float = quantity(1.0, "1", "chance that a run has it", ge=0, le=1)
    start_low_s: float = quantity(0.0, "s", "its start: uniform from", ge=0)
    start_high_s: float = quantity(0.0, "s", "its start: uniform to", ge=0)
    duration_low_s: float = quantity(0.0, "s", "its duration: uniform from (both 0: to the "
                                     "end of the run)", ge=0)
    duration_high_s: float = quantity(0.0, "s", "its duration: uniform to", ge=0)

    def check(self) -> None:
        if self.start_high_s < self.start_low_s:
            raise ValueError("start_high_s: must be at least start_low_s")
        if self.duration_high_s < self.duration_low_s:
            raise ValueError("duration_high_s: must be at least duration_low_s")
        if self.duration_high_s > 0 and not self.duration_low_s > 0:
            raise ValueError("duration_low_s: must be > 0 (or both 0: to the end)")

    def columns(self, i: int) -> tuple[str, str]:
        """The table's columns of fault ``i``: its start and end [s] (empty: not drawn)."""
        name = f"fault{i}_{self.fault.kind}"
        return f"{name}_start_s", f"{name}_end_s"

    def draw(self, rng: np.random.Generator) -> tuple[float, float] | None:
        """(start, end) [s] of the fault in one run, or None if the run does not have it;
        three numbers from ``rng`` whatever the outcome (later draws do not depend on it)."""
        u, a, b = rng.random(3)
        if not u < self.probability:
            return None
        start = self.start_low_s + a * (self.start_high_s - self.start_low_s)
        if self.duration_high_s == 0:
            return float(start), NEVER_S
        return float(start), float(start + self.duration_low_s
                                   + b * (self.duration_high_s - self.duration_low_s))

    def params(self, start_s: float, end_s: float) -> FaultParams:
        """The fault from ``start_s`` to ``end_s`` [s]."""
        return self.fault.replace(start_s=start_s, end_s=end_s)


@dataclass(frozen=True)
class TargetParams(Params):
    """What a run must achieve; a run that misses one fails with that kind."""

    position_rmse_m: float = quantity(0.05, "m", "tracking: position RMSE at most", gt=0)
    min_tether_slack_m: float = quantity(
        0.0, "m", "taut: the tether's least slack (length - distance) must stay above")
    ground_contact_fraction: float = quantity(
        0.0, "1", "ground contact: fraction of the run the tether may touch the ground",
        ge=0, le=1)
    motor_saturation_fraction: float = quantity(
        0.01, "1", "saturation: fraction of the flight the rotors may saturate", ge=0, le=1)
    diverged_error_m: float = quantity(
        2.0, "m", "diverged: the position error may never exceed", gt=0)
    max_tilt_deg: float = quantity(
        45.0, "deg", "tilted: the vehicle's tilt in flight may never exceed (beyond the "
        "position loop's own 35 deg limit: the attitude is lost)", gt=0, le=180)


@dataclass(frozen=True)
class EnvelopeParams(Params):
    """The envelope over one drawn quantity (the summary's table by its bins and the
    values where each limit is first passed)."""

    over: str = quantity("", "", "the drawn quantity (uniform or normal) the envelope is "
                         "read over (empty: no envelope)",
                         choices=("", *(q.value for q in Quantity if not q.is_label)))
    bin_width: float = quantity(1.0, "", "width of the table's bins (the quantity's unit)",
                                gt=0)
    pull_limit_n: float = quantity(35.0, "N", "the pull at the UAV's limit (its peak in "
                                   "flight)", gt=0)
    saturation_limit_fraction: float = quantity(
        0.01, "1", "the rotors' saturation limit (fraction of the flight)", ge=0, le=1)

    @property
    def quantity(self) -> Quantity | None:
        """:attr:`over` as its enum (None: no envelope)."""
        return Quantity(self.over) if self.over else None


@dataclass(frozen=True)
class SweepParams(Params):
    """A Monte Carlo sweep over a scenario."""

    name: str = quantity("sweep", "", "short name (the default output folder)")
    description: str = quantity("", "", "what the sweep asks")
    scenario: str = quantity("circle", "", "a shipped scenario or a scenario file (relative "
                             "to the sweep file)")
    runs: int = quantity(100, "1", "number of runs", ge=1, le=1_000_000)
    seed: int = quantity(0, "1", "seed of every draw", ge=0)
    duration_s: float = quantity(0.0, "s", "simulated time of each run (0: the scenario's)",
                                 ge=0)
    seeds: bool = quantity(True, "", "each run its own seed of the sensors and the wind's "
                           "turbulence (false: the scenario's)")
    targets: TargetParams = quantity(TargetParams(), "", "the targets a run must meet")
    envelope: EnvelopeParams = quantity(EnvelopeParams(), "", "the envelope the summary "
                                        "reads over a drawn quantity")
    vary: tuple[VaryParams, ...] = quantity((), "", "the drawn quantities")
    faults: tuple[FaultDrawParams, ...] = quantity((), "", "the drawn faults (added to the "
                                                   "scenario's own)")

    def check(self) -> None:
        seen: set[str] = set()
        for i, v in enumerate(self.vary):
            if v.parameter in seen:
                raise ValueError(f"vary[{i}].parameter: {v.parameter} is drawn twice")
            seen.add(v.parameter)
        over = self.envelope.over
        if over and not any(v.parameter == over and v.dist is not Distribution.CHOICE
                            for v in self.vary):
            raise ValueError(f"envelope.over: {over} is not drawn uniform or normal")


def shipped_sweeps() -> dict[str, Path]:
    """Name -> path of the sweep files shipped with the package (``tuav_sitl/sweeps``)."""
    folder = resources.files("tuav_sitl") / "sweeps"
    return {Path(str(p)).stem: Path(str(p)) for p in folder.iterdir()
            if str(p).endswith(".toml")}


def sweep_path(name_or_path: str | Path) -> Path:
    """The file of a shipped sweep by name (``robustness``), or a sweep TOML file by path,
    as :func:`tuav_sitl.scenario.load_scenario` takes scenarios. ParameterError for neither,
    naming the shipped sweeps."""
    shipped = shipped_sweeps()
    if str(name_or_path) in shipped:
        return shipped[str(name_or_path)]
    path = Path(name_or_path)
    if not path.is_file():
        raise ParameterError(str(name_or_path), "no such sweep: give a sweep file or one of "
                             + ", ".join(sorted(shipped)))
    return path


def load_sweep(name_or_path: str | Path) -> tuple[SweepParams, ScenarioParams]:
    """A shipped sweep by name, or a sweep file by path, and its scenario (with the
    sweep's duration). ParameterError names the bad field (``robustness.vary[0].high:
    ...``), or the shipped sweeps for a name that is neither."""
    path = sweep_path(name_or_path)
    sweep = load_toml(SweepParams, path)
    name = sweep.scenario
    candidate = path.parent / name
    sc = load_scenario(str(candidate) if candidate.is_file() else name)
    if sweep.duration_s > 0:
        if sc.metrics_after_s >= sweep.duration_s:
            raise ParameterError(f"{path.stem}.duration_s", "must be above the scenario's "
                                 f"metrics_after_s ({sc.metrics_after_s} s)", source=str(path),
                                 line=toml_line(path.read_text(), ("duration_s",)))
        sc = sc.replace(duration_s=sweep.duration_s)
    return sweep, sc


# --- the draws and the scenario of one run ---------------------------------------------

def draw(sweep: SweepParams, index: int) -> tuple[int, dict[str, float | str | None]]:
    """Run ``index``'s seed and drawn values (by quantity name, then each drawn fault's
    start and end by column, None where the run does not have it): a function of the
    sweep's seed and ``index`` only."""
    rng = np.random.default_rng([sweep.seed, index])
    seed = int(rng.integers(0, 2**31 - 1))
    drawn: dict[str, float | str | None] = {v.parameter: v.draw(rng) for v in sweep.vary}
    for i, f in enumerate(sweep.faults):
        when = f.draw(rng)
        start, end = f.columns(i)
        drawn[start], drawn[end] = when if when is not None else (None, None)
    return seed, drawn


_QUANTITIES = frozenset(q.value for q in Quantity)


def apply(sc: ScenarioParams, seed: int | None, drawn: dict[str, float | str | None],
          faults: tuple[FaultDrawParams, ...] = ()) -> ScenarioParams:
    """``sc`` with the drawn truth, wind and sensors, the drawn ``faults`` that the run has
    (their times in ``drawn``) added to its own, and, if ``seed`` is given, the sensors'
    and the turbulence's seed."""
    plant = sc.plant
    veh, teth, wind, sensors = plant.vehicle, plant.tether, sc.wind, sc.sensors
    d = {Quantity(k): v for k, v in drawn.items() if k in _QUANTITIES}
    if (f := d.get(Quantity.MASS_FACTOR)) is not None:
        veh = veh.replace(mass_kg=veh.mass_kg * f)
    if (f := d.get(Quantity.INERTIA_FACTOR)) is not None:
        veh = veh.replace(ixx_kg_m2=veh.ixx_kg_m2 * f, iyy_kg_m2=veh.iyy_kg_m2 * f,
                          izz_kg_m2=veh.izz_kg_m2 * f)
    if (f := d.get(Quantity.THRUST_COEFF_FACTOR)) is not None:
        veh = veh.replace(rotor_thrust_coeff=veh.rotor_thrust_coeff * f)
    att = list(veh.tether_attachment_m)
    for i, q in enumerate((Quantity.ATTACHMENT_X_M, Quantity.ATTACHMENT_Y_M,
                           Quantity.ATTACHMENT_Z_M)):
        if q in d:
            att[i] = float(d[q])
    veh = veh.replace(tether_attachment_m=tuple(att))
    if Quantity.TETHER_MODEL in d:
        teth = teth.replace(model=str(d[Quantity.TETHER_MODEL]))
    if (f := d.get(Quantity.TETHER_DENSITY_FACTOR)) is not None:
        teth = teth.replace(linear_density_kg_m=teth.linear_density_kg_m * f)
    if (f := d.get(Quantity.TETHER_DRAG_FACTOR)) is not None:
        teth = teth.replace(normal_drag_coeff=teth.normal_drag_coeff * f,
                            tangential_drag_coeff=teth.tangential_drag_coeff * f)
    # the mean wind: drawn speed and direction, else the scenario's (from the west when
    # it has none)
    sx, sy, sz = wind.steady_m_s
    speed = math.hypot(sx, sy)
    from_rad = math.atan2(-sx, -sy) if speed > 0 else math.radians(270.0)
    speed = float(d.get(Quantity.WIND_SPEED_M_S, speed))
    if Quantity.WIND_DIRECTION_DEG in d:
        from_rad = math.radians(float(d[Quantity.WIND_DIRECTION_DEG]))
    toward = (-math.sin(from_rad), -math.cos(from_rad))   # (east, north)
    wind = wind.replace(steady_m_s=(speed * toward[0], speed * toward[1], sz))
    if Quantity.TURBULENCE in d:
        wind = wind.replace(turbulence=str(d[Quantity.TURBULENCE]))
    if Quantity.GUST_SPEED_M_S in d or Quantity.GUST_START_S in d:
        span = sc.duration_s - sc.metrics_after_s
        start = float(d.get(Quantity.GUST_START_S, sc.metrics_after_s + 0.5 * span))
        amp = float(d.get(Quantity.GUST_SPEED_M_S, 3.0))
        wind = wind.replace(gusts=(*wind.gusts, GustParams(
            start_s=start, duration_s=2.0, amplitude_m_s=(amp * toward[0], amp * toward[1],
                                                          0.0))))
    if Quantity.GNSS in d:
        sensors = sensors.replace(gnss=str(d[Quantity.GNSS]))
    if seed is not None:
        sensors = sensors.replace(seed=seed)
        wind = wind.replace(seed=seed)
    extra = []
    for i, f in enumerate(faults):
        start, end = (drawn.get(c) for c in f.columns(i))
        if start is not None and end is not None:
            extra.append(f.params(float(start), float(end)))
    return sc.replace(plant=plant.replace(vehicle=veh, tether=teth), wind=wind,
                      sensors=sensors, faults=(*sc.faults, *extra))


def run_scenario_of(sweep: SweepParams, sc: ScenarioParams, index: int) -> ScenarioParams:
    """The scenario run ``index`` flies."""
    seed, drawn = draw(sweep, index)
    return apply(sc, seed if sweep.seeds else None, drawn, sweep.faults)


# --- one run and its row --------------------------------------------------------------

#: The sweep's own metrics of a row (:func:`flight_metrics`).
OWN_COLUMNS = ("min_height_flying_m", "tension_peak_flying_n", "tension_p99_flying_n",
               "taut_time_s", "ground_flying_s", "max_tilt_deg")
#: The metrics of a row: metrics.json's scalar fields, then the sweep's own.
METRIC_COLUMNS = (
    "position_rmse_m", "position_max_error_m", "attitude_rmse_rad", "tether_length_rmse_m",
    "tether_length_max_error_m", "min_tether_slack_m", "max_tension_n",
    "max_drum_tension_n", "tether_ground_contact_fraction", "motor_saturation_fraction",
    "position_loop_saturation_fraction", "estimate_position_rmse_m",
    "estimate_velocity_rmse_m_s", "estimate_attitude_rmse_rad", "settling_time_s",
    "overshoot_percent", "sim_time_s", "wall_time_s", *OWN_COLUMNS)

#: Height above the gear from which the vehicle counts as flying for the sweep's own
#: metrics (a mission's take-off and touch-down below it do not count) [m].
FLYING_ABOVE_GEAR_M = 0.5


def failures(sc: ScenarioParams, targets: TargetParams, m: dict[str, Any]
             ) -> list[FailureKind]:
    """The targets run ``m`` (a row's metrics) misses."""
    out = []

    def bad(v: Any, limit: float) -> bool:
        return v is None or not math.isfinite(v) or v > limit

    if m["min_tether_slack_m"] is None or not m["min_tether_slack_m"] > targets.min_tether_slack_m:
        out.append(FailureKind.TAUT)
    if bad(m["tether_ground_contact_fraction"], targets.ground_contact_fraction):
        out.append(FailureKind.GROUND_CONTACT)
    if bad(m["motor_saturation_fraction"], targets.motor_saturation_fraction):
        out.append(FailureKind.SATURATION)
    if bad(m["position_max_error_m"], targets.diverged_error_m):
        out.append(FailureKind.DIVERGED)
    tilt = m.get("max_tilt_deg")
    if tilt is not None and not tilt <= targets.max_tilt_deg:
        out.append(FailureKind.TILTED)
    h = m["min_height_flying_m"]
    if h is not None and math.isfinite(h) and h <= sc.plant.vehicle.gear_height_m + 0.05:
        out.append(FailureKind.CRASHED)
    if bad(m["position_rmse_m"], targets.position_rmse_m):
        out.append(FailureKind.TRACKING)
    return out


def run_one(sweep: SweepParams, sc: ScenarioParams, index: int) -> dict[str, Any]:
    """Run ``index`` of the sweep: its row (index, seed, drawn values, metrics, failures).
    What a Dask worker runs."""
    from tuav_sitl.offline import run_scenario

    seed, drawn = draw(sweep, index)
    try:
        result = run_scenario(apply(sc, seed if sweep.seeds else None, drawn, sweep.faults),
                              progress=None)
    except ParameterError as exc:   # a drawn system the plant or a controller refuses
        return failed_row(sweep, index, seed, drawn, FailureKind.REFUSED, str(exc))
    except Exception as exc:  # noqa: BLE001 - one run's fault must not end the sweep
        return failed_row(sweep, index, seed, drawn, FailureKind.ERROR,
                          f"{type(exc).__name__}: {exc}")
    return row_of(sweep, sc, index, seed, drawn, result.metrics, result.series)


def failed_row(sweep: SweepParams, index: int, seed: int,
               drawn: dict[str, float | str | None], kind: FailureKind, why: str
               ) -> dict[str, Any]:
    """The row of a run that did not fly: no metrics, failed with ``kind``; ``error`` says
    why (kept in runs.json, said by the sweep's progress)."""
    return {"index": index, "seed": seed, **{c: drawn[c] for c in drawn_columns(sweep)},
            **dict.fromkeys(METRIC_COLUMNS), "failed": True, "failures": kind.value,
            "error": why}


def row_of(sweep: SweepParams, sc: ScenarioParams, index: int, seed: int,
           drawn: dict[str, float | str | None], metrics: dict[str, Any],
           series: dict[str, np.ndarray]) -> dict[str, Any]:
    """A run's row from its metrics and series."""
    m = {k: metrics.get(k) for k in METRIC_COLUMNS} | flight_metrics(sc, sweep.targets,
                                                                     series)
    fails = failures(sc, sweep.targets, m)
    return {"index": index, "seed": seed, **{c: drawn[c] for c in drawn_columns(sweep)},
            **m, "failed": bool(fails), "failures": ";".join(f.value for f in fails)}


def flight_metrics(sc: ScenarioParams, targets: TargetParams, series: dict[str, np.ndarray]
                   ) -> dict[str, float | None]:
    """The sweep's own metrics of a run from its series: ``min_height_flying_m`` (the
    lowest height while the reference is above 1 m over the gear); from the scenario's
    ``metrics_after_s`` on, while flying (a reference, more than :data:`FLYING_ABOVE_GEAR_M`
    over the gear), the pull at the UAV's peak and 99th percentile [N] and the largest
    tilt [deg]; over the whole run, the time the tether is taut (its slack at or below the
    target's) and the time it touches the ground while flying [s]. None where the run
    never flies."""
    t, pos = series["t"], series["pos"]
    gear = sc.plant.vehicle.gear_height_m
    ref_z = series["ref_pos"][:, 2]
    high_ref = np.isfinite(ref_z) & (ref_z > gear + 1.0)
    dt = np.diff(t, append=t[-1] + (t[-1] - t[-2] if len(t) > 1 else 0.0))
    flying = np.isfinite(series["ref_pos"]).all(axis=1) & (pos[:, 2] > gear
                                                           + FLYING_ABOVE_GEAR_M)
    win = flying & (t >= sc.metrics_after_s)
    slack = series["length"] - np.linalg.norm(pos, axis=1)
    on_ground = np.isin(series["regime"], GROUND_REGIMES)
    roll, pitch = series["euler"][:, 0], series["euler"][:, 1]
    tilt = np.degrees(np.arccos(np.clip(np.cos(roll) * np.cos(pitch), -1.0, 1.0)))
    pull = series["top_tension"]
    return {
        "min_height_flying_m": float(pos[high_ref, 2].min()) if high_ref.any() else None,
        "tension_peak_flying_n": float(pull[win].max()) if win.any() else None,
        "tension_p99_flying_n": float(np.percentile(pull[win], 99)) if win.any() else None,
        "taut_time_s": float(dt[slack <= targets.min_tether_slack_m].sum()),
        "ground_flying_s": float(dt[on_ground & flying].sum()),
        "max_tilt_deg": float(tilt[win].max()) if win.any() else None,
    }


def drawn_columns(sweep: SweepParams) -> list[str]:
    """The columns of the drawn values: the quantities, then each fault's start and end."""
    return [*(v.parameter for v in sweep.vary),
            *(c for i, f in enumerate(sweep.faults) for c in f.columns(i))]


def columns(sweep: SweepParams) -> list[str]:
    """The table's columns, in order."""
    return ["index", "seed", *drawn_columns(sweep), *METRIC_COLUMNS, "failed", "failures"]


# --- the table -----------------------------------------------------------------------

def _cell(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(v)
    return str(v)


def _parse(col: str, text: str, label_cols: set[str]) -> Any:
    if col in ("index", "seed"):
        return int(text)
    if col == "failed":
        return text == "true"
    if col == "failures" or col in label_cols:
        return text
    return None if text == "" else float(text)


def read_table(path: Path, sweep: SweepParams) -> list[dict[str, Any]]:
    """The rows of a ``runs.csv`` (empty if there is none); a file of another sweep's
    columns is an error."""
    if not path.is_file():
        return []
    labels = {v.parameter for v in sweep.vary if v.kind.is_label}
    with path.open(newline="") as f:
        reader = csv.reader(f)
        header = next(reader, None)
        if header is None:
            return []
        if header != columns(sweep):
            raise ParameterError(str(path), "its columns are another sweep's: give another "
                                 "--out")
        rows = []
        for rec in reader:
            if len(rec) != len(header):
                continue   # a line cut short by an interruption
            rows.append({c: _parse(c, t, labels) for c, t in zip(header, rec, strict=True)})
    return rows


class TableWriter:
    """``runs.csv``, a row appended and flushed as each run finishes (a torn last line,
    from an interruption, is cut off when the file is opened again)."""

    def __init__(self, path: Path, sweep: SweepParams) -> None:
        self.cols = columns(sweep)
        fresh = not path.is_file() or path.stat().st_size == 0
        if not fresh:
            text = path.read_text()
            if not text.endswith("\n"):
                path.write_text(text[:text.rfind("\n") + 1])
        self._f = path.open("a", newline="")
        self._w = csv.writer(self._f)
        if fresh:
            self._w.writerow(self.cols)
            self._f.flush()

    def add(self, row: dict[str, Any]) -> None:
        """Append one row."""
        self._w.writerow([_cell(row.get(c)) for c in self.cols])
        self._f.flush()

    def close(self) -> None:
        self._f.close()


# --- running it ------------------------------------------------------------------------

class SweepProgress:
    """A text progress bar of finished runs."""

    def __init__(self, total: int, done: int, stream: TextIO | None, width: int = 30):
        self.total, self.done, self.stream, self.width = total, done, stream, width
        self.failed = 0
        self._t0 = time.perf_counter()
        self._start_done = done

    def add(self, failed: bool) -> None:
        """One run finished."""
        self.done += 1
        self.failed += failed
        if self.stream is None:
            return
        frac = self.done / self.total
        rate = (self.done - self._start_done) / max(time.perf_counter() - self._t0, 1e-9)
        eta = (self.total - self.done) / rate if rate > 0 else math.inf
        filled = int(frac * self.width)
        self.stream.write(f"\r[{'#' * filled}{'.' * (self.width - filled)}] {self.done}/"
                          f"{self.total} runs, {self.failed} failed, ~{eta:4.0f} s left ")
        self.stream.flush()

    def close(self) -> None:
        if self.stream is not None:
            self.stream.write("\n")
            self.stream.flush()


def run_sweep(sweep: SweepParams, sc: ScenarioParams, out_dir: Path, *,
              scheduler: str | None = None, workers: int | None = None,
              progress: TextIO | None = sys.stderr,
              on_row: Callable[[dict[str, Any]], None] | None = None
              ) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """Run the sweep's runs not yet in ``out_dir/runs.csv`` on Dask (the cluster at
    ``scheduler``, else a LocalCluster of ``workers`` processes, default one per core);
    returns (rows by index, summary) and writes runs.csv, runs.json, summary.json and
    summary.md."""
    out_dir.mkdir(parents=True, exist_ok=True)
    table = out_dir / "runs.csv"
    rows = {r["index"]: r for r in read_table(table, sweep)}
    todo = [i for i in range(sweep.runs) if i not in rows]
    if todo:
        writer = TableWriter(table, sweep)
        bar = SweepProgress(sweep.runs, sweep.runs - len(todo), progress)
        try:
            for row in _on_dask(sweep, sc, todo, scheduler, workers):
                rows[row["index"]] = row
                writer.add(row)
                bar.add(row["failed"])
                if row.get("error") and progress is not None:
                    progress.write(f"\nrun {row['index']} (seed {row['seed']}) did not fly: "
                                   f"{row['error']}\n")
                if on_row is not None:
                    on_row(row)
        finally:
            writer.close()
            bar.close()
    from tuav_sitl.sweep_summary import summarise, summary_text

    ordered = [rows[i] for i in sorted(rows) if i < sweep.runs]
    summary = summarise(sweep, ordered)
    (out_dir / "runs.json").write_text(json.dumps(ordered, indent=1) + "\n")
    (out_dir / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    (out_dir / "summary.md").write_text(summary_text(summary))
    return ordered, summary


def local_client(workers: int | None = None) -> Any:
    """A Dask client of a new LocalCluster of ``workers`` single-threaded worker
    processes (default one per core); closing the client closes the cluster."""
    import os

    from dask.distributed import Client, LocalCluster

    logging.getLogger("distributed").setLevel(logging.WARNING)   # its INFO lines on stderr
    cluster = LocalCluster(n_workers=workers or os.cpu_count() or 1, threads_per_worker=1,
                           processes=True, dashboard_address=":0",
                           silence_logs=logging.WARNING)
    client = Client(cluster)
    client.cluster_owned = cluster   # closed with the client (see close_client)
    return client


def close_client(client: Any) -> None:
    """Close ``client`` and the LocalCluster :func:`local_client` made for it."""
    cluster = getattr(client, "cluster_owned", None)
    client.close()
    if cluster is not None:
        cluster.close()


def rows_on(client: Any, sweep: SweepParams, sc: ScenarioParams, todo: list[int]
            ) -> Iterable[dict[str, Any]]:
    """The rows of runs ``todo`` run on ``client``'s cluster, as they finish."""
    from dask.distributed import as_completed

    futures = client.map(run_one, [sweep] * len(todo), [sc] * len(todo), todo, pure=False)
    for fut in as_completed(futures):
        yield fut.result()


def _on_dask(sweep: SweepParams, sc: ScenarioParams, todo: list[int],
             scheduler: str | None, workers: int | None) -> Iterable[dict[str, Any]]:
    """The rows of runs ``todo``, as they finish on the Dask cluster (at ``scheduler``,
    else a new LocalCluster)."""
    from dask.distributed import Client

    client = local_client(workers) if scheduler is None else Client(scheduler)
    try:
        yield from rows_on(client, sweep, sc, todo)
    finally:
        close_client(client)
