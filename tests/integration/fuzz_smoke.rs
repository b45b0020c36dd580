//! Every fuzz target (`ringswarm::fuzzing`, run under libFuzzer by `scripts/fuzz.sh`) on
//! its committed seed corpus and on seeded mutations of it: a short, deterministic run in
//! every test run. The seeds themselves are checked to be what they claim.

use std::path::{Path, PathBuf};

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use ringswarm::fuzzing;
use ringswarm::vehicle::Phase;
use ringswarm_sitl::autopilot::FlightMode;
use ringswarm_wire::codec::decode_datagram;

fn corpus(target: &str) -> Vec<(PathBuf, Vec<u8>)> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fuzz/corpus")
        .join(target);
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .collect();
    files.sort();
    assert!(!files.is_empty(), "no seeds in {}", dir.display());
    files
        .into_iter()
        .map(|p| {
            let bytes = std::fs::read(&p).unwrap();
            (p, bytes)
        })
        .collect()
}

/// A mutation of `seed`: flipped bytes, a cut, a splice with `other`, or random bytes.
fn mutate(rng: &mut ChaCha8Rng, seed: &[u8], other: &[u8]) -> Vec<u8> {
    let mut out = seed.to_vec();
    match rng.random_range(0..4) {
        0 => {
            for _ in 0..rng.random_range(1..8) {
                if !out.is_empty() {
                    let i = rng.random_range(0..out.len());
                    out[i] = rng.random();
                }
            }
        }
        1 => out.truncate(rng.random_range(0..=out.len())),
        2 => {
            let cut = rng.random_range(0..=out.len());
            let from = rng.random_range(0..=other.len());
            out.truncate(cut);
            out.extend_from_slice(&other[from..]);
        }
        _ => {
            out = (0..rng.random_range(0..300))
                .map(|_| rng.random())
                .collect();
        }
    }
    out
}

/// Runs `target` on every seed and on `mutations` mutations of them.
fn run<T>(target: &str, body: fn(&[u8]) -> T, mutations: usize) {
    let seeds = corpus(target);
    for (path, bytes) in &seeds {
        eprintln!("{}", path.display());
        body(bytes);
    }
    let mut rng = ChaCha8Rng::seed_from_u64(0x5EED);
    for _ in 0..mutations {
        let a = &seeds[rng.random_range(0..seeds.len())].1;
        let b = &seeds[rng.random_range(0..seeds.len())].1;
        body(&mutate(&mut rng, a, b));
    }
}

fn seed(target: &str, name: &str) -> Vec<u8> {
    corpus(target)
        .into_iter()
        .find(|(p, _)| p.ends_with(name))
        .unwrap_or_else(|| panic!("seed {name}"))
        .1
}

#[test]
fn decode_seeds_are_the_frames_they_are_named_for_and_mutations_do_not_panic() {
    let seeds = corpus("decode");
    let named = |name: &str| {
        &seeds
            .iter()
            .find(|(p, _)| p.ends_with(name))
            .unwrap_or_else(|| panic!("seed {name}"))
            .1
    };
    for (name, version, signed) in [
        ("heartbeat-v1", mavlink::MavlinkVersion::V1, false),
        ("heartbeat-v2", mavlink::MavlinkVersion::V2, false),
        ("heartbeat-signed", mavlink::MavlinkVersion::V2, true),
    ] {
        let frames = decode_datagram(named(name));
        let frame = frames[0].as_ref().expect("a frame");
        assert_eq!(frame.version, version, "{name}");
        assert_eq!(frame.signature.is_some(), signed, "{name}");
        assert!(matches!(
            frame.msg,
            mavlink::dialects::common::MavMessage::HEARTBEAT(_)
        ));
    }
    assert_eq!(decode_datagram(named("two-frames")).len(), 2);
    run("decode", fuzzing::decode, 20_000);
}

#[test]
fn emulator_inbound_survives_its_seeds_and_mutations() {
    // The flight seeds fly: 1.5 s of setpoints, arm, OFFBOARD (signed on a signed
    // vehicle); the SETUP_SIGNING seed turns signing on, so its last two arms (a replay,
    // another key) are refused.
    for name in ["offboard-unsigned", "offboard-signed"] {
        let status = fuzzing::emulator_inbound(&seed("emulator_inbound", name));
        assert!(status.armed, "{name}");
        assert_eq!(status.mode, FlightMode::Offboard, "{name}");
    }
    let status = fuzzing::emulator_inbound(&seed("emulator_inbound", "setup-signing"));
    assert_eq!(status.counters.signature_refused, 2);
    run("emulator_inbound", fuzzing::emulator_inbound, 300);
}

#[test]
fn coordinator_inbound_survives_its_seeds_and_mutations() {
    // The seeds pose as vehicle 1 on link 0, armed in OFFBOARD: taken as flying.
    for name in ["vehicle-unsigned", "vehicle-signed"] {
        let phases = fuzzing::coordinator_inbound(&seed("coordinator_inbound", name));
        assert_eq!(phases[0], Phase::Flying, "{name}: {phases:?}");
        assert_eq!(phases[1], Phase::Discovering, "{name}");
    }
    run("coordinator_inbound", fuzzing::coordinator_inbound, 300);
}

#[test]
fn config_parsers_survive_their_seeds_and_mutations() {
    // The seeds are the shipped configurations as they are now…
    let shipped = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config");
    let seeds = corpus("coordinator_config");
    for entry in std::fs::read_dir(&shipped).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap();
        let seed = seeds.iter().find(|(p, _)| p.file_name() == Some(name));
        assert!(
            seed.is_some_and(|(_, bytes)| *bytes == std::fs::read(&path).unwrap()),
            "fuzz/corpus/coordinator_config/{} is not config/{0} as it is now",
            name.to_string_lossy()
        );
    }
    // …and each is taken whole (a parser that refused them all would also survive every
    // mutation).
    for (path, bytes) in corpus("coordinator_config") {
        let text = String::from_utf8_lossy(&bytes);
        let config = ringswarm::config::Config::from_toml(&text)
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        if let Err(e) = config.validate() {
            panic!("{}: {e}", path.display());
        }
        assert!(config.emulator().is_ok(), "{}", path.display());
        assert!(config.lockstep_faults().is_ok(), "{}", path.display());
        assert!(config.link_faults().is_ok(), "{}", path.display());
        assert!(config.transport_layout().is_ok(), "{}", path.display());
        assert!(config.emulator_placements().is_ok(), "{}", path.display());
        assert!(config.bandwidth_check().is_ok(), "{}", path.display());
    }
    // The numbers that once reached a panic through `demo --realtime` (a negative or NaN
    // latency): the fuzz body takes them, and the one constructor names them.
    let paper = std::fs::read_to_string(shipped.join("paper-sim1.toml")).unwrap();
    let bad = paper.replace(
        "[emulator]",
        "[emulator]\nlatency_ms = -1.0\njitter_ms = nan",
    );
    fuzzing::coordinator_config(bad.as_bytes());
    let config = ringswarm::config::Config::from_toml(&bad).unwrap();
    assert_eq!(
        config.link_faults().unwrap_err(),
        "emulator.latency_ms must be in [0, 10000] ms, got -1\nemulator.jitter_ms must be in [0, 10000] ms, got NaN"
    );
    for (path, bytes) in corpus("sitl_config") {
        let text = String::from_utf8_lossy(&bytes);
        let parsed = ringswarm_sitl::config_file::SitlConfig::from_toml(&text);
        assert!(parsed.is_ok(), "{}: {:?}", path.display(), parsed.err());
    }
    run("coordinator_config", fuzzing::coordinator_config, 2_000);
    run("sitl_config", fuzzing::sitl_config, 2_000);
}
