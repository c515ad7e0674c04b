"""Reading the ``flight.tlog`` of a ``tuav-sitl up`` run: what the vehicle was told and did.

One pass over the tlog's messages (every MAVLink frame to and from the ground stations,
stamped with the wall clock [s since the epoch]) collects the pairs of the two clocks
(:mod:`tuav_sitl.clock_pairing`), the winder's global position, the mission uploaded and
the items reached, the guided targets the vehicle accepted and the winch's
``WINCH_STATUS`` (component 169); :func:`read_tlog` then puts them on the simulated clock
[s] and in the z-up frame [m] as a :class:`TlogData`. The goals (:class:`Goal`) are, for
drawing, the waypoints of the mission flown (``MISSION_ITEM_REACHED``) and the guided
targets accepted (``NAV_TAKEOFF``, ``DO_REPOSITION``, ``SET_POSITION_TARGET_*``); a guided
position target answered with a "Guided: ..." warning counts as refused.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from tuav_sitl.clock_pairing import ClockMap, clock_pair
from tuavdefs.frames import local_enu_to_global, ned_to_enu
from tuavdefs.mav_frames import GLOBAL_FRAMES, altitude_to_z, global_to_local
from tuavdefs.simlink import HOME_DEFAULT

__all__ = ["Goal", "TlogData", "read_tlog"]

#: A guided position target counts as refused if the vehicle answers it with a "Guided: ..."
#: warning within this much wall time [s].
_REFUSAL_WINDOW_S = 0.5

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
_WINCH_COMPONENT = 169


class Goal(NamedTuple):
    """A position the vehicle was sent to: when [s, simulated], where [m, z-up], why."""

    t_s: float
    pos_m: tuple[float, float, float]
    source: str


@dataclass
class TlogData:
    """What an up run's tlog says, on the simulated clock [s], positions in the z-up frame
    [m]."""

    clock: ClockMap                         # wall-clock [s since the epoch] to simulated [s]
    origin: tuple[float, float, float]      # the winder's (lat deg, lon deg, alt m AMSL)
    origin_source: str                      # "HOME_POSITION", "GLOBAL_POSITION_INT", "default"
    reached: list[tuple[int, float]]        # MISSION_ITEM_REACHED: (seq, t [s])
    mission_goals: list[Goal]               # the flown mission's navigation items, in order
    guided_goals: list[Goal]                # accepted guided targets, in time order
    winch_t_s: np.ndarray                   # WINCH_STATUS instants [s]
    winch_length_m: np.ndarray              # WINCH_STATUS line_length [m]
    winch_speed_m_s: np.ndarray             # WINCH_STATUS speed [m/s, + paying out]
    winch_tension_kg: np.ndarray            # WINCH_STATUS tension [kg], as the message has it
    messages: int = 0                       # messages read (BAD_DATA not counted)
    notes: list[str] = field(default_factory=list)  # what could not be read or placed


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
        pair = clock_pair(msg, wall)
        if pair is not None:
            self.clock_pairs.append(pair)
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
    clock = ClockMap.from_pairs(parser.clock_pairs)
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
