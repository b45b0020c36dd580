"""The steps of MAVSDK-Python's examples/mission.py: three fly-through waypoints at
25 m and 10 m/s, return to launch after the mission, upload, arm, start; ends when the
vehicle, having been in the air, is on the ground again."""

import asyncio

from mavsdk.mission import MissionItem, MissionPlan

from _common import connected_drone, wait_until_ready

WAYPOINTS = [
    (47.398039859999997, 8.5455725400000002),
    (47.398036222362471, 8.5450146439425509),
    (47.397825620791885, 8.5450092830163271),
]


def item(lat, lon):
    nan = float("nan")
    return MissionItem(
        lat, lon, 25, 10, True, nan, nan, MissionItem.CameraAction.NONE,
        nan, nan, nan, nan, nan, MissionItem.VehicleAction.NONE,
    )


async def until_landed_again(drone):
    was_in_air = False
    async for in_air in drone.telemetry.in_air():
        was_in_air = was_in_air or in_air
        if was_in_air and not in_air:
            return


async def main():
    drone = await connected_drone()
    landed = asyncio.ensure_future(until_landed_again(drone))
    await drone.mission.set_return_to_launch_after_mission(True)
    await drone.mission.upload_mission(MissionPlan([item(*w) for w in WAYPOINTS]))
    await wait_until_ready(drone)
    await drone.action.arm()
    await drone.mission.start_mission()
    await landed


if __name__ == "__main__":
    asyncio.run(main())
