"""The steps of MAVSDK-Python's examples/offboard_velocity_ned.py: NED velocity setpoints
(north, east, down m/s, yaw deg) held for the example's durations, then offboard stop."""

import asyncio

from mavsdk.offboard import VelocityNedYaw

from _common import connected_drone, fly_offboard, wait_until_ready

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

    async def setter(args):
        await drone.offboard.set_velocity_ned(VelocityNedYaw(*args))

    await fly_offboard(drone, setter, (0.0, 0.0, 0.0, 0.0), STEPS)


if __name__ == "__main__":
    asyncio.run(main())
