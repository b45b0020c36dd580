//! The fence plan (mission type FENCE) and GF_ACTION, in virtual time. Expected numbers
//! come from PX4's rules: a 200 ms check, GF_ACTION 2 Hold at once, 3/5 after holding
//! COM_FAIL_ACT_T, 4 motors off, and arming refused while breached.

use std::time::Duration;

use mavlink::dialects::common::{
    MISSION_COUNT_DATA, MISSION_ITEM_INT_DATA, MISSION_REQUEST_INT_DATA, MISSION_REQUEST_LIST_DATA,
    MavCmd, MavFrame, MavMessage, MavMissionResult, MavMissionType, MavResult,
    PositionTargetTypemask, SET_POSITION_TARGET_LOCAL_NED_DATA,
};
use nalgebra::Vector3;

use super::tests::Rig;
use super::*;

const FENCE: MavMissionType = MavMissionType::MAV_MISSION_TYPE_FENCE;
/// The fence's radius about home (m).
const RADIUS_M: f64 = 30.0;

/// A circle inclusion of `RADIUS_M` about vehicle 1's home.
fn circle() -> MISSION_ITEM_INT_DATA {
    let g = World::default().to_geodetic(&Vector3::zeros());
    MISSION_ITEM_INT_DATA {
        param1: RADIUS_M as f32,
        param2: 0.0,
        param3: 0.0,
        param4: 0.0,
        x: g.lat_e7(),
        y: g.lon_e7(),
        z: 0.0,
        seq: 0,
        command: MavCmd::MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION,
        target_system: 1,
        target_component: 1,
        frame: MavFrame::MAV_FRAME_GLOBAL,
        current: 0,
        autocontinue: 0,
        mission_type: FENCE,
    }
}

impl Rig {
    fn upload_fence(&mut self, items: &[MISSION_ITEM_INT_DATA]) -> Option<(MavMissionResult, u32)> {
        self.received.clear();
        self.send(MavMessage::MISSION_COUNT(MISSION_COUNT_DATA {
            count: items.len() as u16,
            target_system: 1,
            target_component: 1,
            mission_type: FENCE,
            opaque_id: 0,
        }));
        for item in items {
            self.send(MavMessage::MISSION_ITEM_INT(item.clone()));
        }
        self.received.iter().rev().find_map(|(_, _, m)| match m {
            MavMessage::MISSION_ACK(a) if a.mission_type == FENCE => Some((a.mavtype, a.opaque_id)),
            _ => None,
        })
    }

    /// Takes off in OFFBOARD and flies north at `speed_mps` 10 m up, sending setpoints
    /// for `d` (only while the vehicle is in OFFBOARD: a ground station stops once the
    /// vehicle has left it).
    fn fly_north(&mut self, speed_mps: f32, d: Duration) {
        let send = |rig: &mut Self, vel: [f32; 3]| rig.velocity_setpoint(vel);
        if !self.vehicle.status().armed {
            for _ in 0..5 {
                send(self, [0.0; 3]);
                self.advance(Duration::from_millis(50));
            }
            assert_eq!(self.arm(), MavResult::MAV_RESULT_ACCEPTED);
            assert_eq!(self.offboard(), MavResult::MAV_RESULT_ACCEPTED);
            for _ in 0..160 {
                send(self, [0.0; 3]);
                self.advance(Duration::from_millis(50));
            }
        }
        let end = self.now + d;
        while self.now < end {
            if self.vehicle.status().mode == FlightMode::Offboard {
                send(self, [speed_mps, 0.0, 0.0]);
            }
            self.advance(Duration::from_millis(50));
        }
    }

    /// A horizontal velocity setpoint (NED) at 10 m up.
    fn velocity_setpoint(&mut self, vel: [f32; 3]) {
        self.send(MavMessage::SET_POSITION_TARGET_LOCAL_NED(
            SET_POSITION_TARGET_LOCAL_NED_DATA {
                time_boot_ms: 0,
                x: 0.0,
                y: 0.0,
                z: -10.0,
                vx: vel[0],
                vy: vel[1],
                vz: vel[2],
                afx: 0.0,
                afy: 0.0,
                afz: 0.0,
                yaw: 0.0,
                yaw_rate: 0.0,
                // Velocity x/y, position z, yaw.
                type_mask: PositionTargetTypemask::from_bits_truncate(0x9C3),
                target_system: 1,
                target_component: 1,
                coordinate_frame: MavFrame::MAV_FRAME_LOCAL_NED,
            },
        ));
    }

    fn distance_from_home_m(&self) -> f64 {
        self.vehicle.status().pos_world_ned_m.xy().norm()
    }

    /// The STATUSTEXTs received on the offboard link, chunks joined by their id.
    fn texts(&self) -> Vec<String> {
        let mut texts: Vec<(u16, String)> = Vec::new();
        for (_, link, m) in &self.received {
            let (LinkId::Offboard, MavMessage::STATUSTEXT(t)) = (link, m) else {
                continue;
            };
            let part = String::from_utf8_lossy(&t.text[..])
                .trim_end_matches('\0')
                .to_owned();
            match texts.last_mut() {
                Some((id, text)) if t.id != 0 && *id == t.id && t.chunk_seq > 0 => {
                    text.push_str(&part)
                }
                _ => texts.push((t.id, part)),
            }
        }
        texts.into_iter().map(|(_, t)| t).collect()
    }

    /// Time and distance from home when the mode first became `mode`.
    fn when_mode(&mut self, mode: FlightMode, speed_mps: f32, within: Duration) -> (SimTime, f64) {
        let end = self.now + within;
        while self.now < end {
            self.fly_north(speed_mps, Duration::from_millis(10));
            if self.vehicle.status().mode == mode {
                return (self.now, self.distance_from_home_m());
            }
        }
        panic!("never in {}", mode.name());
    }
}

#[test]
fn a_fence_uploads_item_by_item_and_downloads_as_px4_gives_it_back() {
    let mut rig = Rig::on_ground();
    let (result, opaque) = rig.upload_fence(&[circle()]).expect("a fence ack");
    assert_eq!(result, MavMissionResult::MAV_MISSION_ACCEPTED);
    assert_ne!(opaque, 0);
    // The request carried the fence type.
    assert!(rig.received.iter().any(|(_, _, m)| matches!(m,
        MavMessage::MISSION_REQUEST_INT(r) if r.mission_type == FENCE && r.seq == 0)));
    assert_eq!(rig.vehicle.geofence().items().len(), 1);
    assert_eq!(rig.vehicle.geofence().shapes(), 1);
    rig.received.clear();
    rig.send(MavMessage::MISSION_REQUEST_LIST(
        MISSION_REQUEST_LIST_DATA {
            target_system: 1,
            target_component: 1,
            mission_type: FENCE,
        },
    ));
    let count = rig.received.iter().find_map(|(_, _, m)| match m {
        MavMessage::MISSION_COUNT(c) => Some((c.count, c.mission_type, c.opaque_id)),
        _ => None,
    });
    assert_eq!(count, Some((1, FENCE, opaque)));
    rig.send(MavMessage::MISSION_REQUEST_INT(MISSION_REQUEST_INT_DATA {
        seq: 0,
        target_system: 1,
        target_component: 1,
        mission_type: FENCE,
    }));
    let item = rig
        .received
        .iter()
        .find_map(|(_, _, m)| match m {
            MavMessage::MISSION_ITEM_INT(i) => Some(i.clone()),
            _ => None,
        })
        .expect("the item");
    let sent = circle();
    assert_eq!(item.mission_type, FENCE);
    assert_eq!(item.command, MavCmd::MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION);
    #[allow(deprecated)]
    let global_int = MavFrame::MAV_FRAME_GLOBAL_INT;
    assert_eq!(item.frame, global_int);
    assert_eq!((item.x, item.y, item.param1), (sent.x, sent.y, sent.param1));
    rig.send(MavMessage::MISSION_ACK(
        mavlink::dialects::common::MISSION_ACK_DATA {
            target_system: 1,
            target_component: 1,
            mavtype: MavMissionResult::MAV_MISSION_ACCEPTED,
            mission_type: FENCE,
            opaque_id: 0,
        },
    ));
    // MISSION_CURRENT names the fence by its checksum.
    rig.advance(Duration::from_millis(1100));
    assert!(rig.received.iter().any(|(_, _, m)| matches!(m,
        MavMessage::MISSION_CURRENT(c) if c.fence_id == opaque)));
    // Count 0 clears it.
    assert_eq!(
        rig.upload_fence(&[]),
        Some((MavMissionResult::MAV_MISSION_ACCEPTED, 0))
    );
    assert!(rig.vehicle.geofence().items().is_empty());
}

#[test]
fn a_bad_fence_item_gets_its_error_and_leaves_the_fence_unchanged() {
    let mut rig = Rig::on_ground();
    rig.upload_fence(&[circle()]);
    let mut high = circle();
    high.z = 40.0;
    assert_eq!(
        rig.upload_fence(&[high]).map(|a| a.0),
        Some(MavMissionResult::MAV_MISSION_INVALID_PARAM7)
    );
    let mut two = circle();
    two.command = MavCmd::MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION;
    two.param1 = 2.0;
    assert_eq!(
        rig.upload_fence(&[two.clone(), MISSION_ITEM_INT_DATA { seq: 1, ..two }])
            .map(|a| a.0),
        Some(MavMissionResult::MAV_MISSION_ERROR)
    );
    assert_eq!(
        rig.vehicle.geofence().items(),
        &[mission_item::item_from_int(&circle())]
    );
    // More than PX4's 64 fence points: refused at the count.
    rig.received.clear();
    rig.send(MavMessage::MISSION_COUNT(MISSION_COUNT_DATA {
        count: 65,
        target_system: 1,
        target_component: 1,
        mission_type: FENCE,
        opaque_id: 0,
    }));
    assert!(rig.received.iter().any(|(_, _, m)| matches!(m,
        MavMessage::MISSION_ACK(a) if a.mavtype == MavMissionResult::MAV_MISSION_NO_SPACE)));
}

#[test]
fn a_fence_not_containing_home_is_dropped_with_px4s_message() {
    let mut rig = Rig::on_ground();
    let g = World::default().to_geodetic(&Vector3::new(200.0, 0.0, 0.0));
    let away = MISSION_ITEM_INT_DATA {
        x: g.lat_e7(),
        y: g.lon_e7(),
        ..circle()
    };
    assert_eq!(
        rig.upload_fence(&[away]).map(|a| a.0),
        Some(MavMissionResult::MAV_MISSION_ACCEPTED)
    );
    assert_eq!(rig.vehicle.geofence().shapes(), 0);
    assert!(
        rig.texts()
            .contains(&"Geofence invalid, doesn't contain Home position\t".to_owned()),
        "{:?}",
        rig.texts()
    );
}

#[test]
fn gf_action_hold_takes_the_vehicle_out_of_offboard_at_the_next_200_ms_check() {
    let mut rig = Rig::on_ground();
    rig.upload_fence(&[circle()]);
    rig.fly_north(0.0, Duration::ZERO);
    rig.received.clear();
    let speed = 4.0;
    let (_, at_m) = rig.when_mode(FlightMode::Hold, speed, Duration::from_secs(30));
    // Out by no more than one check interval of travel (and a setpoint period).
    assert!(
        (RADIUS_M..RADIUS_M + f64::from(speed) * 0.25 + 0.05).contains(&at_m),
        "held at {at_m} m"
    );
    assert!(rig.vehicle.status().failsafe);
    assert!(rig.vehicle.geofence().breached());
    let texts = rig.texts();
    assert!(
        texts.contains(&"Geofence: approaching or outside geofence".to_owned()),
        "{texts:?}"
    );
    assert!(
        texts.contains(&"Failsafe activated\t".to_owned()),
        "{texts:?}"
    );
    // It holds: 5 s later it is still there (within a braking distance at MPC_ACC_HOR
    // 3 m/s²: v²/2a = 2.7 m).
    rig.fly_north(speed, Duration::from_secs(5));
    assert_eq!(rig.vehicle.status().mode, FlightMode::Hold);
    assert!(rig.distance_from_home_m() < at_m + 2.7 + 0.5);
    // A mode change is a takeover: OFFBOARD again, and no second failsafe while the
    // breach lasts.
    for _ in 0..3 {
        rig.velocity_setpoint([0.0; 3]);
        rig.advance(Duration::from_millis(50));
    }
    assert_eq!(rig.offboard(), MavResult::MAV_RESULT_ACCEPTED);
    rig.fly_north(1.0, Duration::from_secs(2));
    assert_eq!(rig.vehicle.status().mode, FlightMode::Offboard);
}

#[test]
fn gf_action_land_holds_com_fail_act_t_first() {
    let mut rig = Rig::on_ground();
    rig.set_param("GF_ACTION", f32::from_bits(5));
    rig.set_param("COM_FAIL_ACT_T", 2.0);
    rig.upload_fence(&[circle()]);
    rig.fly_north(0.0, Duration::ZERO);
    rig.received.clear();
    let (held, _) = rig.when_mode(FlightMode::Hold, 4.0, Duration::from_secs(30));
    assert!(
        rig.texts()
            .contains(&"Failsafe activated: entering Hold for 2 seconds\t".to_owned())
    );
    let (landing, _) = rig.when_mode(FlightMode::Land, 4.0, Duration::from_secs(5));
    let delay = landing.saturating_since(held).as_secs_f64();
    assert!(
        (2.0..2.0 + 0.011).contains(&delay),
        "landed after {delay} s"
    );
}

#[test]
fn gf_action_return_without_delay_returns_at_once() {
    let mut rig = Rig::on_ground();
    rig.set_param("GF_ACTION", f32::from_bits(3));
    rig.set_param("COM_FAIL_ACT_T", 0.0);
    rig.upload_fence(&[circle()]);
    rig.fly_north(0.0, Duration::ZERO);
    let (_, at_m) = rig.when_mode(FlightMode::Return, 4.0, Duration::from_secs(30));
    assert!((RADIUS_M..RADIUS_M + 1.05).contains(&at_m), "{at_m}");
}

#[test]
fn gf_action_terminate_stops_the_motors() {
    let mut rig = Rig::on_ground();
    rig.set_param("GF_ACTION", f32::from_bits(4));
    rig.upload_fence(&[circle()]);
    rig.fly_north(0.0, Duration::ZERO);
    let end = rig.now + Duration::from_secs(30);
    while rig.vehicle.status().armed && rig.now < end {
        rig.fly_north(4.0, Duration::from_millis(10));
    }
    assert!(!rig.vehicle.status().armed);
    assert!(rig.distance_from_home_m() >= RADIUS_M);
}

#[test]
fn a_warning_only_fence_lets_it_fly_out_and_then_refuses_to_arm_there() {
    let mut rig = Rig::on_ground();
    rig.set_param("GF_ACTION", f32::from_bits(1));
    rig.upload_fence(&[circle()]);
    rig.fly_north(0.0, Duration::ZERO);
    rig.received.clear();
    rig.fly_north(4.0, Duration::from_secs(12));
    assert_eq!(rig.vehicle.status().mode, FlightMode::Offboard);
    assert!(rig.distance_from_home_m() > RADIUS_M + 5.0);
    assert!(rig.vehicle.geofence().breached());
    assert!(
        rig.texts()
            .contains(&"Geofence: approaching or outside geofence".to_owned())
    );
    // Land out there, disarm, and try to arm again.
    assert_eq!(
        rig.command(MavCmd::MAV_CMD_NAV_LAND, [f32::NAN; 7]),
        MavResult::MAV_RESULT_ACCEPTED
    );
    let end = rig.now + Duration::from_secs(40);
    while rig.vehicle.status().armed && rig.now < end {
        rig.advance(Duration::from_millis(100));
    }
    assert!(!rig.vehicle.status().armed, "landed and disarmed");
    assert_eq!(
        rig.command(
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
        ),
        MavResult::MAV_RESULT_TEMPORARILY_REJECTED
    );
    assert!(
        rig.texts()
            .contains(&"Arming denied: Resolve system health failures first".to_owned())
    );
}
