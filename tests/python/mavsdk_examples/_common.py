"""What every MAVSDK-Python example does first: connect on udpin 14540, wait for the
link, then for a global position and a home position."""

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
