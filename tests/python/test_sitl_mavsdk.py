"""`ringswarm sitl` against MAVSDK-Python's classic API (pip `mavsdk==3.17.4`, which
bundles `mavsdk_server`) on `udpin://0.0.0.0:14540`, as a user would fly vehicle 1 by
hand: discovery, telemetry, then OFFBOARD after a single setpoint, as PX4's code
accepts it."""

import asyncio
import os
import signal
import subprocess
from pathlib import Path

import pytest

pytest.importorskip("mavsdk")
from mavsdk import System  # noqa: E402
from mavsdk.offboard import Attitude  # noqa: E402
from mavsdk.telemetry import FlightMode  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
BIN = os.environ.get("RINGSWARM_BIN", str(ROOT / "target" / "debug" / "ringswarm"))


@pytest.fixture
def sitl():
    proc = subprocess.Popen([BIN, "sitl", "--vehicles", "1"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, text=True)
    yield proc
    proc.send_signal(signal.SIGINT)
    out, _ = proc.communicate(timeout=10)
    assert proc.returncode == 0, out


async def first(generator, timeout=10.0):
    async def take():
        async for value in generator:
            return value

    return await asyncio.wait_for(take(), timeout)


async def until(generator, predicate, timeout=10.0):
    async def take():
        async for value in generator:
            if predicate(value):
                return value

    return await asyncio.wait_for(take(), timeout)


async def fly():
    drone = System()
    try:
        await fly_with(drone)
    finally:
        # The bundled mavsdk_server holds udp 14540 until it stops; later tests need it.
        drone._stop_mavsdk_server()


async def fly_with(drone):
    await drone.connect(system_address="udpin://0.0.0.0:14540")
    state = await first(drone.core.connection_state(), timeout=20.0)
    assert state.is_connected

    position = await first(drone.telemetry.position())
    assert position.latitude_deg == pytest.approx(47.397742, abs=1e-6)
    assert position.longitude_deg == pytest.approx(8.545594, abs=1e-6)
    euler = await first(drone.telemetry.attitude_euler())
    assert abs(euler.roll_deg) < 1.0 and abs(euler.pitch_deg) < 1.0
    assert await first(drone.telemetry.armed()) is False
    assert await first(drone.telemetry.in_air()) is False
    # PX4 boots into Hold (AUTO.LOITER).
    assert await first(drone.telemetry.flight_mode()) == FlightMode.HOLD
    health = await first(drone.telemetry.health())
    assert health.is_local_position_ok and health.is_global_position_ok and health.is_home_position_ok

    # One setpoint, then OFFBOARD: PX4's offboardCheck needs no more (MAVSDK's start()
    # sends two).
    await drone.action.arm()
    await until(drone.telemetry.armed(), lambda armed: armed)
    await drone.offboard.set_attitude(Attitude(0.0, 0.0, 0.0, 0.0))
    await drone.offboard.start()
    await until(drone.telemetry.flight_mode(), lambda mode: mode == FlightMode.OFFBOARD)

    # Thrust above hover (0.5 for x500): it climbs.
    await drone.offboard.set_attitude(Attitude(0.0, 0.0, 0.0, 0.7))
    await asyncio.sleep(3.0)
    climbed = await first(drone.telemetry.position())
    assert climbed.relative_altitude_m > 2.0, climbed.relative_altitude_m
    await until(drone.telemetry.in_air(), lambda in_air: in_air)
    await drone.offboard.set_attitude(Attitude(0.0, 0.0, 0.0, 0.5))
    await drone.action.land()


def test_mavsdk_discovers_reads_telemetry_arms_and_flies_offboard(sitl):
    asyncio.run(asyncio.wait_for(fly(), 90.0))
