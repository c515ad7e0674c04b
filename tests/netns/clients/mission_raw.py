"""MAVSDK's mission_raw example in MAVSDK-Python's gRPC API (``mavsdk_grpc``, ``pip
install mavsdk-grpc``; it starts its own ``mavsdk_server``), flown as MAVSDK's examples
fly: connect on UDP 14540, wait until the global position and home are OK, upload a
mission (home at seq 0 and a take-off first, as ArduPilot wants), arm, start it and wait
until it has finished and the vehicle is on the ground. Run unchanged against ``tuav-sitl
up``."""

import asyncio

import mavsdk_grpc as mavsdk
from mavsdk_grpc.mission_raw import MissionItem


async def main() -> None:
    drone = mavsdk.System()
    await drone.connect(system_address="udpin://0.0.0.0:14540")
    async for state in drone.core.connection_state():
        if state.is_connected:
            break
    print("waiting for a global position estimate and home", flush=True)
    async for health in drone.telemetry.health():
        if health.is_global_position_ok and health.is_home_position_ok:
            break
    async for position in drone.telemetry.home():
        home = position
        break
    lat, lon = round(home.latitude_deg * 1e7), round(home.longitude_deg * 1e7)
    rel = 3                                        # MAV_FRAME_GLOBAL_RELATIVE_ALT
    items = [
        MissionItem(0, 0, 16, 1, 1, 0, 0, 0, 0, lat, lon, home.absolute_altitude_m, 0),
        MissionItem(1, rel, 22, 0, 1, 0, 0, 0, 0, 0, 0, 3, 0),          # take off to 3 m
        MissionItem(2, rel, 16, 0, 1, 0, 0, 0, 0, lat + 270, lon, 3, 0),  # 3 m north
        MissionItem(3, rel, 21, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0),          # land there
    ]
    await drone.mission_raw.upload_mission(items)
    print("-- mission uploaded; arming", flush=True)
    await drone.action.arm()
    await drone.mission_raw.start_mission()
    print("-- mission started", flush=True)
    async for progress in drone.mission_raw.mission_progress():
        print(f"mission progress {progress.current}/{progress.total}", flush=True)
        if progress.current == progress.total:
            break
    async for in_air in drone.telemetry.in_air():
        if not in_air:
            break
    print("mission finished, landed", flush=True)


asyncio.run(main())
