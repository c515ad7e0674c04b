#!/usr/bin/env python3
"""Fly a mission with MAVSDK-Python, unchanged, as against an ArduCopter.

Start the stack first (``tuav-sitl up``; it pushes MAVLink to UDP 14540 for APIs), then::

    pip install mavsdk-grpc        # MAVSDK-Python's gRPC API (or: pip install "mavsdk<4")
    python examples/mavsdk_mission.py

It waits for a healthy vehicle, reads and sets a parameter, arms, takes off with
``action.takeoff()``, flies to a point with ``action.goto_location()``, then uploads and
flies a mission with ``mission_raw`` — home at seq 0 and a take-off item first, as
ArduPilot wants (MAVSDK's ``mission`` plugin does not support ArduPilot) — with a
loiter-turns circle, and returns to launch, where the vehicle lands and disarms.
"""

from __future__ import annotations

import argparse
import asyncio
import math
import sys

try:
    import mavsdk_grpc as mavsdk
    from mavsdk_grpc.mission_raw import MissionItem
except ImportError:            # MAVSDK-Python before the rename (mavsdk<4)
    import mavsdk  # type: ignore[no-redef]
    from mavsdk.mission_raw import MissionItem  # type: ignore[no-redef]

EARTH_R_M = 6378137.0


def offset(lat_deg: float, lon_deg: float, east_m: float, north_m: float
           ) -> tuple[float, float]:
    """The point ``east_m``, ``north_m`` [m] from (lat, lon) [deg]."""
    lat = lat_deg + math.degrees(north_m / EARTH_R_M)
    lon = lon_deg + math.degrees(east_m / (EARTH_R_M * math.cos(math.radians(lat_deg))))
    return lat, lon


def item(seq: int, command: int, frame: int, params: tuple[float, float, float, float],
         lat: float, lon: float, alt: float, current: int = 0) -> MissionItem:
    """A MISSION_ITEM_INT as mission_raw takes it."""
    return MissionItem(seq, frame, command, current, 1, *params, round(lat * 1e7),
                       round(lon * 1e7), alt, 0)


async def fly(address: str, grpc_port: int) -> list[int]:
    """Run the flight; returns the mission items reached, in order."""
    drone = mavsdk.System(port=grpc_port)
    await drone.connect(system_address=address)
    async for state in drone.core.connection_state():
        if state.is_connected:
            break
    async for health in drone.telemetry.health():
        if health.is_global_position_ok and health.is_home_position_ok and health.is_armable:
            break
    home = None
    async for position in drone.telemetry.home():
        home = position
        break
    print(f"home at {home.latitude_deg:.7f}, {home.longitude_deg:.7f}")
    await drone.param.set_param_float("WPNAV_SPEED", 250.0)     # ArduCopter's cm/s
    print(f"WPNAV_SPEED = {await drone.param.get_param_float('WPNAV_SPEED')} cm/s")

    await drone.action.set_takeoff_altitude(8.0)
    await drone.action.arm()
    await drone.action.takeoff()
    async for pos in drone.telemetry.position():
        if pos.relative_altitude_m > 7.7:
            break
    print("took off")
    lat, lon = offset(home.latitude_deg, home.longitude_deg, 4.0, 4.0)
    await drone.action.goto_location(lat, lon, home.absolute_altitude_m + 9.0, 0.0)
    async for pos in drone.telemetry.position():
        north = math.radians(pos.latitude_deg - lat) * EARTH_R_M
        east = math.radians(pos.longitude_deg - lon) * EARTH_R_M * math.cos(math.radians(lat))
        if math.hypot(north, east) < 0.3:
            break
    print("reached the goto point")

    rel = 3   # MAV_FRAME_GLOBAL_RELATIVE_ALT
    plan = [item(0, 16, 0, (0, 0, 0, 0), home.latitude_deg, home.longitude_deg,
                 home.absolute_altitude_m, current=1),
            item(1, 22, rel, (0, 0, 0, 0), 0.0, 0.0, 9.0),
            item(2, 18, rel, (1, 0, -4.0, 0), *offset(home.latitude_deg, home.longitude_deg,
                                                      0.0, 6.0), 10.0),
            item(3, 16, rel, (0, 0.5, 0, 0), *offset(home.latitude_deg, home.longitude_deg,
                                                     -6.0, 2.0), 10.0),
            item(4, 20, rel, (0, 0, 0, 0), 0.0, 0.0, 0.0)]
    await drone.mission_raw.upload_mission(plan)
    await drone.mission_raw.start_mission()
    print("mission started")
    # MISSION_CURRENT moves past each item once it is reached; the last one (RTL) ends
    # with the landing and disarm
    reached: list[int] = []
    async for progress in drone.mission_raw.mission_progress():
        reached += [i for i in range(1, progress.current) if i not in reached]
        if progress.current == progress.total - 1:
            break
    async for armed in drone.telemetry.armed():
        if not armed:
            break
    reached.append(len(plan) - 1)
    print(f"landed and disarmed; mission items reached: {reached}")
    return reached


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--connect", default="udpin://0.0.0.0:14540", help="MAVSDK address")
    ap.add_argument("--grpc-port", type=int, default=50051, help="mavsdk_server's port")
    ap.add_argument("--timeout", type=float, default=600.0, help="give up after [s]")
    args = ap.parse_args()
    reached = asyncio.run(asyncio.wait_for(fly(args.connect, args.grpc_port), args.timeout))
    return 0 if reached == [1, 2, 3, 4] else 1


if __name__ == "__main__":
    sys.exit(main())
