"""MAVLink 2 signing end to end over UDP: `ringswarm sitl` vehicles without a key are
provisioned by `ringswarm sign-setup`, then `ringswarm fly` flies them with every frame
signed, both ways, while a hostile peer floods both links of every vehicle at 10x the
50 Hz telemetry rate (500 frames/s per link) with commands that would end the flight
(arm, forced disarm, land, AUTO.LAND, zero thrust, SETUP_SIGNING with its own key,
heartbeats), unsigned and signed with another key, and replays the vehicles' own signed
GCS-link telemetry back at them.

The flight is tests/fixtures/ground-diamond.toml (see test_fly.py for how its expected
values are derived: a predicted final velocity of exactly (0, 0) and a formation error
below 0.5 m after 8 s). Every frame of the .tlog is checked here with hashlib against the
key: SHA-256(key | frame without its last 6 bytes), first 6 bytes.
"""

import hashlib
import json
import math
import os
import random
import socket
import struct
import subprocess
import threading
import time
from pathlib import Path

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink2

# One worker runs this module, so its module-scoped flight is flown once.
pytestmark = pytest.mark.xdist_group("test_fly_signed")

ROOT = Path(__file__).resolve().parents[2]
BIN = os.environ.get("RINGSWARM_BIN", str(ROOT / "target" / "debug" / "ringswarm"))
FIXTURE = ROOT / "tests" / "fixtures" / "ground-diamond.toml"
N = 4


class Sink:
    def __init__(self):
        self.buf = b""

    def write(self, b):
        self.buf += b


def hostile_frames(sysid):
    """What the attacker sends vehicle `sysid`: each message unsigned and signed with
    its own key, from the coordinator's ids and from its own."""
    m = mavlink2
    msgs = [
        m.MAVLink_command_long_message(sysid, 1, m.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0, 21196, 0, 0, 0, 0, 0),
        m.MAVLink_command_long_message(0, 0, m.MAV_CMD_NAV_LAND, 0, 0, 0, 0, 0, 0, 0, 0),
        m.MAVLink_command_long_message(sysid, 1, m.MAV_CMD_DO_SET_MODE, 0, 1, 4, 6, 0, 0, 0, 0),
        m.MAVLink_set_attitude_target_message(0, sysid, 1, 7, [1, 0, 0, 0], 0, 0, 0, 0.0),
        m.MAVLink_setup_signing_message(sysid, 1, [0xEE] * 32, 1),
        m.MAVLink_heartbeat_message(m.MAV_TYPE_GCS, m.MAV_AUTOPILOT_INVALID, 0, 0, m.MAV_STATE_ACTIVE, 3),
    ]
    frames = []
    for src in (253, 66):
        for key in (None, bytes([0xEE] * 32)):
            sink = Sink()
            mav = mavlink2.MAVLink(sink, srcSystem=src, srcComponent=190)
            if key is not None:
                mav.signing.secret_key = key
                mav.signing.sign_outgoing = True
                mav.signing.timestamp = int((time.time() - 1420070400) * 100_000)
            for msg in msgs:
                sink.buf = b""
                mav.send(msg)
                frames.append(sink.buf)
    return frames


class Attacker(threading.Thread):
    """Sends to every vehicle's offboard (14580+i) and GCS (18570+i) link, one datagram
    per link every 2 ms, from 127.0.0.1:14550, where the vehicles' GCS links send their
    (signed) telemetry, which it keeps to replay."""

    def __init__(self, n):
        super().__init__(daemon=True)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 14550))
        self.sock.setblocking(False)
        self.frames = [hostile_frames(i + 1) for i in range(n)]
        self.captured = [[] for _ in range(n)]
        self.stop = threading.Event()
        self.sent = 0
        self.replayed = 0

    def run(self):
        rng = random.Random(7)
        tick = time.monotonic()
        while not self.stop.is_set():
            while True:
                try:
                    data, (_, port) = self.sock.recvfrom(2048)
                except BlockingIOError:
                    break
                i = port - 18570
                if 0 <= i < len(self.captured) and len(self.captured[i]) < 200:
                    self.captured[i].append(data)
            for i, frames in enumerate(self.frames):
                for port in (14580 + i, 18570 + i):
                    if self.captured[i] and rng.random() < 0.25:
                        data = rng.choice(self.captured[i])
                        self.replayed += 1
                    else:
                        data = rng.choice(frames)
                    self.sock.sendto(data, ("127.0.0.1", port))
                    self.sent += 1
            tick += 0.002
            time.sleep(max(0.0, tick - time.monotonic()))


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
        attacker = Attacker(N)
        attacker.start()
        out = tmp / "run"
        started = time.monotonic()
        fly = subprocess.run([BIN, "fly", "--config", str(config), "--out", str(out)], capture_output=True, text=True, timeout=120)
        attacked_s = time.monotonic() - started
        attacker.stop.set()
        attacker.join(timeout=5)
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
        "attacker": attacker,
        "attacked_s": attacked_s,
    }


def test_sign_setup_gives_every_vehicle_the_key_and_they_store_it(signed_run):
    setup = signed_run["setup"]
    assert setup.returncode == 0, setup.stderr
    assert setup.stdout.count("key taken") == N, setup.stdout
    for sysid in range(1, N + 1):
        stored = (signed_run["state"] / f"vehicle-{sysid}" / "mavlink" / "mavlink-signing-key.bin").read_bytes()
        assert stored[:32] == signed_run["key"]


def test_the_signed_flight_meets_the_unsigned_numbers_under_attack(signed_run):
    attacker = signed_run["attacker"]
    # 500 datagrams/s on each of 8 links for the whole flight; a loaded machine may
    # send fewer: at least a quarter of that, and replays among them.
    assert attacker.sent > 0.25 * 8 * 500 * signed_run["attacked_s"], attacker.sent
    assert attacker.replayed > 100
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
