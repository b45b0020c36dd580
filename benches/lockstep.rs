//! Lockstep speed: the coordinator and the emulator exchanging encoded MAVLink frames in
//! virtual time (1 kHz physics), with and without a run directory being written.
//! `cargo bench --bench lockstep` prints one table row per case; `-- WORD …` keeps the
//! cases whose name contains one of the words (`-- paper` for the two paper-sim1 rows).

use std::time::{Duration, Instant};

use ringswarm::config::Config;
use ringswarm::driver::lockstep::Lockstep;
use ringswarm::record::Recorder;
use ringswarm::swarm::Swarm;
use ringswarm_wire::time::SimTime;

mod common;
use common::ring;

fn lockstep(toml: &str) -> Lockstep {
    Lockstep::from_config(&Config::from_toml(toml).expect("scenario parses")).expect("scenario")
}

fn main() {
    let sim1 = include_str!("../config/paper-sim1.toml");
    let full = 61.2; // handshake (1.2 s) + the paper's 60 s
    println!(
        "| case | vehicles | control | simulated s | wall s | x real time | µs per vehicle per simulated ms |"
    );
    println!("|---|---|---|---|---|---|---|");
    let words: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with('-'))
        .collect();
    let row = |name: &str, toml: &str, record: bool, seconds: f64| {
        if !words.is_empty() && !words.iter().any(|w| name.contains(w.as_str())) {
            return;
        }
        let end = SimTime::from_micros((seconds * 1e6) as u64);
        let mut run = lockstep(toml);
        let n = run.vehicles().len();
        let rate = 1.0 / run.swarm().setup().control_interval.as_secs_f64();
        let dir = std::env::temp_dir().join(format!("ringswarm-bench-{}", std::process::id()));
        let start = Instant::now();
        if record {
            let mut recorder = Recorder::create(&dir, run.swarm(), 0).expect("temp dir");
            struct Rec<'a>(&'a mut Recorder);
            impl ringswarm::driver::Observer for Rec<'_> {
                fn datagram(&mut self, now: SimTime, _: usize, _: bool, bytes: &[u8]) {
                    self.0.datagram(now, bytes);
                }
                fn swarm(&mut self, swarm: &Swarm, now: SimTime) {
                    self.0.sample(swarm, now);
                }
            }
            run.run_observed(end, &mut Rec(&mut recorder));
            let wall = start.elapsed();
            let _ = recorder
                .finish(run.swarm(), run.now(), wall.as_secs_f64())
                .expect("summary");
        } else {
            run.run_until(end, |_| {});
        }
        let wall = start.elapsed();
        let _ = std::fs::remove_dir_all(&dir);
        print_row(name, n, rate, seconds, wall);
    };
    row("paper-sim1", sim1, false, full);
    row("paper-sim1 + run directory", sim1, true, full);
    row("ring of 6", &ring(6, 250.0), false, full);
    row("ring of 16", &ring(16, 250.0), false, full);
    row("ring of 64", &ring(64, 250.0), false, full);
    row("ring of 64, 50 Hz", &ring(64, 50.0), false, full);
    row("ring of 250, 50 Hz", &ring(250, 50.0), false, 20.0);
    row("ring of 1000, 50 Hz", &ring(1000, 50.0), false, 5.0);
    row(
        "ring of 1000, 50 Hz + run directory",
        &ring(1000, 50.0),
        true,
        5.0,
    );
}

fn print_row(name: &str, n: usize, rate: f64, seconds: f64, wall: Duration) {
    let w = wall.as_secs_f64();
    println!(
        "| {name} | {n} | {rate:.0} Hz | {seconds:.1} | {w:.3} | {:.0} | {:.2} |",
        seconds / w,
        w * 1e6 / (n as f64 * seconds * 1e3)
    );
}
