"""Scenarios of the offline runner: the paper's experiments as TOML files.

A scenario file has top-level ``name``, ``description``, ``duration_s``,
``metrics_after_s``, and the tables ``[initial]``, ``[trajectory]`` (with
``[[trajectory.waypoints]]`` for waypoint missions), and optionally ``[vehicle]``,
``[tether]``, ``[winder]``, ``[environment]``, ``[wind]``, ``[control]``,
``[winder_control]``, ``[lbar]`` to override the defaults. Every field is checked at load
time and an error names it (``circle.trajectory.radius_m: must be > 0 m, got -1.0``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

from companion.gains import FlightControlParams
from groundstation.lbar import LBarParams
from groundstation.winder_control import WinderControlParams
from tuavdefs.params import (
    EnvironmentParams,
    SystemParams,
    TetherParams,
    VehicleParams,
    WinderParams,
    WindParams,
)
from tuavdefs.paramspec import ParameterError, Params, load_toml, quantity

TRAJECTORY_KINDS = ("hold", "step", "setpoint", "line", "circle", "waypoints")


@dataclass(frozen=True)
class InitialParams(Params):
    """Where the run starts: the UAV in hover trim, the tether at its L-bar length."""

    position_m: tuple[float, ...] = quantity(
        (2.0, 0.0, 10.0), "m", "initial position (x east, y north, z up)", length=3)
    yaw_rad: float = quantity(0.0, "rad", "initial heading (from east, counter-clockwise)")


@dataclass(frozen=True)
class WaypointParams(Params):
    """One waypoint of a waypoint mission."""

    position_m: tuple[float, ...] = quantity((0.0, 0.0, 10.0), "m", "waypoint", length=3)


@dataclass(frozen=True)
class TrajectoryParams(Params):
    """The reference the UAV flies. Fields apply to the kinds named in their description."""

    kind: str = quantity("hold", "", "hold, step (the goal held from t = 0: regulation from "
                         "an offset), setpoint, line, circle or waypoints",
                         choices=TRAJECTORY_KINDS)
    start_s: float = quantity(1.0, "s", "time the reference starts to move", ge=0)
    goal_m: tuple[float, ...] = quantity(
        (5.0, 5.0, 20.0), "m", "step, setpoint and line: where to go", length=3)
    max_speed_m_s: float = quantity(4.0, "m/s", "speed limit of moves", gt=0)
    max_acc_m_s2: float = quantity(2.0, "m/s^2", "acceleration limit of moves", gt=0)
    speed_m_s: float = quantity(2.0, "m/s", "line and circle: cruise speed", gt=0)
    centre_m: tuple[float, ...] = quantity((12.0, 0.0), "m", "circle: centre (x, y)", length=2)
    radius_m: float = quantity(10.0, "m", "circle: radius", gt=0)
    altitude_m: float = quantity(20.0, "m", "circle: height", gt=0)
    lead_in_s: float = quantity(5.0, "s", "circle: time to reach the cruise speed", gt=0)
    turns: float = quantity(2.0, "1", "circle: number of turns", gt=0)
    acceptance_radius_m: float = quantity(
        0.3, "m", "waypoints: distance at which a waypoint counts as reached", gt=0)
    hold_s: float = quantity(2.0, "s", "waypoints: time spent at each waypoint", ge=0)
    waypoints: tuple[WaypointParams, ...] = quantity((), "", "waypoints: the list")

    def check(self) -> None:
        if self.kind == "waypoints" and not self.waypoints:
            raise ValueError("waypoints: a waypoint mission needs at least one waypoint")


@dataclass(frozen=True)
class ScenarioParams(Params):
    """A complete offline experiment."""

    name: str = quantity("custom", "", "short name, used for the output files")
    description: str = quantity("", "", "what the experiment shows")
    duration_s: float = quantity(30.0, "s", "simulated time", gt=0)
    metrics_after_s: float = quantity(
        0.0, "s", "tracking metrics ignore the time before this (a lead-in)", ge=0)
    physics_rate_hz: float = quantity(1000.0, "Hz", "RK4 integration rate", gt=0, le=20000)
    initial: InitialParams = quantity(InitialParams(), "", "initial state")
    trajectory: TrajectoryParams = quantity(TrajectoryParams(), "", "the reference")
    environment: EnvironmentParams = quantity(EnvironmentParams(), "", "gravity and air")
    vehicle: VehicleParams = quantity(VehicleParams(), "", "the quadrotor")
    tether: TetherParams = quantity(TetherParams(), "", "the tether")
    winder: WinderParams = quantity(WinderParams(), "", "the winder")
    wind: WindParams = quantity(WindParams(), "", "the wind")
    control: FlightControlParams = quantity(FlightControlParams(), "", "onboard control")
    winder_control: WinderControlParams = quantity(
        WinderControlParams(), "", "winder control")
    lbar: LBarParams = quantity(LBarParams(), "", "the L-bar estimator")

    def check(self) -> None:
        if self.metrics_after_s >= self.duration_s:
            raise ValueError("metrics_after_s: must be below duration_s")
        steps = self.physics_rate_hz / self.control.rate_hz
        if abs(steps - round(steps)) > 1e-9:
            raise ValueError("physics_rate_hz: must be a multiple of control.rate_hz")
        steps = self.physics_rate_hz / self.winder_control.rate_hz
        if abs(steps - round(steps)) > 1e-9:
            raise ValueError("physics_rate_hz: must be a multiple of winder_control.rate_hz")
        if not math.isfinite(self.duration_s * self.physics_rate_hz):
            raise ValueError("duration_s: too long")

    def system(self) -> SystemParams:
        """The plant's parameters."""
        return SystemParams(environment=self.environment, vehicle=self.vehicle,
                            tether=self.tether, winder=self.winder, wind=self.wind)


def shipped_scenarios() -> dict[str, Path]:
    """Name -> path of the scenarios shipped with the package."""
    folder = resources.files("tuav_sitl") / "scenarios"
    return {Path(str(p)).stem: Path(str(p)) for p in folder.iterdir()
            if str(p).endswith(".toml")}


def load_scenario(name_or_path: str) -> ScenarioParams:
    """A shipped scenario by name, or a scenario TOML file by path."""
    shipped = shipped_scenarios()
    if name_or_path in shipped:
        path = shipped[name_or_path]
    else:
        path = Path(name_or_path)
        if not path.is_file():
            raise ParameterError(name_or_path, "no such scenario: give a file or one of "
                                 + ", ".join(sorted(shipped)))
    return load_toml(ScenarioParams, path)
