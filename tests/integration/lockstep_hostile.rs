//! A hostile third party on every link, in lockstep: during paper-sim1 it injects valid
//! frames of the messages that matter, both ways, at 10× the 50 Hz telemetry rate
//! (500 frames/s per link and direction): arm, forced disarm, land, mode changes, a zero
//! thrust setpoint, SETUP_SIGNING with its own key, spoofed heartbeats and positions of
//! the vehicle, with spoofed system ids (the coordinator's, the vehicle's, others) and
//! wrong targets; unsigned, signed with another key, and replays of captured authentic
//! frames. With signing on, nothing of it is obeyed and the flight meets the numbers of
//! the undisturbed one; with signing off the same attack takes vehicles away (so the
//! check can fail).

use crate::common;

use nalgebra::Vector2;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::time::Duration;

use mavlink::dialects::common::{
    COMMAND_LONG_DATA, HEARTBEAT_DATA, LOCAL_POSITION_NED_DATA, MavAutopilot, MavCmd, MavMessage,
    MavModeFlag, MavState, MavType, SET_ATTITUDE_TARGET_DATA, SETUP_SIGNING_DATA,
};
use ringswarm::driver::Observer;
use ringswarm::driver::lockstep::Lockstep;
use ringswarm::swarm::VehicleIndex;
use ringswarm_sitl::autopilot::FlightMode;
use ringswarm_wire::codec::Encoder;
use ringswarm_wire::signing::{Signing, SigningKey};
use ringswarm_wire::time::SimTime;

const START: u64 = common::START;
const N: usize = 6;

fn build(key: Option<&SigningKey>) -> Lockstep {
    common::signed_paper_sim1(key, &vec![key.cloned(); N])
}

/// Keeps the last authentic datagrams of every link, both ways, to replay.
#[derive(Default)]
struct Capture {
    to_vehicle: Vec<Vec<Vec<u8>>>,
    from_vehicle: Vec<Vec<Vec<u8>>>,
}

impl Observer for Capture {
    fn datagram(&mut self, _now: SimTime, vehicle: VehicleIndex, to_vehicle: bool, bytes: &[u8]) {
        let vehicle = vehicle.get();
        let store = if to_vehicle {
            &mut self.to_vehicle
        } else {
            &mut self.from_vehicle
        };
        if store.len() < N {
            store.resize(N, Vec::new());
        }
        let kept = &mut store[vehicle];
        if kept.len() == 64 {
            kept.remove(0);
        }
        kept.push(bytes.to_vec());
    }
}

fn command(target_system: u8, command: MavCmd, p1: f32, p2: f32, p3: f32) -> MavMessage {
    MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
        target_system,
        target_component: 1,
        command,
        confirmation: 0,
        param1: p1,
        param2: p2,
        param3: p3,
        param4: 0.0,
        param5: 0.0,
        param6: 0.0,
        param7: 0.0,
    })
}

/// One hostile message towards vehicle `sysid`.
fn to_vehicle(rng: &mut ChaCha8Rng, sysid: u8) -> MavMessage {
    let target = [0, sysid, sysid % 6 + 1][rng.random_range(0..3)];
    match rng.random_range(0..7) {
        0 => command(
            target,
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            0.0,
            21196.0,
            0.0,
        ),
        1 => command(target, MavCmd::MAV_CMD_NAV_LAND, 0.0, 0.0, 0.0),
        // AUTO.LAND: main mode 4, sub mode 6.
        2 => command(target, MavCmd::MAV_CMD_DO_SET_MODE, 1.0, 4.0, 6.0),
        3 => MavMessage::SET_ATTITUDE_TARGET(SET_ATTITUDE_TARGET_DATA {
            target_system: target,
            target_component: 1,
            q: [1.0, 0.0, 0.0, 0.0],
            thrust: 0.0,
            type_mask: mavlink::dialects::common::AttitudeTargetTypemask::from_bits_truncate(7),
            ..Default::default()
        }),
        4 => MavMessage::SETUP_SIGNING(SETUP_SIGNING_DATA {
            initial_timestamp: if rng.random() { 0 } else { START * 2 },
            target_system: target,
            target_component: 1,
            secret_key: if rng.random() { [0; 32] } else { [0xEE; 32] },
        }),
        5 => command(target, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, 1.0, 0.0, 0.0),
        _ => heartbeat(MavType::MAV_TYPE_GCS, MavModeFlag::empty(), 0),
    }
}

fn heartbeat(mavtype: MavType, base_mode: MavModeFlag, custom_mode: u32) -> MavMessage {
    MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode,
        mavtype,
        autopilot: MavAutopilot::MAV_AUTOPILOT_PX4,
        base_mode,
        system_status: MavState::MAV_STATE_CRITICAL,
        mavlink_version: 3,
    })
}

/// One hostile message towards the coordinator, posing as the vehicle.
fn to_coordinator(rng: &mut ChaCha8Rng) -> MavMessage {
    match rng.random_range(0..2) {
        // Disarmed, in AUTO.LAND.
        0 => heartbeat(
            MavType::MAV_TYPE_QUADROTOR,
            MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
            (4 << 16) | (6 << 24),
        ),
        _ => MavMessage::LOCAL_POSITION_NED(LOCAL_POSITION_NED_DATA {
            time_boot_ms: 0,
            x: rng.random_range(-500.0..500.0),
            y: rng.random_range(-500.0..500.0),
            z: -50.0,
            vx: rng.random_range(-20.0..20.0),
            vy: rng.random_range(-20.0..20.0),
            vz: 0.0,
        }),
    }
}

/// Flies paper-sim1 for `seconds` under attack; returns the run and the frames injected.
fn attacked(key: Option<&SigningKey>, seconds: u64) -> (Lockstep, u64) {
    let mut run = build(key);
    let mut capture = Capture::default();
    let mut rng = ChaCha8Rng::seed_from_u64(99);
    let attacker = SigningKey::from_bytes([0xA5; 32]);
    let mut attacker_clock = Signing::new(attacker, START + 1_000_000);
    let mut injected = 0;
    let mut max_in_flight = 0;
    let mut encoders: Vec<Encoder> = (0..=255).map(|s| Encoder::new(s as u8, 1)).collect();
    while run.now() < SimTime::from_millis(seconds * 1000) {
        let next = run.now() + Duration::from_millis(1);
        run.run_observed(next, &mut capture);
        // 500 frames/s per link and direction: one every 2 ms.
        if !run.now().as_micros().is_multiple_of(2000) || run.now() < SimTime::from_millis(500) {
            continue;
        }
        for i in 0..N {
            let sysid = (i + 1) as u8;
            for to_vehicle_side in [true, false] {
                let form = rng.random_range(0..3);
                let bytes = if form == 2 {
                    let captured = if to_vehicle_side {
                        capture.to_vehicle.get(i)
                    } else {
                        capture.from_vehicle.get(i)
                    };
                    match captured {
                        Some(c) if !c.is_empty() => c[rng.random_range(0..c.len())].clone(),
                        _ => continue,
                    }
                } else {
                    let (source, msg) = if to_vehicle_side {
                        let source = [253u8, 255, rng.random()][rng.random_range(0..3)];
                        (source, to_vehicle(&mut rng, sysid))
                    } else {
                        (sysid, to_coordinator(&mut rng))
                    };
                    let enc = &mut encoders[usize::from(source)];
                    if form == 0 {
                        enc.encode(&msg)
                    } else {
                        enc.encode_signed(&msg, &mut attacker_clock, rng.random())
                    }
                };
                run.inject(to_vehicle_side, i, bytes);
                injected += 1;
            }
        }
        max_in_flight = max_in_flight.max(run.in_flight());
    }
    // Memory stays bounded: nothing piles up in the link queues.
    assert!(max_in_flight < 100, "{max_in_flight} datagrams in flight");
    (run, injected)
}

#[test]
fn with_signing_the_attack_changes_nothing_and_the_flight_meets_its_numbers() {
    let key = SigningKey::from_bytes([0x3C; 32]);
    let (run, injected) = attacked(Some(&key), 40);
    // 39.5 s × 6 links × 2 directions × 500/s, less the replays not yet possible.
    assert!(injected > 200_000, "{injected} frames injected");
    let predicted = Vector2::new(271.0 / 21.0, 157.0 / 21.0);
    for (i, v) in run.vehicles().iter().enumerate() {
        let s = v.status();
        assert_eq!(s.mode, FlightMode::Offboard, "vehicle {}", i + 1);
        let vel = Vector2::new(s.vel_ned_mps.y, s.vel_ned_mps.x);
        assert!(
            (vel - predicted).norm() <= 0.01 * predicted.norm(),
            "vehicle {}: {vel:?} vs {predicted:?}",
            i + 1
        );
        assert!((-s.pos_world_ned_m.z - 50.0).abs() <= 0.5);
        // 39.5 s × 500/s = 19 750 frames towards each vehicle; all refused but the
        // unsigned heartbeats PX4 lets through (a seventh of a third) and the replays
        // not yet possible in the first moments: over 80 %.
        let c = s.counters;
        assert!(
            c.unsigned_refused + c.signature_refused > 15_800,
            "vehicle {}: {c:?}",
            i + 1
        );
    }
    // The coordinator takes no unsigned frame at all.
    for link in run.swarm().links() {
        assert!(link.refused_frames() > 15_800, "{}", link.refused_frames());
        assert_eq!(link.phase(), ringswarm::vehicle::Phase::Flying);
    }
}

#[test]
fn without_signing_the_same_attack_takes_vehicles_away() {
    let (run, _) = attacked(None, 10);
    let lost = run
        .vehicles()
        .iter()
        .filter(|v| v.status().mode != FlightMode::Offboard || !v.status().armed)
        .count();
    assert!(lost >= 3, "only {lost} vehicles taken away");
}
