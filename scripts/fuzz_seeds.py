#!/usr/bin/env python3
"""Writes the seed corpus of the binary fuzz targets (fuzz/corpus/{decode,
emulator_inbound,coordinator_inbound}) with pymavlink's own encoder, so the seeds are
independent of the code under test. The scripts follow ringswarm::fuzzing's format:
one selector byte (odd: signing on), then steps: 0x80|ms advances time; otherwise
opcode (low 2 bits: 0 unsigned, 1 signed with the key, 2 another key, 3 replay; the
rest is the link id), message id (u16 little-endian), system, component, payload length,
payload.

Run: .venv/bin/python scripts/fuzz_seeds.py
"""

from pathlib import Path

from pymavlink.dialects.v20 import common as m
from pymavlink.generator.mavcrc import x25crc

ROOT = Path(__file__).resolve().parents[1]
CORPUS = ROOT / "fuzz" / "corpus"
KEY = bytes([0x42] * 32)


class Sink:
    def __init__(self):
        self.buf = b""

    def write(self, b):
        self.buf += b


def v1_frame(msg, sys, comp):
    """MAVLink 1: the same payload (no extensions) under the 6-byte header."""
    payload = frame(msg)[10:-2][: msg.unpacker.size]
    body = bytes([len(payload), 0, sys, comp, msg.get_msgId()]) + payload
    crc = x25crc(body)
    crc.accumulate(bytes([msg.crc_extra]))
    return b"\xfe" + body + crc.crc.to_bytes(2, "little")


def frame(msg, sys=255, comp=190, key=None, link_id=0, timestamp=36_000_000_000_000):
    sink = Sink()
    mav = m.MAVLink(sink, srcSystem=sys, srcComponent=comp)
    if key is not None:
        mav.signing.secret_key = key
        mav.signing.link_id = link_id
        mav.signing.timestamp = timestamp
        mav.signing.sign_outgoing = True
    mav.send(msg)
    return sink.buf


def step(msg, sign=1, sys=255, comp=190):
    payload = frame(msg)[10:-2]
    msgid = msg.get_msgId()
    return bytes([sign, msgid & 0xFF, msgid >> 8, sys, comp, len(payload)]) + payload


def advance(ms):
    return bytes([0x80 | ms])


def cmd(command, *params, target=1):
    p = list(params) + [0.0] * (7 - len(params))
    return m.MAVLink_command_long_message(target, 1, command, 0, *p)


gcs_hb = m.MAVLink_heartbeat_message(m.MAV_TYPE_GCS, m.MAV_AUTOPILOT_INVALID, 0, 0, m.MAV_STATE_ACTIVE, 3)
px4_hb = m.MAVLink_heartbeat_message(m.MAV_TYPE_QUADROTOR, m.MAV_AUTOPILOT_PX4, 129, 6 << 16, m.MAV_STATE_ACTIVE, 3)
attitude = m.MAVLink_set_attitude_target_message(0, 1, 1, 7, [1, 0, 0, 0], 0, 0, 0, 0.6)
arm = cmd(m.MAV_CMD_COMPONENT_ARM_DISARM, 1)
offboard = cmd(m.MAV_CMD_DO_SET_MODE, 1, 6, 0)
takeoff = cmd(m.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 10)
setup = m.MAVLink_setup_signing_message(1, 1, list(KEY), 1)
mission_count = m.MAVLink_mission_count_message(1, 1, 2, 0)
position = m.MAVLink_local_position_ned_message(1000, 1.0, 2.0, -5.0, 0.5, 0.0, 0.0)
origin = m.MAVLink_gps_global_origin_message(473977420, 85455940, 488000)
ack = m.MAVLink_command_ack_message(m.MAV_CMD_COMPONENT_ARM_DISARM, 0)
ext = m.MAVLink_extended_sys_state_message(0, m.MAV_LANDED_STATE_IN_AIR)


def offboard_flight(sign):
    s = step(gcs_hb, sign)
    for _ in range(30):
        s += step(attitude, sign) + advance(50)
    s += step(arm, sign) + advance(20) + step(offboard, sign)
    for _ in range(40):
        s += step(attitude, sign) + advance(50)
    return s


def write(target, name, data):
    (CORPUS / target).mkdir(parents=True, exist_ok=True)
    (CORPUS / target / name).write_bytes(data)


# The decoder: MAVLink 2, MAVLink 1, signed, two in one datagram, garbage and truncation.
hb2 = frame(px4_hb, 1, 1)
write("decode", "heartbeat-v2", hb2)
write("decode", "heartbeat-v1", v1_frame(px4_hb, 1, 1))
write("decode", "heartbeat-signed", frame(px4_hb, 1, 1, key=KEY, link_id=7))
write("decode", "two-frames", hb2 + frame(arm))
write("decode", "garbage-and-truncated", b"\x00\x11" + hb2 + hb2[:7])
write("decode", "command-signed-v2", frame(arm, key=KEY))

# The emulator: an offboard flight unsigned and signed, a takeoff, SETUP_SIGNING, a
# mission upload, replays and another key.
write("emulator_inbound", "offboard-unsigned", b"\x00" + offboard_flight(0))
write("emulator_inbound", "offboard-signed", b"\x01" + offboard_flight(1))
write("emulator_inbound", "takeoff", b"\x00" + step(gcs_hb, 0) + step(arm, 0) + step(takeoff, 0) + advance(127) * 40)
write("emulator_inbound", "setup-signing", b"\x00" + step(setup, 0) + advance(10) + step(arm, 0) + step(arm, 1) + step(arm, 3) + step(arm, 2))
write("emulator_inbound", "mission-count", b"\x00" + step(mission_count, 0) + advance(100) * 3)

# The coordinator: a vehicle's heartbeat, origin, positions and acks (the byte before
# each step picks the link).
def vehicle_steps(sign):
    s = b""
    for i in range(60):
        s += b"\x00" + step(px4_hb if i % 10 == 0 else position, sign, 1, 1)
        s += b"\x00" + step(origin, sign, 1, 1) if i == 0 else b""
        s += b"\x00" + advance(20)
    s += b"\x00" + step(ack, sign, 1, 1) + b"\x00" + step(ext, sign, 1, 1)
    return s


write("coordinator_inbound", "vehicle-unsigned", b"\x00" + vehicle_steps(0))
write("coordinator_inbound", "vehicle-signed", b"\x01" + vehicle_steps(1))
