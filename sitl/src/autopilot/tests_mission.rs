//! The mission protocol and AUTO.MISSION, with the emulator's own encoder as the peer.

use std::time::Duration;

use mavlink::dialects::common::{
    MISSION_COUNT_DATA, MISSION_ITEM_INT_DATA, MISSION_REQUEST_INT_DATA, MISSION_REQUEST_LIST_DATA,
    MavCmd, MavFrame, MavMessage, MavMissionResult, MavMissionType, MavResult, MissionState,
};
use nalgebra::Vector3;

use super::tests::Rig;
use super::*;

/// A waypoint `north_m`, `east_m` from vehicle 1's origin, `alt_m` above home.
fn waypoint(seq: u16, north_m: f64, east_m: f64, alt_m: f32) -> MISSION_ITEM_INT_DATA {
    let g = World::default().to_geodetic(&Vector3::new(north_m, east_m, 0.0));
    MISSION_ITEM_INT_DATA {
        param1: 0.0,
        param2: 1.0,
        param3: 0.0,
        param4: f32::NAN,
        x: g.lat_e7(),
        y: g.lon_e7(),
        z: alt_m,
        seq,
        command: MavCmd::MAV_CMD_NAV_WAYPOINT,
        target_system: 1,
        target_component: 1,
        frame: MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT,
        current: u8::from(seq == 0),
        autocontinue: 1,
        mission_type: MavMissionType::MAV_MISSION_TYPE_MISSION,
    }
}

impl Rig {
    fn count(&mut self, n: u16) {
        self.send(MavMessage::MISSION_COUNT(MISSION_COUNT_DATA {
            count: n,
            target_system: 1,
            target_component: 1,
            mission_type: MavMissionType::MAV_MISSION_TYPE_MISSION,
            opaque_id: 0,
        }));
    }

    fn requests(&self) -> Vec<u16> {
        self.received
            .iter()
            .filter_map(|(_, _, m)| match m {
                MavMessage::MISSION_REQUEST_INT(r) => Some(r.seq),
                _ => None,
            })
            .collect()
    }

    fn last_mission_ack(&self) -> Option<MavMissionResult> {
        self.received.iter().rev().find_map(|(_, _, m)| match m {
            MavMessage::MISSION_ACK(a) => Some(a.mavtype),
            _ => None,
        })
    }

    /// Uploads `items` answering each request in order.
    fn upload(&mut self, items: &[MISSION_ITEM_INT_DATA]) -> Option<MavMissionResult> {
        self.received.clear();
        self.count(items.len() as u16);
        for item in items {
            self.send(MavMessage::MISSION_ITEM_INT(item.clone()));
        }
        self.last_mission_ack()
    }
}

fn three_waypoints() -> Vec<MISSION_ITEM_INT_DATA> {
    vec![
        waypoint(0, 0.0, 0.0, 10.0),
        waypoint(1, 30.0, 0.0, 10.0),
        waypoint(2, 30.0, 30.0, 15.0),
    ]
}

#[test]
fn upload_is_requested_item_by_item_and_accepted() {
    let mut rig = Rig::on_ground();
    assert_eq!(
        rig.upload(&three_waypoints()),
        Some(MavMissionResult::MAV_MISSION_ACCEPTED)
    );
    assert_eq!(rig.requests(), vec![0, 1, 2]);
    assert_eq!(rig.vehicle.navigator.mission.items().len(), 3);
}

#[test]
fn download_returns_what_was_uploaded() {
    let mut rig = Rig::on_ground();
    let items = three_waypoints();
    rig.upload(&items);
    rig.received.clear();
    rig.send(MavMessage::MISSION_REQUEST_LIST(
        MISSION_REQUEST_LIST_DATA {
            target_system: 1,
            target_component: 1,
            mission_type: MavMissionType::MAV_MISSION_TYPE_MISSION,
        },
    ));
    let count = rig.received.iter().find_map(|(_, _, m)| match m {
        MavMessage::MISSION_COUNT(c) => Some(c.count),
        _ => None,
    });
    assert_eq!(count, Some(3));
    for seq in 0..3 {
        rig.send(MavMessage::MISSION_REQUEST_INT(MISSION_REQUEST_INT_DATA {
            seq,
            target_system: 1,
            target_component: 1,
            mission_type: MavMissionType::MAV_MISSION_TYPE_MISSION,
        }));
        let got = rig.received.iter().rev().find_map(|(_, _, m)| match m {
            MavMessage::MISSION_ITEM_INT(i) => Some(i.clone()),
            _ => None,
        });
        let got = got.expect("an item per request");
        let sent = &items[usize::from(seq)];
        assert_eq!(
            (got.seq, got.x, got.y, got.z),
            (seq, sent.x, sent.y, sent.z)
        );
        assert_eq!(got.command, MavCmd::MAV_CMD_NAV_WAYPOINT);
        // PX4 answers relative altitudes in GLOBAL_RELATIVE_ALT_INT (6).
        assert_eq!(got.frame as u8, 6);
    }
}

#[test]
fn an_item_out_of_sequence_is_ignored_and_the_right_one_asked_again() {
    let mut rig = Rig::on_ground();
    let items = three_waypoints();
    rig.count(3);
    rig.send(MavMessage::MISSION_ITEM_INT(items[0].clone()));
    rig.send(MavMessage::MISSION_ITEM_INT(items[2].clone())); // seq 1 lost
    rig.received.clear();
    rig.advance(Duration::from_millis(300));
    assert_eq!(rig.requests(), vec![1], "seq 1 asked again after 250 ms");
    rig.send(MavMessage::MISSION_ITEM_INT(items[1].clone()));
    rig.send(MavMessage::MISSION_ITEM_INT(items[2].clone()));
    assert_eq!(
        rig.last_mission_ack(),
        Some(MavMissionResult::MAV_MISSION_ACCEPTED)
    );
}

#[test]
fn bad_items_get_their_specific_error_and_leave_the_mission_unchanged() {
    let mut rig = Rig::on_ground();
    rig.upload(&three_waypoints());
    let stored = rig.vehicle.navigator.mission.items().to_vec();
    let mut unsupported = waypoint(0, 0.0, 0.0, 10.0);
    unsupported.command = MavCmd::MAV_CMD_NAV_LOITER_TURNS;
    let mut bad_frame = waypoint(0, 0.0, 0.0, 10.0);
    bad_frame.frame = MavFrame::MAV_FRAME_LOCAL_NED;
    let mut bad_param3 = waypoint(0, 0.0, 0.0, 10.0);
    bad_param3.param3 = 5.0;
    let mut bad_lat = waypoint(0, 0.0, 0.0, 10.0);
    bad_lat.x = 95 * 10_000_000;
    let mut do_in_global = waypoint(0, 0.0, 0.0, 10.0);
    do_in_global.command = MavCmd::MAV_CMD_DO_CHANGE_SPEED;
    for (item, expected) in [
        (unsupported, MavMissionResult::MAV_MISSION_UNSUPPORTED),
        (bad_frame, MavMissionResult::MAV_MISSION_UNSUPPORTED_FRAME),
        (bad_param3, MavMissionResult::MAV_MISSION_INVALID_PARAM3),
        (bad_lat, MavMissionResult::MAV_MISSION_INVALID_PARAM5_X),
        (
            do_in_global,
            MavMissionResult::MAV_MISSION_UNSUPPORTED_FRAME,
        ),
    ] {
        assert_eq!(
            rig.upload(&[item, waypoint(1, 1.0, 1.0, 5.0)]),
            Some(expected)
        );
        // NaN params: compare what is printed.
        assert_eq!(
            format!("{:?}", rig.vehicle.navigator.mission.items()),
            format!("{stored:?}"),
            "{expected:?}"
        );
    }
    // Too many items.
    rig.received.clear();
    rig.count(20_000);
    assert_eq!(
        rig.last_mission_ack(),
        Some(MavMissionResult::MAV_MISSION_NO_SPACE)
    );
}

#[test]
fn a_silent_partner_ends_the_upload_after_five_seconds_without_an_ack() {
    let mut rig = Rig::on_ground();
    rig.count(2);
    rig.received.clear();
    rig.advance(Duration::from_millis(5100));
    // Re-asked every 250 ms, then dropped with no ack.
    assert!(
        (19..=21).contains(&rig.requests().len()),
        "{}",
        rig.requests().len()
    );
    assert_eq!(rig.last_mission_ack(), None);
    // A new upload works afterwards.
    assert_eq!(
        rig.upload(&three_waypoints()),
        Some(MavMissionResult::MAV_MISSION_ACCEPTED)
    );
}

#[test]
fn mission_from_the_ground_climbs_visits_every_waypoint_and_loiters_at_the_last() {
    let mut rig = Rig::on_ground();
    let mut items = three_waypoints();
    items[0].param2 = 0.5; // acceptance radii: PX4's param2
    items[1].param2 = 0.5;
    items[2].param2 = 0.5;
    rig.upload(&items);
    assert_eq!(rig.arm(), MavResult::MAV_RESULT_ACCEPTED);
    let r = rig.command(
        MavCmd::MAV_CMD_DO_SET_MODE,
        [1.0, 4.0, 4.0, 0.0, 0.0, 0.0, 0.0],
    );
    assert_eq!(r, MavResult::MAV_RESULT_ACCEPTED);
    rig.advance(Duration::from_secs(60));
    let reached: Vec<u16> = rig
        .received
        .iter()
        .filter_map(|(_, l, m)| match (l, m) {
            (LinkId::Offboard, MavMessage::MISSION_ITEM_REACHED(r)) => Some(r.seq),
            _ => None,
        })
        .collect();
    let mut distinct = reached.clone();
    distinct.dedup();
    assert_eq!(distinct, vec![0, 1, 2], "reached {reached:?}");
    assert_eq!(rig.vehicle.status().mode, FlightMode::Hold);
    let end = rig.vehicle.body().pos_ned_m;
    assert!(
        (end - Vector3::new(30.0, 30.0, -15.0)).norm() < 0.2,
        "loitering at {end:?}"
    );
    let last_state = rig.received.iter().rev().find_map(|(_, _, m)| match m {
        MavMessage::MISSION_CURRENT(c) => Some(c.mission_state),
        _ => None,
    });
    assert_eq!(last_state, Some(MissionState::MISSION_STATE_COMPLETE));
}

#[test]
fn mission_mode_without_a_mission_is_rejected_when_armed() {
    let mut rig = Rig::on_ground();
    rig.arm();
    let r = rig.command(
        MavCmd::MAV_CMD_DO_SET_MODE,
        [1.0, 4.0, 4.0, 0.0, 0.0, 0.0, 0.0],
    );
    assert_eq!(r, MavResult::MAV_RESULT_TEMPORARILY_REJECTED);
    let r = rig.command(MavCmd::MAV_CMD_MISSION_START, [0.0; 7]);
    assert_eq!(r, MavResult::MAV_RESULT_DENIED);
}

#[test]
fn a_huge_hold_time_is_held_without_breaking_anything() {
    let mut rig = Rig::on_ground();
    let mut items = three_waypoints();
    items[0].param1 = 1e30;
    items[0].param2 = 0.5;
    assert_eq!(
        rig.upload(&items),
        Some(MavMissionResult::MAV_MISSION_ACCEPTED)
    );
    rig.arm();
    rig.command(MavCmd::MAV_CMD_MISSION_START, [0.0; 7]);
    rig.advance(Duration::from_secs(20));
    // Still holding the first waypoint, 10 m up.
    assert!((rig.vehicle.body().pos_ned_m - Vector3::new(0.0, 0.0, -10.0)).norm() < 0.2);
    assert_eq!(rig.vehicle.navigator.mission.current_seq(), 0);
}

#[test]
fn mission_start_after_a_finished_mission_starts_at_the_asked_item() {
    let mut rig = Rig::on_ground();
    let mut items = three_waypoints();
    for i in &mut items {
        i.param2 = 0.5;
    }
    rig.upload(&items);
    rig.arm();
    rig.command(MavCmd::MAV_CMD_MISSION_START, [0.0; 7]);
    rig.advance(Duration::from_secs(60));
    assert!(rig.vehicle.navigator.mission.finished());
    rig.received.clear();
    let r = rig.command(
        MavCmd::MAV_CMD_MISSION_START,
        [2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    );
    assert_eq!(r, MavResult::MAV_RESULT_ACCEPTED);
    assert_eq!(rig.vehicle.navigator.mission.current_seq(), 2);
}

// MISSION_REQUEST and MISSION_ITEM are deprecated in the XML (which asks for an _INT
// answer), but PX4's mavlink_mission.cpp answers a legacy request in kind.
#[allow(deprecated)]
#[test]
fn a_legacy_request_gets_a_legacy_item_in_degrees() {
    use mavlink::dialects::common::MISSION_REQUEST_DATA;
    let mut rig = Rig::on_ground();
    let items = three_waypoints();
    rig.upload(&items);
    rig.send(MavMessage::MISSION_REQUEST_LIST(
        MISSION_REQUEST_LIST_DATA {
            target_system: 1,
            target_component: 1,
            mission_type: MavMissionType::MAV_MISSION_TYPE_MISSION,
        },
    ));
    rig.received.clear();
    rig.send(MavMessage::MISSION_REQUEST(MISSION_REQUEST_DATA {
        seq: 1,
        target_system: 1,
        target_component: 1,
        mission_type: MavMissionType::MAV_MISSION_TYPE_MISSION,
    }));
    let got = rig.received.iter().find_map(|(_, _, m)| match m {
        MavMessage::MISSION_ITEM(i) => Some(i.clone()),
        _ => None,
    });
    let got = got.expect("a MISSION_ITEM");
    assert!((f64::from(got.x) - f64::from(items[1].x) * 1e-7).abs() < 1e-5);
    assert_eq!(got.frame, MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT);
}
