"""The mission protocol of `ringswarm sitl --vehicles 1` with pymavlink as the ground
station, over UDP on the offboard link (14540 ↔ 14580): upload, download round trip,
each specific MISSION_ACK error with the stored mission left unchanged, a lost
MISSION_ITEM_INT asked for again, and a flown mission reported item by item.

Expected behaviour is PX4's `mavlink_mission.cpp`: a request re-sent every 250 ms, items
out of sequence ignored, a bad item answered with its error and the transfer ended.
"""

import math
import os
import signal
import subprocess
import time
from pathlib import Path

import pytest
from pymavlink import mavutil

ROOT = Path(__file__).resolve().parents[2]
BIN = os.environ.get("RINGSWARM_BIN", str(ROOT / "target" / "debug" / "ringswarm"))


def mavlink2_common():
    """pymavlink's MAVLink 2 common dialect (mission_type and MISSION_CURRENT's
    mission_state are MAVLink 2 extensions); the previous dialect is put back after."""
    previous = (os.environ.get("MAVLINK20"), mavutil.current_dialect)
    os.environ["MAVLINK20"] = "1"
    mavutil.set_dialect("common")
    return previous


def restore_dialect(previous):
    env, dialect = previous
    if env is None:
        os.environ.pop("MAVLINK20", None)
    else:
        os.environ["MAVLINK20"] = env
    mavutil.set_dialect(dialect)


class _Mav:
    """`M.NAME` reads the dialect in force now, not the one at import."""

    def __getattr__(self, name):
        return getattr(mavutil.mavlink, name)


M = _Mav()
HOME = (47.397742, 8.545594)
EARTH_RADIUS_M = 6_371_000.0


def lat_lon_e7(north_m, east_m):
    lat = HOME[0] + math.degrees(north_m / EARTH_RADIUS_M)
    lon = HOME[1] + math.degrees(east_m / (EARTH_RADIUS_M * math.cos(math.radians(HOME[0]))))
    return round(lat * 1e7), round(lon * 1e7)


@pytest.fixture
def link():
    previous = mavlink2_common()
    proc = subprocess.Popen([BIN, "sitl", "--vehicles", "1"], stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    conn = mavutil.mavlink_connection("udpin:127.0.0.1:14540", source_system=246, source_component=190)
    try:
        conn.wait_heartbeat(timeout=10)
        yield conn
    finally:
        conn.close()
        restore_dialect(previous)
        proc.send_signal(signal.SIGINT)
        try:
            out, _ = proc.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            out, _ = proc.communicate()
    assert proc.returncode == 0, out


def item(seq, north_m, east_m, alt_m, command=16, frame=6, params=(0, 1.0, 0, math.nan)):
    """A MISSION_ITEM_INT (default NAV_WAYPOINT in GLOBAL_RELATIVE_ALT_INT)."""
    lat, lon = lat_lon_e7(north_m, east_m)
    return M.MAVLink_mission_item_int_message(1, 1, seq, frame, command, int(seq == 0), 1, *params, lat, lon, alt_m, 0)


def recv(conn, kind, timeout=3.0, where=lambda m: True):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        m = conn.recv_match(type=kind, blocking=True, timeout=0.2)
        if m is not None and where(m):
            return m
    return None


def upload(conn, items, drop=(), mission_type=None):
    """Answers each MISSION_REQUEST_INT with its item (never those in `drop` the first
    time); returns (the requested sequence numbers, the final MISSION_ACK)."""
    mission_type = M.MAV_MISSION_TYPE_MISSION if mission_type is None else mission_type
    conn.mav.mission_count_send(1, 1, len(items), mission_type)
    asked, dropped = [], set()
    while True:
        m = recv(conn, ["MISSION_REQUEST_INT", "MISSION_ACK"], timeout=6.0)
        if m is None or m.get_type() == "MISSION_ACK":
            return asked, m
        asked.append(m.seq)
        if m.seq in drop and m.seq not in dropped:
            dropped.add(m.seq)
            continue
        conn.mav.send(items[m.seq])


def download(conn, mission_type=None):
    mission_type = M.MAV_MISSION_TYPE_MISSION if mission_type is None else mission_type
    conn.mav.mission_request_list_send(1, 1, mission_type)
    count = recv(conn, "MISSION_COUNT", where=lambda m: m.mission_type == mission_type)
    assert count is not None
    got = []
    for seq in range(count.count):
        conn.mav.mission_request_int_send(1, 1, seq, mission_type)
        m = recv(conn, "MISSION_ITEM_INT", where=lambda m, s=seq: m.seq == s)
        assert m is not None, f"item {seq}"
        got.append(m)
    conn.mav.mission_ack_send(1, 1, M.MAV_MISSION_ACCEPTED, mission_type)
    return got


def square():
    return [item(0, 0, 0, 10), item(1, 20, 0, 10), item(2, 20, 20, 12), item(3, 0, 20, 12)]


def test_upload_then_download_round_trips(link):
    asked, ack = upload(link, square())
    assert asked == [0, 1, 2, 3]
    assert ack.type == M.MAV_MISSION_ACCEPTED
    got = download(link)
    assert [(m.seq, m.x, m.y, m.z, m.command) for m in got] == [(i.seq, i.x, i.y, i.z, i.command) for i in square()]
    assert all(m.frame == M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT for m in got)


def test_a_lost_item_is_asked_for_again(link):
    start = time.monotonic()
    asked, ack = upload(link, square(), drop={2})
    assert ack.type == M.MAV_MISSION_ACCEPTED
    assert asked == [0, 1, 2, 2, 3], asked
    # The second request comes after PX4's 250 ms retry (well under the 5 s timeout).
    assert time.monotonic() - start < 3.0


@pytest.mark.parametrize(
    "bad, error",
    [
        # NAV_LOITER_TURNS (18): PX4 does not take it in missions.
        (dict(command=18), "MAV_MISSION_UNSUPPORTED"),
        # MAV_FRAME_LOCAL_NED (1) for a waypoint.
        (dict(frame=1), "MAV_MISSION_UNSUPPORTED_FRAME"),
        # A waypoint's param3 (pass radius) is not used by PX4.
        (dict(params=(0, 1.0, 7.0, math.nan)), "MAV_MISSION_INVALID_PARAM3"),
        # DO_CHANGE_SPEED (178) in a global frame instead of MAV_FRAME_MISSION.
        (dict(command=178), "MAV_MISSION_UNSUPPORTED_FRAME"),
    ],
    ids=["unsupported-command", "local-frame", "waypoint-param3", "do-item-in-global-frame"],
)
def test_a_bad_item_gets_its_error_and_the_stored_mission_stays(link, bad, error):
    bad = item(1, 5, 5, 10, **bad)
    error = getattr(M, error)
    upload(link, square())
    asked, ack = upload(link, [item(0, 1, 1, 5), bad, item(2, 3, 3, 5)])
    assert ack is not None and ack.type == error, ack
    assert asked == [0, 1]
    assert [m.x for m in download(link)] == [i.x for i in square()]


def test_too_many_items_is_no_space(link):
    link.mav.mission_count_send(1, 1, 20000, M.MAV_MISSION_TYPE_MISSION)
    ack = recv(link, "MISSION_ACK")
    assert ack.type == M.MAV_MISSION_NO_SPACE


def test_clear_all_empties_the_mission(link):
    upload(link, square())
    link.mav.mission_clear_all_send(1, 1, M.MAV_MISSION_TYPE_MISSION)
    assert recv(link, "MISSION_ACK").type == M.MAV_MISSION_ACCEPTED
    link.mav.mission_request_list_send(1, 1, M.MAV_MISSION_TYPE_MISSION)
    assert recv(link, "MISSION_COUNT").count == 0


def test_mission_start_flies_every_item_and_reports_it(link):
    upload(link, square())
    link.mav.command_long_send(1, 1, M.MAV_CMD_MISSION_START, 0, 0, 0, 0, 0, 0, 0, 0)
    ack = recv(link, "COMMAND_ACK", where=lambda m: m.command == M.MAV_CMD_MISSION_START)
    assert ack.result == M.MAV_RESULT_ACCEPTED
    reached = []
    end = time.monotonic() + 90
    while time.monotonic() < end and len(set(reached)) < 4:
        m = recv(link, "MISSION_ITEM_REACHED", timeout=1.0)
        if m is not None and m.seq not in reached:
            reached.append(m.seq)
    assert reached == [0, 1, 2, 3]
    # Then Hold at the last waypoint, 12 m up, and MISSION_CURRENT says complete.
    current = recv(link, "MISSION_CURRENT", timeout=3.0, where=lambda m: m.mission_state == 5)
    assert current is not None and current.total == 4
    beat = recv(link, "HEARTBEAT", where=lambda m: m.get_srcComponent() == 1)
    assert mavutil.mode_string_v10(beat) == "LOITER"
    # Holding the last waypoint: within ~0.35 m (30 degE7 of latitude, 45 of longitude)
    # and 0.3 m of its altitude.
    lat, lon = lat_lon_e7(0, 20)
    def holding(m):
        return abs(m.relative_alt / 1000.0 - 12.0) < 0.3 and abs(m.lat - lat) < 30 and abs(m.lon - lon) < 45
    assert recv(link, "GLOBAL_POSITION_INT", timeout=15.0, where=holding) is not None
