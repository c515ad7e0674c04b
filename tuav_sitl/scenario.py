"""Scenarios of the offline runner: the paper's experiments as TOML files.

A scenario file has top-level ``name``, ``description``, ``duration_s``,
``metrics_after_s``, and the tables ``[initial]`` and either ``[trajectory]`` (the paper's
experiments: a reference streamed to the vehicle in GUIDED; ``[[trajectory.waypoints]]``
for waypoint runs) or a mission flown in AUTO, as ArduPilot users write one: ``[[mission]]``
items (MAV_CMD names, frames and parameters) or ``mission_file`` (QGC WPL 110, as
MAVProxy's ``wp save`` writes it; home is its item 0 and the winder's position). Optionally
``home``, ``[navigation]`` (the flight logic's speeds and limits), ``[vehicle]``,
``[tether]``, ``[winder]``, ``[environment]``, ``[wind]``, ``[control]``,
``[winder_control]``, ``[lbar]`` override the defaults. Every field is checked at load time
and an error names it (``circle.trajectory.radius_m: must be > 0 m, got -1.0``).

``[vehicle]``, ``[tether]``, ``[winder]`` and ``[environment]`` are the system as its
designers believe it: the controllers' model (the companion's and the ground station's).
``[plant.vehicle]``, ``[plant.tether]``, ``[plant.winder]``, ``[plant.environment]`` set the
truth apart from it, field by field (a field not given there is the model's); ``[wind]`` is
the plant's alone. The truth's line is the lumped-mass model unless ``[tether] model`` or
``[plant.tether] model`` says otherwise (:data:`DEFAULT_TRUTH_TETHER`; the controllers model
the line as a catenary whatever the truth).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any, Self

from pymavlink.dialects.v20 import common as mavlink2

from companion import mission_file
from companion.ekf import EstimatorParams
from companion.gains import FlightControlParams
from companion.mission_protocol import MissionItem, degrees_to_e7, home_item
from companion.navigation import NavigationParams, air_start_too_low_m
from groundstation.lbar import LBarParams
from groundstation.tether_fix import TetherFixParams
from groundstation.winch import WinchParams
from groundstation.winder_control import WinderControlParams
from sitl.faults import FaultParams
from sitl.sensors import GnssPreset, SensorNoise
from tuavdefs.frames import local_enu_to_global
from tuavdefs.params import (
    DEFAULT_TRUTH_TETHER,
    EnvironmentParams,
    SystemParams,
    TetherParams,
    VehicleParams,
    WinderParams,
    WindParams,
)
from tuavdefs.paramspec import ParameterError, Params, load_toml, quantity
from tuavdefs.simlink import HOME_DEFAULT

TRAJECTORY_KINDS = ("hold", "step", "setpoint", "line", "circle", "waypoints")
#: The tables the plant's truth may set apart from the controllers' model.
PLANT_TABLES = ("environment", "vehicle", "tether", "winder")


@dataclass(frozen=True)
class PlantParams(Params):
    """The plant's truth where the controllers' model may be wrong. Loaded from a scenario,
    each table starts from the scenario's model table of that name
    (:meth:`ScenarioParams.from_dict`)."""

    environment: EnvironmentParams = quantity(EnvironmentParams(), "", "gravity and air")
    vehicle: VehicleParams = quantity(VehicleParams(), "", "the quadrotor")
    tether: TetherParams = quantity(TetherParams(model=DEFAULT_TRUTH_TETHER.value), "",
                                    "the tether (the lumped-mass line unless a model is "
                                    "given)")
    winder: WinderParams = quantity(WinderParams(), "", "the winder")


@dataclass(frozen=True)
class InitialParams(Params):
    """Where the run starts: the UAV in hover trim, the tether at its L-bar length."""

    position_m: tuple[float, ...] = quantity(
        (2.0, 0.0, 10.0), "m", "initial position (x east, y north, z up)", length=3)
    yaw_rad: float = quantity(0.0, "rad", "initial heading (from east, counter-clockwise)")


@dataclass(frozen=True)
class SensorParams(Params):
    """The plant's sensors (``sitl.sensors``): the GNSS receiver's preset and the seed of
    every sensor's random streams."""

    gnss: str = quantity("rtk", "", "GNSS receiver: rtk (ZED-F9P class, ~2 cm) or gnss "
                         "(M9N/M10 class, 0.5-1 m, wandering)",
                         choices=tuple(p.value for p in GnssPreset))
    seed: int = quantity(0, "", "seed of the sensors' random streams", ge=0)
    noise: bool = quantity(True, "", "false: every reading is the exact truth")
    accel_calibration: bool = quantity(
        True, "", "the accelerometer was calibrated before the flight (ArduPilot's "
        "six-position calibration, run on these sensors: tuav_sitl/calibration.py); its "
        "offsets become the companion's [estimator] accel_offsets_m_s2")

    def noise_model(self) -> SensorNoise:
        """The sensors' error models."""
        return (SensorNoise.preset(self.gnss, self.seed) if self.noise
                else SensorNoise.off(self.gnss))


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


#: The MAV_CMD names a scenario's ``[[mission]]`` may use (without ``MAV_CMD_``).
MISSION_COMMANDS: dict[str, int] = {
    name: getattr(mavlink2, f"MAV_CMD_{name}")
    for name in ("NAV_TAKEOFF", "NAV_WAYPOINT", "NAV_LOITER_TURNS", "NAV_LOITER_TIME",
                 "NAV_LAND", "NAV_RETURN_TO_LAUNCH", "DO_CHANGE_SPEED", "DO_WINCH")}
#: The global frames a mission item may be given in (without ``MAV_FRAME_``).
MISSION_FRAMES: dict[str, int] = {
    name: getattr(mavlink2, f"MAV_FRAME_{name}")
    for name in ("GLOBAL", "GLOBAL_RELATIVE_ALT", "GLOBAL_TERRAIN_ALT", "GLOBAL_INT",
                 "GLOBAL_RELATIVE_ALT_INT", "GLOBAL_TERRAIN_ALT_INT")}


@dataclass(frozen=True)
class MissionItemParams(Params):
    """One mission item, as a ground station would upload it (MISSION_ITEM_INT)."""

    command: str = quantity("NAV_WAYPOINT", "", "the MAV_CMD, without MAV_CMD_",
                            choices=tuple(MISSION_COMMANDS))
    frame: str = quantity("GLOBAL_RELATIVE_ALT", "", "the MAV_FRAME of latitude_deg, "
                          "longitude_deg, altitude_m, without MAV_FRAME_",
                          choices=tuple(MISSION_FRAMES))
    param1: float = quantity(0.0, "", "the command's param1 (hold time [s], turns, ...)")
    param2: float = quantity(0.0, "", "param2 (acceptance radius [m], speed [m/s], ...)")
    param3: float = quantity(0.0, "", "param3 (loiter radius [m], > 0 clockwise, ...)")
    param4: float = quantity(0.0, "", "param4 (yaw [deg], ...)")
    position_m: tuple[float, ...] = quantity(
        (), "m", "the item's place in the local frame (x east, y north, z up from the "
        "winder); latitude and longitude follow from home, z is the height above the "
        "winder's ground. Empty: latitude_deg, longitude_deg, altitude_m instead")
    latitude_deg: float = quantity(0.0, "deg", "latitude (with longitude_deg 0: where the "
                                   "vehicle is when the item begins)", ge=-90, le=90)
    longitude_deg: float = quantity(0.0, "deg", "longitude", ge=-180, le=180)
    altitude_m: float = quantity(0.0, "m", "altitude in the frame's reference")

    def check(self) -> None:
        if len(self.position_m) not in (0, 3):
            raise ValueError("position_m: expected 3 elements (x, y, z) or none")
        if self.position_m and (self.latitude_deg or self.longitude_deg):
            raise ValueError("position_m: give the position or latitude_deg and "
                             "longitude_deg, not both")

    def to_item(self, home: tuple[float, float, float]) -> MissionItem:
        """The stored mission item, latitude and longitude from ``home`` (the winder's
        latitude [deg], longitude [deg], ground altitude AMSL [m]) for a local position."""
        frame, lat, lon, alt = (MISSION_FRAMES[self.frame], self.latitude_deg,
                                self.longitude_deg, self.altitude_m)
        if self.position_m:
            x, y, z = self.position_m
            lat, lon, _ = local_enu_to_global((x, y, 0.0), home)
            frame, alt = mavlink2.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, z
        return MissionItem(command=MISSION_COMMANDS[self.command], frame=frame,
                           param1=self.param1, param2=self.param2, param3=self.param3,
                           param4=self.param4, x=degrees_to_e7(lat), y=degrees_to_e7(lon),
                           z=alt)


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
    trajectory: TrajectoryParams = quantity(TrajectoryParams(), "", "the reference (when "
                                            "there is no mission)")
    home: tuple[float, ...] = quantity(
        HOME_DEFAULT, "deg, deg, m", "the winder's global position: latitude, longitude, "
        "ground altitude AMSL (a mission_file's item 0 replaces it)", length=3)
    mission: tuple[MissionItemParams, ...] = quantity(
        (), "", "a mission flown in AUTO from the ground (home is seq 0; these are 1, 2, ...)")
    mission_file: str = quantity("", "", "a QGC WPL 110 mission file, flown in AUTO (path "
                                 "relative to the scenario file)")
    navigation: NavigationParams = quantity(NavigationParams(), "", "the flight logic: "
                                            "speeds, acceptance radius, landing")
    environment: EnvironmentParams = quantity(EnvironmentParams(), "", "gravity and air, "
                                              "as the controllers believe them")
    vehicle: VehicleParams = quantity(VehicleParams(), "", "the quadrotor, as the "
                                      "controllers believe it")
    tether: TetherParams = quantity(TetherParams(), "", "the tether, as the controllers "
                                    "believe it")
    winder: WinderParams = quantity(WinderParams(), "", "the winder, as the controllers "
                                    "believe it")
    plant: PlantParams = quantity(PlantParams(), "", "the truth the plant integrates: "
                                  "each table the model's, with the fields given here")
    wind: WindParams = quantity(WindParams(), "", "the wind")
    control: FlightControlParams = quantity(FlightControlParams(), "", "onboard control")
    winder_control: WinderControlParams = quantity(
        WinderControlParams(), "", "winder control")
    lbar: LBarParams = quantity(LBarParams(), "", "the L-bar estimator")
    sensors: SensorParams = quantity(SensorParams(), "", "the plant's sensors")
    estimator: EstimatorParams = quantity(EstimatorParams(), "", "the companion's navigation "
                                          "filter; kind = \"truth\" flies on the plant's "
                                          "state")
    winch: WinchParams = quantity(WinchParams(), "", "the winch component (its WINCH_STATUS "
                                  "rate: what the companion's tether model hears)")
    tether_fix: TetherFixParams = quantity(
        TetherFixParams(), "", "the winch's tether fix (the ground station's model of the "
        "line it fixes the UAV with, and the wind it is given); computed only for a vehicle "
        "that fuses it (not one flying on the truth)")
    faults: tuple[FaultParams, ...] = quantity(
        (), "", "faults the plant injects (sitl/faults.py: gnss_loss, wind, motor, "
        "winder_motor over start_s..end_s)")

    @classmethod
    def from_dict(cls, data: dict[str, Any], prefix: str | None = None) -> Self:
        """Build from a scenario's tables; each ``[plant.X]`` table starts from ``[X]``, the
        truth's line model from :data:`DEFAULT_TRUTH_TETHER` where neither names one."""
        data = dict(data)
        plant = data.get("plant", {})
        if isinstance(plant, dict):
            merged = dict(plant)
            for name in PLANT_TABLES:
                model, truth = data.get(name, {}), plant.get(name, {})
                if isinstance(model, dict) and isinstance(truth, dict):
                    merged[name] = {**model, **truth}
            if isinstance(merged.get("tether"), dict):
                merged["tether"] = {"model": DEFAULT_TRUTH_TETHER.value, **merged["tether"]}
            data["plant"] = merged
        return super().from_dict(data, prefix)

    @classmethod
    def nominal(cls, **fields: Any) -> ScenarioParams:
        """A scenario built in code whose plant is its model (``fields`` as for the
        constructor; a ``plant`` given wins)."""
        plant = PlantParams(**{n: fields[n] for n in PLANT_TABLES if n in fields})
        return cls(**{"plant": plant, **fields})

    def check(self) -> None:
        if self.mission and self.mission_file:
            raise ValueError("mission_file: give [[mission]] items or a mission_file, "
                             "not both")
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
        if self.estimator.kind == "ekf" and self.initial.position_m:
            need = air_start_too_low_m(self.initial.position_m[2],
                                       self.plant.vehicle.gear_height_m,
                                       self.sensors.noise_model().gps_epv_m)
            if need is not None:
                raise ValueError(
                    f"initial.position_m: a start in the air on the estimate with the "
                    f"{self.sensors.gnss} receiver needs z >= {need:.2f} m (its first fix "
                    "decides whether the vehicle is in the air); start on the ground "
                    "(z = 0) or higher")

    @property
    def flies_mission(self) -> bool:
        """Whether the scenario flies a mission (else its trajectory)."""
        return bool(self.mission or self.mission_file)

    def mission_items(self) -> tuple[tuple[float, float, float], list[MissionItem]]:
        """(home, items): the winder's global position (latitude deg, longitude deg,
        altitude m AMSL) and the mission as stored, home at seq 0. MissionFileError for a
        mission file that cannot be read."""
        if self.mission_file:
            items = mission_file.load(self.mission_file)
            h = items[0]
            return (h.x * 1e-7, h.y * 1e-7, h.z), items
        home = (self.home[0], self.home[1], self.home[2])
        return home, [home_item(*home), *(m.to_item(home) for m in self.mission)]

    def system(self) -> SystemParams:
        """The plant's parameters: the truth (``[plant]``) and the wind."""
        p = self.plant
        return SystemParams(environment=p.environment, vehicle=p.vehicle, tether=p.tether,
                            winder=p.winder, wind=self.wind)

    def with_tether_model(self, model: str) -> Self:
        """This scenario with the plant's tether ``model`` ("lumped" or "catenary"; the
        truth's, ``[plant.tether] model``, and the model table's, which the TOML's
        ``[tether] model`` sets for both)."""
        p = self.plant
        return self.replace(tether=self.tether.replace(model=model),
                            plant=p.replace(tether=p.tether.replace(model=model)))

    def model(self) -> SystemParams:
        """The controllers' model: the system as its designers believe it (no wind: they
        do not know it)."""
        return SystemParams(environment=self.environment, vehicle=self.vehicle,
                            tether=self.tether, winder=self.winder)


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
    sc = load_toml(ScenarioParams, path)
    if sc.mission_file and not Path(sc.mission_file).is_absolute():
        sc = sc.replace(mission_file=str((Path(path).parent / sc.mission_file).resolve()))
    return sc
