"""The steps of MAVSDK-Python's examples/offboard_position_ned.py: NED position
setpoints (north, east, down m, yaw deg) for the example's durations, then offboard
stop."""

import asyncio

from mavsdk.offboard import OffboardError, PositionNedYaw

from _common import connected_drone, wait_until_ready

STEPS = [
    ((0.0, 0.0, -5.0, 0.0), 10),
    ((5.0, 0.0, -5.0, 90.0), 10),
    ((5.0, 10.0, -5.0, 90.0), 15),
    ((0.0, 10.0, 0.0, 180.0), 10),
]


async def main():
    drone = await connected_drone()
    await wait_until_ready(drone)
    await drone.action.arm()
    await drone.offboard.set_position_ned(PositionNedYaw(0.0, 0.0, 0.0, 0.0))
    try:
        await drone.offboard.start()
    except OffboardError:
        await drone.action.disarm()
        raise
    for setpoint, seconds in STEPS:
        await drone.offboard.set_position_ned(PositionNedYaw(*setpoint))
        await asyncio.sleep(seconds)
    await drone.offboard.stop()


if __name__ == "__main__":
    asyncio.run(main())
