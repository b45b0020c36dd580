//! Flight modes and offboard setpoints flown by the position controller, in virtual time.
//! Expected numbers come from PX4's parameters (MIS_TAKEOFF_ALT 2.5 m, MPC_TKO_SPEED
//! 1.5 m/s, MPC_XY_CRUISE 5 m/s, MPC_ACC_HOR 3 m/s², RTL_RETURN_ALT 30 m).

// MAV_FRAME_BODY_NED (8) is deprecated in the XML, but it is what MAVSDK sends and PX4
// reads for body velocities (BODY_FRD is 12).
#![allow(deprecated)]

use std::time::Duration;

use mavlink::dialects::common::{
    COMMAND_INT_DATA, HEARTBEAT_DATA, MavAutopilot, MavCmd, MavFrame, MavMessage, MavModeFlag,
    MavResult, MavState, MavType, PositionTargetTypemask, SET_POSITION_TARGET_LOCAL_NED_DATA,
};
use nalgebra::Vector3;

use super::tests::Rig;
use super::*;

const NAN: f32 = f32::NAN;

impl Rig {
    fn height(&self) -> f64 {
        self.vehicle.status().height_m
    }

    fn pos(&self) -> Vector3<f64> {
        self.vehicle.body().pos_ned_m
    }

    fn yaw(&self) -> f64 {
        self.vehicle.body().attitude.euler_angles().2
    }

    fn takeoff(&mut self) {
        assert_eq!(self.arm(), MavResult::MAV_RESULT_ACCEPTED);
        let r = self.command(MavCmd::MAV_CMD_NAV_TAKEOFF, [NAN; 7]);
        assert_eq!(r, MavResult::MAV_RESULT_ACCEPTED);
    }

    fn command_int(&mut self, command: MavCmd, p: [f32; 4], x: i32, y: i32, z: f32) -> MavResult {
        self.send(MavMessage::COMMAND_INT(COMMAND_INT_DATA {
            param1: p[0],
            param2: p[1],
            param3: p[2],
            param4: p[3],
            x,
            y,
            z,
            command,
            target_system: 1,
            target_component: 1,
            frame: MavFrame::MAV_FRAME_GLOBAL,
            current: 0,
            autocontinue: 0,
        }));
        self.last_ack(command)
    }

    /// Sends a local NED setpoint every 50 ms (MAVSDK's 20 Hz) for `d`.
    fn stream_local(
        &mut self,
        d: Duration,
        frame: MavFrame,
        mask: u16,
        pos: [f32; 3],
        vel: [f32; 3],
        yaw: f32,
    ) {
        let end = self.now + d;
        while self.now < end {
            self.send(MavMessage::SET_POSITION_TARGET_LOCAL_NED(
                SET_POSITION_TARGET_LOCAL_NED_DATA {
                    time_boot_ms: 0,
                    x: pos[0],
                    y: pos[1],
                    z: pos[2],
                    vx: vel[0],
                    vy: vel[1],
                    vz: vel[2],
                    afx: 0.0,
                    afy: 0.0,
                    afz: 0.0,
                    yaw,
                    yaw_rate: 0.0,
                    type_mask: PositionTargetTypemask::from_bits_truncate(mask),
                    target_system: 1,
                    target_component: 1,
                    coordinate_frame: frame,
                },
            ));
            self.advance(Duration::from_millis(50));
        }
    }
}

/// The geodetic degE7 of a local NED point of vehicle 1 (origin at the reference).
fn lat_lon_e7(north_m: f64, east_m: f64) -> (i32, i32) {
    let g = World::default().to_geodetic(&Vector3::new(north_m, east_m, 0.0));
    (g.lat_e7(), g.lon_e7())
}

#[test]
fn takeoff_climbs_at_takeoff_speed_and_holds_exactly_mis_takeoff_alt() {
    let mut rig = Rig::on_ground();
    rig.takeoff();
    let mut peak_climb = 0.0_f64;
    for _ in 0..100 {
        rig.advance(Duration::from_millis(100));
        peak_climb = peak_climb.max(-rig.vehicle.status().vel_ned_mps.z);
    }
    assert_eq!(
        rig.vehicle.status().mode,
        FlightMode::Hold,
        "Takeoff ends in Hold"
    );
    // MPC_TKO_SPEED 1.5 m/s; the reference leaves while the motors spin up and the
    // vehicle catches up with it: up to 10 % more (measured 8 % on the x500).
    assert!(
        peak_climb <= 1.5 * 1.1 && peak_climb > 1.4,
        "climb {peak_climb}"
    );
    let mut worst = 0.0_f64;
    for _ in 0..50 {
        rig.advance(Duration::from_millis(100));
        worst = worst.max((rig.height() - 2.5).abs());
    }
    assert!(worst < 0.02, "held 2.5 m within {worst} m");
}

#[test]
fn takeoff_to_an_amsl_altitude_and_never_below_the_current_one() {
    let mut rig = Rig::on_ground();
    assert_eq!(rig.arm(), MavResult::MAV_RESULT_ACCEPTED);
    // Home is 488 m AMSL: 498 m is 10 m up.
    let mut p = [NAN; 7];
    p[6] = 498.0;
    assert_eq!(
        rig.command(MavCmd::MAV_CMD_NAV_TAKEOFF, p),
        MavResult::MAV_RESULT_ACCEPTED
    );
    rig.advance(Duration::from_secs(20));
    assert!(
        (rig.height() - 10.0).abs() < 0.02,
        "height {}",
        rig.height()
    );
}

#[test]
fn goto_flies_to_the_point_at_cruise_speed_and_faces_the_asked_yaw() {
    let mut rig = Rig::on_ground();
    rig.takeoff();
    rig.advance(Duration::from_secs(6));
    let (lat, lon) = lat_lon_e7(40.0, 20.0);
    // MAVSDK's goto_location: COMMAND_INT, param2 = change mode, yaw in param4 (rad).
    let r = rig.command_int(
        MavCmd::MAV_CMD_DO_REPOSITION,
        [NAN, 1.0, NAN, 0.5],
        lat,
        lon,
        488.0 + 15.0,
    );
    assert_eq!(r, MavResult::MAV_RESULT_ACCEPTED);
    let mut peak = 0.0_f64;
    // 44.7 m at 5 m/s with 3 m/s² ramps: 44.7/5 + 5/3 = 10.6 s of reference.
    for _ in 0..160 {
        rig.advance(Duration::from_millis(100));
        peak = peak.max(rig.vehicle.status().vel_ned_mps.xy().norm());
    }
    let err = (rig.pos() - Vector3::new(40.0, 20.0, -15.0)).norm();
    assert!(err < 0.3, "off by {err} m");
    assert!(peak <= 5.0 * 1.1 && peak > 4.5, "peak speed {peak}");
    assert!((rig.yaw() - 0.5).abs() < 0.02, "yaw {}", rig.yaw());
    assert_eq!(rig.vehicle.status().mode, FlightMode::Hold);
}

#[test]
fn reposition_without_the_mode_flag_is_denied_outside_hold() {
    let mut rig = Rig::on_ground();
    // PX4 boots in Hold; leave it for POSCTL.
    assert_eq!(rig.vehicle.status().mode, FlightMode::Hold);
    let r = rig.command(
        MavCmd::MAV_CMD_DO_SET_MODE,
        [1.0, 3.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    );
    assert_eq!(r, MavResult::MAV_RESULT_ACCEPTED);
    let (lat, lon) = lat_lon_e7(10.0, 0.0);
    let r = rig.command_int(
        MavCmd::MAV_CMD_DO_REPOSITION,
        [NAN, 0.0, NAN, NAN],
        lat,
        lon,
        500.0,
    );
    assert_eq!(r, MavResult::MAV_RESULT_DENIED);
}

#[test]
fn return_climbs_to_rtl_return_alt_flies_home_lands_and_disarms() {
    let mut rig = Rig::on_ground();
    rig.takeoff();
    rig.advance(Duration::from_secs(6));
    let (lat, lon) = lat_lon_e7(60.0, 0.0);
    rig.command_int(
        MavCmd::MAV_CMD_DO_REPOSITION,
        [10.0, 1.0, NAN, NAN],
        lat,
        lon,
        488.0 + 5.0,
    );
    rig.advance(Duration::from_secs(20));
    assert!((rig.pos() - Vector3::new(60.0, 0.0, -5.0)).norm() < 0.3);
    assert_eq!(
        rig.command(MavCmd::MAV_CMD_NAV_RETURN_TO_LAUNCH, [NAN; 7]),
        MavResult::MAV_RESULT_ACCEPTED
    );
    let mut peak_height = 0.0_f64;
    let mut landed_at = None;
    for i in 0..1200 {
        rig.advance(Duration::from_millis(100));
        peak_height = peak_height.max(rig.height());
        if !rig.vehicle.status().armed {
            landed_at = Some(i);
            break;
        }
    }
    // 60 m from home is beyond NAV_ACC_RAD: climb to RTL_RETURN_ALT (30 m), then home,
    // then land (RTL_LAND_DELAY 0), then disarm after COM_DISARM_LAND.
    assert!((peak_height - 30.0).abs() < 0.3, "peak {peak_height}");
    assert!(landed_at.is_some(), "disarmed on the ground");
    assert!(
        rig.pos().xy().norm() < 0.5,
        "landed {:?} from home",
        rig.pos()
    );
}

#[test]
fn land_descends_at_px4_speeds_and_disarms_after_two_seconds() {
    let mut rig = Rig::on_ground();
    rig.takeoff();
    rig.advance(Duration::from_secs(6));
    assert_eq!(
        rig.command(MavCmd::MAV_CMD_NAV_LAND, [NAN; 7]),
        MavResult::MAV_RESULT_ACCEPTED
    );
    let mut fastest = 0.0_f64;
    let mut touchdown = None;
    for i in 0..200 {
        rig.advance(Duration::from_millis(50));
        fastest = fastest.max(rig.vehicle.status().vel_ned_mps.z);
        if touchdown.is_none() && rig.vehicle.status().landed {
            touchdown = Some(i);
        }
        if !rig.vehicle.status().armed {
            let td = touchdown.expect("landed before disarming");
            let after_s = (i - td) as f64 * 0.05;
            assert!(
                (1.9..=2.2).contains(&after_s),
                "disarmed {after_s} s after touchdown"
            );
            // Below MPC_LAND_ALT2 (5 m) the descent is MPC_LAND_SPEED, 0.7 m/s.
            assert!(fastest <= 0.7 * 1.1, "descent {fastest}");
            return;
        }
    }
    panic!("never disarmed");
}

#[test]
fn offboard_velocity_ned_is_tracked_with_its_yaw() {
    let mut rig = Rig::on_ground();
    rig.arm();
    // MAVSDK's set_velocity_ned: mask 0x9C7 (velocity + yaw).
    rig.stream_local(
        Duration::from_millis(100),
        MavFrame::MAV_FRAME_LOCAL_NED,
        0x9C7,
        [0.0; 3],
        [0.0, 0.0, -2.0],
        0.0,
    );
    assert_eq!(rig.offboard(), MavResult::MAV_RESULT_ACCEPTED);
    rig.stream_local(
        Duration::from_secs(4),
        MavFrame::MAV_FRAME_LOCAL_NED,
        0x9C7,
        [0.0; 3],
        [0.0, 0.0, -2.0],
        0.0,
    );
    let vz = rig.vehicle.status().vel_ned_mps.z;
    assert!((vz + 2.0).abs() < 0.1, "climb {vz}");
    let yaw = std::f32::consts::FRAC_PI_2;
    rig.stream_local(
        Duration::from_secs(6),
        MavFrame::MAV_FRAME_LOCAL_NED,
        0x9C7,
        [0.0; 3],
        [2.0, 0.0, 0.0],
        yaw,
    );
    let v = rig.vehicle.status().vel_ned_mps;
    assert!(
        (v - Vector3::new(2.0, 0.0, 0.0)).norm() < 0.1,
        "velocity {v:?}"
    );
    assert!(
        (rig.yaw() - f64::from(yaw)).abs() < 0.03,
        "yaw {}",
        rig.yaw()
    );
}

#[test]
fn offboard_velocity_body_turns_with_the_yaw_rate() {
    let mut rig = Rig::on_ground();
    rig.arm();
    rig.stream_local(
        Duration::from_millis(100),
        MavFrame::MAV_FRAME_BODY_NED,
        0x5C7,
        [0.0; 3],
        [0.0, 0.0, -1.0],
        0.0,
    );
    assert_eq!(rig.offboard(), MavResult::MAV_RESULT_ACCEPTED);
    rig.stream_local(
        Duration::from_secs(4),
        MavFrame::MAV_FRAME_BODY_NED,
        0x5C7,
        [0.0; 3],
        [0.0, 0.0, -1.0],
        0.0,
    );
    // Forward 3 m/s in the body frame: the NED velocity points where the nose points.
    rig.stream_local(
        Duration::from_secs(6),
        MavFrame::MAV_FRAME_BODY_NED,
        0x5C7,
        [0.0; 3],
        [3.0, 0.0, 0.0],
        0.0,
    );
    let v = rig.vehicle.status().vel_ned_mps;
    let heading = rig.yaw();
    let expected = Vector3::new(3.0 * heading.cos(), 3.0 * heading.sin(), 0.0);
    assert!(
        (v - expected).norm() < 0.15,
        "velocity {v:?} heading {heading}"
    );
}

#[test]
fn offboard_position_ned_holds_the_point() {
    let mut rig = Rig::on_ground();
    rig.arm();
    // MAVSDK's set_position_ned: mask 0x9F8.
    let pos = [5.0, 10.0, -5.0];
    rig.stream_local(
        Duration::from_millis(100),
        MavFrame::MAV_FRAME_LOCAL_NED,
        0x9F8,
        pos,
        [0.0; 3],
        1.0,
    );
    assert_eq!(rig.offboard(), MavResult::MAV_RESULT_ACCEPTED);
    rig.stream_local(
        Duration::from_secs(20),
        MavFrame::MAV_FRAME_LOCAL_NED,
        0x9F8,
        pos,
        [0.0; 3],
        1.0,
    );
    let err = (rig.pos() - Vector3::new(5.0, 10.0, -5.0)).norm();
    assert!(err < 0.05, "off by {err} m");
    assert!((rig.yaw() - 1.0).abs() < 0.02);
}

#[test]
fn offset_frames_are_refused_and_keep_no_offboard_signal() {
    let mut rig = Rig::on_ground();
    rig.arm();
    rig.stream_local(
        Duration::from_millis(500),
        MavFrame::MAV_FRAME_LOCAL_OFFSET_NED,
        0x9F8,
        [1.0; 3],
        [0.0; 3],
        0.0,
    );
    assert_eq!(rig.offboard(), MavResult::MAV_RESULT_TEMPORARILY_REJECTED);
    assert!(rig.vehicle.status().counters.rejected_setpoints >= 10);
}

pub(super) fn gcs_heartbeat() -> MavMessage {
    MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: 0,
        mavtype: MavType::MAV_TYPE_GCS,
        autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
        base_mode: MavModeFlag::empty(),
        system_status: MavState::MAV_STATE_ACTIVE,
        mavlink_version: 3,
    })
}

#[test]
fn data_link_loss_lands_when_nav_dll_act_says_land() {
    let mut rig = Rig::on_ground();
    rig.set_param("NAV_DLL_ACT", f32::from_ne_bytes(3i32.to_ne_bytes()));
    // No ground station yet: arming is refused, as PX4's "No connection to the GCS".
    assert_eq!(rig.arm(), MavResult::MAV_RESULT_TEMPORARILY_REJECTED);
    rig.send(gcs_heartbeat());
    rig.takeoff();
    for _ in 0..8 {
        rig.advance(Duration::from_secs(1));
        rig.send(gcs_heartbeat());
    }
    // Silence: lost after COM_DL_LOSS_T (10 s) + 2.5 s of heartbeat staleness.
    let last = rig.now;
    let mut lost_at = None;
    for _ in 0..200 {
        rig.advance(Duration::from_millis(100));
        if rig.vehicle.status().mode == FlightMode::Land {
            lost_at = Some(rig.now.saturating_since(last));
            break;
        }
    }
    let after = lost_at
        .expect("the failsafe landed the vehicle")
        .as_secs_f64();
    assert!(
        (12.5..=12.7).contains(&after),
        "landing {after} s after the last heartbeat"
    );
    assert!(rig.vehicle.status().failsafe);
}

#[test]
fn orbit_circles_the_centre_at_the_asked_radius_and_speed_facing_it() {
    let mut rig = Rig::on_ground();
    rig.takeoff();
    rig.advance(Duration::from_secs(6));
    // Centre 20 m north of home, 15 m radius clockwise, 3 m/s, 10 m above home
    // (MAVSDK's do_orbit: COMMAND_INT, frame left at GLOBAL_RELATIVE_ALT, z AMSL).
    let (lat, lon) = lat_lon_e7(20.0, 0.0);
    let r = rig.command_int(
        MavCmd::MAV_CMD_DO_ORBIT,
        [15.0, 3.0, 0.0, NAN],
        lat,
        lon,
        498.0,
    );
    assert_eq!(r, MavResult::MAV_RESULT_ACCEPTED);
    assert_eq!(rig.vehicle.status().mode, FlightMode::Orbit);
    // 3 m/s on 15 m (0.2 rad/s, centripetal 0.6 m/s²): one lap in 31.4 s.
    rig.advance(Duration::from_secs(20));
    let (mut worst_r, mut worst_v, mut worst_yaw) = (0.0_f64, 0.0_f64, 0.0_f64);
    for _ in 0..300 {
        rig.advance(Duration::from_millis(100));
        let p = rig.pos();
        let to_centre = Vector3::new(20.0, 0.0, -10.0) - p;
        worst_r = worst_r.max((to_centre.xy().norm() - 15.0).abs());
        worst_v = worst_v.max((rig.vehicle.status().vel_ned_mps.xy().norm() - 3.0).abs());
        let facing = to_centre.y.atan2(to_centre.x);
        worst_yaw = worst_yaw.max(crate::position_control::wrap_pi(rig.yaw() - facing).abs());
        assert!((p.z + 10.0).abs() < 0.1, "altitude {}", -p.z);
    }
    assert!(worst_r < 0.3, "radius off by {worst_r} m");
    assert!(worst_v < 0.15, "speed off by {worst_v} m/s");
    assert!(worst_yaw < 5f64.to_radians(), "yaw off by {worst_yaw} rad");
    // Clockwise from above: the bearing from the centre increases.
    let before = rig.pos() - Vector3::new(20.0, 0.0, 0.0);
    rig.advance(Duration::from_secs(2));
    let after = rig.pos() - Vector3::new(20.0, 0.0, 0.0);
    assert!(
        crate::position_control::wrap_pi(after.y.atan2(after.x) - before.y.atan2(before.x)) > 0.0
    );
}

#[test]
fn orbit_is_refused_on_the_ground_and_with_a_bad_radius() {
    let mut rig = Rig::on_ground();
    let (lat, lon) = lat_lon_e7(20.0, 0.0);
    let r = rig.command_int(
        MavCmd::MAV_CMD_DO_ORBIT,
        [15.0, 3.0, 0.0, NAN],
        lat,
        lon,
        498.0,
    );
    assert_eq!(r, MavResult::MAV_RESULT_TEMPORARILY_REJECTED);
    rig.takeoff();
    rig.advance(Duration::from_secs(6));
    let r = rig.command_int(
        MavCmd::MAV_CMD_DO_ORBIT,
        [0.5, 3.0, 0.0, NAN],
        lat,
        lon,
        498.0,
    );
    assert_eq!(r, MavResult::MAV_RESULT_DENIED);
}

#[test]
fn takeoff_while_higher_than_the_takeoff_altitude_stays_up() {
    let mut rig = Rig::on_ground();
    assert_eq!(rig.arm(), MavResult::MAV_RESULT_ACCEPTED);
    let mut p = [NAN; 7];
    p[6] = 488.0 + 12.0;
    rig.command(MavCmd::MAV_CMD_NAV_TAKEOFF, p);
    rig.advance(Duration::from_secs(20));
    // A second takeoff with PX4's default (NaN): MIS_TAKEOFF_ALT would be 2.5 m, but PX4
    // never descends for a takeoff.
    assert_eq!(
        rig.command(MavCmd::MAV_CMD_NAV_TAKEOFF, [NAN; 7]),
        MavResult::MAV_RESULT_ACCEPTED
    );
    rig.advance(Duration::from_secs(10));
    assert!(
        (rig.height() - 12.0).abs() < 0.05,
        "height {}",
        rig.height()
    );
}

#[test]
fn a_disarmed_vehicle_in_offboard_has_no_failsafe_and_cannot_arm_without_the_signal() {
    let mut rig = Rig::on_ground();
    assert_eq!(rig.offboard(), MavResult::MAV_RESULT_ACCEPTED);
    rig.advance(Duration::from_millis(1500));
    let status = rig.vehicle.status();
    assert!(
        !status.failsafe && status.mode == FlightMode::Offboard,
        "{status:?}"
    );
    assert_eq!(rig.arm(), MavResult::MAV_RESULT_TEMPORARILY_REJECTED);
}

#[test]
fn numbers_that_would_break_the_controller_are_refused_or_contained() {
    let mut rig = Rig::on_ground();
    // MPC_THR_MIN above MPC_THR_MAX (each in range): no panic, the hover thrust is MAX.
    rig.set_param("MPC_THR_MAX", 0.1);
    assert!((rig.vehicle.tuning.mpc.thr_hover - 0.1).abs() < 1e-6);
    rig.set_param("MPC_THR_MAX", 1.0);
    rig.takeoff();
    rig.advance(Duration::from_secs(6));
    // An infinite orbit altitude is no altitude: PX4's PX4_ISFINITE makes it "here".
    let (lat, lon) = lat_lon_e7(20.0, 0.0);
    let r = rig.command_int(
        MavCmd::MAV_CMD_DO_ORBIT,
        [15.0, 3.0, 0.0, NAN],
        lat,
        lon,
        f32::INFINITY,
    );
    assert_eq!(r, MavResult::MAV_RESULT_ACCEPTED);
    rig.advance(Duration::from_secs(10));
    assert!((rig.height() - 2.5).abs() < 0.1, "height {}", rig.height());
    assert!(rig.pos().iter().all(|x| x.is_finite()));
}
