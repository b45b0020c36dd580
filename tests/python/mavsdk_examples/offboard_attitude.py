"""The steps of MAVSDK-Python's examples/offboard_attitude.py: one level zero-thrust
setpoint, offboard start, then 2 s each of 70 % thrust, roll 30° and −30° at 60 %, level
at 60 %; offboard stop (Hold) and land."""

import asyncio

from mavsdk.offboard import Attitude, OffboardError

from _common import connected_drone, wait_until_ready


async def main():
    drone = await connected_drone()
    await wait_until_ready(drone)
    await drone.action.arm()
    await drone.offboard.set_attitude(Attitude(0.0, 0.0, 0.0, 0.0))
    try:
        await drone.offboard.start()
    except OffboardError:
        await drone.action.disarm()
        raise
    for roll_deg, thrust in [(0.0, 0.7), (30.0, 0.6), (-30.0, 0.6), (0.0, 0.6)]:
        await drone.offboard.set_attitude(Attitude(roll_deg, 0.0, 0.0, thrust))
        await asyncio.sleep(2)
    await drone.offboard.stop()
    await drone.action.land()


if __name__ == "__main__":
    asyncio.run(main())
