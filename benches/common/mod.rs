//! What the benchmarks share: the ring they fly.

use std::fmt::Write as _;

/// `n` ideal vehicles on a circle of radius 3n m at 50 m, drifting east at 2 m/s, asked
/// for a polygon of radius 2n m; k = 1, alpha = 1 and beta 25 % above Yu's bound; on
/// MAVLink networks of 250 (system ids 1..=250 on each); attitude reports at 10 Hz.
pub fn ring(n: usize, rate_hz: f64) -> String {
    ring_sized(n, rate_hz, 2.0 * n as f64, 3.0 * n as f64)
}

/// The same ring packed for the safety filter: a polygon whose sides are 3.3 m (the
/// filter's 3 m separation and a tenth), the vehicles starting on a circle half as
/// large again (5 m apart): as they close in, neighbours' constraints bind.
#[allow(dead_code)] // the real-time bench's; the lockstep bench does not fly it
pub fn dense_ring(n: usize, rate_hz: f64) -> String {
    let radius_m = 3.3 / (2.0 * (std::f64::consts::PI / n as f64).sin());
    ring_sized(n, rate_hz, radius_m, 1.5 * radius_m)
}

fn ring_sized(n: usize, rate_hz: f64, formation_radius_m: f64, start_radius_m: f64) -> String {
    let ring = ringswarm::consensus::RingDigraph::for_agents(n, 1.0).expect("even n");
    let report = ringswarm::consensus::analyze(&ring, None).expect("analysis");
    let beta = (1.25 * report.yu_bound.unwrap_or(1.0)).sqrt();
    let mut s = format!(
        "[swarm]\ncontrol_rate_hz = {rate_hz}\nattitude_rate_hz = 10.0\nduration_s = 60.0\n[gains]\nk = 1.0\nalpha = 1.0\n\
         beta = {beta}\nk_pz = 1.0\nk_vz = 4.0\n[formation]\nkind = \"polygon\"\nradius_m = {}\n\
         altitude_m = 50.0\n[envelope]\nmax_tilt_deg = 45.0\n[emulator]\nground_below_m = 100.0\n",
        formation_radius_m
    );
    for i in 0..n {
        let a = std::f64::consts::TAU * i as f64 / n as f64;
        let r = start_radius_m;
        let _ = write!(
            s,
            "[[vehicle]]\nsystem_id = {}\nnetwork = \"n{}\"\nprofile = \"ideal\"\nmass_kg = 1.0\n\
             hover_throttle = 0.2\nstart_enu_m = [{}, {}, 50.0]\n\
             start_velocity_enu_mps = [2.0, 0.0, 0.0]\nin_air = true\n",
            i % 250 + 1,
            i / 250,
            r * a.cos(),
            r * a.sin()
        );
    }
    for j in 0..n.div_ceil(250) {
        let _ = write!(
            s,
            "[[network]]\nname = \"n{j}\"\nbind = \"0.0.0.0:{}\"\n",
            14600 + j
        );
    }
    s
}
