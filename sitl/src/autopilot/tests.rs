//! The autopilot machine driven by encoded frames in virtual time.

use std::time::Duration;

use mavlink::dialects::common::{
    AttitudeTargetTypemask, COMMAND_LONG_DATA, MavCmd, MavMessage, MavResult,
    PARAM_REQUEST_LIST_DATA, PARAM_REQUEST_READ_DATA, SET_ATTITUDE_TARGET_DATA,
};
use nalgebra::Vector3;

use super::*;
use crate::codec::{Encoder, decode_datagram};
use crate::profile::Profile;

const GCS: (u8, u8) = (255, 190);

pub(super) struct Rig {
    pub vehicle: Vehicle,
    pub now: SimTime,
    pub gcs: Encoder,
    pub received: Vec<(SimTime, LinkId, MavMessage)>,
}

impl Rig {
    pub fn new(cfg: VehicleConfig) -> Self {
        Self {
            vehicle: Vehicle::new(cfg, World::default()).unwrap(),
            now: SimTime::ZERO,
            gcs: Encoder::new(GCS.0, GCS.1),
            received: Vec::new(),
        }
    }

    pub fn on_ground() -> Self {
        Self::new(VehicleConfig::new(1, Profile::x500()))
    }

    pub fn send(&mut self, msg: MavMessage) {
        let bytes = self.gcs.encode(&msg);
        self.vehicle
            .handle_datagram(self.now, LinkId::Offboard, &bytes);
        self.drain();
    }

    pub fn drain(&mut self) {
        while let Some(tx) = self.vehicle.poll_transmit() {
            for frame in decode_datagram(&tx.bytes) {
                self.received.push((self.now, tx.link, frame.unwrap().msg));
            }
        }
    }

    pub fn advance(&mut self, d: Duration) {
        let end = self.now + d;
        while self.now < end {
            self.now = self.now + PHYSICS_STEP;
            self.vehicle.handle_timeout(self.now);
            self.drain();
        }
    }

    /// Streams setpoints at `hz` for `d`.
    pub fn stream(&mut self, d: Duration, hz: f64, thrust: f32) {
        let period = Duration::from_secs_f64(1.0 / hz);
        let end = self.now + d;
        while self.now < end {
            self.send(setpoint(1, thrust));
            self.advance(period);
        }
    }

    pub fn command(&mut self, command: MavCmd, params: [f32; 7]) -> MavResult {
        self.send(MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
            target_system: 1,
            target_component: 1,
            command,
            confirmation: 0,
            param1: params[0],
            param2: params[1],
            param3: params[2],
            param4: params[3],
            param5: params[4],
            param6: params[5],
            param7: params[6],
        }));
        self.last_ack(command)
    }

    /// Sets a parameter as PARAM_SET does (the tuning follows).
    pub fn set_param(&mut self, name: &str, value: f32) {
        self.vehicle
            .params
            .set(name, value)
            .expect("a known parameter");
        self.vehicle.tuning = tuning::Tuning::from_params(&self.vehicle.params);
    }

    /// The result of the last COMMAND_ACK for `command`.
    pub fn last_ack(&self, command: MavCmd) -> MavResult {
        self.received
            .iter()
            .rev()
            .find_map(|(_, _, m)| match m {
                MavMessage::COMMAND_ACK(a) if a.command == command => Some(a.result),
                _ => None,
            })
            .expect("every command is acknowledged")
    }

    pub fn offboard(&mut self) -> MavResult {
        self.command(
            MavCmd::MAV_CMD_DO_SET_MODE,
            [1.0, 6.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        )
    }

    pub fn arm(&mut self) -> MavResult {
        self.command(
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        )
    }
}

pub(super) fn setpoint(target: u8, thrust: f32) -> MavMessage {
    MavMessage::SET_ATTITUDE_TARGET(SET_ATTITUDE_TARGET_DATA {
        time_boot_ms: 0,
        q: [1.0, 0.0, 0.0, 0.0],
        body_roll_rate: 0.0,
        body_pitch_rate: 0.0,
        body_yaw_rate: 0.0,
        thrust,
        target_system: target,
        target_component: 1,
        type_mask: AttitudeTargetTypemask::ATTITUDE_TARGET_TYPEMASK_BODY_ROLL_RATE_IGNORE
            | AttitudeTargetTypemask::ATTITUDE_TARGET_TYPEMASK_BODY_PITCH_RATE_IGNORE
            | AttitudeTargetTypemask::ATTITUDE_TARGET_TYPEMASK_BODY_YAW_RATE_IGNORE,
        thrust_body: [0.0; 3],
    })
}

#[test]
fn offboard_needs_one_setpoint_within_the_loss_timeout_when_armed() {
    // PX4's offboardCheck: one setpoint younger than COM_OF_LOSS_T (1 s) is enough.
    let mut rig = Rig::on_ground();
    assert_eq!(rig.arm(), MavResult::MAV_RESULT_ACCEPTED);
    assert_eq!(rig.offboard(), MavResult::MAV_RESULT_TEMPORARILY_REJECTED);
    rig.send(setpoint(1, 0.0));
    rig.advance(Duration::from_millis(900));
    assert_eq!(rig.offboard(), MavResult::MAV_RESULT_ACCEPTED);
    assert_eq!(rig.vehicle.status().mode, FlightMode::Offboard);
}

#[test]
fn offboard_refused_when_the_last_setpoint_is_older_than_the_loss_timeout() {
    let mut rig = Rig::on_ground();
    rig.arm();
    rig.send(setpoint(1, 0.0));
    rig.advance(Duration::from_millis(1100));
    assert_eq!(rig.offboard(), MavResult::MAV_RESULT_TEMPORARILY_REJECTED);
}

#[test]
fn disarmed_offboard_is_accepted_but_arming_then_needs_the_signal() {
    // PX4 takes any mode while disarmed; arming checks that the mode can run.
    let mut rig = Rig::on_ground();
    assert_eq!(rig.offboard(), MavResult::MAV_RESULT_ACCEPTED);
    assert_eq!(rig.arm(), MavResult::MAV_RESULT_TEMPORARILY_REJECTED);
    rig.send(setpoint(1, 0.0));
    assert_eq!(rig.arm(), MavResult::MAV_RESULT_ACCEPTED);
}

#[test]
fn setpoints_without_thrust_are_no_offboard_signal() {
    let mut rig = Rig::on_ground();
    rig.arm();
    for _ in 0..40 {
        let mut sp = setpoint(1, 0.5);
        if let MavMessage::SET_ATTITUDE_TARGET(ref mut d) = sp {
            d.type_mask |= AttitudeTargetTypemask::ATTITUDE_TARGET_TYPEMASK_THROTTLE_IGNORE;
        }
        rig.send(sp);
        rig.advance(Duration::from_millis(50));
    }
    assert_eq!(rig.offboard(), MavResult::MAV_RESULT_TEMPORARILY_REJECTED);
}

#[test]
fn failsafe_enters_between_loss_timeout_and_200_ms_later() {
    for (action, expected) in [
        (5i32, Some(FlightMode::Hold)),
        (4, Some(FlightMode::Land)),
        (7, None),
    ] {
        let mut rig = Rig::on_ground();
        rig.set_param("COM_OBL_RC_ACT", f32::from_ne_bytes(action.to_ne_bytes()));
        rig.stream(Duration::from_millis(1100), 50.0, 0.7);
        assert_eq!(rig.arm(), MavResult::MAV_RESULT_ACCEPTED);
        assert_eq!(rig.offboard(), MavResult::MAV_RESULT_ACCEPTED);
        rig.stream(Duration::from_secs(2), 50.0, 0.6);
        assert!(
            !rig.vehicle.status().landed,
            "climbing with thrust above hover"
        );
        let last = SimTime::from_micros(rig.now.as_micros() - 20_000);
        rig.advance(Duration::from_millis(1500));
        let lost_at = std::iter::from_fn(|| rig.vehicle.poll_event())
            .find_map(|e| match e {
                VehicleEvent::OffboardLost { at, last_setpoint } => Some((at, last_setpoint)),
                _ => None,
            })
            .expect("failsafe event");
        let delay = lost_at.0.saturating_since(lost_at.1);
        assert!(lost_at.1 >= last);
        assert!(
            delay > Duration::from_secs(1) && delay <= Duration::from_millis(1200),
            "delay {delay:?}"
        );
        let status = rig.vehicle.status();
        match expected {
            Some(mode) => {
                assert_eq!(status.mode, mode);
                assert!(status.failsafe && status.armed);
            }
            None => assert!(!status.armed),
        }
    }
}

#[test]
fn unknown_commands_are_acknowledged_unsupported_and_nan_params_are_unused() {
    let mut rig = Rig::on_ground();
    assert_eq!(
        rig.command(MavCmd::MAV_CMD_DO_SET_SERVO, [1.0; 7]),
        MavResult::MAV_RESULT_UNSUPPORTED
    );
    // MAVSDK's DO_SET_MODE: NaN in the unused params.
    rig.stream(Duration::from_millis(1100), 20.0, 0.0);
    let nan = f32::NAN;
    assert_eq!(
        rig.command(
            MavCmd::MAV_CMD_DO_SET_MODE,
            [129.0, 6.0, 0.0, nan, nan, nan, nan]
        ),
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert_eq!(rig.vehicle.status().counters.unsupported_commands, 1);
}

#[test]
fn messages_for_another_system_are_ignored() {
    let mut rig = Rig::on_ground();
    rig.arm();
    for _ in 0..30 {
        rig.send(setpoint(2, 0.5));
        rig.advance(Duration::from_millis(50));
    }
    assert_eq!(rig.offboard(), MavResult::MAV_RESULT_TEMPORARILY_REJECTED);
    assert_eq!(rig.vehicle.status().counters.foreign_target, 30);
}

#[test]
fn bad_setpoints_are_refused_and_counted() {
    let mut rig = Rig::on_ground();
    for (q, thrust) in [
        ([0.5f32, 0.0, 0.0, 0.0], 0.5f32),
        ([1.0, 0.0, 0.0, 0.0], f32::NAN),
        ([1.0, 0.0, 0.0, 0.0], 1.5),
    ] {
        let mut sp = setpoint(1, thrust);
        if let MavMessage::SET_ATTITUDE_TARGET(ref mut d) = sp {
            d.q = q;
        }
        rig.send(sp);
    }
    assert_eq!(rig.vehicle.status().counters.rejected_setpoints, 3);
}

#[test]
fn disarm_in_the_air_is_denied_unless_forced_and_landing_disarms() {
    let mut rig = Rig::on_ground();
    rig.stream(Duration::from_millis(1100), 50.0, 0.6);
    rig.arm();
    rig.offboard();
    rig.stream(Duration::from_secs(2), 50.0, 0.6);
    assert_eq!(
        rig.command(MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, [0.0; 7]),
        MavResult::MAV_RESULT_DENIED
    );
    assert_eq!(
        rig.command(MavCmd::MAV_CMD_NAV_LAND, [0.0; 7]),
        MavResult::MAV_RESULT_ACCEPTED
    );
    rig.advance(Duration::from_secs(20));
    let status = rig.vehicle.status();
    assert!(status.landed && !status.armed, "{status:?}");
    assert!(status.height_m.abs() < 1e-9);
}

#[test]
fn preflight_disarm_after_ten_seconds_without_takeoff() {
    let mut rig = Rig::on_ground();
    rig.arm();
    rig.advance(Duration::from_millis(9_900));
    assert!(rig.vehicle.status().armed);
    rig.advance(Duration::from_millis(200));
    assert!(!rig.vehicle.status().armed);
}

#[test]
fn heartbeat_at_one_hertz_and_fast_streams_at_fifty() {
    let mut rig = Rig::on_ground();
    rig.advance(Duration::from_secs(10));
    let count = |name: &str| {
        rig.received
            .iter()
            .filter(|(_, l, m)| *l == LinkId::Offboard && m.message_name() == name)
            .count()
    };
    use mavlink::Message;
    assert!(
        (10..=11).contains(&count("HEARTBEAT")),
        "{}",
        count("HEARTBEAT")
    );
    assert!((500..=501).contains(&count("ATTITUDE")));
    assert!((500..=501).contains(&count("GLOBAL_POSITION_INT")));
}

#[test]
fn message_interval_changes_the_rate_on_that_link_only() {
    use mavlink::Message;
    let mut rig = Rig::on_ground();
    // LOCAL_POSITION_NED (32) every 100 ms on the offboard link.
    assert_eq!(
        rig.command(
            MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
            [32.0, 100_000.0, 0.0, 0.0, 0.0, 0.0, 0.0]
        ),
        MavResult::MAV_RESULT_ACCEPTED
    );
    let start = rig.now;
    rig.advance(Duration::from_secs(10));
    let on = |link: LinkId| {
        rig.received
            .iter()
            .filter(|(t, l, m)| {
                *t > start && *l == link && m.message_name() == "LOCAL_POSITION_NED"
            })
            .count()
    };
    assert!(
        (99..=101).contains(&on(LinkId::Offboard)),
        "{}",
        on(LinkId::Offboard)
    );
    assert!((499..=501).contains(&on(LinkId::Gcs)));
}

#[test]
fn an_unwired_link_gets_nothing_and_the_other_is_unchanged_across_a_reboot() {
    let mut rig = Rig::on_ground();
    rig.vehicle.set_link_wired(LinkId::Gcs, false);
    let count = |rig: &Rig, link: LinkId, name: &str| {
        rig.received
            .iter()
            .filter(|(_, l, m)| *l == link && mavlink::Message::message_name(m) == name)
            .count()
    };
    rig.advance(Duration::from_secs(2));
    // The offboard link keeps PX4's default streams (LOCAL_POSITION_NED at 50 Hz: 100 in
    // 2 s, the first at boot), and a command is answered on it.
    assert!((100..=101).contains(&count(&rig, LinkId::Offboard, "LOCAL_POSITION_NED")));
    assert_eq!(
        rig.command(
            MavCmd::MAV_CMD_REQUEST_MESSAGE,
            [148.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
        ),
        MavResult::MAV_RESULT_ACCEPTED
    );
    assert_eq!(
        rig.received
            .iter()
            .filter(|(_, l, _)| *l == LinkId::Gcs)
            .count(),
        0
    );
    rig.vehicle.reboot(rig.now);
    rig.received.clear();
    rig.advance(Duration::from_secs(1));
    assert!(count(&rig, LinkId::Offboard, "HEARTBEAT") >= 1);
    assert_eq!(
        rig.received
            .iter()
            .filter(|(_, l, _)| *l == LinkId::Gcs)
            .count(),
        0,
        "the wiring survives a reboot"
    );
    rig.vehicle.set_link_wired(LinkId::Gcs, true);
    rig.advance(Duration::from_secs(1));
    assert!(count(&rig, LinkId::Gcs, "HEARTBEAT") >= 1);
}

#[test]
fn parameter_list_and_set_are_answered() {
    let mut rig = Rig::on_ground();
    rig.send(MavMessage::PARAM_REQUEST_LIST(PARAM_REQUEST_LIST_DATA {
        target_system: 1,
        target_component: 1,
    }));
    let values: Vec<_> = rig
        .received
        .iter()
        .filter_map(|(_, _, m)| match m {
            MavMessage::PARAM_VALUE(p) => Some(p.clone()),
            _ => None,
        })
        .collect();
    assert_eq!(values.len(), rig.vehicle.params().len());
    assert!(
        values
            .iter()
            .all(|p| usize::from(p.param_count) == values.len())
    );
}

#[test]
fn a_vehicle_started_in_the_air_is_armed_and_holds_its_velocity() {
    let mut cfg = VehicleConfig::new(1, Profile::ideal());
    cfg.start = StartState {
        pos_world_ned_m: Vector3::new(0.0, 0.0, -30.0),
        vel_ned_mps: Vector3::new(4.0, 9.0, -7.0),
        yaw_rad: 0.0,
        in_air: true,
    };
    let mut rig = Rig::new(cfg);
    assert!(rig.vehicle.status().armed);
    rig.advance(Duration::from_secs(2));
    let v = rig.vehicle.status().vel_ned_mps;
    assert!((v - Vector3::new(4.0, 9.0, -7.0)).norm() < 0.5, "{v:?}");
}

#[test]
fn timesync_request_is_answered_with_our_time() {
    let mut rig = Rig::on_ground();
    rig.advance(Duration::from_millis(1234));
    rig.send(MavMessage::TIMESYNC(
        mavlink::dialects::common::TIMESYNC_DATA {
            tc1: 0,
            ts1: 42,
            target_system: 0,
            target_component: 0,
        },
    ));
    let reply = rig.received.iter().rev().find_map(|(_, _, m)| match m {
        MavMessage::TIMESYNC(t) => Some(t.clone()),
        _ => None,
    });
    let reply = reply.expect("timesync reply");
    assert_eq!(reply.ts1, 42);
    assert_eq!(reply.tc1, 1_234_000_000);
}

/// PX4's target rules (mavlink_receiver.cpp `evaluate_target_ok`, the setpoint handlers,
/// mavlink_parameters.cpp): commands and setpoints for this system or broadcast and for
/// component 1 or all; parameters for this system exactly. Anything else is ignored,
/// counted, and never answered.
#[test]
fn messages_for_another_system_or_component_are_ignored_as_px4_ignores_them() {
    let mut rig = Rig::on_ground();
    let long = |sys: u8, comp: u8| {
        MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
            target_system: sys,
            target_component: comp,
            command: MavCmd::MAV_CMD_REQUEST_MESSAGE,
            confirmation: 0,
            param1: 148.0, // AUTOPILOT_VERSION
            ..COMMAND_LONG_DATA::default()
        })
    };
    let answered = |rig: &mut Rig, msg: MavMessage| {
        rig.received.clear();
        rig.send(msg);
        rig.received
            .iter()
            .any(|(_, _, m)| matches!(m, MavMessage::COMMAND_ACK(_) | MavMessage::PARAM_VALUE(_)))
    };
    assert!(answered(&mut rig, long(1, 1)));
    assert!(
        answered(&mut rig, long(0, 0)),
        "broadcast, as PX4 main accepts"
    );
    assert!(answered(&mut rig, long(1, 0)));
    let before = rig.vehicle.status().counters.foreign_target;
    assert!(!answered(&mut rig, long(2, 1)), "another system");
    assert!(
        !answered(&mut rig, long(1, 190)),
        "another component of ours"
    );
    assert!(
        !answered(&mut rig, long(0, 100)),
        "broadcast to another component"
    );
    let read = |sys: u8, comp: u8| {
        MavMessage::PARAM_REQUEST_READ(PARAM_REQUEST_READ_DATA {
            param_index: 0,
            target_system: sys,
            target_component: comp,
            param_id: "".into(),
        })
    };
    assert!(answered(&mut rig, read(1, 1)));
    assert!(answered(&mut rig, read(1, 0)));
    assert!(
        !answered(&mut rig, read(0, 1)),
        "parameters are never broadcast"
    );
    assert!(!answered(&mut rig, read(1, 50)));
    assert_eq!(rig.vehicle.status().counters.foreign_target - before, 5);
}

#[test]
fn only_a_datagram_that_vouches_for_its_sender_may_latch_the_link() {
    use ringswarm_wire::signing::{Signing, SigningKey};
    let key = SigningKey::from_bytes([3; 32]);
    let mut cfg = VehicleConfig::new(1, Profile::x500());
    cfg.signing = Some(crate::keystore::StoredKey {
        key: key.clone(),
        timestamp: 1_000,
    });
    let mut signed = Vehicle::new(cfg, World::default()).unwrap();
    let mut plain = Vehicle::new(VehicleConfig::new(1, Profile::x500()), World::default()).unwrap();
    let mut gcs = Encoder::new(GCS.0, GCS.1);
    let heartbeat = crate::autopilot::tests_modes::gcs_heartbeat();
    let unsigned = gcs.encode(&heartbeat);
    let now = SimTime::ZERO;
    // Without a key anything decoded vouches, as in PX4.
    assert!(plain.handle_datagram(now, LinkId::Offboard, &unsigned));
    // With a key an unsigned HEARTBEAT is admitted (PX4 lets it through) but proves
    // nothing; garbage and another key's frames neither.
    assert!(!signed.handle_datagram(now, LinkId::Offboard, &unsigned));
    assert!(!signed.handle_datagram(now, LinkId::Offboard, &[0xFD, 1, 2, 3]));
    let mut theirs = Signing::new(SigningKey::from_bytes([4; 32]), 2_000);
    let forged = gcs.encode_signed(&heartbeat, &mut theirs, 0);
    assert!(!signed.handle_datagram(now, LinkId::Offboard, &forged));
    let mut ours = Signing::new(key, 2_000);
    let genuine = gcs.encode_signed(&heartbeat, &mut ours, 0);
    assert!(signed.handle_datagram(now, LinkId::Offboard, &genuine));
    let c = signed.status().counters;
    assert_eq!(
        (c.unsigned_refused, c.signature_refused, c.bad_frames),
        (0, 1, 1)
    );
}
