"""What every MAVSDK-Python example does first: connect on udpin 14540, wait for the
link, then for a global position and a home position."""

import asyncio

from mavsdk import System

ADDRESS = "udpin://0.0.0.0:14540"


async def connected_drone():
    drone = System()
    await drone.connect(system_address=ADDRESS)
    async for state in drone.core.connection_state():
        if state.is_connected:
            break
    return drone


async def wait_until_ready(drone):
    async for health in drone.telemetry.health():
        if health.is_global_position_ok and health.is_home_position_ok:
            return


async def fly_offboard(drone, setter, initial, steps):
    """What the offboard examples share: arm, one initial setpoint, offboard start
    (disarm and re-raise if refused), each `(setpoint args, seconds)` step, offboard
    stop."""
    from mavsdk.offboard import OffboardError

    await drone.action.arm()
    await setter(initial)
    try:
        await drone.offboard.start()
    except OffboardError:
        await drone.action.disarm()
        raise
    for args, seconds in steps:
        await setter(args)
        await asyncio.sleep(seconds)
    await drone.offboard.stop()
