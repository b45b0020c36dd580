//! The coordinator's vehicle machine against the emulator's, exchanging encoded MAVLink
//! frames in virtual time (1 ms steps), with faults injected by the harness.

use std::time::Duration;

use mavlink::Message;
use mavlink::dialects::common::MavMessage;
use nalgebra::UnitQuaternion;
use ringswarm::control::AttitudeThrust;
use ringswarm::link::decode_datagram;
use ringswarm::vehicle::{LinkConfig, LinkEvent, Phase, VehicleLink};
use ringswarm_sitl::autopilot::{FlightMode, LinkId, Vehicle, VehicleConfig};
use ringswarm_sitl::profile::Profile;
use ringswarm_sitl::world::World;
use ringswarm_wire::time::SimTime;

pub(crate) struct Harness {
    pub(crate) link: VehicleLink,
    pub(crate) vehicle: Vehicle,
    pub(crate) now: SimTime,
    pub(crate) events: Vec<(SimTime, LinkEvent)>,
    pub(crate) sent_to_vehicle: Vec<MavMessage>,
}

/// Decides whether a frame gets through: `(to_vehicle, message) -> deliver?`.
pub(crate) type Filter<'a> = &'a mut dyn FnMut(bool, &MavMessage) -> bool;

impl Harness {
    fn new(expected_system: u8, vehicle_system: u8) -> Self {
        Self::with_config(LinkConfig::new(expected_system), vehicle_system)
    }

    fn with_config(cfg: LinkConfig, vehicle_system: u8) -> Self {
        Self::with_vehicle(cfg, VehicleConfig::new(vehicle_system, Profile::x500()))
    }

    /// A link with `cfg` and its idle setpoint level at thrust `0.5`, to the emulated
    /// vehicle `vehicle`.
    pub(crate) fn with_vehicle(cfg: LinkConfig, vehicle: VehicleConfig) -> Self {
        let idle = AttitudeThrust {
            attitude_ned_frd: UnitQuaternion::identity(),
            thrust_norm: 0.5,
            thrust_n: 0.0,
        };
        Self {
            link: VehicleLink::new(cfg, idle),
            vehicle: Vehicle::new(vehicle, World::default()).unwrap(),
            now: SimTime::ZERO,
            events: Vec::new(),
            sent_to_vehicle: Vec::new(),
        }
    }

    pub(crate) fn run(&mut self, d: Duration, filter: Filter<'_>) {
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

    /// What was sent to the vehicle apart from our ground-station heartbeats.
    pub(crate) fn commands_sent(&self) -> Vec<&MavMessage> {
        self.sent_to_vehicle
            .iter()
            .filter(|m| !matches!(m, MavMessage::HEARTBEAT(_)))
            .collect()
    }

    /// `(message id, interval µs)` of every SET_MESSAGE_INTERVAL sent, in order.
    fn intervals_asked(&self) -> Vec<(f32, f32)> {
        self.commands_sent()
            .iter()
            .filter_map(|m| match m {
                MavMessage::COMMAND_LONG(c) if c.command as u32 == 511 => {
                    Some((c.param1, c.param2))
                }
                _ => None,
            })
            .collect()
    }

    /// Runs for `d`, delivering everything; the ids of the messages the vehicle sent.
    fn ids_sent_by_vehicle(&mut self, d: Duration) -> Vec<u32> {
        let mut seen = Vec::new();
        let mut record = |to_vehicle: bool, m: &MavMessage| {
            if !to_vehicle {
                seen.push(m.message_id());
            }
            true
        };
        self.run(d, &mut record);
        seen
    }

    /// The reason of the first `Failed` event.
    pub(crate) fn failure(&self) -> Option<String> {
        self.events.iter().find_map(|(_, e)| match e {
            LinkEvent::Failed(r) => Some(r.clone()),
            _ => None,
        })
    }

    pub(crate) fn flying_at(&self) -> Option<SimTime> {
        self.events
            .iter()
            .find(|(_, e)| *e == LinkEvent::Flying)
            .map(|(t, _)| *t)
    }
}

pub(crate) fn deliver_all(_: bool, _: &MavMessage) -> bool {
    true
}

#[test]
fn handshake_reaches_armed_offboard_after_the_pre_stream() {
    let mut h = Harness::new(1, 1);
    h.run(Duration::from_secs(3), &mut deliver_all);
    assert_eq!(h.link.phase(), Phase::Flying);
    let status = h.vehicle.status();
    assert!(status.armed && status.mode == FlightMode::Offboard);
    // First heartbeat at 1 ms, 1.2 s of stream, then arm and OFFBOARD acknowledged at once
    // (twice, as PX4 main: an early ACCEPTED, then the real one), and 100 ms for a second
    // answer that might have refused.
    let t = h.flying_at().unwrap().as_secs_f64();
    assert!((1.3..1.4).contains(&t), "flying at {t} s");
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
fn the_link_turns_off_the_streams_it_does_not_read_and_waits_for_the_origin() {
    // Every GPS_GLOBAL_ORIGIN is lost until 2.5 s (the answer to the first request and the
    // 0.2 Hz stream's): no arming before the origin, which is asked again each second.
    let mut origin_lost = |to_vehicle: bool, m: &MavMessage| {
        to_vehicle || !matches!(m, MavMessage::GPS_GLOBAL_ORIGIN(_))
    };
    let mut h = Harness::new(1, 1);
    h.run(Duration::from_millis(2500), &mut origin_lost);
    assert!(
        matches!(h.link.phase(), Phase::Streaming(_)),
        "{:?}",
        h.link.phase()
    );
    assert!(!h.vehicle.status().armed, "armed without an origin");
    let requests = |h: &Harness| {
        h.commands_sent()
            .iter()
            .filter(|m| matches!(m, MavMessage::COMMAND_LONG(c) if c.command as u32 == 512 && c.param1 == 49.0))
            .count()
    };
    // At discovery and with the first heartbeat (both at 1 ms), then with the heartbeats
    // at 1 s and 2 s.
    assert_eq!(requests(&h), 4);
    h.run(Duration::from_millis(1500), &mut deliver_all);
    assert!(h.link.state().origin.is_some());
    assert_eq!(h.link.phase(), Phase::Flying);
    // The answer to the 3 s request came: no more requests after it.
    assert_eq!(requests(&h), 5);
    // The two streams it reads at the control rate (20 ms), then every stream of PX4's
    // onboard link it does not read off on this link (interval −1).
    let asked = h.intervals_asked();
    assert_eq!(asked[..2], [(32.0, 20_000.0), (31.0, 20_000.0)]);
    let off: Vec<f32> = asked[2..].iter().map(|(id, _)| *id).collect();
    assert!(asked[2..].iter().all(|(_, interval)| *interval == -1.0));
    for id in [30.0, 33.0, 105.0, 331.0, 1.0, 24.0, 147.0, 242.0] {
        assert!(off.contains(&id), "{id} not turned off: {off:?}");
    }
    // None of them is one it reads.
    for id in [0.0, 31.0, 32.0, 49.0, 77.0, 230.0, 245.0] {
        assert!(!off.contains(&id), "{id} turned off");
    }
    // And the vehicle stopped sending the ones it has: over a second only heartbeats,
    // the two asked for, EXTENDED_SYS_STATE (5 Hz), GPS_GLOBAL_ORIGIN (0.2 Hz),
    // ESTIMATOR_STATUS (1 Hz: whether the position is good), the acknowledgements and the
    // answers to our TIMESYNC (1 Hz) remain.
    let seen = h.ids_sent_by_vehicle(Duration::from_secs(1));
    for id in &seen {
        assert!(
            [0, 31, 32, 49, 77, 245, 42, 230, 111].contains(id),
            "{id} still sent: {seen:?}"
        );
    }
    assert!(seen.iter().filter(|id| **id == 32).count() >= 49);
}

#[test]
fn a_lower_attitude_rate_is_asked_for_and_flown_with() {
    let cfg = LinkConfig {
        attitude_interval: Duration::from_millis(100),
        ..LinkConfig::new(1)
    };
    let mut h = Harness::with_config(cfg, 1);
    h.run(Duration::from_secs(3), &mut deliver_all);
    assert_eq!(h.link.phase(), Phase::Flying);
    assert_eq!(
        h.intervals_asked()[..2],
        [(32.0, 20_000.0), (31.0, 100_000.0)]
    );
    // Over 2 s: LOCAL_POSITION_NED every 20 ms, ATTITUDE_QUATERNION every 100 ms (one
    // more of each when a period boundary falls on both ends).
    let seen = h.ids_sent_by_vehicle(Duration::from_secs(2));
    let count = |id: u32| seen.iter().filter(|s| **s == id).count();
    assert!((100..=101).contains(&count(32)), "{}", count(32));
    assert!((20..=21).contains(&count(31)), "{}", count(31));
    assert!(h.link.state().attitude.is_some());
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
    assert!((2.3..2.4).contains(&t), "flying at {t} s");
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
    // No setpoint reaches the vehicle before 1 s: the DO_SET_MODE at 0.3 s and its resend
    // at 0.8 s find no offboard signal (an early ACCEPTED, then TEMPORARILY_REJECTED, as PX4
    // main answers: the refusal wins); the one at 1.3 s does.
    let mut filter = |to_vehicle: bool, msg: &MavMessage| {
        !(to_vehicle && matches!(msg, MavMessage::SET_ATTITUDE_TARGET(_)))
    };
    h.run(Duration::from_secs(1), &mut filter);
    h.run(Duration::from_secs(2), &mut deliver_all);
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
    let reason = h.failure();
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
    assert!(h.commands_sent().is_empty(), "{:?}", h.commands_sent());
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
    let silent = lost_at.saturating_since(cut).as_secs_f64();
    // Telemetry arrives every 20 ms up to the cut; loss is declared 1.5 s after the last
    // frame heard.
    assert!(
        (1.48..=1.501).contains(&silent),
        "lost {silent} s after the cut"
    );
    h.run(Duration::from_secs(3), &mut deliver_all);
    assert!(h.events.iter().any(|(_, e)| *e == LinkEvent::Recovered));
    assert_eq!(h.link.phase(), Phase::Flying, "{:?}", h.events);
}

#[test]
fn land_is_resent_when_lost_then_the_vehicle_is_disarmed_on_the_ground() {
    use mavlink::dialects::common::MavCmd;
    let mut h = Harness::new(1, 1);
    h.run(Duration::from_secs(2), &mut deliver_all);
    assert_eq!(h.link.phase(), Phase::Flying);
    // Climb for a second, then level off: the vehicle is in the air when told to land.
    let climb = AttitudeThrust {
        attitude_ned_frd: UnitQuaternion::identity(),
        thrust_norm: 0.65,
        thrust_n: 0.0,
    };
    h.link.set_setpoint(h.now, climb);
    h.run(Duration::from_secs(1), &mut deliver_all);
    h.link.set_setpoint(
        h.now,
        AttitudeThrust {
            thrust_norm: 0.5,
            ..climb
        },
    );
    h.run(Duration::from_millis(500), &mut deliver_all);
    assert!(!h.vehicle.status().landed && h.vehicle.status().height_m > 1.0);
    h.link.land(h.now);
    let told = h.now;
    // The first NAV_LAND never reaches the vehicle.
    let mut lands = 0;
    let mut filter = |to_vehicle: bool, msg: &MavMessage| match msg {
        MavMessage::COMMAND_LONG(c) if to_vehicle && c.command == MavCmd::MAV_CMD_NAV_LAND => {
            lands += 1;
            lands > 1
        }
        _ => true,
    };
    h.run(Duration::from_secs(15), &mut filter);
    assert_eq!(h.link.phase(), Phase::Done);
    let status = h.vehicle.status();
    assert!(!status.armed && status.landed, "{status:?}");
    let sent: Vec<(MavCmd, u8, f32)> = h
        .sent_to_vehicle
        .iter()
        .filter_map(|m| match m {
            MavMessage::COMMAND_LONG(c)
                if matches!(
                    c.command,
                    MavCmd::MAV_CMD_NAV_LAND | MavCmd::MAV_CMD_COMPONENT_ARM_DISARM
                ) =>
            {
                Some((c.command, c.confirmation, c.param1))
            }
            _ => None,
        })
        .collect();
    // Arm (handshake), NAV_LAND twice (confirmation 0 then 1), then disarm (param1 0).
    assert_eq!(
        sent,
        vec![
            (MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, 0, 1.0),
            (MavCmd::MAV_CMD_NAV_LAND, 0, 0.0),
            (MavCmd::MAV_CMD_NAV_LAND, 1, 0.0),
            (MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, 0, 0.0),
        ]
    );
    let kinds: Vec<&LinkEvent> = h
        .events
        .iter()
        .filter(|(t, _)| *t > told)
        .map(|(_, e)| e)
        .collect();
    assert!(
        matches!(
            kinds.as_slice(),
            [
                LinkEvent::Retrying { .. },
                LinkEvent::Landing,
                LinkEvent::Landed,
                LinkEvent::Disarmed
            ]
        ),
        "{kinds:?}"
    );
    // Once the vehicle took NAV_LAND no more setpoints are sent.
    assert!(!matches!(
        h.commands_sent().last(),
        Some(MavMessage::SET_ATTITUDE_TARGET(_))
    ));
}

#[test]
fn a_vehicle_never_armed_is_done_at_once_when_told_to_land() {
    let mut h = Harness::new(1, 1);
    h.run(Duration::from_millis(500), &mut deliver_all);
    assert!(matches!(h.link.phase(), Phase::Streaming(_)));
    h.link.land(h.now);
    assert_eq!(h.link.phase(), Phase::Done);
    let before = h.commands_sent().len();
    h.run(Duration::from_secs(2), &mut deliver_all);
    assert_eq!(
        h.commands_sent().len(),
        before,
        "nothing but heartbeats after done"
    );
    assert!(!h.vehicle.status().armed);
}

#[test]
fn a_vehicle_that_never_answers_is_reported_once_and_never_commanded() {
    // Expecting system 1, but only system 2 is there: the link warns once about the
    // foreign system, once (after 10 s) that system 1 was never heard, and sends nothing.
    let mut h = Harness::new(1, 2);
    h.run(Duration::from_secs(25), &mut deliver_all);
    assert_eq!(h.link.phase(), Phase::Discovering);
    assert!(h.commands_sent().is_empty());
    let not_heard: Vec<SimTime> = h
        .events
        .iter()
        .filter(|(_, e)| matches!(e, LinkEvent::NeverHeard { .. }))
        .map(|(t, _)| *t)
        .collect();
    assert_eq!(not_heard, vec![SimTime::from_millis(10_000)]);
    assert_eq!(
        h.events
            .iter()
            .filter(|(_, e)| matches!(e, LinkEvent::WrongSystem { system_id: 2 }))
            .count(),
        1
    );
}

#[test]
fn a_vehicle_taken_out_of_offboard_by_someone_else_is_never_commanded_again() {
    use mavlink::dialects::common::{COMMAND_LONG_DATA, MavCmd};
    let mut h = Harness::new(1, 1);
    h.run(Duration::from_secs(2), &mut deliver_all);
    assert_eq!(h.link.phase(), Phase::Flying);
    // A ground station on the GCS link switches the vehicle to POSCTL (main mode 3).
    let mut gcs = ringswarm::link::Encoder::new(250, 190);
    let switch = gcs.encode(&MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
        target_system: 1,
        target_component: 1,
        command: MavCmd::MAV_CMD_DO_SET_MODE,
        confirmation: 0,
        param1: 1.0,
        param2: 3.0,
        param3: 0.0,
        param4: 0.0,
        param5: 0.0,
        param6: 0.0,
        param7: 0.0,
    }));
    h.vehicle.handle_datagram(h.now, LinkId::Gcs, &switch);
    let switched = h.now;
    h.run(Duration::from_secs(3), &mut deliver_all);
    assert_eq!(h.link.phase(), Phase::Overridden);
    let (at, mode) = h
        .events
        .iter()
        .find_map(|(t, e)| match e {
            LinkEvent::LeftOffboard { custom_mode, .. } => Some((*t, *custom_mode)),
            _ => None,
        })
        .expect("reported");
    assert_eq!((mode >> 16) & 0xFF, 3, "POSCTL");
    // Heartbeats are 1 Hz: the second one outside OFFBOARD comes 1-2 s after the switch.
    let after = at.saturating_since(switched).as_secs_f64();
    assert!((1.0..=2.1).contains(&after), "{after} s");
    // Nothing but heartbeats is sent to the vehicle after that.
    let before = h.commands_sent().len();
    h.run(Duration::from_secs(2), &mut deliver_all);
    assert_eq!(h.commands_sent().len(), before);
    assert_eq!(h.vehicle.status().mode, FlightMode::Position);
    // Told to land, the link leaves it to whoever flies it.
    h.link.land(h.now);
    h.run(Duration::from_secs(1), &mut deliver_all);
    assert_eq!(h.commands_sent().len(), before);
}

#[test]
fn the_link_sends_a_ground_station_heartbeat_every_second_from_its_own_ids() {
    let mut h = Harness::new(1, 1);
    h.run(Duration::from_millis(9500), &mut deliver_all);
    let beats: Vec<_> = h
        .sent_to_vehicle
        .iter()
        .filter_map(|m| match m {
            MavMessage::HEARTBEAT(hb) => Some(hb.clone()),
            _ => None,
        })
        .collect();
    // At the first step (1 ms), then 1, 2, …, 9 s: ten in 9.5 s; type GCS (6), autopilot
    // INVALID (8).
    assert_eq!(beats.len(), 10);
    assert!(
        beats
            .iter()
            .all(|hb| hb.mavtype as u8 == 6 && hb.autopilot as u8 == 8)
    );
}

/// The reason of the link's first `Failed` event after one HEARTBEAT from system 1 with
/// `autopilot`, and what it sent afterwards (nothing but heartbeats is allowed).
fn refusal_of(
    cfg: LinkConfig,
    autopilot: mavlink::dialects::common::MavAutopilot,
) -> Option<String> {
    use mavlink::dialects::common::{HEARTBEAT_DATA, MavModeFlag, MavState, MavType};
    let mut link = VehicleLink::new(
        cfg,
        AttitudeThrust {
            attitude_ned_frd: UnitQuaternion::identity(),
            thrust_norm: 0.5,
            thrust_n: 0.0,
        },
    );
    let heartbeat =
        ringswarm::link::Encoder::new(1, 1).encode(&MavMessage::HEARTBEAT(HEARTBEAT_DATA {
            custom_mode: 4,
            mavtype: MavType::MAV_TYPE_QUADROTOR,
            autopilot,
            base_mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
            system_status: MavState::MAV_STATE_STANDBY,
            mavlink_version: 3,
        }));
    link.handle_datagram(SimTime::from_millis(5), &heartbeat);
    assert_eq!(link.phase(), Phase::Failed);
    let reason = std::iter::from_fn(|| link.poll_event()).find_map(|e| match e {
        LinkEvent::Failed(r) => Some(r),
        _ => None,
    });
    // Nothing but heartbeats is ever sent to it.
    link.handle_timeout(SimTime::from_millis(3000));
    while let Some(bytes) = link.poll_transmit() {
        let msg = decode_datagram(&bytes).remove(0).unwrap().msg;
        assert!(matches!(msg, MavMessage::HEARTBEAT(_)), "{msg:?}");
    }
    reason
}

#[test]
fn a_vehicle_of_an_autopilot_not_spoken_or_not_configured_is_refused_at_discovery() {
    use mavlink::dialects::common::MavAutopilot;
    use ringswarm::vehicle::{Autopilot, AutopilotChoice};
    assert_eq!(
        refusal_of(LinkConfig::new(1), MavAutopilot::MAV_AUTOPILOT_GENERIC).as_deref(),
        Some(
            "vehicle 1: autopilot is generic (MAV_AUTOPILOT_GENERIC): refused (ringswarm speaks PX4 and ArduPilot)"
        )
    );
    let px4_only = LinkConfig {
        autopilot: AutopilotChoice::Only(Autopilot::Px4),
        ..LinkConfig::new(1)
    };
    assert_eq!(
        refusal_of(px4_only, MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA).as_deref(),
        Some(
            "vehicle 1: its heartbeat says ArduPilot (MAV_AUTOPILOT_ARDUPILOTMEGA), the configuration autopilot = \"px4\": refused"
        )
    );
}

/// A link to vehicle 1 that gives it `fence` (ENU about the emulator's world reference,
/// where vehicle 1 starts).
pub(crate) fn fenced(fence: &ringswarm::safety::Fence) -> LinkConfig {
    let frame = ringswarm::frame::CommonFrame::new(World::default().reference);
    let plan = ringswarm::vehicle::FencePlan::new(fence, &frame).expect("a plan");
    LinkConfig {
        fence: Some(std::sync::Arc::new(plan)),
        ..LinkConfig::new(1)
    }
}

/// A regular polygon of `n` vertices and radius `r_m` about the start.
pub(crate) fn polygon(n: usize, r_m: f64) -> ringswarm::safety::Fence {
    let vertices_m = (0..n)
        .map(|k| {
            let a = std::f64::consts::TAU * k as f64 / n as f64;
            nalgebra::Vector2::new(r_m * a.cos(), r_m * a.sin())
        })
        .collect();
    ringswarm::safety::Fence {
        shape: ringswarm::safety::FenceShape::Polygon { vertices_m },
        min_altitude_m: 2.0,
        max_altitude_m: 60.0,
    }
}

#[test]
fn the_fence_is_given_to_the_vehicle_before_it_is_armed() {
    let mut h = Harness::with_config(fenced(&polygon(4, 100.0)), 1);
    h.run(Duration::from_secs(3), &mut deliver_all);
    assert_eq!(h.link.phase(), Phase::Flying);
    let uploaded = h
        .events
        .iter()
        .position(|(_, e)| *e == LinkEvent::FenceUploaded { items: 4 })
        .expect("the fence acknowledged");
    let armed = h
        .events
        .iter()
        .position(|(_, e)| *e == LinkEvent::Armed)
        .expect("armed");
    assert!(uploaded < armed, "{:?}", h.events);
    // The vehicle holds one polygon of the four vertices, each where the plan put it.
    let fence = h.vehicle.geofence();
    assert_eq!(fence.items().len(), 4);
    assert_eq!(fence.shapes(), 1);
    assert!(!fence.breached());
    let frame = ringswarm::frame::CommonFrame::new(World::default().reference);
    let first = fence.items()[0];
    let (lat, lon) = first.lat_lon_deg();
    let back = frame.offset_ned_m(&ringswarm::frame::Geodetic {
        lat_deg: lat,
        lon_deg: lon,
        alt_amsl_m: World::default().reference.alt_amsl_m,
    });
    // Vertex 0 is 100 m east (ENU x): NED (0, 100), to the 1e-7° rounding (≤ 1.1 cm).
    assert!(
        back.x.abs() < 0.012 && (back.y - 100.0).abs() < 0.012,
        "{back:?}"
    );
    assert_eq!((first.command, first.params[0]), (5001, 4.0));
}

#[test]
fn a_lost_fence_request_is_asked_again_by_the_vehicle() {
    let mut h = Harness::with_config(fenced(&polygon(5, 80.0)), 1);
    let mut dropped = 0;
    let mut lose_two = |to_vehicle: bool, m: &MavMessage| {
        if !to_vehicle
            && matches!(m, MavMessage::MISSION_REQUEST_INT(r) if r.seq == 2)
            && dropped < 2
        {
            dropped += 1;
            return false;
        }
        true
    };
    h.run(Duration::from_secs(4), &mut lose_two);
    assert_eq!(dropped, 2);
    assert_eq!(h.link.phase(), Phase::Flying);
    assert_eq!(h.vehicle.geofence().items().len(), 5);
}

#[test]
fn a_vehicle_that_refuses_the_fence_is_never_armed_and_the_reason_is_named() {
    // 70 vertices: more than the 64 fence points PX4 stores.
    let mut h = Harness::with_config(fenced(&polygon(70, 100.0)), 1);
    h.run(Duration::from_secs(4), &mut deliver_all);
    assert_eq!(h.link.phase(), Phase::Failed);
    let reason = h.failure();
    assert_eq!(
        reason.as_deref(),
        Some("vehicle 1: the vehicle refused the fence: MISSION_ACK MAV_MISSION_NO_SPACE")
    );
    assert!(!h.vehicle.status().armed);
}

#[test]
fn a_vehicle_that_never_answers_the_fence_upload_is_not_armed() {
    let mut h = Harness::with_config(fenced(&polygon(4, 100.0)), 1);
    let mut no_mission = |to_vehicle: bool, m: &MavMessage| {
        !(to_vehicle && matches!(m, MavMessage::MISSION_COUNT(_)))
    };
    h.run(Duration::from_secs(6), &mut no_mission);
    assert_eq!(h.link.phase(), Phase::Failed);
    let reason = h.failure();
    // MISSION_COUNT at discovery and every second after: four sends, then given up.
    assert_eq!(
        reason.as_deref(),
        Some(
            "vehicle 1: the vehicle did not answer the fence upload (MISSION_COUNT 4 sent 4 times, 1000 ms apart)"
        )
    );
    assert!(!h.vehicle.status().armed);
}

#[test]
fn the_round_trip_is_timed_with_timesync_once_a_second() {
    let mut h = Harness::new(1, 1);
    assert_eq!(h.link.round_trip(), None);
    h.run(Duration::from_secs(3), &mut deliver_all);
    let requests: Vec<i64> = h
        .sent_to_vehicle
        .iter()
        .filter_map(|m| match m {
            MavMessage::TIMESYNC(t) if t.tc1 == 0 => Some(t.ts1),
            _ => None,
        })
        .collect();
    // With every heartbeat from discovery on (the first in the same 1 ms step as the
    // vehicle's first heartbeat), stamped with the link's clock in ns + 1.
    assert_eq!(
        requests,
        [1_000_001, 1_000_000_001, 2_000_000_001, 3_000_000_001]
    );
    // The harness delivers within its 1 ms step, both ways.
    let rtt = h.link.round_trip().expect("measured");
    assert!(rtt <= Duration::from_millis(2), "{rtt:?}");
}

#[test]
fn two_foreign_systems_interleaved_on_one_link_are_reported_once_each() {
    // Frames from systems 2 and 3, alternating, on the link of vehicle 1: two events in
    // all, not one per frame.
    let mut link = VehicleLink::new(
        LinkConfig::new(1),
        AttitudeThrust {
            attitude_ned_frd: UnitQuaternion::identity(),
            thrust_norm: 0.5,
            thrust_n: 0.0,
        },
    );
    let beat = |system: u8| {
        ringswarm::link::Encoder::new(system, 1).encode(&MavMessage::HEARTBEAT(
            mavlink::dialects::common::HEARTBEAT_DATA {
                custom_mode: 0,
                mavtype: mavlink::dialects::common::MavType::MAV_TYPE_QUADROTOR,
                autopilot: mavlink::dialects::common::MavAutopilot::MAV_AUTOPILOT_PX4,
                base_mode: mavlink::dialects::common::MavModeFlag::empty(),
                system_status: mavlink::dialects::common::MavState::MAV_STATE_STANDBY,
                mavlink_version: 3,
            },
        ))
    };
    for k in 0..1000u64 {
        let now = SimTime::from_millis(k);
        link.handle_datagram(now, &beat(2 + (k % 2) as u8));
    }
    let mut reported = Vec::new();
    while let Some(e) = link.poll_event() {
        if let LinkEvent::WrongSystem { system_id } = e {
            reported.push(system_id);
        }
    }
    assert_eq!(reported, [2, 3]);
    assert_eq!(link.ignored_frames(), 1000);
    assert_eq!(link.phase(), Phase::Discovering);
}

#[test]
fn a_stall_of_the_coordinator_is_not_taken_for_the_vehicle_going_silent() {
    let mut h = Harness::new(1, 1);
    h.run(Duration::from_secs(2), &mut deliver_all);
    assert_eq!(h.link.phase(), Phase::Flying);
    // The coordinator's host stalls for 0.8 s: beyond the 0.3 s state timeout, within the
    // vehicle's own 1 s offboard-loss timeout. The vehicle goes on sending; nothing is read.
    let stalled_at = h.now;
    let mut unread = Vec::new();
    for _ in 0..800 {
        h.now = h.now + Duration::from_millis(1);
        h.vehicle.handle_timeout(h.now);
        while let Some(tx) = h.vehicle.poll_transmit() {
            if tx.link == LinkId::Offboard {
                unread.push(tx.bytes.clone());
            }
        }
    }
    // It wakes: its timers run first, before the frames waiting for it are read.
    let mut unaware = h.link.clone();
    unaware.handle_timeout(h.now);
    let mut told = Vec::new();
    while let Some(e) = unaware.poll_event() {
        told.push(e);
    }
    assert!(
        told.iter().any(|e| matches!(e, LinkEvent::HandedToHold(_))),
        "{told:?}"
    );
    // With the lag its driver measured, the same wake-up judges nothing.
    h.link.set_listen_lag(h.now.saturating_since(stalled_at));
    h.link.handle_timeout(h.now);
    for bytes in &unread {
        h.link.handle_datagram(h.now, bytes);
    }
    h.link.set_listen_lag(Duration::ZERO);
    let woke = h.now;
    h.run(Duration::from_secs(2), &mut deliver_all);
    let after: Vec<_> = h.events.iter().filter(|(t, _)| *t >= woke).collect();
    assert!(
        !after.iter().any(|(_, e)| matches!(
            e,
            LinkEvent::Lost | LinkEvent::HandedToHold(_) | LinkEvent::Recovered
        )),
        "{after:?}"
    );
    assert_eq!(h.link.phase(), Phase::Flying);
}
