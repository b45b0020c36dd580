"""The steps of MAVSDK-Python's examples/takeoff_and_land.py: arm, take off, wait 10 s,
land (the script ends once the landing is acknowledged)."""

import asyncio

from _common import connected_drone, wait_until_ready


async def main():
    drone = await connected_drone()
    await wait_until_ready(drone)
    await drone.action.arm()
    await drone.action.takeoff()
    await asyncio.sleep(10)
    await drone.action.land()


if __name__ == "__main__":
    asyncio.run(main())
