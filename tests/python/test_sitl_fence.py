"""The fence plan (mission type FENCE) of `ringswarm sitl --vehicles 1` with pymavlink as
the ground station, over UDP on the offboard link: upload and download round trip, PX4's
specific errors with the stored fence left unchanged, and PX4's breach action (GF_ACTION
2, Hold, its default) when the vehicle is flown out of the fence.

Expected behaviour is PX4 main's `mavlink_mission.cpp` (fence items per item: at least 3
vertices, param2-4 and z zero or NaN; items come back in MAV_FRAME_GLOBAL_INT) and its
navigator's 200 ms geofence check with the commander's GF_ACTION.
"""

import math
import time

from test_sitl_mission import EARTH_RADIUS_M, HOME, M, download, lat_lon_e7, link, recv, upload  # noqa: F401

POLYGON_VERTEX_INCLUSION = 5001
CIRCLE_INCLUSION = 5003


def vertex(seq, north_m, east_m, count=4, z=0.0, command=POLYGON_VERTEX_INCLUSION):
    lat, lon = lat_lon_e7(north_m, east_m)
    return M.MAVLink_mission_item_int_message(
        1, 1, seq, M.MAV_FRAME_GLOBAL, command, 0, 0, float(count), 0, 0, 0, lat, lon, z, M.MAV_MISSION_TYPE_FENCE
    )


def square(half_m=50.0):
    corners = [(-half_m, -half_m), (-half_m, half_m), (half_m, half_m), (half_m, -half_m)]
    return [vertex(seq, n, e) for seq, (n, e) in enumerate(corners)]


def test_a_fence_uploads_and_downloads_as_px4_gives_it_back(link):
    asked, ack = upload(link, square(), mission_type=M.MAV_MISSION_TYPE_FENCE)
    assert asked == [0, 1, 2, 3]
    assert ack.type == M.MAV_MISSION_ACCEPTED and ack.mission_type == M.MAV_MISSION_TYPE_FENCE
    got = download(link, mission_type=M.MAV_MISSION_TYPE_FENCE)
    assert [(m.x, m.y, m.command, m.param1) for m in got] == [(v.x, v.y, v.command, 4.0) for v in square()]
    assert all(m.frame == M.MAV_FRAME_GLOBAL_INT and m.mission_type == M.MAV_MISSION_TYPE_FENCE for m in got)
    # The mission is untouched. (This pymavlink's dialect predates the opaque_id and
    # fence_id fields; the Rust tests check them.)
    link.mav.mission_request_list_send(1, 1, M.MAV_MISSION_TYPE_MISSION)
    assert recv(link, "MISSION_COUNT", where=lambda m: m.mission_type == M.MAV_MISSION_TYPE_MISSION).count == 0


def test_bad_fence_items_get_px4s_errors_and_the_stored_fence_stays(link):
    upload(link, square(), mission_type=M.MAV_MISSION_TYPE_FENCE)
    too_few = [vertex(seq, 10 * seq, 0, count=2) for seq in range(2)]
    _, ack = upload(link, too_few, mission_type=M.MAV_MISSION_TYPE_FENCE)
    assert ack.type == M.MAV_MISSION_ERROR
    high = [vertex(0, 0, 0, count=30.0, command=CIRCLE_INCLUSION, z=40.0)]
    _, ack = upload(link, high, mission_type=M.MAV_MISSION_TYPE_FENCE)
    assert ack.type == M.MAV_MISSION_INVALID_PARAM7
    link.mav.mission_count_send(1, 1, 65, M.MAV_MISSION_TYPE_FENCE)
    assert recv(link, "MISSION_ACK").type == M.MAV_MISSION_NO_SPACE
    got = download(link, mission_type=M.MAV_MISSION_TYPE_FENCE)
    assert [m.x for m in got] == [v.x for v in square()]
    link.mav.mission_clear_all_send(1, 1, M.MAV_MISSION_TYPE_FENCE)
    assert recv(link, "MISSION_ACK").type == M.MAV_MISSION_ACCEPTED
    assert download(link, mission_type=M.MAV_MISSION_TYPE_FENCE) == []


def test_flown_out_of_its_fence_the_vehicle_holds_as_gf_action_says(link):
    """A circle of 8 m about home; offboard velocity north at 3 m/s from 5 m up: the
    vehicle switches to Hold (AUTO.LOITER) at the first 200 ms check past 8 m."""
    radius_m = 8.0
    _, ack = upload(link, [vertex(0, 0, 0, count=radius_m, command=CIRCLE_INCLUSION)], mission_type=M.MAV_MISSION_TYPE_FENCE)
    assert ack.type == M.MAV_MISSION_ACCEPTED
    # Velocity x/y, position z, yaw (MAVSDK's set_velocity_ned masks out the rest).
    mask = 0x9C3

    def setpoint(vn):
        link.mav.set_position_target_local_ned_send(0, 1, 1, M.MAV_FRAME_LOCAL_NED, mask, 0, 0, -5.0, vn, 0, 0, 0, 0, 0, 0, 0)

    for _ in range(10):
        setpoint(0.0)
        time.sleep(0.05)
    link.mav.command_long_send(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
    assert recv(link, "COMMAND_ACK", where=lambda m: m.command == M.MAV_CMD_COMPONENT_ARM_DISARM).result == M.MAV_RESULT_ACCEPTED
    link.mav.command_long_send(1, 1, M.MAV_CMD_DO_SET_MODE, 0, 1, 6, 0, 0, 0, 0, 0)
    assert recv(link, "COMMAND_ACK", where=lambda m: m.command == M.MAV_CMD_DO_SET_MODE).result == M.MAV_RESULT_ACCEPTED
    texts, held, north_m, up_m = [], None, 0.0, 0.0
    end = time.monotonic() + 60
    while time.monotonic() < end and held is None:
        # North once 4 m up (the climb to 5 m is inside the fence).
        setpoint(3.0 if up_m > 4.0 else 0.0)
        # Every message is read here: recv_match with a type drops the others.
        for m in iter(lambda: link.recv_match(blocking=False), None):
            kind = m.get_type()
            if kind == "STATUSTEXT":
                texts.append(m.text)
            elif kind == "LOCAL_POSITION_NED":
                north_m, up_m = m.x, -m.z
            elif kind == "HEARTBEAT" and m.get_srcComponent() == 1 and m.custom_mode == (4 << 16 | 3 << 24):
                held = north_m
        time.sleep(0.05)
    assert held is not None, f"never in Hold; texts {texts}"
    assert "Geofence: approaching or outside geofence" in texts, texts
    assert "Failsafe activated\t" in texts, texts
    # Held just outside the circle: past it by one check interval (0.2 s) of travel at
    # 3 m/s and a position report's age (20 ms), then the braking in Hold
    # (3²/(2·3 m/s²) = 1.5 m) before the 1 Hz heartbeat says so.
    assert radius_m <= held < radius_m + 0.6 + 0.1 + 1.5, held
