"""MAVSDK-Python's examples against `ringswarm sitl --vehicles 1`, judged on what the
vehicle did, read with pymavlink on the ground-station link (udp 14550), not on what the
scripts print.

The scripts run are `tests/python/mavsdk_examples/*.py`, which take the same steps with
the same values as the official examples of mavlink/MAVSDK-Python (classic API, pip
`mavsdk==3.17.4`); point RINGSWARM_MAVSDK_EXAMPLES at a checkout's `examples/` to run
the official files themselves.

Expected values come from the scripts' setpoints and PX4's defaults (MIS_TAKEOFF_ALT
2.5 m, RTL_RETURN_ALT 30 m, home 47.397742 N 8.545594 E 488 m). Waits are on
conditions with generous timeouts; judgements look for a sustained window (1 s unless
said) in which the telemetry matches within the stated tolerance.
"""

import math
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

pytest.importorskip("mavsdk")
from pymavlink import mavutil  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
BIN = os.environ.get("RINGSWARM_BIN", str(ROOT / "target" / "debug" / "ringswarm"))
EXAMPLES = Path(os.environ.get("RINGSWARM_MAVSDK_EXAMPLES", str(Path(__file__).parent / "mavsdk_examples")))
HOME = (47.397742, 8.545594)
EARTH_RADIUS_M = 6_371_000.0


def local_of(lat, lon):
    """North/east metres of a latitude/longitude from home (the emulator's projection)."""
    north = math.radians(lat - HOME[0]) * EARTH_RADIUS_M
    east = math.radians(lon - HOME[1]) * EARTH_RADIUS_M * math.cos(math.radians(HOME[0]))
    return north, east


class Observer:
    """Records the vehicle's telemetry on the GCS link in a background thread."""

    def __init__(self):
        self.link = mavutil.mavlink_connection("udpin:127.0.0.1:14550", source_system=200)
        self.samples = []  # (time, kind, message)
        self.stop = False
        self.thread = threading.Thread(target=self.run, daemon=True)
        self.thread.start()

    def run(self):
        while not self.stop:
            msg = self.link.recv_match(blocking=True, timeout=0.2)
            if msg is not None and msg.get_srcSystem() == 1:
                self.samples.append((time.monotonic(), msg.get_type(), msg))

    def of(self, kind):
        return [(t, m) for t, k, m in list(self.samples) if k == kind]

    def wait(self, predicate, timeout, what):
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if predicate(self):
                return
            time.sleep(0.2)
        raise AssertionError(f"timed out waiting for {what}")

    def armed(self):
        beats = self.of("HEARTBEAT")
        return bool(beats) and bool(beats[-1][1].base_mode & 128)

    def mode(self):
        beats = self.of("HEARTBEAT")
        return mavutil.mode_string_v10(beats[-1][1]) if beats else None

    def landed(self):
        states = self.of("EXTENDED_SYS_STATE")
        return bool(states) and states[-1][1].landed_state == 1

    def close(self):
        self.stop = True
        self.thread.join(timeout=2)
        self.link.close()


def held(samples, check, seconds=1.0):
    """Whether `check(message)` is true for every sample of some window `seconds` long."""
    start = None
    for t, m in samples:
        if check(m):
            start = t if start is None else start
            if t - start >= seconds:
                return True
        else:
            start = None
    return False


def yaw_close(yaw_rad, want_deg, tol_deg):
    return abs((math.degrees(yaw_rad) - want_deg + 180.0) % 360.0 - 180.0) <= tol_deg


def stop_group(proc, timeout=10):
    """Stops a process started in its own session and everything it started (the
    example's mavsdk_server holds udp 14540 until it dies): SIGINT, then SIGKILL."""
    for sig in (signal.SIGINT, signal.SIGKILL):
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            break
        try:
            return proc.communicate(timeout=timeout)[0]
        except subprocess.TimeoutExpired:
            continue
    return proc.communicate()[0]


@pytest.fixture
def flight():
    sitl = subprocess.Popen([BIN, "sitl", "--vehicles", "1"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, stdin=subprocess.DEVNULL, text=True, start_new_session=True)
    observer = Observer()
    try:
        observer.wait(lambda o: o.of("HEARTBEAT"), 10, "the first heartbeat")
        yield observer
    finally:
        observer.close()
        err = stop_group(sitl)
    assert sitl.returncode == 0, err


def start_example(name):
    script = EXAMPLES / f"{name}.py"
    return subprocess.Popen([sys.executable, str(script)], cwd=str(script.parent), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True)


def run_example(name, timeout_s):
    """Runs an example to its end (at most `timeout_s`); its whole process group is
    stopped either way."""
    proc = start_example(name)
    try:
        out, _ = proc.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        out = stop_group(proc)
        raise AssertionError(f"{name} did not finish in {timeout_s} s:\n{out}")
    finally:
        stop_group(proc, timeout=5)
    assert proc.returncode == 0, f"{name} failed:\n{out}"
    return out


def local(o):
    return o.of("LOCAL_POSITION_NED")


def test_takeoff_and_land(flight):
    run_example("takeoff_and_land", 120)
    # Takeoff to MIS_TAKEOFF_ALT = 2.5 m and a hold exactly there.
    assert held(local(flight), lambda m: abs(-m.z - 2.5) < 0.05, seconds=3.0), "held 2.5 m"
    assert max(-m.z for _, m in local(flight)) < 2.5 + 0.15
    flight.wait(lambda o: o.landed() and not o.armed(), 60, "landed and disarmed")


def test_offboard_attitude(flight):
    run_example("offboard_attitude", 120)
    attitude = flight.of("ATTITUDE")
    assert held(attitude, lambda m: abs(math.degrees(m.roll) - 30.0) < 3.0, 0.5), "rolled +30°"
    assert held(attitude, lambda m: abs(math.degrees(m.roll) + 30.0) < 3.0, 0.5), "rolled −30°"
    assert max(-m.z for _, m in local(flight)) > 3.0, "climbed at 70 % thrust"
    # offboard.stop() then land(): Hold, then AUTO.LAND descending at MPC_Z_V_AUTO_DN
    # (1.5 m/s) from tens of metres (the touchdown itself is test_takeoff_and_land's).
    flight.wait(lambda o: o.mode() == "LAND", 20, "AUTO.LAND")
    flight.wait(lambda o: any(abs(m.vz - 1.5) < 0.1 for _, m in local(o)[-10:]), 30, "descending at 1.5 m/s")


def test_offboard_velocity_ned(flight):
    run_example("offboard_velocity_ned", 120)
    pos = local(flight)
    for (vn, ve, vd), yaw in [((0, 0, -2), None), ((2, 0, 0), 90), ((-2, 0, 0), 270), ((0, -2, 0), 90), ((0, 2, 0), 90), ((0, 0, 1), None)]:
        # 4 s phases that start with a reversal and a yaw turn: held for half a second.
        ok = held(pos, lambda m: math.dist((m.vx, m.vy, m.vz), (vn, ve, vd)) < 0.2, 0.5)
        closest = min(math.dist((m.vx, m.vy, m.vz), (vn, ve, vd)) for _, m in pos)
        assert ok, f"velocity ({vn}, {ve}, {vd}) held for 0.5 s (closest {closest:.2f} m/s)"
        if yaw is not None:
            ok = held(flight.of("ATTITUDE"), lambda m: yaw_close(m.yaw, yaw, 3.0))
            assert ok, f"yaw {yaw}°"


def test_offboard_velocity_body(flight):
    run_example("offboard_velocity_body", 150)
    att, pos = flight.of("ATTITUDE"), local(flight)
    assert held(att, lambda m: abs(math.degrees(m.yawspeed) - 60.0) < 6.0), "turning at +60°/s"
    assert held(att, lambda m: abs(math.degrees(m.yawspeed) + 60.0) < 6.0), "turning at −60°/s"
    assert held(pos, lambda m: abs(m.vz + 1.0) < 0.15), "climbing at 1 m/s"
    # Circles: 5 m/s while turning at 30°/s (radius 5/0.524 = 9.5 m), for 5 s.
    assert held(pos, lambda m: abs(math.hypot(m.vx, m.vy) - 5.0) < 0.3, 5.0), "circling at 5 m/s"
    assert held(att, lambda m: abs(math.degrees(m.yawspeed) - 30.0) < 3.0, 5.0), "turning at 30°/s"


def test_offboard_position_ned(flight):
    run_example("offboard_position_ned", 120)
    pos, att = local(flight), flight.of("ATTITUDE")
    for (n, e, d), yaw in [((0, 0, -5), 0), ((5, 0, -5), 90), ((5, 10, -5), 90), ((0, 10, 0), 180)]:
        assert held(pos, lambda m: math.dist((m.x, m.y, m.z), (n, e, d)) < 0.3), f"held ({n}, {e}, {d})"
        assert held(att, lambda m: yaw_close(m.yaw, yaw, 3.0)), f"yaw {yaw}°"


def test_offboard_position_velocity_ned(flight):
    run_example("offboard_position_velocity_ned", 120)
    pos = local(flight)
    # A velocity feed-forward that stays on moves the equilibrium: PX4's position loop
    # settles where P·(p_sp − p) + v_ff = 0, i.e. v_ff/P beyond the setpoint: 1 m above
    # 10 m (MPC_Z_P 1.0); then, with no vertical feed-forward, at 10 m and 1/0.95 m past
    # 50 m north (MPC_XY_P 0.95).
    up = (0.0, 0.0, -10.0 - 1.0 / 1.0)
    north = (50.0 + 1.0 / 0.95, 0.0, -10.0)
    for point in (up, north):
        closest = min(math.dist((m.x, m.y, m.z), point) for _, m in pos)
        assert held(pos, lambda m: math.dist((m.x, m.y, m.z), point) < 0.3), f"held {point} (closest {closest:.2f} m)"


def test_goto(flight):
    target = local_of(47.397606, 8.543060)
    def there(o):
        last = o.of("GLOBAL_POSITION_INT")
        if not last:
            return False
        m = last[-1][1]
        n, e = local_of(m.lat * 1e-7, m.lon * 1e-7)
        return math.dist((n, e), target) < 1.0 and abs(m.relative_alt / 1000.0 - 20.0) < 0.3
    done = threading.Event()
    def stop_when_there():
        try:
            flight.wait(there, 150, "the goto target")
            done.set()
        except AssertionError:
            pass
    watcher = threading.Thread(target=stop_when_there)
    watcher.start()
    # The example never ends: it is stopped once the vehicle is there (or after 160 s).
    proc = start_example("goto")
    done.wait(160)
    stop_group(proc)
    watcher.join()
    assert done.is_set(), "reached 47.397606, 8.543060 at 20 m above home within 1 m"
    att = flight.of("ATTITUDE")
    assert held(att, lambda m: yaw_close(m.yaw, 0.0, 3.0)), "facing north"
    assert flight.mode() == "LOITER"


def test_mission(flight):
    run_example("mission", 300)
    reached = {m.seq for _, m in flight.of("MISSION_ITEM_REACHED")}
    # Items: WP, speed, WP, speed, WP, speed, RTL.
    assert {0, 2, 4, 6} <= reached, reached
    glob = flight.of("GLOBAL_POSITION_INT")
    for lat, lon in [(47.398039860, 8.545572540), (47.398036222, 8.545014644), (47.397825621, 8.545009283)]:
        wp = local_of(lat, lon)
        near = [m for _, m in glob if math.dist(local_of(m.lat * 1e-7, m.lon * 1e-7), wp) < 3.0]
        assert near, f"passed within 3 m of {lat}, {lon}"
        alts = [m.relative_alt / 1000.0 for m in near]
        assert any(abs(a - 25.0) < 0.5 for a in alts), f"at 25 m: {min(alts):.2f}..{max(alts):.2f}"
    # Returned: climbed to RTL_RETURN_ALT (30 m) and landed at home, disarmed.
    assert max(m.relative_alt for _, m in glob) / 1000.0 > 29.5
    flight.wait(lambda o: o.landed() and not o.armed(), 60, "landed and disarmed")
    last = flight.of("GLOBAL_POSITION_INT")[-1][1]
    assert math.dist(local_of(last.lat * 1e-7, last.lon * 1e-7), (0.0, 0.0)) < 1.0
