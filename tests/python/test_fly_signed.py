"""MAVLink 2 signing end to end over UDP: `ringswarm sitl` vehicles without a key are
provisioned by `ringswarm sign-setup`, then `ringswarm fly` flies them with every frame
signed, both ways.

The flight is tests/fixtures/ground-diamond.toml (see test_fly.py for how its expected
values are derived: a predicted final velocity of exactly (0, 0) and a formation error
below 0.5 m after 8 s). Every frame of the .tlog is checked here with hashlib against the
key: SHA-256(key | frame without its last 6 bytes), first 6 bytes.
"""

import hashlib
import json
import math
import os
import struct
import subprocess
from pathlib import Path

import pytest
from pymavlink import mavutil

ROOT = Path(__file__).resolve().parents[2]
BIN = os.environ.get("RINGSWARM_BIN", str(ROOT / "target" / "debug" / "ringswarm"))
FIXTURE = ROOT / "tests" / "fixtures" / "ground-diamond.toml"
N = 4


@pytest.fixture(scope="module")
def signed_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("signed")
    key_file = tmp / "key.hex"
    subprocess.run([BIN, "keygen", str(key_file)], check=True, capture_output=True)
    config = tmp / "signed.toml"
    config.write_text(FIXTURE.read_text() + f'\n[security]\nsigning_key_file = "{key_file}"\n')
    log = open(tmp / "sitl.log", "w")
    sitl = subprocess.Popen(
        [BIN, "sitl", "--config", str(FIXTURE), "--state-dir", str(tmp / "state")], stdout=log, stderr=subprocess.STDOUT
    )
    try:
        setup = subprocess.run([BIN, "sign-setup", "--config", str(config)], capture_output=True, text=True, timeout=60)
        out = tmp / "run"
        fly = subprocess.run([BIN, "fly", "--config", str(config), "--out", str(out)], capture_output=True, text=True, timeout=120)
    finally:
        sitl.terminate()
        sitl.wait(timeout=10)
        log.close()
    return {
        "key": bytes.fromhex(key_file.read_text().strip()),
        "setup": setup,
        "fly": fly,
        "out": out,
        "state": tmp / "state",
        "clock": tmp / "key.hex.timestamp",
    }


def test_sign_setup_gives_every_vehicle_the_key_and_they_store_it(signed_run):
    setup = signed_run["setup"]
    assert setup.returncode == 0, setup.stderr
    assert setup.stdout.count("key taken") == N, setup.stdout
    for sysid in range(1, N + 1):
        stored = (signed_run["state"] / f"vehicle-{sysid}" / "mavlink" / "mavlink-signing-key.bin").read_bytes()
        assert stored[:32] == signed_run["key"]


def test_the_signed_flight_meets_the_unsigned_numbers(signed_run):
    fly = signed_run["fly"]
    assert fly.returncode == 0, fly.stderr[-3000:]
    summary = json.loads((signed_run["out"] / "summary.json").read_text())
    assert summary["vehicles"] == N
    assert summary["predicted_final_velocity"] == pytest.approx([0.0, 0.0], abs=1e-6)
    assert math.hypot(*summary["achieved_final_velocity"]) < 0.1
    assert summary["formation_error_m"] < 0.5
    assert "refused by signing" not in fly.stderr


def test_every_frame_both_ways_is_signed_with_the_key(signed_run):
    key = signed_run["key"]
    log = mavutil.mavlink_connection(str(signed_run["out"] / "traffic.tlog"))
    frames = {"to": 0, "from": 0}
    stamps = {}
    while True:
        msg = log.recv_match()
        if msg is None:
            break
        buf = bytes(msg.get_msgbuf())
        assert buf[0] == 0xFD and buf[2] & 0x01, f"unsigned {msg.get_type()}"
        assert hashlib.sha256(key + buf[:-6]).digest()[:6] == buf[-6:], f"bad signature on {msg.get_type()}"
        direction = "from" if msg.get_srcComponent() == 1 else "to"
        frames[direction] += 1
        stamp = struct.unpack("<Q", buf[-12:-6] + b"\0\0")[0]
        stream = (buf[-13], msg.get_srcSystem(), msg.get_srcComponent())
        assert stamp > stamps.get(stream, -1), f"stamp not increasing on stream {stream}"
        stamps[stream] = stamp
    # 4 links x about 12 s x 50 Hz setpoints one way and 100 Hz telemetry the other.
    assert frames["to"] > 1500 and frames["from"] > 3000, frames
    # The coordinator's clock is kept ahead of every stamp it used.
    mark = int(signed_run["clock"].read_text())
    ours = [s for (link, sysid, comp), s in stamps.items() if comp != 1]
    assert mark > max(ours)
