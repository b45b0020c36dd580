//! Dense swarms, the pieces alone (no emulator, no links): place assignment and the
//! safety filter on blocks packed 4 m apart with 3 m enforced.
//! `cargo bench --bench dense` prints two tables:
//! - place assignment (`core/src/assignment.rs`) of a square block to a circle of the
//!   same spacing, against its floor: filling the n × n cost matrix;
//! - the safety filter flying a mirror swap for 1500 ticks of 10 ms (double integrators,
//!   a block 4 m apart at rest, each vehicle flown by a PD law to its start mirrored
//!   through the centre, inside its 6 m/s² disc; 3 m enforced): every path crosses the
//!   centre, where the block binds. Each size flies with the barrier counting on half and
//!   on a quarter of each disc for braking (`[safety] braking_share`), with the time limit
//!   of real time at 100 Hz with `budget_share` 0.2 (2 ms) and, up to 256 vehicles,
//!   without one (as in lockstep). Time per tick (the first, cold, apart), sweeps of the
//!   dual ascent, the largest piece, unfinished ticks and the closest pair, against the
//!   floor: finding the neighbouring pairs of the block as it starts (the sweep).
//!
//! `-- WORD …` keeps the rows whose vehicle count is one of the words (`-- 1024`), and
//! `barrier` or `stopping` the rows of that kind only.

use std::hint::black_box;
use std::time::{Duration, Instant};

use nalgebra::{Vector2, Vector3};
use ringswarm::assignment::assign_places;
use ringswarm::safety::{Agent, Rows, SafetyFilter, Separation, Settings, Side, Sweep};

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

fn filter_table(sides: &[usize], kinds: &[Rows]) {
    println!(
        "\n| vehicles | rows | braking share | time limit | ticks | rows (last) | largest piece | sweeps p50 / max | unfinished | braked | unresolved | closest m | left m | first ms | p50 ms | p99 ms | max ms | sweep floor ms | p50 / floor |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for &side in sides {
        for &kind in kinds {
            for share in [0.5, 0.25] {
                // As in real time at 100 Hz with `budget_share` 0.2; without a limit (as
                // in lockstep) only up to 256, where one tick can take 0.1 s.
                for limit_s in [0.002, f64::INFINITY] {
                    if limit_s.is_infinite() && side > 16 {
                        continue;
                    }
                    filter_row(side, share, limit_s, kind);
                }
            }
        }
    }
}

/// One row of the filter table: the mirror swap of a `side` × `side` block, each vehicle
/// braking at `share` of its disc, with the filter's time limit `limit_s` and rows `kind`.
fn filter_row(side: usize, share: f64, limit_s: f64, kind: Rows) {
    let sep = Separation {
        horizontal_m: 3.0,
        vertical_m: 9.0,
        gamma: 1.0,
    };
    let settings = Settings {
        separation: sep,
        age_s: 0.02,
        period_s: 0.01,
        keep_weighted_sum: true,
        time_limit_s: limit_s,
        rows: kind,
        brake_to_mps: Vector2::zeros(),
    };
    {
        let spacing_m = 4.0;
        let dt = 0.01;
        let ticks = 1500;
        let mut pos: Vec<Vector2<f64>> = block_at(side, spacing_m);
        // Each vehicle's place: its start mirrored through the centre.
        let places: Vec<Vector2<f64>> = pos.iter().map(|p| -p).collect();
        let mut vel: Vec<Vector2<f64>> = vec![Vector2::zeros(); pos.len()];
        let mut flying: Vec<Vector2<f64>> = vec![Vector2::zeros(); pos.len()];
        let n = pos.len();
        let mut filter = SafetyFilter::default();
        let mut times = Vec::with_capacity(ticks);
        let mut sweeps = Vec::with_capacity(ticks);
        let (mut largest, mut unfinished, mut rows) = (0, 0, 0);
        let (mut braked, mut unresolved) = (0, 0);
        let mut closest = f64::INFINITY;
        for _ in 0..ticks {
            let agents: Vec<Agent> = pos
                .iter()
                .zip(&vel)
                .map(|(p, v)| Agent {
                    side: Some(Side {
                        pos_m: Vector3::new(p.x, p.y, 50.0),
                        vel_mps: Vector3::new(v.x, v.y, 0.0),
                        accel_z_mps2: 0.0,
                    }),
                    controlled: true,
                    weight: 1.0,
                    drift_mps2: Vector2::zeros(),
                    limit_mps2: 6.0,
                    braking_mps2: share * 6.0,
                    lag_s: 0.0,
                    spread_m: 0.0,
                    unseen_mps: 0.0,
                })
                .collect();
            // Every vehicle flown to its place (0.05/s² and 0.5/s, inside its disc):
            // every path crosses the centre, where the block binds.
            let mut commands: Vec<Vector2<f64>> = (0..n)
                .map(|k| {
                    let u = (places[k] - pos[k]) * 0.05 - vel[k] * 0.5;
                    if u.norm() > 6.0 {
                        u * (6.0 / u.norm())
                    } else {
                        u
                    }
                })
                .collect();
            let start = Instant::now();
            let report = filter.filter(&settings, &agents, &mut commands, None);
            times.push(start.elapsed());
            black_box(&commands);
            sweeps.push(report.sweeps);
            braked += report.braked;
            unresolved += report.unresolved;
            largest = largest.max(report.largest_piece);
            rows = report.rows;
            unfinished += usize::from(matches!(
                report.outcome,
                ringswarm::safety::Outcome::Unfinished { .. }
            ));
            if let Some((_, _, d)) = report.closest {
                closest = closest.min(d);
            }
            // Each command acts a tick after the state it was filtered on (the state age
            // of 0.02 s: a tick of delay and a tick of hold).
            for k in 0..n {
                pos[k] += vel[k] * dt + flying[k] * (0.5 * dt * dt);
                vel[k] += flying[k] * dt;
            }
            flying = commands;
        }
        let first = times[0];
        // How far the block is from its places at the end, on average.
        let left = pos
            .iter()
            .zip(&places)
            .map(|(p, q)| (p - q).norm())
            .sum::<f64>()
            / n as f64;
        times.sort();
        sweeps.sort();
        // The floor on the block as it starts (4 m apart).
        let positions: Vec<Option<Vector3<f64>>> = block_at(side, spacing_m)
            .iter()
            .map(|p| Some(Vector3::new(p.x, p.y, 50.0)))
            .collect();
        let mut sweep = Sweep::default();
        let start = Instant::now();
        for _ in 0..ticks {
            black_box(
                sweep
                    .pairs_within(&positions, sep.vertical_scale(), 9.0)
                    .len(),
            );
        }
        let floor = start.elapsed() / ticks as u32;
        let p50 = percentile(&times, 0.5);
        println!(
            "| {n} | {} | {share} | {} | {ticks} | {rows} | {largest} | {} / {} | {unfinished} | {braked} | {unresolved} | {closest:.3} | {left:.2} | {:.2} | {:.3} | {:.3} | {:.3} | {:.3} | {:.0} |",
            match kind {
                Rows::Barrier => "barrier",
                Rows::Stopping => "stopping",
            },
            if limit_s.is_finite() {
                format!("{} ms", limit_s * 1e3)
            } else {
                "none".to_string()
            },
            sweeps[sweeps.len() / 2],
            sweeps[sweeps.len() - 1],
            ms(first),
            ms(p50),
            ms(percentile(&times, 0.99)),
            ms(*times.last().expect("ticks")),
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
    let named = |w: &str| words.iter().any(|x| x == w);
    let kinds: Vec<Rows> = [("barrier", Rows::Barrier), ("stopping", Rows::Stopping)]
        .into_iter()
        .filter(|(w, _)| !(named("barrier") || named("stopping")) || named(w))
        .map(|(_, k)| k)
        .collect();
    let sizes: Vec<&String> = words
        .iter()
        .filter(|w| w.parse::<usize>().is_ok())
        .collect();
    let keep =
        |side: &usize| sizes.is_empty() || sizes.iter().any(|w| **w == (side * side).to_string());
    let assignment: Vec<usize> = [4, 10, 32, 64].into_iter().filter(keep).collect();
    let filter: Vec<usize> = [10, 16, 32].into_iter().filter(keep).collect();
    assignment_table(&assignment);
    filter_table(&filter, &kinds);
}
