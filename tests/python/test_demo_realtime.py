"""`ringswarm demo --realtime` watched live by pymavlink on the GCS port (udp 14550), as
QGroundControl or MAVProxy would: every emulated vehicle heartbeats, goes armed in PX4's
OFFBOARD mode, flies, lands and disarms, while the coordinator flies it over real UDP in
the same process. Scenario: tests/fixtures/ground-diamond.toml (four x500, 8 s).
"""

import json
import os
import subprocess
import time
from pathlib import Path

from pymavlink import mavutil

ROOT = Path(__file__).resolve().parents[2]
BIN = os.environ.get("RINGSWARM_BIN", str(ROOT / "target" / "debug" / "ringswarm"))
CONFIG = ROOT / "tests" / "fixtures" / "ground-diamond.toml"
OFFBOARD = 6  # PX4 main mode
ARMED = mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED


def test_a_gcs_sees_every_vehicle_armed_in_offboard_then_disarmed(tmp_path):
    gcs = mavutil.mavlink_connection("udpin:0.0.0.0:14550", source_system=250)
    out = tmp_path / "run"
    demo = subprocess.Popen(
        [BIN, "demo", "--realtime", "--scenario", str(CONFIG), "--out", str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    seen_offboard_armed = {}
    last = {}
    start = time.monotonic()
    try:
        while demo.poll() is None and time.monotonic() - start < 90:
            msg = gcs.recv_match(type="HEARTBEAT", blocking=True, timeout=0.5)
            if msg is None or msg.get_srcComponent() != 1:
                continue
            system = msg.get_srcSystem()
            last[system] = msg
            main_mode = (msg.custom_mode >> 16) & 0xFF
            if main_mode == OFFBOARD and msg.base_mode & ARMED:
                seen_offboard_armed.setdefault(system, time.monotonic() - start)
        stdout, _ = demo.communicate(timeout=30)
    finally:
        if demo.poll() is None:
            demo.kill()
        gcs.close()
    assert demo.returncode == 0
    assert "| achieved final velocity |" in stdout
    assert sorted(seen_offboard_armed) == [1, 2, 3, 4], seen_offboard_armed
    # The handshake needs 1.2 s of setpoints; allow a loaded machine 5 s.
    assert max(seen_offboard_armed.values()) < 5.0, seen_offboard_armed
    # Landed and disarmed at the end (the last heartbeat each vehicle sent the GCS may
    # predate the disarm by up to 1 s, so the summary says where it ended).
    summary = json.loads((out / "summary.json").read_text())
    assert summary["final_phase"] == "landing"
    assert summary["formation_error_m"] < 0.5
    assert abs(summary["sim_seconds"] - summary["wall_seconds"]) < 1.0  # real time
