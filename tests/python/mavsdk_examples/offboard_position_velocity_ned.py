"""The steps of MAVSDK-Python's examples/offboard_position_velocity_ned.py: position
with velocity feed-forward, 10 m up at 1 m/s for 10 s, then 50 m north at 1 m/s for
20 s, then land and offboard stop (in that order, as the example does)."""

import asyncio

from mavsdk.offboard import OffboardError, PositionNedYaw, VelocityNedYaw

from _common import connected_drone, wait_until_ready


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
    await drone.offboard.set_position_velocity_ned(
        PositionNedYaw(0.0, 0.0, -10.0, 0.0), VelocityNedYaw(0.0, 0.0, -1.0, 0.0)
    )
    await asyncio.sleep(10)
    await drone.offboard.set_position_velocity_ned(
        PositionNedYaw(50.0, 0.0, -10.0, 0.0), VelocityNedYaw(1.0, 0.0, 0.0, 0.0)
    )
    await asyncio.sleep(20)
    await drone.action.land()
    await drone.offboard.stop()


if __name__ == "__main__":
    asyncio.run(main())
