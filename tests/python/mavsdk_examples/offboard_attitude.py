"""The steps of MAVSDK-Python's examples/offboard_attitude.py: one level zero-thrust
setpoint, offboard start, then 2 s each of 70 % thrust, roll 30° and −30° at 60 %, level
at 60 %; offboard stop (Hold) and land."""

import asyncio

from mavsdk.offboard import Attitude

from _common import connected_drone, fly_offboard, wait_until_ready

STEPS = [
    ((0.0, 0.0, 0.0, 0.7), 2),
    ((30.0, 0.0, 0.0, 0.6), 2),
    ((-30.0, 0.0, 0.0, 0.6), 2),
    ((0.0, 0.0, 0.0, 0.6), 2),
]


async def main():
    drone = await connected_drone()
    await wait_until_ready(drone)

    async def setter(args):
        await drone.offboard.set_attitude(Attitude(*args))

    await fly_offboard(drone, setter, (0.0, 0.0, 0.0, 0.0), STEPS)
    await drone.action.land()


if __name__ == "__main__":
    asyncio.run(main())
