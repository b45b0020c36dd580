"""`ringswarm sitl --autopilot ardupilot` against pymavlink and MAVProxy over real UDP, as
they speak to ArduCopter: its heartbeat and mode names, nothing streamed until asked, the
arm refused with its STATUSTEXT until the EKF settles, GUIDED thrust read as a climb rate,
its parameters by name, and MAVProxy's own `mode GUIDED`, `arm throttle`, `takeoff`.

Expected numbers are ArduCopter's (../shared/ardupilot-sitl/INTERFACE.md): a climb rate of
(thrust − 0.5) · 2 · WPNAV_SPEED_UP (250 cm/s). Timing tolerances are wide enough for a
loaded CI machine; every check still compares a number with an expected value.
"""

import os
import queue
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from pymavlink import mavutil

ROOT = Path(__file__).resolve().parents[2]
BIN = os.environ.get("RINGSWARM_BIN", str(ROOT / "target" / "debug" / "ringswarm"))
MAVPROXY = Path(sys.executable).parent / "mavproxy.py"

ARM = mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM
SET_MODE = mavutil.mavlink.MAV_CMD_DO_SET_MODE
SET_INTERVAL = mavutil.mavlink.MAV_CMD_SET_MESSAGE_INTERVAL
GUIDED, LAND = 4, 9
LEVEL = [1.0, 0.0, 0.0, 0.0]
SETTLE_S = 4.0


def start_sitl():
    return subprocess.Popen(
        [BIN, "sitl", "--vehicles", "1", "--autopilot", "ardupilot", "--ekf-settle-s", str(SETTLE_S)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )


def stop_sitl(proc):
    proc.send_signal(signal.SIGINT)
    out, _ = proc.communicate(timeout=10)
    assert proc.returncode == 0, out
    assert "panicked" not in out


@pytest.fixture
def copter():
    proc = start_sitl()
    link = mavutil.mavlink_connection("udpin:127.0.0.1:14540", source_system=255, source_component=190)
    link.wait_heartbeat(timeout=10)
    link.started = time.time()
    link.texts = []
    yield link
    link.close()
    stop_sitl(proc)


def ack_for(link, command, timeout=3.0):
    """The COMMAND_ACK for `command`; the STATUSTEXTs read meanwhile go to `link.texts`
    (ArduPilot says why it refuses before it acknowledges)."""
    deadline = time.time() + timeout
    while time.time() < deadline:
        msg = link.recv_match(type=["COMMAND_ACK", "STATUSTEXT"], blocking=True, timeout=0.05)
        if msg is not None and msg.get_type() == "STATUSTEXT":
            link.texts.append(msg.text)
        elif msg is not None and msg.command == command:
            return msg
    return None


def command(link, cmd, *params):
    params = list(params) + [0.0] * (7 - len(params))
    link.mav.command_long_send(1, 1, cmd, 0, *params)
    return ack_for(link, cmd)


def param(link, name, value=None):
    if value is None:
        link.mav.param_request_read_send(1, 1, name.encode(), -1)
    else:
        link.mav.param_set_send(1, 1, name.encode(), value, mavutil.mavlink.MAV_PARAM_TYPE_INT32)
    deadline = time.time() + 3
    while time.time() < deadline:
        p = link.recv_match(type="PARAM_VALUE", blocking=True, timeout=0.2)
        if p is not None and p.param_id == name:
            return p
    raise AssertionError(f"no PARAM_VALUE for {name}")


def climb_while_streaming(link, thrust, seconds, hz=20.0):
    """Streams a level attitude with `thrust` for `seconds`; the climb rates (m/s, up) of
    the LOCAL_POSITION_NED reports of the last second."""
    end = time.time() + seconds
    climbs = []
    while time.time() < end:
        link.mav.set_attitude_target_send(0, 1, 1, 7, LEVEL, 0, 0, 0, thrust)
        tick_end = time.time() + 1.0 / hz
        while time.time() < tick_end:
            msg = link.recv_match(type="LOCAL_POSITION_NED", blocking=True, timeout=0.01)
            if msg is not None and end - time.time() < 1.0:
                climbs.append(-msg.vz)
    return climbs


def types_for(link, seconds):
    seen = set()
    end = time.time() + seconds
    while time.time() < end:
        msg = link.recv_match(blocking=True, timeout=0.05)
        if msg is not None:
            seen.add(msg.get_type())
    return seen


def test_arducopter_on_the_wire_to_pymavlink(copter):
    link = copter
    hb = link.recv_match(type="HEARTBEAT", blocking=True, timeout=3)
    assert (hb.type, hb.autopilot, hb.base_mode, hb.custom_mode) == (2, 3, 81, 0)
    assert mavutil.mode_string_v10(hb) == "STABILIZE"
    # Nothing but its heartbeat until asked.
    assert types_for(link, 1.5) <= {"HEARTBEAT", "STATUSTEXT"}
    # Parameters by 4.7 name, integers as plain floats.
    assert param(link, "MAV_SYSID").param_value == 1.0
    assert param(link, "GUID_OPTIONS").param_value == 0.0
    assert param(link, "MAV_GCS_SYSID").param_value == 255.0
    assert abs(param(link, "MOT_THST_HOVER").param_value - 0.39) < 1e-6
    # SET_MESSAGE_INTERVAL: param3 must be 0.
    assert command(link, SET_INTERVAL, 32, 50_000, 1).result == mavutil.mavlink.MAV_RESULT_DENIED
    assert command(link, SET_INTERVAL, 32, 50_000, 0).result == mavutil.mavlink.MAV_RESULT_ACCEPTED
    # GUIDED, one ACK, the heartbeat at once; arming refused before the EKF settles.
    assert command(link, SET_MODE, 1, GUIDED).result == mavutil.mavlink.MAV_RESULT_ACCEPTED
    hb = link.recv_match(type="HEARTBEAT", blocking=True, timeout=2)
    assert mavutil.mode_string_v10(hb) == "GUIDED"
    if time.time() - link.started < SETTLE_S - 1.0:
        assert command(link, ARM, 1).result == mavutil.mavlink.MAV_RESULT_FAILED
        assert link.texts[-1:] == ["Arm: Need Position Estimate"]
    # The position stream starts once the EKF has an origin; then it arms.
    first = link.recv_match(type="LOCAL_POSITION_NED", blocking=True, timeout=SETTLE_S + 5)
    assert first is not None
    assert time.time() - link.started >= SETTLE_S - 1.0
    assert command(link, ARM, 1).result == mavutil.mavlink.MAV_RESULT_ACCEPTED
    # Thrust is a climb rate: 0.75 → (0.75 − 0.5) · 2 · 2.5 m/s = 1.25 m/s up (the motors
    # start 2 s after the arm, then it takes off and settles).
    climbs = climb_while_streaming(link, 0.75, 8.0)
    assert climbs and abs(sum(climbs) / len(climbs) - 1.25) < 0.1, climbs
    # 0.5 holds the altitude.
    climbs = climb_while_streaming(link, 0.5, 4.0)
    assert climbs and abs(sum(climbs) / len(climbs)) < 0.1, climbs
    # LAND: down and disarmed by itself, still in LAND.
    assert command(link, SET_MODE, 1, LAND).result == mavutil.mavlink.MAV_RESULT_ACCEPTED
    deadline = time.time() + 40
    hb = None
    while time.time() < deadline:
        hb = link.recv_match(type="HEARTBEAT", blocking=True, timeout=1)
        if hb is not None and not hb.base_mode & mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED:
            break
    assert hb is not None and hb.base_mode == 81 and hb.custom_mode == LAND


def test_mavproxy_flies_it_with_its_own_commands(tmp_path):
    """MAVProxy (headless, commands on stdin) sees an ArduCopter: `mode GUIDED`,
    `arm throttle`, `takeoff 10`, then `mode LAND`, each sent once MAVProxy shows what the
    one before did; its telemetry log shows the climb to 10 m above home and the disarm on
    the ground."""
    if not MAVPROXY.exists():
        pytest.skip(f"MAVProxy is not installed in this venv ({MAVPROXY})")
    proc = start_sitl()
    mavproxy = subprocess.Popen(
        [sys.executable, str(MAVPROXY), "--master=udpin:127.0.0.1:14540", f"--state-basedir={tmp_path}"],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        cwd=tmp_path,
    )
    lines = queue.Queue()
    threading.Thread(target=lambda: [lines.put(l) for l in mavproxy.stdout], daemon=True).start()
    seen = []

    def wait_for(text, timeout=30.0, poll=None):
        """Reads MAVProxy's output until a line holds `text` (sending `poll` every
        second meanwhile); the line."""
        deadline = time.time() + timeout
        next_poll = time.time()
        while time.time() < deadline:
            if poll is not None and time.time() >= next_poll:
                send(poll)
                next_poll = time.time() + 1.0
            try:
                line = lines.get(timeout=0.2)
            except queue.Empty:
                continue
            seen.append(line)
            if text(line) if callable(text) else text in line:
                return line
        raise AssertionError(f"MAVProxy never printed {text!r}:\n{''.join(seen)[-3000:]}")

    def send(command):
        mavproxy.stdin.write(command + "\n")
        mavproxy.stdin.flush()

    def climbed(line):
        # `status GLOBAL_POSITION_INT` prints the last one: "... relative_alt : 9876 ...".
        if "relative_alt" not in line:
            return False
        alt_mm = line.split("relative_alt")[1].split(":")[1].split(",")[0]
        return int(alt_mm.strip()) >= 9500

    try:
        # Commands only once MAVProxy knows the vehicle (it maps mode names by autopilot).
        wait_for("online system 1")
        send("mode GUIDED")
        wait_for("GUIDED>")
        # Arming waits for the EKF (--ekf-settle-s): MAVProxy says so, and is asked again.
        deadline = time.time() + SETTLE_S + 20.0
        while time.time() < deadline:
            send("arm throttle")
            ack = wait_for("COMPONENT_ARM_DISARM")
            if "ACCEPTED" in ack:
                break
            time.sleep(1.0)
        # MAVProxy says ARMED when the heartbeat shows it (before or after the ACK).
        armed_line = lambda l: "ARMED" in l and "DISARMED" not in l  # noqa: E731
        if not any(armed_line(l) for l in seen):
            wait_for(armed_line)
        send("takeoff 10")
        wait_for("Got COMMAND_ACK: NAV_TAKEOFF: ACCEPTED")
        wait_for(climbed, timeout=40.0, poll="status GLOBAL_POSITION_INT")
        send("mode LAND")
        wait_for("LAND>")
        wait_for("DISARMED", timeout=60.0)
        # The end of its input stops MAVProxy.
        mavproxy.stdin.close()
        mavproxy.wait(timeout=20)
        while not lines.empty():
            seen.append(lines.get())
    finally:
        if mavproxy.poll() is None:
            mavproxy.kill()
        stop_sitl(proc)
    out = "".join(seen)
    assert "Got COMMAND_ACK: DO_SET_MODE: ACCEPTED" in out, out
    assert "Got COMMAND_ACK: COMPONENT_ARM_DISARM: ACCEPTED" in out, out
    tlog = mavutil.mavlink_connection(str(next(tmp_path.rglob("mav.tlog"))))
    top, modes, armed = 0.0, [], False
    while (msg := tlog.recv_match(type=["GLOBAL_POSITION_INT", "HEARTBEAT"])) is not None:
        if msg.get_type() == "GLOBAL_POSITION_INT":
            top = max(top, msg.relative_alt / 1000.0)
        elif msg.get_srcSystem() == 1:
            modes.append(msg.custom_mode)
            armed = armed or bool(msg.base_mode & mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
    # The disarm is what MAVProxy printed last (its log may stop before that heartbeat).
    assert armed
    assert GUIDED in modes and modes[-1] == LAND
    # NAV_TAKEOFF's altitude is above home: 10 m (the takeoff's own slow-down).
    assert 9.5 <= top < 10.5, top
