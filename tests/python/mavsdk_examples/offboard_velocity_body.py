"""The steps of MAVSDK-Python's examples/offboard_velocity_body.py: body velocity
setpoints (forward, right, down m/s, yaw rate deg/s) for the example's durations, then
offboard stop."""

import asyncio

from mavsdk.offboard import VelocityBodyYawspeed

from _common import connected_drone, fly_offboard, wait_until_ready

STEPS = [
    ((0.0, 0.0, -1.0, 60.0), 5),
    ((0.0, 0.0, 0.0, -60.0), 5),
    ((0.0, 0.0, 0.0, 0.0), 2),
    ((5.0, 0.0, 0.0, 30.0), 15),
    ((0.0, 0.0, 0.0, 0.0), 5),
    ((0.0, -5.0, 0.0, 30.0), 15),
    ((0.0, 0.0, 0.0, 0.0), 8),
]


async def main():
    drone = await connected_drone()
    await wait_until_ready(drone)

    async def setter(args):
        await drone.offboard.set_velocity_body(VelocityBodyYawspeed(*args))

    await fly_offboard(drone, setter, (0.0, 0.0, 0.0, 0.0), STEPS)


if __name__ == "__main__":
    asyncio.run(main())
