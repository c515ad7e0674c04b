#!/usr/bin/env python3
"""Fly the paper's kind of mission from a script, as with any ArduCopter.

Start the stack first (``tuav-sitl up``), then::

    python examples/fly_mission.py                       # tcp:127.0.0.1:5760
    python examples/fly_mission.py --connect udpin:127.0.0.1:14550

It connects with pymavlink, switches to GUIDED, arms, takes off to 10 m, uploads a mission
(home, take-off, a loiter-turns circle of radius 5 m, three waypoints, land), flies it in
AUTO, and waits for the landing and disarm. Positions are given in metres from the winder
(x east, y north) and turned into latitude/longitude from the vehicle's own home and
origin, so the script works wherever ``--home`` puts the stack. With ``--record FILE`` it
writes what it saw (waypoint events, the UAV's positions, the winch's WINCH_STATUS) as
JSON. ``--short`` flies the same steps small and quick (take-off to 2 m, a mission of one
waypoint 1 m away, land: about 15 s of simulated time instead of about 86 s), for tests and
``python -m benchmarks --quick``.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time

from pymavlink import mavutil

M = mavutil.mavlink
REL = M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
EARTH_R_M = 6378137.0

#: (x east [m], y north [m], height [m]) of the three waypoints after the circle.
WAYPOINTS = ((10.0, 0.0, 12.0), (6.0, 8.0, 10.0), (-2.0, 6.0, 8.0))
CIRCLE = (4.0, 4.0, 10.0, 5.0)          # centre x, y, height, radius [m]
TAKEOFF_M = 10.0
#: ``--short``: take-off height [m] and the one waypoint (x east, y north, height [m]).
SHORT_TAKEOFF_M = 2.0
SHORT_WAYPOINT = (3.0, 0.0, 2.0)


class Flight:
    """One pymavlink connection and what it has seen."""

    def __init__(self, address: str, timeout_s: float) -> None:
        self.m = mavutil.mavlink_connection(address, source_system=255, source_component=190)
        self.deadline = time.monotonic() + timeout_s
        self.record: dict = {"reached": [], "positions": [], "winch": [], "texts": []}
        hb = self.wait("HEARTBEAT", lambda h: h.get_srcComponent() == 1
                       and h.autopilot == M.MAV_AUTOPILOT_ARDUPILOTMEGA)
        self.m.target_system, self.m.target_component = hb.get_srcSystem(), 1
        print(f"connected to system {hb.get_srcSystem()} in {self.m.flightmode}")

    def wait(self, mtype: str | list[str], cond=None, timeout_s: float = 60.0):
        """The next ``mtype`` message satisfying ``cond``, recording all on the way."""
        end = min(time.monotonic() + timeout_s, self.deadline)
        types = [mtype] if isinstance(mtype, str) else mtype
        while time.monotonic() < end:
            msg = self.m.recv_match(blocking=True, timeout=0.5)
            if msg is None:
                continue
            self._note(msg)
            if msg.get_type() in types and (cond is None or cond(msg)):
                return msg
        raise TimeoutError(f"no {mtype} in time")

    def _note(self, msg) -> None:
        kind = msg.get_type()
        if kind == "GLOBAL_POSITION_INT":
            self.record["positions"].append(
                [msg.time_boot_ms * 1e-3, msg.lat, msg.lon, msg.relative_alt * 1e-3])
        elif kind == "WINCH_STATUS":
            self.record["winch"].append([time.time(), msg.line_length, msg.speed,
                                         msg.tension, msg.status])
        elif kind == "MISSION_ITEM_REACHED":
            pos = self.m.messages.get("GLOBAL_POSITION_INT")
            where = [pos.lat, pos.lon, pos.relative_alt * 1e-3] if pos else None
            self.record["reached"].append([msg.seq, where])
            print(f"reached mission item {msg.seq}")
        elif kind == "STATUSTEXT":
            self.record["texts"].append(msg.text)

    def command(self, cmd: int, *params: float) -> int:
        """COMMAND_LONG; returns the ACK's result."""
        p = list(params) + [0.0] * (7 - len(params))
        self.m.mav.command_long_send(self.m.target_system, 1, cmd, 0, *p)
        return self.wait("COMMAND_ACK", lambda a: a.command == cmd, 5.0).result

    def set_mode(self, name: str) -> None:
        """Change mode (MAV_CMD_DO_SET_MODE with the copter mode number)."""
        number = self.m.mode_mapping()[name]
        result = self.command(M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                              number)
        if result != M.MAV_RESULT_ACCEPTED:
            raise RuntimeError(f"mode {name} refused ({result})")

    def upload(self, items: list[tuple]) -> None:
        """Upload MISSION_ITEM_INTs (command, p1, p2, p3, p4, lat, lon, alt) after home."""
        home = self.wait("HOME_POSITION", timeout_s=10.0)
        rows = [(M.MAV_CMD_NAV_WAYPOINT, M.MAV_FRAME_GLOBAL, 0, 0, 0, 0, home.latitude,
                 home.longitude, home.altitude * 1e-3)]
        rows += [(c, REL, p1, p2, p3, p4, lat, lon, alt) for c, p1, p2, p3, p4, lat, lon, alt
                 in items]
        self.m.mav.mission_count_send(self.m.target_system, 1, len(rows),
                                      M.MAV_MISSION_TYPE_MISSION)
        while True:
            msg = self.wait(["MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"],
                            timeout_s=10.0)
            if msg.get_type() == "MISSION_ACK":
                if msg.type != M.MAV_MISSION_ACCEPTED:
                    raise RuntimeError(f"mission refused ({msg.type})")
                return
            c, frame, p1, p2, p3, p4, lat, lon, alt = rows[msg.seq]
            self.m.mav.mission_item_int_send(self.m.target_system, 1, msg.seq, frame, c, 0, 1,
                                             p1, p2, p3, p4, int(lat), int(lon), alt,
                                             M.MAV_MISSION_TYPE_MISSION)


def latlon_e7(origin_lat: float, origin_lon: float, x_m: float, y_m: float
              ) -> tuple[int, int]:
    """Latitude and longitude ×1e7 of a point x east, y north [m] of an origin [deg]
    (a local tangent plane: fine over a tether's reach)."""
    lat = origin_lat + math.degrees(y_m / EARTH_R_M)
    lon = origin_lon + math.degrees(x_m / (EARTH_R_M * math.cos(math.radians(origin_lat))))
    return round(lat * 1e7), round(lon * 1e7)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--connect", default="tcp:127.0.0.1:5760", help="pymavlink address")
    ap.add_argument("--timeout", type=float, default=600.0, help="give up after [s]")
    ap.add_argument("--record", default=None, help="write what was seen here (JSON)")
    ap.add_argument("--short", action="store_true",
                    help="a short flight: take off to 2 m, one waypoint 1 m away, land")
    args = ap.parse_args()
    takeoff_m = SHORT_TAKEOFF_M if args.short else TAKEOFF_M
    f = Flight(args.connect, args.timeout)
    # the winder's position: LOCAL_POSITION_NED is relative to it (ArduPilot's EKF origin)
    lp = f.wait("LOCAL_POSITION_NED")
    gp = f.wait("GLOBAL_POSITION_INT")
    north = lp.x
    east = lp.y
    origin_lat = gp.lat * 1e-7 - math.degrees(north / EARTH_R_M)
    origin_lon = gp.lon * 1e-7 - math.degrees(
        east / (EARTH_R_M * math.cos(math.radians(origin_lat))))

    # position telemetry at 20 Hz (of the vehicle's time), as a logging script would ask
    f.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, 50_000)
    f.set_mode("GUIDED")
    # the pre-arm checks pass (the estimator has converged): SYS_STATUS's PREARM_CHECK
    # health bit, as ArduPilot sets it and MAVSDK's is_armable reads it; then arm, again
    # while a pre-arm check still denies it (COMMAND_ACK DENIED, "PreArm: ..."), for up to
    # a minute
    f.wait("SYS_STATUS", lambda s: s.onboard_control_sensors_health
           & M.MAV_SYS_STATUS_PREARM_CHECK, 120)
    end = time.monotonic() + 60.0
    while (result := f.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1)) == M.MAV_RESULT_DENIED \
            and time.monotonic() < end:
        time.sleep(0.5)
    if result != M.MAV_RESULT_ACCEPTED:
        raise RuntimeError(f"arming refused ({result})")
    print("armed; taking off")
    if f.command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, 0, 0, takeoff_m) \
            != M.MAV_RESULT_ACCEPTED:
        raise RuntimeError("take-off refused")
    f.wait("GLOBAL_POSITION_INT", lambda g: g.relative_alt > (takeoff_m - 0.3) * 1000, 120)
    print(f"at {takeoff_m:.0f} m; uploading the mission")

    cx, cy, cz, r = CIRCLE
    items = [(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, 0, 0, takeoff_m)]
    if not args.short:
        items.append((M.MAV_CMD_NAV_LOITER_TURNS, 1, 0, -r, 0,
                      *latlon_e7(origin_lat, origin_lon, cx, cy), cz))
    for x, y, z in (SHORT_WAYPOINT,) if args.short else WAYPOINTS:
        items.append((M.MAV_CMD_NAV_WAYPOINT, 0, 0.5, 0, math.nan,
                      *latlon_e7(origin_lat, origin_lon, x, y), z))
    items.append((M.MAV_CMD_NAV_LAND, 0, 0, 0, math.nan, 0, 0, 0))
    f.upload(items)
    f.set_mode("AUTO")
    print("flying the mission in AUTO")
    f.wait("HEARTBEAT", lambda h: h.get_srcComponent() == 1
           and not h.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED, args.timeout)
    reached = [seq for seq, _ in f.record["reached"]]
    print(f"landed and disarmed; items reached: {reached}")
    if args.record:
        f.record["origin"] = [origin_lat, origin_lon]
        f.record["waypoints"] = [list(w) for w in ((SHORT_WAYPOINT,) if args.short
                                                   else WAYPOINTS)]
        f.record["circle"] = None if args.short else list(CIRCLE)
        with open(args.record, "w") as out:
            json.dump(f.record, out)
    return 0 if reached == list(range(1, len(items) + 1)) else 1


if __name__ == "__main__":
    sys.exit(main())
