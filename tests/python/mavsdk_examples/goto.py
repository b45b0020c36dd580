"""The steps of MAVSDK-Python's examples/goto.py: read home's AMSL altitude, arm, take
off, after 1 s go to 47.397606 N 8.543060 E at 20 m above home facing north, then stay
connected until stopped (the example never ends on its own)."""

import asyncio

from _common import connected_drone, wait_until_ready


async def main():
    drone = await connected_drone()
    await wait_until_ready(drone)
    async for home in drone.telemetry.home():
        home_amsl_m = home.absolute_altitude_m
        break
    await drone.action.arm()
    await drone.action.takeoff()
    await asyncio.sleep(1)
    await drone.action.goto_location(47.397606, 8.543060, home_amsl_m + 20.0, 0)
    while True:
        await asyncio.sleep(1)


if __name__ == "__main__":
    asyncio.run(main())
