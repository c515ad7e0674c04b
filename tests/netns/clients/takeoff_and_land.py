"""MAVSDK's takeoff-and-land example in MAVSDK's native Python binding (``mavsdk.asyncio``,
``pip install mavsdk``), written as MAVSDK's examples fly it: connect on UDP 14540, wait
until the global position and home are OK, arm, take off, land, and wait until the
vehicle is on the ground again; then say the calibrations MAVSDK reports (read once it has
had the vehicle's SYS_STATUS a while: in the first second after it connects MAVSDK can
report the global position and home before it has taken the calibration bits). Run
unchanged against ``tuav-sitl up``."""

import asyncio

from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
from mavsdk.asyncio.plugins.action import ActionAsync
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync


async def main() -> None:
    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    async with Mavsdk(config) as sdk:
        await sdk.add_any_connection("udpin://0.0.0.0:14540")
        drone = await sdk.first_autopilot(timeout_s=30)
        telemetry, action = TelemetryAsync(drone), ActionAsync(drone)
        print("waiting for a global position estimate and home", flush=True)
        async for health in telemetry.subscribe_health():
            if health.is_global_position_ok and health.is_home_position_ok:
                break
        print("-- arming", flush=True)
        await action.arm()
        await action.set_takeoff_altitude(3.0)
        print("-- taking off", flush=True)
        await action.takeoff()
        async for position in telemetry.subscribe_position():
            if position.relative_altitude_m > 2.7:
                break
        print("-- landing", flush=True)
        await action.land()
        async for in_air in telemetry.subscribe_in_air():
            if not in_air:
                break
        health = await telemetry.health()
        print(f"calibration ok: gyro {health.is_gyrometer_calibration_ok}, accelerometer "
              f"{health.is_accelerometer_calibration_ok}, magnetometer "
              f"{health.is_magnetometer_calibration_ok}", flush=True)
        print("landed", flush=True)


asyncio.run(main())
