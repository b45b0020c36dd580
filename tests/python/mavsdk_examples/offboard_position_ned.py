"""The steps of MAVSDK-Python's examples/offboard_position_ned.py: NED position
setpoints (north, east, down m, yaw deg) for the example's durations, then offboard
stop."""

import asyncio

from mavsdk.offboard import PositionNedYaw

from _common import connected_drone, fly_offboard, wait_until_ready

STEPS = [
    ((0.0, 0.0, -5.0, 0.0), 10),
    ((5.0, 0.0, -5.0, 90.0), 10),
    ((5.0, 10.0, -5.0, 90.0), 15),
    ((0.0, 10.0, 0.0, 180.0), 10),
]


async def main():
    drone = await connected_drone()
    await wait_until_ready(drone)

    async def setter(args):
        await drone.offboard.set_position_ned(PositionNedYaw(*args))

    await fly_offboard(drone, setter, (0.0, 0.0, 0.0, 0.0), STEPS)


if __name__ == "__main__":
    asyncio.run(main())
