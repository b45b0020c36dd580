//! Dense swarms, the pieces alone (no emulator, no links): place assignment and the
//! safety filter on blocks packed 4 m apart with 3 m enforced.
//! `cargo bench --bench dense` prints two tables:
//! - place assignment (`core/src/assignment.rs`) of a square block to a circle of the
//!   same spacing, against its floor: filling the n × n cost matrix;
//! - one safety-filter call on a block packed 3.3 m apart that contracts uniformly (every
//!   neighbouring pair closing at 0.5 m/s), each vehicle commanded an inward acceleration
//!   of 4/s times its velocity (the inner rows broken and binding together), per call
//!   over repeated calls, against its floor: finding the neighbouring pairs (the sweep).
//!
//! `-- WORD …` keeps the rows whose vehicle count is one of the words (`-- 1024`).

use std::hint::black_box;
use std::time::{Duration, Instant};

use nalgebra::{Vector2, Vector3};
use ringswarm::assignment::assign_places;
use ringswarm::safety::{Agent, SafetyFilter, Separation, Settings, Side, Sweep};

/// A `side` × `side` block `spacing_m` apart about the origin.
fn block_at(side: usize, spacing_m: f64) -> Vec<Vector2<f64>> {
    let half = 0.5 * spacing_m * (side - 1) as f64;
    (0..side * side)
        .map(|i| {
            Vector2::new(
                spacing_m * (i % side) as f64 - half,
                spacing_m * (i / side) as f64 - half,
            )
        })
        .collect()
}

/// A `side` × `side` block 4 m apart about the origin.
fn block(side: usize) -> Vec<Vector2<f64>> {
    block_at(side, 4.0)
}

/// A circle of `n` places 4 m apart (chord).
fn circle(n: usize) -> Vec<Vector2<f64>> {
    let radius = 2.0 / (std::f64::consts::PI / n as f64).sin();
    (0..n)
        .map(|l| {
            let a = 2.0 * std::f64::consts::PI * l as f64 / n as f64;
            Vector2::new(a.cos(), a.sin()) * radius
        })
        .collect()
}

fn percentile(sorted: &[Duration], p: f64) -> Duration {
    let k = ((sorted.len() - 1) as f64 * p).round() as usize;
    sorted[k]
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

fn assignment_table(sides: &[usize]) {
    println!("| vehicles | assignment ms | cost matrix floor ms | total / floor | moved |");
    println!("|---|---|---|---|---|");
    for &side in sides {
        let (from, to) = (block(side), circle(side * side));
        let n = from.len();
        let start = Instant::now();
        let floor: f64 = (0..n)
            .flat_map(|i| (0..n).map(move |j| (i, j)))
            .map(|(i, j)| black_box((from[i] - to[j]).norm_squared()))
            .sum();
        black_box(floor);
        let floor_t = start.elapsed();
        let start = Instant::now();
        let a = assign_places(&from, &to).expect("finite");
        let t = start.elapsed();
        println!(
            "| {n} | {:.2} | {:.3} | {:.0} | {} |",
            ms(t),
            ms(floor_t),
            t.as_secs_f64() / floor_t.as_secs_f64().max(1e-9),
            a.moved()
        );
    }
}

fn filter_table(sides: &[usize]) {
    let sep = Separation {
        horizontal_m: 3.0,
        vertical_m: 9.0,
        gamma: 1.0,
    };
    let settings = Settings {
        separation: sep,
        age_s: 0.02,
        keep_weighted_sum: true,
        time_limit_s: 1.0,
    };
    println!(
        "\n| vehicles | rows | active | outcome | p50 ms | p99 ms | max ms | sweep floor ms | p50 / floor |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for &side in sides {
        let spacing_m = 3.3;
        let pos = block_at(side, spacing_m);
        let n = pos.len();
        let agents: Vec<Agent> = pos
            .iter()
            .map(|p| {
                // Uniform contraction: neighbours close at 0.5 m/s.
                let v = -p * (0.5 / spacing_m);
                Agent {
                    side: Some(Side {
                        pos_m: Vector3::new(p.x, p.y, 50.0),
                        vel_mps: Vector3::new(v.x, v.y, 0.0),
                        accel_z_mps2: 0.0,
                    }),
                    controlled: true,
                    weight: 1.0,
                    drift_mps2: Vector2::zeros(),
                    limit_mps2: 6.0,
                    braking_mps2: 3.0,
                }
            })
            .collect();
        let given: Vec<Vector2<f64>> = agents
            .iter()
            .map(|a| a.side.map_or(Vector2::zeros(), |s| s.vel_mps.xy() * 4.0))
            .collect();
        let mut filter = SafetyFilter::default();
        let calls = if n > 500 { 20 } else { 100 };
        let mut times = Vec::with_capacity(calls);
        let mut report = None;
        for _ in 0..calls {
            let mut commands = given.clone();
            let start = Instant::now();
            report = Some(filter.filter(&settings, &agents, &mut commands, None));
            times.push(start.elapsed());
            black_box(&commands);
        }
        times.sort();
        let positions: Vec<Option<Vector3<f64>>> =
            agents.iter().map(|a| a.side.map(|s| s.pos_m)).collect();
        let mut sweep = Sweep::default();
        let start = Instant::now();
        for _ in 0..calls {
            black_box(
                sweep
                    .pairs_within(&positions, sep.vertical_scale(), 9.0)
                    .len(),
            );
        }
        let floor = start.elapsed() / calls as u32;
        let r = report.expect("called");
        let outcome = match r.outcome {
            ringswarm::safety::Outcome::Untouched => "untouched".to_owned(),
            ringswarm::safety::Outcome::Filtered { sum_kept, relaxed } => {
                format!("filtered (sum kept {sum_kept}, relaxed {relaxed})")
            }
            ringswarm::safety::Outcome::Fallback { reason } => format!("fallback: {reason}"),
        };
        let p50 = percentile(&times, 0.5);
        println!(
            "| {n} | {} | {} | {outcome} | {:.2} | {:.2} | {:.2} | {:.3} | {:.0} |",
            r.rows,
            r.active,
            ms(p50),
            ms(percentile(&times, 0.99)),
            ms(*times.last().expect("calls")),
            ms(floor),
            p50.as_secs_f64() / floor.as_secs_f64().max(1e-9),
        );
    }
}

fn main() {
    let words: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with('-'))
        .collect();
    let keep =
        |side: &usize| words.is_empty() || words.iter().any(|w| *w == (side * side).to_string());
    let assignment: Vec<usize> = [4, 10, 32, 64].into_iter().filter(keep).collect();
    let filter: Vec<usize> = [10, 16, 32].into_iter().filter(keep).collect();
    assignment_table(&assignment);
    filter_table(&filter);
}
