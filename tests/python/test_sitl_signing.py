"""MAVLink 2 signing between `ringswarm sitl` and pymavlink's own signing (`setup_signing`),
over real UDP: signed frames checked by pymavlink in one direction and pymavlink-signed
commands obeyed in the other; unsigned, foreign-key, replayed and stale commands never
obeyed; SETUP_SIGNING by PX4's rules, and the key kept across a restart.

A command "not obeyed" is one that gets no COMMAND_ACK within 1.5 s (PX4 drops a refused
frame before any handler sees it) and leaves the heartbeat's armed flag as it was.
"""

import os
import signal
import struct
import subprocess
import time
from pathlib import Path

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink2

ROOT = Path(__file__).resolve().parents[2]
BIN = os.environ.get("RINGSWARM_BIN", str(ROOT / "target" / "debug" / "ringswarm"))
ARM = mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM
ARMED_FLAG = mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED
# Signing timestamps: 10 us units since 2015-01-01.
EPOCH_2015 = 1420070400
ONE_MINUTE = 60 * 100_000
# The emulator answers a command within milliseconds on loopback; a command still
# unanswered after this long was dropped.
NOT_OBEYED_S = 1.5


def now_stamp():
    return int((time.time() - EPOCH_2015) * 100_000)


class Sitl:
    def __init__(self, state_dir, key_file=None):
        args = [BIN, "sitl", "--vehicles", "1", "--state-dir", str(state_dir)]
        if key_file is not None:
            args += ["--signing-key", str(key_file)]
        self.proc = subprocess.Popen(args, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        self.links = []

    def connect(self, port, key=None, link_id=None, initial_timestamp=None):
        link = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=255, source_component=190)
        self.links.append(link)
        # mavutil makes a new MAVLink 2 parser on the first MAVLink 2 frame, dropping any
        # signing set up before: the key goes on after the first heartbeat.
        assert link.wait_heartbeat(timeout=10) is not None
        if key is not None:
            link.setup_signing(key, sign_outgoing=True, link_id=link_id, initial_timestamp=initial_timestamp)
        return link

    def stop(self):
        for link in self.links:
            link.close()
        self.proc.send_signal(signal.SIGINT)
        out, _ = self.proc.communicate(timeout=10)
        assert self.proc.returncode == 0, out
        assert "panicked" not in out
        return out


@pytest.fixture
def key(tmp_path):
    path = tmp_path / "key.hex"
    subprocess.run([BIN, "keygen", str(path)], check=True, capture_output=True)
    return path, bytes.fromhex(path.read_text().strip())


def drain(link):
    """Reads whatever is queued on `link`: a socket left unread while another link is
    watched overflows within a second at the emulator's 250 messages/s, and would then
    drop the very answer a test waits for."""
    while link.recv_match(blocking=False) is not None:
        pass


def write(link, data):
    drain(link)
    link.write(data)


def acks(link, command, seconds=NOT_OBEYED_S):
    """The COMMAND_ACKs for `command` until `seconds` pass, or 0.3 s after the first."""
    found = []
    end = time.time() + seconds
    while time.time() < end:
        msg = link.recv_match(blocking=True, timeout=0.05)
        if msg is not None and msg.get_type() == "COMMAND_ACK" and msg.command == command:
            found.append(msg)
            end = min(end, time.time() + 0.3)
    return found


def arm(link, value, seconds=NOT_OBEYED_S):
    drain(link)
    link.mav.command_long_send(1, 1, ARM, 0, float(value), 0, 0, 0, 0, 0, 0)
    return acks(link, ARM, seconds)


def armed(link):
    """The armed flag of the next heartbeat from system 1."""
    drain(link)
    end = time.time() + 3
    while time.time() < end:
        hb = link.recv_match(type="HEARTBEAT", blocking=True, timeout=0.2)
        if hb is not None and hb.get_srcSystem() == 1:
            return bool(hb.base_mode & ARMED_FLAG)
    raise AssertionError("no heartbeat")


def statustext(link, seconds=3.0):
    end = time.time() + seconds
    while time.time() < end:
        msg = link.recv_match(type="STATUSTEXT", blocking=True, timeout=0.1)
        if msg is not None:
            return msg.text
    return None


def signed_bytes(key, link_id, timestamp, msg):
    """`msg` from 255/190, signed by a fresh pymavlink encoder at `timestamp`."""
    mav = mavlink2.MAVLink(None, srcSystem=255, srcComponent=190)
    mav.signing.secret_key = key
    mav.signing.link_id = link_id
    mav.signing.timestamp = timestamp
    mav.signing.sign_outgoing = True
    return bytes(msg.pack(mav))


def arm_msg(value):
    return mavlink2.MAVLink_command_long_message(1, 1, ARM, 0, float(value), 0, 0, 0, 0, 0, 0)


def test_signed_telemetry_checks_out_in_pymavlink_and_a_signed_client_arms(tmp_path, key):
    key_file, secret = key
    sitl = Sitl(tmp_path / "state", key_file)
    try:
        link = sitl.connect(14540, key=secret)
        hb = link.recv_match(type="HEARTBEAT", blocking=True, timeout=3)
        # pymavlink checked the signature against the key (it drops a frame that fails).
        assert hb.get_signed()
        assert hb.get_link_id() == 1, "PX4's offboard/API link is MAVLink instance 1"
        stamp = struct.unpack("<Q", hb.get_msgbuf()[-12:-6] + b"\0\0")[0]
        assert abs(stamp - now_stamp()) < 10 * 100_000, "the vehicle's clock starts at the wall clock"
        got = arm(link, 1)
        assert [a.result for a in got] == [0]
        assert armed(link)
        assert arm(link, 0)[0].result == 0
    finally:
        sitl.stop()
    stored = (tmp_path / "state" / "vehicle-1" / "mavlink" / "mavlink-signing-key.bin").read_bytes()
    assert stored[:32] == secret and len(stored) == 40


def test_unsigned_foreign_replayed_and_stale_commands_are_not_obeyed(tmp_path, key):
    key_file, secret = key
    sitl = Sitl(tmp_path / "state", key_file)
    try:
        signed = sitl.connect(14540, key=secret)
        # An unsigned client on the GCS link hears the vehicle (signed frames parse
        # without a key) but is not obeyed.
        unsigned = sitl.connect(14550)
        assert arm(unsigned, 1) == []
        assert not armed(signed)
        # Signed with another key.
        write(signed, signed_bytes(bytes(32 * [7]), 3, now_stamp(), arm_msg(1)))
        assert acks(signed, ARM) == []
        assert not armed(signed)
        # Arm and disarm signed, then replay the arm frame: refused.
        arm_frame = signed_bytes(secret, 4, now_stamp(), arm_msg(1))
        write(signed, arm_frame)
        assert [a.result for a in acks(signed, ARM)] == [0]
        assert arm(signed, 0)[0].result == 0
        write(signed, arm_frame)
        assert acks(signed, ARM) == []
        assert not armed(signed)
        # A new stream two minutes older than the vehicle's clock: stale. One minute
        # minus a second old: taken (the C library's window).
        write(signed, signed_bytes(secret, 5, now_stamp() - 2 * ONE_MINUTE, arm_msg(1)))
        assert acks(signed, ARM) == []
        write(signed, signed_bytes(secret, 6, now_stamp() - ONE_MINUTE + 100_000, arm_msg(1)))
        assert [a.result for a in acks(signed, ARM)] == [0]
        assert armed(signed)
    finally:
        sitl.stop()


def test_setup_signing_follows_px4_and_the_key_survives_a_restart(tmp_path, key):
    _, secret = key
    state = tmp_path / "state"
    sitl = Sitl(state)
    try:
        plain = sitl.connect(14540)
        assert arm(plain, 1)[0].result == 0, "no key: unsigned commands are obeyed"
        # While armed, SETUP_SIGNING is refused.
        drain(plain)
        plain.mav.setup_signing_send(1, 1, secret, now_stamp())
        assert statustext(plain) == "MAVLink signing: rejected while armed"
        assert arm(plain, 0)[0].result == 0
        # Disarmed: accepted unsigned (there is no key yet), whatever its target.
        drain(plain)
        plain.mav.setup_signing_send(0, 0, secret, now_stamp())
        assert statustext(plain) == "MAVLink signing key accepted"
        assert arm(plain, 1) == [], "unsigned commands are refused from now on"
    finally:
        sitl.stop()
    # A restart without --signing-key boots with the stored key.
    sitl = Sitl(state)
    try:
        plain = sitl.connect(14550)
        assert arm(plain, 1) == []
        signed = sitl.connect(14540, key=secret, initial_timestamp=now_stamp())
        assert arm(signed, 1)[0].result == 0
        assert arm(signed, 0)[0].result == 0
        # A blank key unsigned is refused (as every unsigned SETUP_SIGNING now); signed
        # it disables signing.
        drain(plain)
        plain.mav.setup_signing_send(1, 1, bytes(32), 0)
        assert statustext(plain, 1.5) is None
        drain(signed)
        signed.mav.setup_signing_send(1, 1, bytes(32), 0)
        assert statustext(signed) == "MAVLink signing disabled"
        assert arm(plain, 1)[0].result == 0, "no key: unsigned commands are obeyed again"
    finally:
        sitl.stop()
    stored = (state / "vehicle-1" / "mavlink" / "mavlink-signing-key.bin").read_bytes()
    assert stored == bytes(40), "PX4's no-key file"
