//! The bodies of the fuzz targets (`fuzz/fuzz_targets`, run with `scripts/fuzz.sh`), here
//! so that `tests/integration/fuzz_smoke.rs` runs the same code on the seed corpus and on seeded
//! random inputs in every test run. Each takes arbitrary bytes and must not panic; the
//! inbound ones also check what comes out.
//!
//! The inbound targets are structure-aware: the bytes are read as a script of operations,
//! each either "advance time by n ms" or "deliver a frame": a message id from the common
//! dialect, sender ids and a payload, encoded with a valid checksum, unsigned, signed with
//! the right key, signed with another key, or a replay of the previous frame. So the
//! fuzzer spends its time in the handlers, not in checksum rejection.

use std::sync::OnceLock;
use std::time::Duration;

use mavlink::MavlinkVersion;
use mavlink::Message;
use mavlink::dialects::common::MavMessage;
use ringswarm_sitl::autopilot::{Vehicle, VehicleConfig};
use ringswarm_sitl::keystore::StoredKey;
use ringswarm_sitl::profile::Profile;
use ringswarm_sitl::world::World;
use ringswarm_wire::codec::{Encoder, decode_datagram_with, raw_frames};
use ringswarm_wire::signing::{PX4_UNSIGNED_ALLOWED, Signing, SigningKey};
use ringswarm_wire::time::SimTime;

use crate::config::Config;
use crate::swarm::{Swarm, SwarmSetup, VehicleIndex};

/// The key of the signed targets.
const KEY: [u8; 32] = [0x42; 32];
/// Another key.
const OTHER_KEY: [u8; 32] = [0x24; 32];
/// A signing stamp in 2026 (10 µs units since 2015).
const STAMP: u64 = 36_000_000_000_000;

/// Every message id of the common dialect.
fn message_ids() -> &'static [u32] {
    static IDS: OnceLock<Vec<u32>> = OnceLock::new();
    IDS.get_or_init(|| {
        (0..=u32::from(u16::MAX))
            .filter(|id| MavMessage::default_message_from_id(*id).is_some())
            .collect()
    })
}

/// Reads bytes off the front of the input; zeros once it is used up.
struct Script<'a>(&'a [u8]);

impl Script<'_> {
    fn byte(&mut self) -> u8 {
        match self.0.split_first() {
            Some((b, rest)) => {
                self.0 = rest;
                *b
            }
            None => 0,
        }
    }

    fn bytes(&mut self, n: usize) -> &[u8] {
        let n = n.min(self.0.len());
        let (head, rest) = self.0.split_at(n);
        self.0 = rest;
        head
    }

    fn is_empty(&self) -> bool {
        self.0.is_empty()
    }
}

/// One step of an inbound script.
enum Step {
    /// Let time pass.
    Advance(Duration),
    /// A datagram to deliver.
    Deliver(Vec<u8>),
}

/// Builds the next step: bit 7 of the opcode set: advance by the low 7 bits in ms;
/// else a frame from (system, component) with a message id (u16 little-endian: that id
/// if the common dialect has it, else the id at that index modulo their number) and a
/// payload from the script, its signing chosen by the low 2 bits.
fn next_step(
    s: &mut Script<'_>,
    signing: &mut (Signing, Signing),
    last: &mut Vec<u8>,
) -> Option<Step> {
    let op = s.byte();
    if op & 0x80 != 0 {
        return Some(Step::Advance(Duration::from_millis(u64::from(op & 0x7F))));
    }
    let ids = message_ids();
    let wanted = u32::from(u16::from_le_bytes([s.byte(), s.byte()]));
    let id = if ids.binary_search(&wanted).is_ok() {
        wanted
    } else {
        ids[wanted as usize % ids.len()]
    };
    let (system, component) = (s.byte(), s.byte());
    let len = usize::from(s.byte());
    let payload = s.bytes(len).to_vec();
    let msg = MavMessage::parse(MavlinkVersion::V2, id, &payload).ok()?;
    let mut encoder = Encoder::new(system, component);
    let bytes = match op & 3 {
        0 => encoder.encode(&msg),
        1 => encoder.encode_signed(&msg, &mut signing.0, op >> 2),
        2 => encoder.encode_signed(&msg, &mut signing.1, op >> 2),
        _ => last.clone(),
    };
    last.clone_from(&bytes);
    Some(Step::Deliver(bytes))
}

fn signings() -> (Signing, Signing) {
    (
        Signing::new(SigningKey::from_bytes(KEY), STAMP),
        Signing::new(SigningKey::from_bytes(OTHER_KEY), STAMP),
    )
}

/// The decoder: every frame of the datagram, without a key and with one, each signed one
/// through the stream rules; the raw splitter must agree on frame boundaries it finds.
pub fn decode(bytes: &[u8]) {
    let key = SigningKey::from_bytes(KEY);
    let mut signing = Signing::new(key.clone(), STAMP);
    for frame in decode_datagram_with(bytes, Some(&key))
        .into_iter()
        .flatten()
    {
        let _ = signing.accept(&frame.stamp(), &PX4_UNSIGNED_ALLOWED);
        // A decoded message encodes again.
        let mut enc = Encoder::new(1, 1);
        assert!(!enc.encode(&frame.msg).is_empty());
    }
    let _ = decode_datagram_with(bytes, None);
    for frame in raw_frames(bytes) {
        assert!(frame.len() <= bytes.len());
    }
}

/// The emulator's inbound handling: a vehicle (signed when the first byte is odd) fed a
/// script; it must keep a finite state and a bounded outbox. Returns its status at the
/// end.
pub fn emulator_inbound(bytes: &[u8]) -> ringswarm_sitl::autopilot::VehicleStatus {
    static VEHICLES: OnceLock<[Vehicle; 2]> = OnceLock::new();
    let vehicles = VEHICLES.get_or_init(|| {
        let plain = VehicleConfig::new(1, Profile::x500());
        let mut signed = plain.clone();
        signed.signing = Some(StoredKey {
            key: SigningKey::from_bytes(KEY),
            timestamp: STAMP,
        });
        [plain, signed]
            .map(|cfg| Vehicle::new(cfg, World::default()).expect("a valid built-in vehicle"))
    });
    let mut s = Script(bytes);
    let mut vehicle = vehicles[usize::from(s.byte() & 1)].clone();
    let (mut signing, mut last) = (signings(), Vec::new());
    let mut now = SimTime::ZERO;
    while !s.is_empty() {
        match next_step(&mut s, &mut signing, &mut last) {
            Some(Step::Advance(d)) => {
                now = now + d;
                vehicle.handle_timeout(now);
            }
            Some(Step::Deliver(datagram)) => {
                vehicle.handle_datagram(
                    now,
                    ringswarm_sitl::autopilot::LinkId::Offboard,
                    &datagram,
                );
            }
            None => {}
        }
        let mut sent = 0;
        while vehicle.poll_transmit().is_some() {
            sent += 1;
        }
        while vehicle.poll_event().is_some() {}
        assert!(sent < 10_000, "{sent} frames queued at once");
        let status = vehicle.status();
        assert!(
            status.pos_world_ned_m.iter().all(|x| x.is_finite())
                && status.vel_ned_mps.iter().all(|x| x.is_finite()),
            "the vehicle's state went non-finite"
        );
    }
    vehicle.status()
}

/// Two vehicles on the ground, 50 Hz, signing on both links.
const COORDINATOR: &str = r#"
[swarm]
control_rate_hz = 50.0
duration_s = 20.0
[gains]
k = 1.0
alpha = 0.6
beta = 1.2
k_pz = 1.0
k_vz = 2.0
[formation]
kind = "offsets"
offsets_m = [[-2.0, 0.0], [2.0, 0.0]]
altitude_m = 5.0
[[vehicle]]
system_id = 1
profile = "x500"
mass_kg = 2.0
hover_throttle = 0.5
drag_per_s = 0.1
start_enu_m = [0.0, 0.0, 0.0]
[[vehicle]]
system_id = 2
profile = "x500"
mass_kg = 2.0
hover_throttle = 0.5
drag_per_s = 0.1
start_enu_m = [5.0, 0.0, 0.0]
"#;

/// The coordinator's inbound handling: a two-vehicle swarm (signed when the first byte is
/// odd) fed a script, each frame delivered on the link the next byte picks. Whatever
/// arrives, every setpoint it sends is finite with thrust in [0, 1]. Returns each link's
/// phase at the end.
pub fn coordinator_inbound(bytes: &[u8]) -> Vec<crate::vehicle::Phase> {
    static SETUPS: OnceLock<[SwarmSetup; 2]> = OnceLock::new();
    let setups = SETUPS.get_or_init(|| {
        let plain = Config::from_toml(COORDINATOR)
            .and_then(|c| c.validate().map_err(|e| e.to_string()))
            .expect("the built-in coordinator config is valid");
        let mut signed = plain.clone();
        crate::security::sign_links(&mut signed.links, &SigningKey::from_bytes(KEY), STAMP);
        [plain, signed]
    });
    let mut s = Script(bytes);
    let mut swarm = Swarm::new(setups[usize::from(s.byte() & 1)].clone());
    let (mut signing, mut last) = (signings(), Vec::new());
    let mut now = SimTime::ZERO;
    while !s.is_empty() {
        let link = usize::from(s.byte() & 1);
        match next_step(&mut s, &mut signing, &mut last) {
            Some(Step::Advance(d)) => {
                now = now + d;
                swarm.handle_timeout(now);
            }
            Some(Step::Deliver(datagram)) => {
                swarm.handle_datagram(now, VehicleIndex(link), &datagram);
            }
            None => {}
        }
        while let Some((_, datagram)) = swarm.poll_transmit() {
            for frame in decode_datagram_with(&datagram, None).into_iter().flatten() {
                check_setpoint(&frame.msg);
            }
        }
    }
    swarm
        .links()
        .map(crate::vehicle::VehicleLink::phase)
        .collect()
}

fn check_setpoint(msg: &MavMessage) {
    match msg {
        MavMessage::SET_ATTITUDE_TARGET(m) => {
            assert!(
                m.q.iter().all(|x| x.is_finite()),
                "non-finite attitude {:?}",
                m.q
            );
            assert!((0.0..=1.0).contains(&m.thrust), "thrust {}", m.thrust);
        }
        MavMessage::SET_POSITION_TARGET_LOCAL_NED(m) => {
            assert!(
                [m.afx, m.afy, m.afz].iter().all(|x| x.is_finite()),
                "non-finite acceleration"
            );
        }
        _ => {}
    }
}

/// The coordinator's configuration parser and every path that takes its numbers: the
/// validation, the bandwidth gate, the transport layout, the emulator's vehicles, places
/// and link faults (lockstep and real time), the split into shards and each shard's plan,
/// and a lockstep flight's first steps.
pub fn coordinator_config(bytes: &[u8]) {
    let Ok(config) = Config::from_toml(&String::from_utf8_lossy(bytes)) else {
        return;
    };
    let _ = config.validate();
    let _ = config.bandwidth_check();
    let _ = config.transport_layout();
    let _ = config.emulator();
    let _ = config.emulator_placements();
    let _ = config.link_faults();
    let _ = config.lockstep_faults();
    if let (Ok(Some(layout)), Ok(setup)) = (config.shard_layout(), config.validate()) {
        for name in &layout.names {
            let _ = config.shard_plan(name, &setup.ring);
        }
    }
    // A flight of up to 16 vehicles (larger rings take too long per input).
    if config.vehicle.len() <= 16
        && let Ok(mut run) = crate::driver::lockstep::Lockstep::from_config(&config)
    {
        for _ in 0..20 {
            run.step();
        }
    }
}

/// The emulator's configuration parser.
pub fn sitl_config(bytes: &[u8]) {
    let _ = ringswarm_sitl::config_file::SitlConfig::from_toml(&String::from_utf8_lossy(bytes));
}
