"""The steps of MAVSDK-Python's examples/offboard_velocity_ned.py: NED velocity setpoints
(north, east, down m/s, yaw deg) held for the example's durations, then offboard stop."""

import asyncio

from mavsdk.offboard import OffboardError, VelocityNedYaw

from _common import connected_drone, wait_until_ready

STEPS = [
    ((0.0, 0.0, -2.0, 0.0), 4),
    ((2.0, 0.0, 0.0, 90.0), 4),
    ((-2.0, 0.0, 0.0, 270.0), 4),
    ((0.0, -2.0, 0.0, 90.0), 4),
    ((0.0, 2.0, 0.0, 90.0), 4),
    ((0.0, 0.0, 0.0, 180.0), 2),
    ((0.0, 0.0, 1.0, 0.0), 4),
]


async def main():
    drone = await connected_drone()
    await wait_until_ready(drone)
    await drone.action.arm()
    await drone.offboard.set_velocity_ned(VelocityNedYaw(0.0, 0.0, 0.0, 0.0))
    try:
        await drone.offboard.start()
    except OffboardError:
        await drone.action.disarm()
        raise
    for setpoint, seconds in STEPS:
        await drone.offboard.set_velocity_ned(VelocityNedYaw(*setpoint))
        await asyncio.sleep(seconds)
    await drone.offboard.stop()


if __name__ == "__main__":
    asyncio.run(main())
