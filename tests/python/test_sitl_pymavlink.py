"""`ringswarm sitl --vehicles 2` against pymavlink over real UDP (PX4's SITL ports).

Timing tolerances are wide enough for a loaded CI machine; every check still compares a
number with an expected value.
"""

import math
import os
import signal
import struct
import subprocess
import time
from pathlib import Path

import pytest
from pymavlink import mavutil

ROOT = Path(__file__).resolve().parents[2]
BIN = os.environ.get("RINGSWARM_BIN", str(ROOT / "target" / "debug" / "ringswarm"))

ARM = mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM
SET_MODE = mavutil.mavlink.MAV_CMD_DO_SET_MODE
SET_INTERVAL = mavutil.mavlink.MAV_CMD_SET_MESSAGE_INTERVAL
LEVEL = [1.0, 0.0, 0.0, 0.0]


@pytest.fixture
def sitl():
    proc = subprocess.Popen(
        [BIN, "sitl", "--vehicles", "2"], stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
    )
    links = []

    def connect(instance):
        link = mavutil.mavlink_connection(f"udpin:127.0.0.1:{14540 + instance}", source_system=255, source_component=190)
        link.wait_heartbeat(timeout=10)
        links.append(link)
        return link

    connect.proc = proc
    yield connect
    for link in links:
        link.close()
    proc.send_signal(signal.SIGINT)
    out, _ = proc.communicate(timeout=10)
    assert proc.returncode == 0, out
    assert "panicked" not in out


def ack_for(link, command, timeout=3.0, settle=0.3):
    """The last COMMAND_ACK for `command`: PX4 main answers DO_SET_MODE twice (an early
    ACCEPTED, then the commander's verdict), so acks are read until `settle` s pass
    without another one."""
    deadline = time.time() + timeout
    last = None
    while time.time() < deadline:
        msg = link.recv_match(type="COMMAND_ACK", blocking=True, timeout=0.05)
        if msg is not None and msg.command == command:
            last = msg
            deadline = min(deadline, time.time() + settle)
    return last


def command(link, target, cmd, *params):
    params = list(params) + [0.0] * (7 - len(params))
    link.mav.command_long_send(target, 1, cmd, 0, *params)
    return ack_for(link, cmd)


def stream(link, target, seconds, thrust, hz=20.0):
    """Streams a level attitude at `thrust` for `seconds`; the time of the last send."""
    end = time.time() + seconds
    sent = time.time()
    while time.time() < end:
        link.mav.set_attitude_target_send(0, target, 1, 7, LEVEL, 0, 0, 0, thrust)
        sent = time.time()
        drain(link, 1.0 / hz)
    return sent


def drain(link, seconds):
    """Reads (and drops) telemetry for `seconds`: an unread UDP socket overflows within
    about a second at the emulator's 200+ messages/s, and then drops what comes next."""
    end = time.time() + seconds
    while time.time() < end:
        link.recv_match(blocking=True, timeout=max(0.0, min(0.01, end - time.time())))


def latest(link, kind, timeout=2.0):
    """The newest message of a kind, draining whatever is buffered first."""
    found = None
    deadline = time.time() + timeout
    while time.time() < deadline:
        msg = link.recv_match(type=kind, blocking=found is None, timeout=0.05)
        if msg is None and found is not None:
            return found
        if msg is not None:
            found = msg
    return found


def offboard_flight(link):
    stream(link, 1, 1.2, 0.0)
    arm = command(link, 1, ARM, 1)
    assert arm is not None and arm.result == 0
    mode = command(link, 1, SET_MODE, 1, 6, 0)
    assert mode is not None and mode.result == 0


def test_heartbeat_arm_and_offboard_handshake(sitl):
    link = sitl(0)
    hb = latest(link, "HEARTBEAT")
    assert (hb.get_srcSystem(), hb.get_srcComponent()) == (1, 1)
    assert hb.type == mavutil.mavlink.MAV_TYPE_QUADROTOR
    assert hb.autopilot == mavutil.mavlink.MAV_AUTOPILOT_PX4
    assert hb.base_mode & mavutil.mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    assert hb.system_status == mavutil.mavlink.MAV_STATE_STANDBY
    ack = command(link, 1, ARM, 1)
    assert ack.result == mavutil.mavlink.MAV_RESULT_ACCEPTED
    assert (ack.target_system, ack.target_component) == (255, 190)
    # Armed, OFFBOARD without a setpoint within COM_OF_LOSS_T: TEMPORARILY_REJECTED; after
    # one setpoint: accepted (PX4's offboardCheck).
    assert command(link, 1, SET_MODE, 1, 6, 0).result == mavutil.mavlink.MAV_RESULT_TEMPORARILY_REJECTED
    stream(link, 1, 0.05, 0.0)
    assert command(link, 1, SET_MODE, 1, 6, 0).result == mavutil.mavlink.MAV_RESULT_ACCEPTED
    stream(link, 1, 1.2, 0.0)
    hb = latest(link, "HEARTBEAT")
    assert mavutil.mode_string_v10(hb) == "OFFBOARD"
    assert hb.base_mode & mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED


def read_param(link, name):
    link.mav.param_request_read_send(1, 1, name.encode(), -1)
    deadline = time.time() + 3
    while time.time() < deadline:
        p = link.recv_match(type="PARAM_VALUE", blocking=True, timeout=0.2)
        if p is not None and p.param_id == name:
            return p.param_value
    raise AssertionError(f"no PARAM_VALUE for {name}")


def test_hover_throttle_leaves_only_drag(sitl):
    link = sitl(0)
    hover = read_param(link, "MPC_THR_HOVER")
    drag = read_param(link, "SIM_DRAG")  # linear drag, 1/s
    assert hover == pytest.approx(0.5)
    offboard_flight(link)
    stream(link, 1, 1.0, 0.65)  # climb
    stream(link, 1, 0.5, hover)  # let the motors settle on hover thrust
    before = latest(link, "LOCAL_POSITION_NED")
    stream(link, 1, 3.0, hover)
    after = latest(link, "LOCAL_POSITION_NED")
    dt = (after.time_boot_ms - before.time_boot_ms) / 1000.0
    assert after.z < -1.0, "the vehicle climbed"
    # At hover throttle thrust cancels gravity, so only drag acts: vz(t) = vz0·e^(−c·t),
    # z(t) − z0 = vz0·(1 − e^(−c·t))/c.
    decay = math.exp(-drag * dt)
    assert after.vz == pytest.approx(before.vz * decay, abs=0.05), (before.vz, after.vz, dt)
    climb = before.vz * (1 - decay) / drag if drag > 0 else before.vz * dt
    assert (after.z - before.z) == pytest.approx(climb, abs=0.3)


def test_failsafe_fires_after_com_of_loss_t(sitl):
    link = sitl(0)
    assert command(link, 1, SET_INTERVAL, 0, 20_000).result == 0  # heartbeat at 50 Hz
    offboard_flight(link)
    # Timed from the last setpoint sent, not from the end of the stream's last drain (50 ms
    # later): the vehicle counts its timeout from the last setpoint it received.
    last = stream(link, 1, 1.5, 0.6)
    seen = None
    while time.time() - last < 3.0:
        hb = link.recv_match(type="HEARTBEAT", blocking=True, timeout=0.1)
        if hb is not None and mavutil.mode_string_v10(hb) != "OFFBOARD":
            seen = time.time() - last
            assert hb.system_status == mavutil.mavlink.MAV_STATE_CRITICAL
            assert mavutil.mode_string_v10(hb) == "POSCTL"  # COM_OBL_RC_ACT 0: Position
            break
    assert seen is not None, "no failsafe"
    assert 0.95 <= seen <= 1.5, seen


def test_parameter_list_and_set(sitl):
    link = sitl(0)
    link.mav.param_request_list_send(1, 1)
    values = {}
    count = None
    deadline = time.time() + 5
    while time.time() < deadline and (count is None or len(values) < count):
        p = link.recv_match(type="PARAM_VALUE", blocking=True, timeout=0.5)
        if p is not None:
            count = p.param_count
            values[p.param_index] = p
    assert count is not None and count >= 10
    assert sorted(values) == list(range(count))
    names = {p.param_id for p in values.values()}
    assert {"COM_OF_LOSS_T", "COM_OBL_RC_ACT", "MPC_THR_HOVER", "MAV_SYS_ID"} <= names
    sys_id = next(p for p in values.values() if p.param_id == "MAV_SYS_ID")
    assert sys_id.param_type == mavutil.mavlink.MAV_PARAM_TYPE_INT32
    assert struct.unpack("<i", struct.pack("<f", sys_id.param_value))[0] == 1  # bytewise
    link.mav.param_set_send(1, 1, b"COM_OF_LOSS_T", 2.5, mavutil.mavlink.MAV_PARAM_TYPE_REAL32)
    echo = link.recv_match(type="PARAM_VALUE", blocking=True, timeout=3)
    assert (echo.param_id, echo.param_value) == ("COM_OF_LOSS_T", pytest.approx(2.5))
    # A read-only parameter is echoed unchanged.
    link.mav.param_set_send(1, 1, b"SIM_MASS", 9.0, mavutil.mavlink.MAV_PARAM_TYPE_REAL32)
    echo = link.recv_match(type="PARAM_VALUE", blocking=True, timeout=3)
    assert (echo.param_id, echo.param_value) == ("SIM_MASS", pytest.approx(2.0))


def test_message_interval_changes_the_measured_rate(sitl):
    link = sitl(0)
    assert command(link, 1, SET_INTERVAL, mavutil.mavlink.MAVLINK_MSG_ID_ATTITUDE, 100_000).result == 0
    latest(link, "ATTITUDE", timeout=0.5)
    stamps = []
    end = time.time() + 4.0
    while time.time() < end:
        msg = link.recv_match(type="ATTITUDE", blocking=True, timeout=0.2)
        if msg is not None:
            stamps.append(msg.time_boot_ms)
    rate = (len(stamps) - 1) / ((stamps[-1] - stamps[0]) / 1000.0)
    assert rate == pytest.approx(10.0, rel=0.10), rate


def test_two_vehicles_never_answer_each_others_messages(sitl):
    one, two = sitl(0), sitl(1)
    assert latest(two, "HEARTBEAT").get_srcSystem() == 2
    # A command for system 1 sent to vehicle 2's port is ignored: no ack at all.
    two.mav.command_long_send(1, 1, ARM, 0, 1, 0, 0, 0, 0, 0, 0)
    assert ack_for(two, ARM, timeout=1.5) is None
    # Addressed to 2, it is answered by 2 only.
    ack = command(two, 2, ARM, 1)
    assert ack is not None and ack.get_srcSystem() == 2
    hb1 = latest(one, "HEARTBEAT")
    assert not hb1.base_mode & mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED
    for _ in range(50):
        msg = two.recv_match(blocking=True, timeout=0.1)
        if msg is not None and msg.get_type() != "BAD_DATA":
            assert msg.get_srcSystem() == 2


def test_a_vehicle_can_be_killed_and_restarted(sitl):
    link = sitl(0)
    before = latest(link, "ATTITUDE")
    assert before.time_boot_ms > 0
    sitl.proc.stdin.write("kill 1\n")
    sitl.proc.stdin.flush()
    drain(link, 0.3)
    # Powered off: nothing arrives for a second.
    assert link.recv_match(blocking=True, timeout=1.0) is None
    sitl.proc.stdin.write("restart 1\n")
    sitl.proc.stdin.flush()
    hb = link.recv_match(type="HEARTBEAT", blocking=True, timeout=3.0)
    assert hb is not None and hb.get_srcSystem() == 1
    after = latest(link, "ATTITUDE", timeout=0.5)
    # A fresh boot: time_boot_ms counts from zero again.
    assert after.time_boot_ms < 1000, (before.time_boot_ms, after.time_boot_ms)


def test_hover_throttle_holds_altitude_from_rest_in_the_air(tmp_path):
    """A vehicle started at rest 30 m up (config file, in_air) holds its altitude within a
    few centimetres for 3 s on MPC_THR_HOVER alone."""
    config = tmp_path / "air.toml"
    config.write_text("[[vehicle]]\nprofile = \"ideal\"\nstart_ned_m = [0.0, 0.0, -30.0]\nin_air = true\n")
    proc = subprocess.Popen([BIN, "sitl", "--config", str(config)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    link = mavutil.mavlink_connection("udpin:127.0.0.1:14540", source_system=255, source_component=190)
    try:
        hb = link.wait_heartbeat(timeout=10)
        assert hb.base_mode & mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED, "started in the air: armed"
        hover = read_param(link, "MPC_THR_HOVER")
        assert hover == pytest.approx(0.2)  # ideal profile
        stream(link, 1, 1.2, hover)
        mode = command(link, 1, SET_MODE, 1, 6, 0)
        assert mode is not None and mode.result == 0
        stream(link, 1, 0.5, hover)
        before = latest(link, "LOCAL_POSITION_NED")
        stream(link, 1, 3.0, hover)
        after = latest(link, "LOCAL_POSITION_NED")
        assert mavutil.mode_string_v10(latest(link, "HEARTBEAT")) == "OFFBOARD"
        assert abs(after.z - before.z) < 0.05, (before.z, after.z)
        assert abs(after.vz) < 0.02
    finally:
        link.close()
        proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=10)
        assert proc.returncode == 0, out
