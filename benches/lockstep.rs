//! Lockstep speed: the coordinator and the emulator exchanging encoded MAVLink frames in
//! virtual time (1 kHz physics), with and without a run directory being written.
//! `cargo bench --bench lockstep` prints two tables: the speed of each case, then where
//! the time goes in three of them next to the floor of the work they cannot avoid.
//! `-- WORD …` keeps the cases whose name contains one of the words (`-- paper`).
//! `-- sweep` prints the speed of `ringswarm sweep` instead: paper-sim1-sized flights
//! (six vehicles, 60 s of consensus, no landing) a second, on one thread and on every
//! core, next to the lockstep floor of one such flight.

use std::hint::black_box;
use std::time::{Duration, Instant};

use nalgebra::{UnitQuaternion, Vector2, Vector3, Vector4};
use ringswarm::config::Config;
use ringswarm::consensus::{HorizontalState, ring_accelerations};
use ringswarm::control::{attitude_thrust_from_acceleration, saturate_with};
use ringswarm::driver::Observer;
use ringswarm::driver::lockstep::{Lockstep, PhaseTimes};
use ringswarm::record::rows::Row;
use ringswarm::record::{Recorder, RowText};
use ringswarm::swarm::{Swarm, SwarmSetup, VehicleIndex};
use ringswarm_sitl::control::{AttitudeCommand, AttitudeController, AttitudeSetpoint};
use ringswarm_sitl::physics::{Airframe, BodyState, Environment};
use ringswarm_sitl::profile::{GRAVITY_MPS2, Profile};
use ringswarm_wire::codec::{Encoder, for_each_frame};
use ringswarm_wire::time::SimTime;

mod common;
use common::ring;

fn lockstep(toml: &str) -> Lockstep {
    Lockstep::from_config(&Config::from_toml(toml).expect("scenario parses")).expect("scenario")
}

/// One case of the tables.
struct Case {
    name: &'static str,
    toml: String,
    seconds: f64,
    /// Also measured with a run directory, and broken down into parts.
    breakdown: bool,
}

/// What a run measured.
struct Run {
    n: usize,
    rate_hz: f64,
    wall: Duration,
    phases: Option<PhaseTimes>,
    /// Bytes and vehicle CSV rows of the run directory, when one was written.
    run_dir: Option<(u64, u64)>,
}

/// How a case is run.
#[derive(Clone, Copy, PartialEq)]
enum How {
    Plain,
    RunDirectory,
    PhaseClock,
}

fn fly(case: &Case, how: How) -> Run {
    let end = SimTime::from_micros((case.seconds * 1e6) as u64);
    let mut run = lockstep(&case.toml);
    let n = run.vehicles().len();
    let rate_hz = 1.0 / run.swarm().setup().control_interval.as_secs_f64();
    let dir = std::env::temp_dir().join(format!("ringswarm-bench-{}", std::process::id()));
    if how == How::PhaseClock {
        run.keep_phase_times();
    }
    let start = Instant::now();
    if how == How::RunDirectory {
        let mut recorder =
            Recorder::create(&dir, run.swarm(), 0, RowText::Writer).expect("temp dir");
        struct Rec<'a>(&'a mut Recorder);
        impl Observer for Rec<'_> {
            fn datagram(&mut self, now: SimTime, _: VehicleIndex, _: bool, bytes: &[u8]) {
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
    let run_dir = (how == How::RunDirectory).then(|| dir_size(&dir));
    let _ = std::fs::remove_dir_all(&dir);
    Run {
        n,
        rate_hz,
        wall,
        phases: run.phase_times(),
        run_dir,
    }
}

/// The bytes of the files in `dir`, and the rows of its vehicle CSVs.
fn dir_size(dir: &std::path::Path) -> (u64, u64) {
    let mut bytes = 0;
    let mut rows = 0;
    for entry in std::fs::read_dir(dir).expect("run directory").flatten() {
        bytes += entry.metadata().map_or(0, |m| m.len());
        let name = entry.file_name().to_string_lossy().into_owned();
        if name.starts_with("vehicle-") && name.ends_with(".csv") {
            let text = std::fs::read(entry.path()).expect("vehicle CSV");
            // Less the header line.
            rows += text
                .iter()
                .filter(|b| **b == b'\n')
                .count()
                .saturating_sub(1) as u64;
        }
    }
    (bytes, rows)
}

/// Formatting `rows` vehicle CSV rows as text, as the run directory's writer does (ns).
fn format_ns(rows: u64) -> f64 {
    let row = Row {
        t_s: 0.0,
        swarm_phase: "consensus",
        link_phase: "flying",
        state_enu: [123.4567, -78.9012, 50.0123, 12.8912, 7.4734, -0.0213],
        attitude_wijk: [0.9912, 0.0123, -0.0921, 0.0934],
        command_enu_mps2: [0.3412, -0.2123, 0.0132],
        setpoint_wijk: [0.9909, 0.0131, -0.0934, 0.0941],
        thrust_norm: 0.2132,
        heard_age_ms: 3.912,
    };
    let mut out = Vec::with_capacity(128 << 10);
    let start = Instant::now();
    for i in 0..rows {
        let row = Row {
            t_s: i as f64 * 0.004,
            ..row
        };
        black_box(&row).write_csv(&mut out);
        if out.len() >= 64 << 10 {
            black_box(&out);
            out.clear();
        }
    }
    start.elapsed().as_nanos() as f64
}

/// `bytes` written once to a file through the page cache, in 64 KiB writes, as the run
/// directory's writer does (ns).
fn write_ns(bytes: u64) -> f64 {
    use std::io::Write;
    let path = std::env::temp_dir().join(format!("ringswarm-bench-write-{}", std::process::id()));
    let chunk = vec![b'7'; 64 << 10];
    let mut file = std::fs::File::create(&path).expect("temp file");
    let start = Instant::now();
    let mut left = bytes;
    while left > 0 {
        let n = left.min(chunk.len() as u64) as usize;
        file.write_all(&chunk[..n]).expect("write");
        left -= n as u64;
    }
    drop(file);
    let ns = start.elapsed().as_nanos() as f64;
    let _ = std::fs::remove_file(&path);
    ns
}

/// Every datagram of a case's flight, both ways, as the coordinator sent or received it.
fn traffic(case: &Case) -> Vec<Vec<u8>> {
    struct Capture(Vec<Vec<u8>>);
    impl Observer for Capture {
        fn datagram(&mut self, _: SimTime, _: VehicleIndex, _: bool, bytes: &[u8]) {
            self.0.push(bytes.to_vec());
        }
    }
    let mut capture = Capture(Vec::new());
    lockstep(&case.toml).run_observed(
        SimTime::from_micros((case.seconds * 1e6) as u64),
        &mut capture,
    );
    capture.0
}

/// The codec's floor: every datagram of the flight decoded and each frame encoded again,
/// as the two sides do once each (ns in all).
fn codec_ns(traffic: &[Vec<u8>]) -> f64 {
    let mut encoder = Encoder::new(1, 1);
    let mut out = Vec::with_capacity(300);
    let start = Instant::now();
    for datagram in traffic {
        // As the two sides read them: each frame borrowed where it is decoded.
        for_each_frame(datagram, None, |frame| {
            if let Ok(frame) = frame {
                out.clear();
                encoder.encode_into(&frame.msg, None, &mut out);
                black_box(&out);
            }
        });
    }
    start.elapsed().as_nanos() as f64
}

/// The physics' floor: one vehicle's airframe and inner loops (attitude and rate
/// control, mixer) for one 1 ms step, holding a 10° bank at hover thrust (ns).
fn physics_ns_per_step() -> f64 {
    let profile = Profile::ideal();
    let mut frame = Airframe::new(profile.clone());
    let mut controller = AttitudeController::default();
    let mut state = BodyState::at_rest(Vector3::new(0.0, 0.0, -1e6));
    state.motor_thrust_n = Vector4::repeat(profile.mass_kg * GRAVITY_MPS2 / 4.0);
    let env = Environment {
        ground_z_ned_m: 0.0,
        ..Default::default()
    };
    let command = AttitudeCommand::Attitude {
        setpoint: AttitudeSetpoint {
            attitude: UnitQuaternion::from_euler_angles(10f64.to_radians(), 0.0, 0.3),
            thrust_norm: profile.hover_throttle(),
        },
        yawspeed_ff_rps: 0.0,
    };
    let steps = 2_000_000;
    let start = Instant::now();
    for _ in 0..steps {
        let motors = controller.update_command(&frame, &state, black_box(&command), 1e-3);
        frame.advance(&mut state, &motors, &env, 1e-3);
    }
    black_box(state);
    start.elapsed().as_nanos() as f64 / f64::from(steps)
}

/// The law's floor: one control tick of the whole swarm in formation (ring coupling,
/// altitude loop, swarm-wide saturation, attitude and thrust of each vehicle), in ns.
fn law_ns_per_tick(setup: &SwarmSetup) -> f64 {
    let n = setup.offsets_m.len();
    let states: Vec<HorizontalState> = setup
        .offsets_m
        .iter()
        .map(|d| HorizontalState {
            pos_m: d + Vector2::new(3.0, -2.0),
            vel_mps: Vector2::new(2.0, 0.5),
            offset_m: *d,
        })
        .collect();
    let w: Vec<f64> = (0..n).map(|i| setup.ring.w(i)).collect();
    let mut accel = vec![Vector2::zeros(); n];
    let mut commands = vec![Vector3::zeros(); n];
    let mut boxes = Vec::with_capacity(n);
    let ticks = (200_000 / n).max(20);
    let start = Instant::now();
    for _ in 0..ticks {
        ring_accelerations(&setup.ring, setup.gains, black_box(&states), &mut accel);
        for (i, c) in commands.iter_mut().enumerate() {
            let u_z = setup
                .altitude_gains
                .acceleration_with(49.9, 0.1, setup.altitude_m, 0.0);
            *c = Vector3::new(accel[i].x, accel[i].y, u_z);
        }
        let _ = saturate_with(
            setup.saturation,
            &setup.envelope,
            &setup.models,
            &w,
            &mut commands,
            &mut boxes,
        );
        for (c, model) in commands.iter().zip(&setup.models) {
            black_box(attitude_thrust_from_acceleration(*c, 0.0, model));
        }
    }
    start.elapsed().as_nanos() as f64 / ticks as f64
}

fn main() {
    let words: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with('-'))
        .collect();
    let full = 61.2; // handshake (1.2 s) + the paper's 60 s
    let case = |name, toml, seconds, breakdown| Case {
        name,
        toml,
        seconds,
        breakdown,
    };
    let cases: Vec<Case> = [
        case(
            "paper-sim1",
            include_str!("../config/paper-sim1.toml").to_string(),
            full,
            true,
        ),
        case("ring of 6", ring(6, 250.0), full, false),
        case("ring of 16", ring(16, 250.0), full, false),
        case("ring of 64", ring(64, 250.0), full, true),
        case("ring of 64, 50 Hz", ring(64, 50.0), full, false),
        case("ring of 250, 50 Hz", ring(250, 50.0), 20.0, false),
        case("ring of 1000, 50 Hz", ring(1000, 50.0), 5.0, true),
    ]
    .into_iter()
    .filter(|c| words.is_empty() || words.iter().any(|w| c.name.contains(w.as_str())))
    .collect();

    if words.iter().any(|w| w == "sweep") {
        sweep_table(full);
        return;
    }
    if words.is_empty() || words.iter().any(|w| "safety".contains(w.as_str())) {
        safety_table();
        if !words.is_empty() && cases.is_empty() {
            return;
        }
        println!();
    }
    println!(
        "| case | vehicles | control | simulated s | wall s | x real time | µs per vehicle per simulated ms |"
    );
    println!("|---|---|---|---|---|---|---|");
    let mut breakdowns = Vec::new();
    for c in &cases {
        let plain = fly(c, How::Plain);
        print_row(c.name, &plain, c.seconds);
        if c.breakdown {
            let recorded = fly(c, How::RunDirectory);
            print_row(&format!("{} + run directory", c.name), &recorded, c.seconds);
            breakdowns.push((c, plain, recorded));
        }
    }
    if breakdowns.is_empty() {
        return;
    }

    println!();
    println!(
        "| case | total | emulated vehicles | coordinator | delivery | physics floor | law floor | codec floor | floor sum | total / floor | run directory | run directory floor |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|");
    let physics = physics_ns_per_step() / 1e3;
    for (c, plain, recorded) in breakdowns {
        let vehicle_ms = plain.n as f64 * c.seconds * 1e3;
        let per = |d: Duration| d.as_secs_f64() * 1e6 / vehicle_ms;
        let clocked = fly(c, How::PhaseClock);
        let phases = clocked.phases.expect("phase clock");
        let setup = Config::from_toml(&c.toml)
            .and_then(|cfg| cfg.validate())
            .expect("scenario");
        let law = law_ns_per_tick(&setup) / 1e3 * plain.rate_hz * c.seconds / vehicle_ms;
        let codec = codec_ns(&traffic(c)) / 1e3 / vehicle_ms;
        let total = per(plain.wall);
        let floor = physics + law + codec;
        let (bytes, rows) = recorded.run_dir.unwrap_or((0, 0));
        let recording = (write_ns(bytes) + format_ns(rows)) / 1e3 / vehicle_ms;
        println!(
            "| {} | {total:.3} | {:.3} | {:.3} | {:.3} | {physics:.3} | {law:.3} | {codec:.3} | {floor:.3} | {:.1} | {:.3} | {recording:.3} |",
            c.name,
            per(phases.vehicles),
            per(phases.coordinator),
            per(phases.delivery),
            total / floor,
            per(recorded.wall.saturating_sub(plain.wall)),
        );
    }
}

/// `ringswarm sweep`'s speed: 40 replicates of paper-sim1 (the sweep's own flight: to the
/// end of the duration, no run directory) on 1 thread and on every core, in flights a
/// second, next to the floor of one flight (physics, law and codec, as in the table of
/// where the time goes) and what that floor allows on this machine's cores.
fn sweep_table(seconds: f64) {
    use rayon::prelude::*;
    use ringswarm::sweep::{Sweep, config_of, fly};
    let spec = "[sweep]\nscenario = \"paper-sim1\"\nseed = 1\nreplicates = 40\n";
    let sweep = Sweep::from_toml(spec).expect("spec");
    let base: toml::Table =
        toml::from_str(include_str!("../config/paper-sim1.toml")).expect("paper-sim1");
    let flights: Vec<_> = (0..sweep.flights())
        .filter_map(|i| sweep.flight(i))
        .collect();
    let configs: Vec<Config> = flights
        .iter()
        .map(|f| config_of(&base, &sweep, f).expect("flight").1)
        .collect();
    let cores = ringswarm::driver::cores();
    let case = Case {
        name: "paper-sim1",
        toml: include_str!("../config/paper-sim1.toml").to_string(),
        seconds,
        breakdown: false,
    };
    let setup = configs[0].validate().expect("scenario");
    let vehicle_ms = 6.0 * seconds * 1e3;
    let rate_hz = 1.0 / setup.control_interval.as_secs_f64();
    let physics_s = physics_ns_per_step() * vehicle_ms / 1e9;
    let law_s = law_ns_per_tick(&setup) * rate_hz * seconds / 1e9;
    let codec_s = codec_ns(&traffic(&case)) / 1e9;
    let floor_s = physics_s + law_s + codec_s;
    println!(
        "floor of one flight ({seconds} simulated s, six vehicles): physics {physics_s:.4} s, law {law_s:.4} s, codec {codec_s:.4} s; sum {floor_s:.4} s\n"
    );
    println!(
        "| threads | flights | wall s | flights/s | s per flight per thread | floor: s per flight per core | flights/s the floor allows | total / floor |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for threads in [1, cores] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("pool");
        let start = Instant::now();
        let ended: usize = pool.install(|| {
            configs
                .par_iter()
                .map(|c| usize::from(fly(c).expect("flies").exit_code == 0))
                .sum()
        });
        let wall = start.elapsed().as_secs_f64();
        assert_eq!(ended, configs.len(), "a flight did not end with exit 0");
        let n = configs.len() as f64;
        println!(
            "| {threads} | {} | {wall:.2} | {:.1} | {:.3} | {floor_s:.3} | {:.1} | {:.2} |",
            configs.len(),
            n / wall,
            wall * threads as f64 / n,
            threads as f64 / floor_s,
            wall * threads as f64 / n / floor_s,
        );
    }
}

/// The safety filter's cost per control tick next to the law's floor (one tick of ring
/// coupling, altitude loop, saturation, attitude and thrust for the whole swarm): a
/// formation 10 m apart (every pair checked, none broken) and the same with every other
/// pair 4 m apart closing at 2 m/s on commands that push them together (a QP per pair),
/// and a ring packed 3.3 m apart closing on its centre (one QP over every vehicle).
fn safety_table() {
    use ringswarm::safety::{Agent, Rows, SafetyFilter, Separation, Settings, Side};
    println!(
        "| vehicles | law floor µs/tick | filter, formation µs/tick | ratio | filter, every pair in conflict µs/tick | ratio | filter, a packed ring closing µs/tick | ratio |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    let settings = Settings {
        separation: Separation {
            horizontal_m: 3.0,
            vertical_m: 9.0,
            gamma: 1.0,
        },
        age_s: 0.34,
        period_s: 0.02,
        keep_weighted_sum: true,
        time_limit_s: f64::INFINITY,
        rows: Rows::Barrier,
        brake_to_mps: nalgebra::Vector2::zeros(),
    };
    for n in [6usize, 64, 1000] {
        let setup = Config::from_toml(&ring(n, 50.0))
            .and_then(|cfg| cfg.validate())
            .expect("ring");
        let law = law_ns_per_tick(&setup) / 1e3;
        let agent = |pos: Vector3<f64>, vel: Vector3<f64>, k: usize| Agent {
            side: Some(Side {
                pos_m: pos,
                vel_mps: vel,
                accel_z_mps2: 0.0,
            }),
            controlled: true,
            weight: setup.ring.w(k),
            drift_mps2: Vector2::zeros(),
            limit_mps2: 7.0,
            braking_mps2: 3.5,
            lag_s: 0.0,
            spread_m: 0.0,
            unseen_mps: 0.0,
        };
        // A row of vehicles 10 m apart along east, flying north in formation.
        let formation: Vec<Agent> = (0..n)
            .map(|k| {
                agent(
                    Vector3::new(10.0 * k as f64, 0.0, 50.0),
                    Vector3::new(0.0, 2.0, 0.0),
                    k,
                )
            })
            .collect();
        // Every other pair 4 m apart, closing at 2 m/s.
        let conflict: Vec<Agent> = (0..n)
            .map(|k| {
                let (x, v) = if k % 2 == 0 {
                    (10.0 * k as f64, 1.0)
                } else {
                    (10.0 * (k - 1) as f64 + 4.0, -1.0)
                };
                agent(Vector3::new(x, 0.0, 50.0), Vector3::new(v, 0.0, 0.0), k)
            })
            .collect();
        // µs per tick of filtering `agents`' commands, set afresh each tick by `command`.
        let time = |agents: &[Agent], command: &dyn Fn(usize) -> Vector2<f64>| {
            let mut filter = SafetyFilter::default();
            let ticks = (20_000 / n).max(10);
            let mut commands = vec![Vector2::zeros(); n];
            let start = Instant::now();
            for _ in 0..ticks {
                for (k, c) in commands.iter_mut().enumerate() {
                    *c = command(k);
                }
                black_box(filter.filter(&settings, agents, &mut commands, None));
            }
            start.elapsed().as_secs_f64() * 1e6 / ticks as f64
        };
        let push = |push: f64| {
            move |k: usize| Vector2::new(if k.is_multiple_of(2) { push } else { -push }, 0.0)
        };
        // A ring 3.3 m apart, every vehicle flying at the centre at 3 m/s and pushed on
        // inward: every row binds, one piece round the ring.
        let radius = 3.3 / (2.0 * (std::f64::consts::PI / n as f64).sin());
        let inward = |k: usize| {
            let t = std::f64::consts::TAU * k as f64 / n as f64;
            -Vector2::new(t.cos(), t.sin())
        };
        let packed: Vec<Agent> = (0..n)
            .map(|k| {
                let d = inward(k);
                agent(
                    Vector3::new(-radius * d.x, -radius * d.y, 50.0),
                    Vector3::new(3.0 * d.x, 3.0 * d.y, 0.0),
                    k,
                )
            })
            .collect();
        let packed_us = time(&packed, &|k| inward(k) * 0.8);
        let calm = time(&formation, &push(0.0));
        let busy = time(&conflict, &push(1.0));
        println!(
            "| {n} | {law:.1} | {calm:.1} | {:.2} | {busy:.1} | {:.1} | {packed_us:.1} | {:.1} |",
            calm / law,
            busy / law,
            packed_us / law
        );
    }
}

fn print_row(name: &str, run: &Run, seconds: f64) {
    let w = run.wall.as_secs_f64();
    let speed = seconds / w;
    let digits = if speed < 10.0 { 1 } else { 0 };
    println!(
        "| {name} | {} | {:.0} Hz | {seconds:.1} | {w:.3} | {speed:.digits$} | {:.2} |",
        run.n,
        run.rate_hz,
        w * 1e6 / (run.n as f64 * seconds * 1e3)
    );
}
