//! The coordinator's vehicle machine against the emulator's, exchanging encoded MAVLink
//! frames in virtual time (1 ms steps), with faults injected by the harness.

use std::time::Duration;

use mavlink::dialects::common::MavMessage;
use nalgebra::UnitQuaternion;
use ringswarm::control::AttitudeThrust;
use ringswarm::link::decode_datagram;
use ringswarm::vehicle::{LinkConfig, LinkEvent, Phase, VehicleLink};
use ringswarm_sitl::autopilot::{FlightMode, LinkId, Vehicle, VehicleConfig};
use ringswarm_sitl::profile::Profile;
use ringswarm_sitl::time::SimTime;
use ringswarm_sitl::world::World;

struct Harness {
    link: VehicleLink,
    vehicle: Vehicle,
    now: SimTime,
    events: Vec<(SimTime, LinkEvent)>,
    sent_to_vehicle: Vec<MavMessage>,
}

/// Decides whether a frame gets through: `(to_vehicle, message) -> deliver?`.
type Filter<'a> = &'a mut dyn FnMut(bool, &MavMessage) -> bool;

impl Harness {
    fn new(expected_system: u8, vehicle_system: u8) -> Self {
        let idle = AttitudeThrust {
            attitude_ned_frd: UnitQuaternion::identity(),
            thrust_norm: 0.5,
            thrust_n: 0.0,
        };
        Self {
            link: VehicleLink::new(LinkConfig::new(expected_system), idle),
            vehicle: Vehicle::new(
                VehicleConfig::new(vehicle_system, Profile::x500()),
                World::default(),
            )
            .unwrap(),
            now: SimTime::ZERO,
            events: Vec::new(),
            sent_to_vehicle: Vec::new(),
        }
    }

    fn run(&mut self, d: Duration, filter: Filter<'_>) {
        let end = self.now + d;
        while self.now < end {
            self.now = self.now + Duration::from_millis(1);
            self.vehicle.handle_timeout(self.now);
            while let Some(tx) = self.vehicle.poll_transmit() {
                if tx.link != LinkId::Offboard {
                    continue;
                }
                let msg = decode_datagram(&tx.bytes).remove(0).unwrap().msg;
                if filter(false, &msg) {
                    self.link.handle_datagram(self.now, &tx.bytes);
                }
            }
            if self.now >= self.link.poll_timeout() {
                self.link.handle_timeout(self.now);
            }
            while let Some(bytes) = self.link.poll_transmit() {
                let msg = decode_datagram(&bytes).remove(0).unwrap().msg;
                self.sent_to_vehicle.push(msg.clone());
                if filter(true, &msg) {
                    self.vehicle
                        .handle_datagram(self.now, LinkId::Offboard, &bytes);
                }
            }
            while let Some(e) = self.link.poll_event() {
                self.events.push((self.now, e));
            }
        }
    }

    fn flying_at(&self) -> Option<SimTime> {
        self.events
            .iter()
            .find(|(_, e)| *e == LinkEvent::Flying)
            .map(|(t, _)| *t)
    }
}

fn deliver_all(_: bool, _: &MavMessage) -> bool {
    true
}

#[test]
fn handshake_reaches_armed_offboard_after_the_pre_stream() {
    let mut h = Harness::new(1, 1);
    h.run(Duration::from_secs(3), &mut deliver_all);
    assert_eq!(h.link.phase(), Phase::Flying);
    let status = h.vehicle.status();
    assert!(status.armed && status.mode == FlightMode::Offboard);
    // First heartbeat at 1 ms, 1.2 s of stream, then arm and OFFBOARD acknowledged at once.
    let t = h.flying_at().unwrap().as_secs_f64();
    assert!((1.2..1.3).contains(&t), "flying at {t} s");
    assert!(
        h.link.state().origin.is_some(),
        "GPS_GLOBAL_ORIGIN was requested and received"
    );
    // Setpoints every 20 ms from the first heartbeat (t = 1 ms) to the end (3 s):
    // floor(2999 / 20) + 1 = 150.
    let setpoints = h
        .sent_to_vehicle
        .iter()
        .filter(|m| matches!(m, MavMessage::SET_ATTITUDE_TARGET(_)))
        .count();
    assert_eq!(setpoints, 150);
}

#[test]
fn lost_acknowledgements_are_resent_with_the_next_confirmation() {
    let mut h = Harness::new(1, 1);
    // Drop every COMMAND_LONG for the first two arm attempts (and so their acks).
    let mut arm_seen = 0;
    let mut filter = |to_vehicle: bool, msg: &MavMessage| match msg {
        MavMessage::COMMAND_LONG(c)
            if to_vehicle
                && c.command == mavlink::dialects::common::MavCmd::MAV_CMD_COMPONENT_ARM_DISARM =>
        {
            arm_seen += 1;
            arm_seen > 2
        }
        _ => true,
    };
    h.run(Duration::from_secs(4), &mut filter);
    assert_eq!(h.link.phase(), Phase::Flying);
    let confirmations: Vec<u8> = h
        .sent_to_vehicle
        .iter()
        .filter_map(|m| match m {
            MavMessage::COMMAND_LONG(c)
                if c.command == mavlink::dialects::common::MavCmd::MAV_CMD_COMPONENT_ARM_DISARM =>
            {
                Some(c.confirmation)
            }
            _ => None,
        })
        .collect();
    assert_eq!(confirmations, vec![0, 1, 2]);
    assert_eq!(
        h.events
            .iter()
            .filter(|(_, e)| matches!(e, LinkEvent::Retrying { .. }))
            .count(),
        2
    );
    // Two ack timeouts of 0.5 s later than the clean handshake.
    let t = h.flying_at().unwrap().as_secs_f64();
    assert!((2.2..2.3).contains(&t), "flying at {t} s");
}

#[test]
fn a_refused_offboard_switch_is_retried_until_accepted() {
    let mut h = Harness::new(1, 1);
    h.link = VehicleLink::new(
        LinkConfig {
            pre_stream: Duration::from_millis(300),
            ..LinkConfig::new(1)
        },
        AttitudeThrust {
            attitude_ned_frd: UnitQuaternion::identity(),
            thrust_norm: 0.5,
            thrust_n: 0.0,
        },
    );
    h.run(Duration::from_secs(3), &mut deliver_all);
    // The stream is only 0.3 s old at the first DO_SET_MODE: TEMPORARILY_REJECTED, then
    // resent every 0.5 s until the emulator has seen 1 s of stream.
    assert_eq!(h.link.phase(), Phase::Flying);
    let retries = h
        .events
        .iter()
        .filter(|(_, e)| matches!(e, LinkEvent::Retrying { command: 176, .. }))
        .count();
    assert_eq!(retries, 2, "{:?}", h.events);
}

#[test]
fn a_vehicle_that_never_acknowledges_makes_the_handshake_fail_clearly() {
    let mut h = Harness::new(1, 1);
    let mut filter = |to_vehicle: bool, msg: &MavMessage| {
        !(to_vehicle
            && matches!(msg, MavMessage::COMMAND_LONG(c) if c.command == mavlink::dialects::common::MavCmd::MAV_CMD_COMPONENT_ARM_DISARM))
    };
    h.run(Duration::from_secs(5), &mut filter);
    assert_eq!(h.link.phase(), Phase::Failed);
    let reason = h.events.iter().find_map(|(_, e)| match e {
        LinkEvent::Failed(r) => Some(r.clone()),
        _ => None,
    });
    assert_eq!(
        reason.as_deref(),
        Some("vehicle 1: MAV_CMD_COMPONENT_ARM_DISARM not accepted after 4 attempts")
    );
    assert!(!h.vehicle.status().armed);
}

#[test]
fn a_vehicle_with_another_system_id_is_never_commanded() {
    let mut h = Harness::new(1, 2);
    h.run(Duration::from_secs(3), &mut deliver_all);
    assert_eq!(h.link.phase(), Phase::Discovering);
    assert!(h.sent_to_vehicle.is_empty(), "{:?}", h.sent_to_vehicle);
    assert!(
        h.events
            .iter()
            .any(|(_, e)| *e == LinkEvent::WrongSystem { system_id: 2 })
    );
    assert!(h.link.ignored_frames() > 100);
}

#[test]
fn silence_is_detected_as_loss_and_a_returning_vehicle_is_handshaken_again() {
    let mut h = Harness::new(1, 1);
    h.run(Duration::from_secs(2), &mut deliver_all);
    assert_eq!(h.link.phase(), Phase::Flying);
    let cut = h.now;
    h.run(Duration::from_secs(3), &mut |to_vehicle, _| to_vehicle);
    let lost_at = h
        .events
        .iter()
        .find(|(_, e)| *e == LinkEvent::Lost)
        .map(|(t, _)| *t)
        .unwrap();
    let silent = (lost_at - cut).as_secs_f64();
    // The last heartbeat came up to 1 s before the cut; loss is declared 1.5 s after it.
    assert!(
        (0.5..=1.51).contains(&silent),
        "lost {silent} s after the cut"
    );
    h.run(Duration::from_secs(3), &mut deliver_all);
    assert!(h.events.iter().any(|(_, e)| *e == LinkEvent::Recovered));
    assert_eq!(h.link.phase(), Phase::Flying, "{:?}", h.events);
}
