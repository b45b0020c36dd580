//! What several integration tests build the same way.

// Each test crate that includes this module uses part of it.
#![allow(dead_code)]

use ringswarm::config::Config;
use ringswarm::driver::lockstep::{LinkConditions, Lockstep};
use ringswarm::swarm::Swarm;
use ringswarm_sitl::autopilot::Vehicle;
use ringswarm_sitl::keystore::StoredKey;
use ringswarm_wire::signing::SigningKey;

/// A signing stamp in 2026 (10 µs units since 2015): both sides start from it, as `fly`
/// and `sitl` start from the wall clock.
pub const START: u64 = 36_000_000_000_000;

/// paper-sim1 in lockstep, the coordinator signing with `coordinator` (or not) and
/// vehicle `i` holding `vehicle_keys[i]` (or no key).
pub fn signed_paper_sim1(
    coordinator: Option<&SigningKey>,
    vehicle_keys: &[Option<SigningKey>],
) -> Lockstep {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/paper-sim1.toml");
    let config = Config::from_toml(&std::fs::read_to_string(path).unwrap()).unwrap();
    let mut setup = config.validate().unwrap();
    if let Some(key) = coordinator {
        ringswarm::security::sign_links(&mut setup.links, key, START);
    }
    let (world, vehicles) = config.emulator().unwrap();
    let vehicles = vehicles
        .into_iter()
        .zip(vehicle_keys)
        .map(|(mut v, key)| {
            v.signing = key.clone().map(|key| StoredKey {
                key,
                timestamp: START,
            });
            Vehicle::new(v, world).unwrap()
        })
        .collect();
    Lockstep::new(Swarm::new(setup), vehicles, LinkConditions::default())
}

/// Each emulated vehicle's true position and velocity (NED), to compare runs bit for bit.
pub fn vehicle_states(run: &Lockstep) -> Vec<[f64; 6]> {
    run.vehicles()
        .iter()
        .map(|v| {
            let s = v.status();
            let (p, u) = (s.pos_world_ned_m, s.vel_ned_mps);
            [p.x, p.y, p.z, u.x, u.y, u.z]
        })
        .collect()
}

/// The places of a regular ring of `n` on a circle of `radius_m` (m, ENU), vehicle `l` at
/// `2πl/n` from east: paper-sim2's `[formation] kind = "polygon"` of six at 20 m.
pub fn ring_offsets_m(n: usize, radius_m: f64) -> Vec<nalgebra::Vector2<f64>> {
    (0..n)
        .map(|l| {
            let a = 2.0 * std::f64::consts::PI * l as f64 / n as f64;
            nalgebra::Vector2::new(a.cos(), a.sin()) * radius_m
        })
        .collect()
}

/// The w-weighted mean of the emulated vehicles' true horizontal velocities (m/s, ENU):
/// what the law keeps at its predicted final velocity.
pub fn weighted_mean_velocity_enu(
    vehicles: &[Vehicle],
    ring: &ringswarm::consensus::RingDigraph,
) -> nalgebra::Vector2<f64> {
    let w: Vec<f64> = (0..vehicles.len()).map(|i| ring.w(i)).collect();
    let total: f64 = w.iter().sum();
    vehicles
        .iter()
        .zip(&w)
        .map(|(v, w)| ringswarm::control::ned_to_enu(v.status().vel_ned_mps).xy() * *w)
        .sum::<nalgebra::Vector2<f64>>()
        / total
}
