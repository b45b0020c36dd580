"""`ringswarm sitl` against MAVSDK-Python 4.x (the ctypes API, `mavsdk.asyncio`) on
`udpin://0.0.0.0:14540`, as a user would fly vehicle 1 by hand."""

import asyncio
import os
import signal
import subprocess
from pathlib import Path

import pytest

mavsdk = pytest.importorskip("mavsdk.asyncio")
from mavsdk.asyncio import ComponentType, Configuration, Mavsdk  # noqa: E402
from mavsdk.asyncio.plugins.action import ActionAsync  # noqa: E402
from mavsdk.asyncio.plugins.offboard import Attitude, OffboardAsync  # noqa: E402
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
BIN = os.environ.get("RINGSWARM_BIN", str(ROOT / "target" / "debug" / "ringswarm"))


@pytest.fixture
def sitl():
    proc = subprocess.Popen([BIN, "sitl", "--vehicles", "1"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    yield proc
    proc.send_signal(signal.SIGINT)
    out, _ = proc.communicate(timeout=10)
    assert proc.returncode == 0, out


async def first(generator, timeout=5.0):
    async def take():
        async for value in generator:
            return value

    return await asyncio.wait_for(take(), timeout)


async def fly():
    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    async with Mavsdk(config) as sdk:
        await sdk.add_any_connection("udpin://0.0.0.0:14540")
        system = await sdk.first_autopilot(timeout_s=10.0)
        assert system is not None, "vehicle 1 discovered"
        assert await system.get_system_id() == 1
        telemetry, action, offboard = TelemetryAsync(system), ActionAsync(system), OffboardAsync(system)

        position = await first(telemetry.subscribe_position())
        assert position.latitude_deg == pytest.approx(47.397742, abs=1e-6)
        assert position.longitude_deg == pytest.approx(8.545594, abs=1e-6)
        euler = await first(telemetry.subscribe_attitude_euler())
        assert abs(euler.roll_deg) < 1.0 and abs(euler.pitch_deg) < 1.0
        assert await first(telemetry.subscribe_armed()) is False
        assert await first(telemetry.subscribe_in_air()) is False
        assert (await first(telemetry.subscribe_flight_mode())).name == "POSCTL"
        health = await first(telemetry.subscribe_health(), timeout=10.0)
        assert health.is_local_position_ok and health.is_global_position_ok and health.is_home_position_ok

        # A stream of setpoints for more than a second, then OFFBOARD, as PX4 requires.
        for _ in range(24):
            await offboard.set_attitude(Attitude(0.0, 0.0, 0.0, 0.0))
            await asyncio.sleep(0.05)
        await action.arm()
        assert await first(telemetry.subscribe_armed()) is True
        await offboard.start()
        await asyncio.sleep(1.0)
        assert (await first(telemetry.subscribe_flight_mode())).name == "OFFBOARD"

        # Thrust above hover (0.5 for x500): it climbs.
        await offboard.set_attitude(Attitude(0.0, 0.0, 0.0, 0.7))
        await asyncio.sleep(3.0)
        climbed = await first(telemetry.subscribe_position())
        assert climbed.relative_altitude_m > 2.0, climbed.relative_altitude_m
        assert await first(telemetry.subscribe_in_air()) is True
        await offboard.set_attitude(Attitude(0.0, 0.0, 0.0, 0.5))
        await action.land()


def test_mavsdk_discovers_reads_telemetry_arms_and_flies_offboard(sitl):
    asyncio.run(asyncio.wait_for(fly(), 60.0))
