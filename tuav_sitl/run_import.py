"""Importing a ``tuav-sitl up`` run folder, so that ``tuav-sitl plot`` draws it.

A run folder of ``tuav-sitl up`` (``runs/up-STAMP-I/``) holds what the three processes
recorded, not the offline runner's time series: ``truth.csv`` (the plant's truth, every 5th
control period), ``params.toml`` (the system parameters used), ``flight.tlog`` (every MAVLink
frame to and from the ground stations, wall-clock stamped), ``can.log`` (the winder's bus in
``candump -L`` format, wall-clock stamped) and the processes' logs. :func:`import_up_run`
turns these into the files :mod:`tuav_sitl.figures` and :mod:`tuav_sitl.animation` read:

- ``timeseries.npz`` with every column of :data:`tuav_sitl.offline.SERIES`, at the truth's
  instants (SI units, z-up frame, angles in rad):

  * ``t``, ``pos``, ``vel``, ``euler``, ``length``, ``drum_rate``, ``rotor_cmd``: the truth;
  * ``lbar``, ``lbar_rate``: the ground station's own L-bar estimator
    (:class:`groundstation.lbar.LBarEstimator` with its default settings, as the
    ground-station process runs it) applied to the true position and velocity;
    ``lbar_fresh`` is 1 (L-bar is computed at every sample);
  * ``top_tension``, ``drum_tension``, ``tether_force``, ``regime``, ``lowest``: the
    plant's own tether model (:class:`sitl.tether.Tether`) at the true position and
    paid-out length, i.e. what the plant computed at that instant;
  * ``winder_torque``: the ground station's ``Set_Input_Torque`` commands decoded from
    ``can.log`` with the DBC (held between frames), NaN without a CAN log;
  * everything the companion keeps to itself (the reference ``ref_pos``/``ref_vel``, the
    attitude commands, thrust and torques, the disturbance estimate, the Lyapunov
    functions, the tether-force estimate) and the wind: NaN. The figures that need them
    are skipped (:func:`tuav_sitl.figures.missing_series`).

  Extra columns: ``armed`` (0/1), and from the tlog's ``WINCH_STATUS`` (component 169)
  ``winch_length`` [m], ``winch_speed`` [m/s, + paying out], ``winch_tension`` [N]
  (the message's kilograms times gravity), held between messages, NaN before the first.
- ``metrics.json`` with what the run supports (see :func:`compute_up_metrics`);
- ``scenario.toml``: the run's parameters as a :class:`~tuav_sitl.scenario.ScenarioParams`
  (system parameters from ``params.toml``, the run's start as ``[initial]``) whose
  ``[trajectory]`` carries the goals the vehicle was sent to, for drawing: the waypoints of
  the mission it flew (``MISSION_ITEM_REACHED`` in the tlog), else the guided targets it
  accepted (``NAV_TAKEOFF``, ``DO_REPOSITION``, ``SET_POSITION_TARGET_*``). It describes the
  run; it is not an experiment the offline runner would reproduce.

Time: the tlog and the CAN log are stamped with the wall clock, the truth with simulated
time. The vehicle's telemetry (``ATTITUDE``, ``GLOBAL_POSITION_INT``,
``LOCAL_POSITION_NED``: ``time_boot_ms`` is simulated time) pairs the two clocks;
:class:`ClockMap` interpolates between those pairs (10 Hz of simulated time by default, so
an event's simulated time is known to about 0.1 s). Frames more than a second of wall
time outside the telemetry's span cannot be placed and are left out.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from companion.navigation import NavigationParams
from groundstation.lbar import LBarEstimator, LBarParams
from sitl.tether import Tether
from sitl.truth_log import TRUTH_COLUMNS
from tuav_sitl.candump_format import parse_log_line
from tuav_sitl.offline import GROUND_REGIMES, SERIES, _to_toml
from tuav_sitl.scenario import (
    InitialParams,
    ScenarioParams,
    TrajectoryParams,
    WaypointParams,
)
from tuavdefs.can_protocol import dbc_path
from tuavdefs.frames import local_enu_to_global, ned_to_enu
from tuavdefs.mav_frames import GLOBAL_FRAMES, altitude_to_z, global_to_local
from tuavdefs.params import SystemParams
from tuavdefs.paramspec import ParameterError, load_toml, to_dict
from tuavdefs.simlink import HOME_DEFAULT

__all__ = [
    "ClockMap",
    "Goal",
    "ImportResult",
    "RunImportError",
    "TlogData",
    "build_series",
    "compute_up_metrics",
    "import_up_run",
    "is_up_run",
    "needs_import",
    "read_can_torque",
    "read_tlog",
    "read_truth",
]

#: The UAV counts as flying when armed and this far above its resting height (the gear) [m].
FLYING_MARGIN_M = 0.1
#: A guided position target counts as refused if the vehicle answers it with a "Guided: ..."
#: warning within this much wall time [s].
_REFUSAL_WINDOW_S = 0.5
#: The files an up run's import reads (all but truth.csv optional).
SOURCES = ("truth.csv", "params.toml", "flight.tlog", "can.log", "companion.parm")

# MAVLink constants used here (common dialect values, fixed by the standard).
_MAV_AUTOPILOT_INVALID = 8
_MAV_RESULT_ACCEPTED = 0
_MAV_MISSION_ACCEPTED = 0
_MAV_SEVERITY_WARNING = 4
_CMD_NAV_WAYPOINT = 16
_CMD_NAV_LOITER_TURNS = 18
_CMD_NAV_LOITER_TIME = 19
_CMD_NAV_LAND = 21
_CMD_NAV_TAKEOFF = 22
_CMD_DO_REPOSITION = 192
_NAV_COMMANDS = (_CMD_NAV_WAYPOINT, _CMD_NAV_LOITER_TURNS, _CMD_NAV_LOITER_TIME,
                 _CMD_NAV_LAND, _CMD_NAV_TAKEOFF)
_FRAME_LOCAL_NED = 1
_POS_IGNORE_MASK = 0b111   # POSITION_TARGET_TYPEMASK_X/Y/Z_IGNORE
_TELEMETRY_CLOCK = ("ATTITUDE", "GLOBAL_POSITION_INT", "LOCAL_POSITION_NED")
_WINCH_COMPONENT = 169


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
    """The plant's truth log as columns (the names of ``sitl.__main__.TRUTH_COLUMNS``; SI
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
# flight.tlog


class ClockMap:
    """Wall-clock time [s since the epoch] to simulated time [s], from pairs of the two:
    piecewise linear between them; up to :attr:`EDGE_S` of wall time beyond the first or
    last pair (an event just after the last telemetry) extrapolated at the mean rate of the
    nearest :attr:`EDGE_PAIRS` pairs; NaN further out, which cannot be placed."""

    #: How far beyond the pairs' span an instant is still placed [s of wall time].
    EDGE_S = 1.0
    #: Pairs whose mean rate extrapolates beyond the span.
    EDGE_PAIRS = 10

    def __init__(self, wall_s: Iterable[float], sim_s: Iterable[float]) -> None:
        w = np.asarray(list(wall_s), dtype=float)
        s = np.asarray(list(sim_s), dtype=float)
        if len(w) != len(s):
            raise ValueError("wall_s and sim_s must have the same length")
        order = np.argsort(w, kind="stable")
        w, s = w[order], s[order]
        if len(s):
            s = np.maximum.accumulate(s)
        # one pair per wall stamp (the latest simulated time stamped with it)
        keep = np.ones(len(w), dtype=bool)
        keep[:-1] = w[1:] > w[:-1]
        self.wall_s, self.sim_s = w[keep], s[keep]

    def __len__(self) -> int:
        return len(self.wall_s)

    def sim(self, wall_s: np.ndarray | float) -> np.ndarray:
        """Simulated time [s] of wall-clock instants ``wall_s`` [s]."""
        w = np.asarray(wall_s, dtype=float)
        ws, ss = self.wall_s, self.sim_s
        if len(ws) < 2:
            return np.full(w.shape, np.nan)
        out = np.interp(w, ws, ss)
        k = min(self.EDGE_PAIRS, len(ws) - 1)
        rate_lo = (ss[k] - ss[0]) / (ws[k] - ws[0])
        rate_hi = (ss[-1] - ss[-1 - k]) / (ws[-1] - ws[-1 - k])
        out = np.where(w < ws[0], ss[0] + (w - ws[0]) * rate_lo, out)
        out = np.where(w > ws[-1], ss[-1] + (w - ws[-1]) * rate_hi, out)
        inside = (w >= ws[0] - self.EDGE_S) & (w <= ws[-1] + self.EDGE_S)
        return np.where(inside, out, np.nan)


class Goal(NamedTuple):
    """A position the vehicle was sent to: when [s, simulated], where [m, z-up], why."""

    t_s: float
    pos_m: tuple[float, float, float]
    source: str


@dataclass
class TlogData:
    """What an up run's tlog says, on the simulated clock."""

    clock: ClockMap
    origin: tuple[float, float, float]      # the winder's (lat deg, lon deg, alt m AMSL)
    origin_source: str                      # "HOME_POSITION", "GLOBAL_POSITION_INT", "default"
    reached: list[tuple[int, float]]        # MISSION_ITEM_REACHED: (seq, t [s])
    mission_goals: list[Goal]               # the flown mission's navigation items, in order
    guided_goals: list[Goal]                # accepted guided targets, in time order
    winch_t_s: np.ndarray                   # WINCH_STATUS instants [s]
    winch_length_m: np.ndarray
    winch_speed_m_s: np.ndarray
    winch_tension_kg: np.ndarray
    messages: int = 0
    notes: list[str] = field(default_factory=list)


@dataclass
class _Item:
    """A mission item as uploaded (latitude and longitude in 1e-7 degrees)."""

    seq: int
    command: int
    frame: int
    param2: float
    x: int
    y: int
    z: float


def _origin_from(lat_deg: float, lon_deg: float, alt_m: float,
                 enu_m: tuple[float, float, float]) -> tuple[float, float, float]:
    """The origin (lat, lon, alt AMSL) of the z-up frame, given a point's global position
    and its position ``enu_m`` [m] in that frame (inverting
    :func:`tuavdefs.frames.local_enu_to_global` by fixed-point iteration)."""
    guess = (lat_deg, lon_deg, alt_m - enu_m[2])
    for _ in range(5):
        lat, lon, _ = local_enu_to_global(enu_m, guess)
        guess = (guess[0] + lat_deg - lat, guess[1] + lon_deg - lon, guess[2])
    return guess


class _TlogParser:
    """One pass over the tlog's messages (wall-clock stamped), kept raw; resolved into a
    :class:`TlogData` once the clocks are paired."""

    def __init__(self) -> None:
        self.vehicle_sys = 1
        self.vehicle_seen = False
        self.clock_pairs: list[tuple[float, float]] = []
        self.home: Any = None
        self.gpi: dict[int, Any] = {}
        self.lpn: dict[int, Any] = {}
        self.upload: dict[str, Any] | None = None
        self.mission: dict[int, _Item] = {}
        self.mission_at_reached: list[tuple[int, float, dict[int, _Item]]] = []
        self.commands: list[tuple[float, int, list[float], int | None]] = []
        self.accepted_commands: list[tuple[float, int, list[float], int | None]] = []
        self.targets: list[dict[str, Any]] = []
        self.winch: list[tuple[float, float, float, float]] = []
        self.count = 0

    def _from_vehicle(self, msg: Any) -> bool:
        return msg.get_srcSystem() == self.vehicle_sys and msg.get_srcComponent() == 1

    def _from_gcs(self, msg: Any) -> bool:
        return msg.get_srcSystem() != self.vehicle_sys

    def feed(self, msg: Any) -> None:
        """Take one message (``msg._timestamp``: its wall-clock stamp [s])."""
        kind = msg.get_type()
        if kind == "BAD_DATA":
            return
        self.count += 1
        wall = float(msg._timestamp)
        if kind == "HEARTBEAT" and not self.vehicle_seen and msg.get_srcComponent() == 1 \
                and msg.autopilot != _MAV_AUTOPILOT_INVALID:
            self.vehicle_sys, self.vehicle_seen = msg.get_srcSystem(), True
        if kind == "WINCH_STATUS" and msg.get_srcComponent() == _WINCH_COMPONENT:
            self.winch.append((wall, msg.line_length, msg.speed, msg.tension))
            return
        if self._from_vehicle(msg):
            self._vehicle_message(kind, msg, wall)
        elif self._from_gcs(msg):
            self._gcs_message(kind, msg, wall)

    def _vehicle_message(self, kind: str, msg: Any, wall: float) -> None:
        if kind in _TELEMETRY_CLOCK:
            self.clock_pairs.append((wall, msg.time_boot_ms * 1e-3))
            if kind == "GLOBAL_POSITION_INT" and len(self.gpi) < 50:
                self.gpi.setdefault(msg.time_boot_ms, msg)
            elif kind == "LOCAL_POSITION_NED" and len(self.lpn) < 50:
                self.lpn.setdefault(msg.time_boot_ms, msg)
        elif kind == "HOME_POSITION" and self.home is None:
            self.home = msg
        elif kind == "MISSION_ACK" and getattr(msg, "mission_type", 0) == 0:
            up, self.upload = self.upload, None
            if up is not None and msg.type == _MAV_MISSION_ACCEPTED:
                if up["clear"]:
                    self.mission = {}
                elif len(up["items"]) == up["count"]:
                    self.mission = dict(up["items"])
        elif kind == "MISSION_ITEM_REACHED":
            self.mission_at_reached.append((int(msg.seq), wall, self.mission))
        elif kind == "COMMAND_ACK":
            for i, (w, cmd, p, frame) in enumerate(self.commands):
                if cmd == msg.command:
                    del self.commands[i]
                    if msg.result == _MAV_RESULT_ACCEPTED:
                        self.accepted_commands.append((w, cmd, p, frame))
                    break
        elif kind == "STATUSTEXT" and msg.severity <= _MAV_SEVERITY_WARNING \
                and str(msg.text).startswith("Guided"):
            for target in reversed(self.targets):
                if wall - target["wall"] <= _REFUSAL_WINDOW_S and not target["refused"]:
                    target["refused"] = True
                    break

    def _gcs_message(self, kind: str, msg: Any, wall: float) -> None:
        if getattr(msg, "target_system", self.vehicle_sys) not in (0, self.vehicle_sys):
            return
        if kind == "MISSION_COUNT" and getattr(msg, "mission_type", 0) == 0:
            self.upload = {"count": int(msg.count), "items": {}, "clear": False}
        elif kind == "MISSION_CLEAR_ALL" and getattr(msg, "mission_type", 0) == 0:
            self.upload = {"count": 0, "items": {}, "clear": True}
        elif kind in ("MISSION_ITEM_INT", "MISSION_ITEM") and self.upload is not None \
                and getattr(msg, "mission_type", 0) == 0:
            if kind == "MISSION_ITEM_INT":
                x, y = int(msg.x), int(msg.y)
            else:
                x, y = round(msg.x * 1e7), round(msg.y * 1e7)
            self.upload["items"][int(msg.seq)] = _Item(int(msg.seq), int(msg.command),
                                                       int(msg.frame), float(msg.param2),
                                                       x, y, float(msg.z))
        elif kind in ("COMMAND_LONG", "COMMAND_INT") and msg.command in (
                _CMD_NAV_TAKEOFF, _CMD_DO_REPOSITION):
            if kind == "COMMAND_LONG":
                p = [msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6,
                     msg.param7]
                frame = None
            else:
                p = [msg.param1, msg.param2, msg.param3, msg.param4, msg.x * 1e-7,
                     msg.y * 1e-7, msg.z]
                frame = int(msg.frame)
            self.commands.append((wall, int(msg.command), [float(v) for v in p], frame))
        elif kind.startswith("SET_POSITION_TARGET_") and msg.type_mask & _POS_IGNORE_MASK:
            return   # a velocity or acceleration target: no position to draw
        elif kind == "SET_POSITION_TARGET_LOCAL_NED" \
                and msg.coordinate_frame == _FRAME_LOCAL_NED:
            self.targets.append({"wall": wall, "ned": (msg.x, msg.y, msg.z),
                                 "refused": False})
        elif kind == "SET_POSITION_TARGET_GLOBAL_INT" \
                and msg.coordinate_frame in GLOBAL_FRAMES:
            self.targets.append({"wall": wall, "global": (msg.lat_int * 1e-7,
                                                          msg.lon_int * 1e-7, msg.alt),
                                 "frame": int(msg.coordinate_frame), "refused": False})

    # ----- resolving

    def origin(self) -> tuple[tuple[float, float, float], str]:
        """The winder's global position: from HOME_POSITION (global and local), else from a
        GLOBAL_POSITION_INT and LOCAL_POSITION_NED of the same instant, else the default."""
        h = self.home
        if h is not None:
            enu = ned_to_enu((h.x, h.y, h.z))
            return _origin_from(h.latitude * 1e-7, h.longitude * 1e-7, h.altitude * 1e-3,
                                enu), "HOME_POSITION"
        for boot_ms, g in self.gpi.items():
            lp = self.lpn.get(boot_ms)
            if lp is not None:
                enu = ned_to_enu((lp.x, lp.y, lp.z))
                return _origin_from(g.lat * 1e-7, g.lon * 1e-7, g.alt * 1e-3,
                                    enu), "GLOBAL_POSITION_INT"
        return HOME_DEFAULT, "default"


class _TruthAt:
    """The truth's position at a simulated instant (linear interpolation, clamped)."""

    def __init__(self, t: np.ndarray, pos: np.ndarray) -> None:
        self.t, self.pos = t, pos

    def __call__(self, t_s: float) -> tuple[float, float, float]:
        if not math.isfinite(t_s):
            t_s = float(self.t[0])
        return tuple(float(np.interp(t_s, self.t, self.pos[:, i])) for i in range(3))


def read_tlog(path: Path, truth_t: np.ndarray, truth_pos: np.ndarray) -> TlogData:
    """Read an up run's ``flight.tlog``: the clock pairs, the winder's global position, the
    mission items reached and the goals, the guided targets the vehicle accepted, and the
    winch's ``WINCH_STATUS``; positions of items flown "from where the vehicle is" (a
    take-off, an item without latitude and longitude) come from the truth
    (``truth_t`` [s], ``truth_pos`` [m])."""
    from pymavlink import mavutil

    parser = _TlogParser()
    conn = mavutil.mavlink_connection(str(path), robust_parsing=True)
    try:
        while True:
            msg = conn.recv_match()
            if msg is None:
                break
            parser.feed(msg)
    finally:
        conn.close()
    clock = ClockMap(*zip(*parser.clock_pairs, strict=True)) if parser.clock_pairs \
        else ClockMap([], [])
    notes = []
    if len(clock) < 2:
        notes.append("flight.tlog has no vehicle telemetry: its events cannot be timed")
    origin, origin_source = parser.origin()
    if origin_source == "default":
        notes.append("flight.tlog gives no home position: global positions are taken "
                     "relative to the default home")
    at = _TruthAt(truth_t, truth_pos)

    reached = []
    mission_goals: list[Goal] = []
    if parser.mission_at_reached:
        for seq, wall, _ in parser.mission_at_reached:
            reached.append((seq, float(clock.sim(wall))))
        mission = parser.mission_at_reached[-1][2]
        times = {seq: t for seq, t in reached}
        prev = at(reached[0][1])
        for seq in sorted(mission):
            item = mission[seq]
            if seq == 0 or item.command not in _NAV_COMMANDS:
                continue
            t_item = times.get(seq, math.nan)
            here = at(t_item) if math.isfinite(t_item) else prev
            if item.x != 0 or item.y != 0:
                x, y, z = global_to_local(item.x * 1e-7, item.y * 1e-7, item.z, item.frame,
                                           origin)
            else:   # flown from where the vehicle is
                x, y = here[0], here[1]
                z = altitude_to_z(item.z, item.frame, origin)
            if item.command == _CMD_NAV_LAND:
                z = here[2] if math.isfinite(t_item) else 0.0
            prev = (x, y, z)
            mission_goals.append(Goal(t_item, (x, y, z), f"mission item {seq}"))

    guided: list[tuple[float, Goal]] = []
    for wall, cmd, p, frame in parser.accepted_commands:
        t = float(clock.sim(wall))
        if cmd == _CMD_NAV_TAKEOFF:   # straight up from where the vehicle is
            here = at(t)
            alt = altitude_to_z(p[6], frame if frame is not None else 3, origin)
            guided.append((wall, Goal(t, (here[0], here[1], alt), "NAV_TAKEOFF")))
        else:
            lat, lon, alt = p[4], p[5], p[6]
            target = global_to_local(lat, lon, alt if math.isfinite(alt) else 0.0, frame,
                                      origin)
            if not math.isfinite(alt):
                target = (target[0], target[1], at(t)[2])
            guided.append((wall, Goal(t, target, "DO_REPOSITION")))
    for tgt in parser.targets:
        if tgt["refused"]:
            continue
        t = float(clock.sim(tgt["wall"]))
        if "ned" in tgt:
            pos = tuple(float(v) for v in ned_to_enu(tgt["ned"]))
            source = "SET_POSITION_TARGET_LOCAL_NED"
        else:
            lat, lon, alt = tgt["global"]
            pos = global_to_local(lat, lon, alt, tgt["frame"], origin)
            source = "SET_POSITION_TARGET_GLOBAL_INT"
        guided.append((tgt["wall"], Goal(t, pos, source)))
    guided.sort(key=lambda g: g[0])

    w = np.array(parser.winch, dtype=float).reshape(-1, 4)
    winch_t = clock.sim(w[:, 0])
    ok = np.isfinite(winch_t)
    return TlogData(clock, origin, origin_source, reached, mission_goals,
                    [g for _, g in guided], winch_t[ok], w[ok, 1], w[ok, 2], w[ok, 3],
                    parser.count, notes)


# --------------------------------------------------------------------------------------
# can.log


def read_can_torque(path: Path, clock: ClockMap) -> tuple[np.ndarray, np.ndarray, int]:
    """The ``Set_Input_Torque`` commands [N m] on an up run's ``can.log`` (candump -L),
    decoded with the project's DBC (any ODrive axis node: the DBC's layout, node 0's id):
    (simulated times [s], torques [N m], frames that could not be timed)."""
    import cantools

    db = cantools.database.load_file(str(dbc_path()), strict=True)
    msg = db.get_message_by_name("Set_Input_Torque")
    cmd_id = msg.frame_id & 0x1F
    walls: list[float] = []
    torques: list[float] = []
    with open(path) as f:
        for line in f:
            line = line.strip()
            if not line:
                continue
            try:
                frame = parse_log_line(line)
            except ValueError:
                continue
            arb = frame.arbitration_id
            # axis nodes are 0..0x2F; the winch sensors sit on 0x30 (tuavdefs.can_protocol)
            if frame.is_remote or arb & 0x1F != cmd_id or arb >> 5 >= 0x30 \
                    or len(frame.data) < msg.length:
                continue
            walls.append(frame.timestamp)
            torques.append(float(msg.decode(bytes(frame.data))["Input_Torque"]))
    t = clock.sim(np.array(walls, dtype=float))
    ok = np.isfinite(t)
    return t[ok], np.array(torques, dtype=float)[ok], int((~ok).sum())


def _held(t: np.ndarray, t_events: np.ndarray, values: np.ndarray) -> np.ndarray:
    """``values`` at ``t_events`` held until the next one, sampled at ``t`` (NaN before the
    first)."""
    out = np.full(len(t), np.nan)
    if len(t_events) == 0:
        return out
    order = np.argsort(t_events, kind="stable")
    te, v = t_events[order], values[order]
    idx = np.searchsorted(te, t + 1e-9, side="right") - 1
    ok = idx >= 0
    out[ok] = v[idx[ok]]
    return out


# --------------------------------------------------------------------------------------
# The series and the metrics


def build_series(truth: dict[str, np.ndarray], params: SystemParams,
                 lbar_params: LBarParams | None = None) -> dict[str, np.ndarray]:
    """The offline runner's columns (:data:`tuav_sitl.offline.SERIES`) from the truth:
    the truth itself, L-bar from the ground station's estimator, the tether's forces from
    the plant's model; NaN for what an up run does not record. Plus ``armed``."""
    t = truth["t_s"]
    n = len(t)
    s: dict[str, np.ndarray] = {name: np.full((n,) if w == 0 else (n, w), np.nan)
                                for name, w in SERIES}
    s["t"] = t.copy()
    s["pos"] = np.column_stack((truth["x_m"], truth["y_m"], truth["z_m"]))
    s["vel"] = np.column_stack((truth["vx_m_s"], truth["vy_m_s"], truth["vz_m_s"]))
    s["euler"] = np.column_stack((truth["roll_rad"], truth["pitch_rad"], truth["yaw_rad"]))
    s["length"] = truth["tether_length_m"].copy()
    s["drum_rate"] = truth["drum_rate_rad_s"].copy()
    s["rotor_cmd"] = np.column_stack([truth[f"rotor{i}"] for i in range(1, 5)])
    s["armed"] = truth["armed"].copy()
    g = params.environment.gravity_m_s2
    est = LBarEstimator(lbar_params or LBarParams(), params.tether.weight_per_length_n_m(g))
    tether = Tether(params.tether, g)
    pos, vel, length = s["pos"], s["vel"], s["length"]
    for i in range(n):
        p = (float(pos[i, 0]), float(pos[i, 1]), float(pos[i, 2]))
        lb = est.estimate(p, (float(vel[i, 0]), float(vel[i, 1]), float(vel[i, 2])))
        s["lbar"][i], s["lbar_rate"][i] = lb.length_m, lb.rate_m_s
        try:
            f = tether.forces(p[0], p[1], max(p[2], 0.0), float(length[i]))
        except (ValueError, RuntimeError):
            tether.reset_warm_start()
            continue
        s["top_tension"][i], s["drum_tension"][i] = f.top_tension_n, f.drum_tension_n
        s["tether_force"][i] = f.on_uav_n
        s["regime"][i] = int(f.info.regime)
        s["lowest"][i] = f.info.lowest_point_height_m
    s["lbar_fresh"] = np.ones(n)
    return s


def flying_mask(s: dict[str, np.ndarray], gear_height_m: float) -> np.ndarray:
    """Samples at which the UAV flies: armed and more than :data:`FLYING_MARGIN_M` above
    its resting height."""
    return (s["armed"] > 0.5) & (s["pos"][:, 2] > gear_height_m + FLYING_MARGIN_M)


def _finite_or_none(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def compute_up_metrics(s: dict[str, np.ndarray], params: SystemParams,
                       tlog: TlogData | None, name: str) -> dict[str, Any]:
    """What an up run supports of the offline runner's figures of merit, and its own:

    ``sim_time_s`` (last truth instant), ``flight_time_s`` (time flying: armed and above
    the gear, see :func:`flying_mask`), ``armed_time_s``,
    ``max_tether_slack_violation_m`` (max of straight-line distance minus paid-out
    length: positive if the tether was ever stretched beyond its unstretched length),
    ``min_tether_slack_m`` (its negative, as the offline runner defines it),
    ``tether_length_rmse_m`` and ``tether_length_max_error_m`` (L - L-bar while flying),
    ``max_tension_n``, ``max_drum_tension_n``, ``tether_ground_contact_fraction`` (the
    plant's tether model), ``max_winder_torque_n_m`` (CAN), ``waypoints_reached``
    (``MISSION_ITEM_REACHED``: mission sequence number and simulated time; null if the tlog
    has none). Tracking metrics need the reference, which an up run does not log: null.
    """
    t = s["t"]
    dt = np.diff(t)
    fly = flying_mask(s, params.vehicle.gear_height_m)
    armed = s["armed"] > 0.5
    dist = np.linalg.norm(s["pos"], axis=1)
    err = (s["length"] - s["lbar"])[fly]
    top, drum, regime = s["top_tension"], s["drum_tension"], s["regime"]
    solved = np.isfinite(regime)
    torque = s["winder_torque"]
    m: dict[str, Any] = {
        "scenario": name,
        "source": "tuav-sitl up",
        "sim_time_s": float(t[-1]),
        "samples": len(t),
        "flight_time_s": float(dt[fly[:-1]].sum()),
        "armed_time_s": float(dt[armed[:-1]].sum()),
        "max_tether_slack_violation_m": float(np.max(dist - s["length"])),
        "min_tether_slack_m": float(np.min(s["length"] - dist)),
        "tether_length_rmse_m": float(np.sqrt(np.mean(err ** 2))) if len(err) else None,
        "tether_length_max_error_m": float(np.max(np.abs(err))) if len(err) else None,
        "max_tension_n": _finite_or_none(np.max(top[solved])) if solved.any() else None,
        "max_drum_tension_n": _finite_or_none(np.max(drum[solved])) if solved.any() else None,
        "tether_ground_contact_fraction": (float(np.isin(regime[solved], GROUND_REGIMES)
                                                 .mean()) if solved.any() else None),
        "max_winder_torque_n_m": (float(np.nanmax(np.abs(torque)))
                                  if np.isfinite(torque).any() else None),
        "position_rmse_m": None,
        "position_max_error_m": None,
        "attitude_rmse_rad": None,
        "waypoints_reached": None,
    }
    if tlog is not None and tlog.reached:
        m["waypoints_reached"] = [
            {"index": seq, "t_s": round(ts, 3) if math.isfinite(ts) else None}
            for seq, ts in tlog.reached]
    return m


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
    """The companion's waypoint acceptance radius: ``WP_RADIUS`` of ``companion.parm`` if
    set there, else its default [m]."""
    radius = NavigationParams().acceptance_radius_m
    parm = run_dir / "companion.parm"
    if parm.is_file():
        for line in parm.read_text().splitlines():
            parts = line.replace(",", " ").split()
            if len(parts) >= 2 and parts[0] == "WP_RADIUS":
                try:
                    value = float(parts[1])
                except ValueError:
                    continue
                if value > 0 and math.isfinite(value):
                    radius = value
    return radius


def _scenario(run_dir: Path, s: dict[str, np.ndarray], params: SystemParams,
              goals: list[Goal], acceptance_m: float) -> ScenarioParams:
    t = s["t"]
    trajectory = TrajectoryParams(kind="hold", acceptance_radius_m=acceptance_m)
    if len(goals) == 1:
        trajectory = trajectory.replace(kind="setpoint", goal_m=goals[0].pos_m)
    elif goals:
        trajectory = trajectory.replace(kind="waypoints", waypoints=tuple(
            WaypointParams(position_m=g.pos_m) for g in goals))
    return ScenarioParams(
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
        s["winch_length"] = _held(s["t"], tlog.winch_t_s, tlog.winch_length_m)
        s["winch_speed"] = _held(s["t"], tlog.winch_t_s, tlog.winch_speed_m_s)
        s["winch_tension"] = _held(s["t"], tlog.winch_t_s, tlog.winch_tension_kg * g)
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
            s["winder_torque"] = _held(s["t"], t_can, torque)
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
