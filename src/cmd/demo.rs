//! `ringswarm demo`: a built-in scenario flown in lockstep, the coordinator and the
//! emulated vehicles exchanging MAVLink frames in virtual time, then a summary table and
//! a run directory. An I/O edge (terminal, files).

use std::io::IsTerminal;
use std::path::PathBuf;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use anyhow::{Context, bail};
use ringswarm_wire::time::SimTime;

use crate::cli::DemoArgs;
use crate::config::Config;
use crate::control::SaturationMode;
use crate::driver::Observer;
use crate::driver::lockstep::Lockstep;
use crate::record::metrics::Summary;
use crate::record::{Recorder, RowText};
use crate::swarm::{Swarm, SwarmPhase, VehicleIndex};
use indicatif::{ProgressBar, ProgressStyle};

/// A built-in scenario: name, one line, the config file's text.
pub struct Scenario {
    /// Name (`--scenario`), also the file name in `config/`.
    pub name: &'static str,
    /// What it shows.
    pub about: &'static str,
    /// The TOML.
    pub toml: &'static str,
}

/// The scenarios shipped in `config/`.
pub const SCENARIOS: &[Scenario] = &[
    Scenario {
        name: "paper-sim1",
        about: "the paper's first simulation: six ideal quadrotors, k = 5, hexagon at 50 m",
        toml: include_str!("../../config/paper-sim1.toml"),
    },
    Scenario {
        name: "paper-sim2",
        about: "the paper's second simulation: the planner re-targets one agent in flight for v_f = (20, 30)",
        toml: include_str!("../../config/paper-sim2.toml"),
    },
    Scenario {
        name: "hexagon-x500",
        about: "the first simulation's start and gains flown by x500 vehicles, 35° tilt, 0.3x speed",
        toml: include_str!("../../config/hexagon-x500.toml"),
    },
    Scenario {
        name: "hexagon-x500-wrong-model",
        about: "hexagon-x500 with hover throttles 10 % off and drag 0.05-0.2 1/s: estimated and corrected",
        toml: include_str!("../../config/hexagon-x500-wrong-model.toml"),
    },
    Scenario {
        name: "hexagon-x500-noisy",
        about: "hexagon-x500 with telemetry noise, GPS drift, 40 ms estimate delay and battery sag",
        toml: include_str!("../../config/hexagon-x500-noisy.toml"),
    },
    Scenario {
        name: "ground-start",
        about: "six x500 on the ground: arm, climb, hexagon, cruise at a planned (3, 2) m/s",
        toml: include_str!("../../config/ground-start.toml"),
    },
    Scenario {
        name: "mixed-autopilots",
        about: "three PX4 x500s and three ArduCopters in one ring: OFFBOARD and GUIDED, one prediction",
        toml: include_str!("../../config/mixed-autopilots.toml"),
    },
    Scenario {
        name: "link-loss",
        about: "paper-sim1 with quadrotor 3 silent from 20 s to 23 s: failsafe, hold, resume",
        toml: include_str!("../../config/link-loss.toml"),
    },
    Scenario {
        name: "lossy",
        about: "paper-sim1 with 20 % loss and 20 ± 10 ms latency on every link, half speed",
        toml: include_str!("../../config/lossy.toml"),
    },
    Scenario {
        name: "big-ring",
        about: "64 ideal quadrotors in a circle, velocities mismatched, k = 1",
        toml: include_str!("../../config/big-ring.toml"),
    },
];

/// Longest the landing may take after the flight (simulated seconds).
const LANDING_ALLOWANCE: Duration = Duration::from_secs(600);

/// Runs the demo and prints its summary.
///
/// # Errors
/// An unknown scenario, an invalid config, a run directory that cannot be written.
pub fn run(args: &DemoArgs) -> anyhow::Result<()> {
    if args.list {
        for s in SCENARIOS {
            crate::report::emit(&format!("{:<26} {}", s.name, s.about))?;
        }
        return Ok(());
    }
    let (name, text) = scenario_text(&args.scenario)?;
    let mut config =
        Config::from_toml(&text).map_err(|e| anyhow::anyhow!("scenario {name}: {e}"))?;
    if let Some(mode) = args.saturation {
        config.envelope.saturation = mode;
    }
    if args.realtime {
        return realtime(&name, &config, args);
    }
    if args.live.web.is_some() || !args.live.mirror.is_empty() {
        anyhow::bail!(
            "--web and --mirror need --realtime: a lockstep demo is over in a moment \
             (replay its run directory with `ringswarm view RUN_DIR`)"
        );
    }
    let stability = if args.unstable_gains {
        crate::config::Stability::Unchecked
    } else {
        crate::config::Stability::Required
    };
    let mut run = Lockstep::from_config_with(&config, stability)
        .map_err(|e| anyhow::anyhow!("scenario {name}:\n{e}"))?;
    crate::config::warn_if_too_fast(run.swarm().setup(), config.gains.time_scale);
    let limit = SimTime::ZERO
        + run
            .swarm()
            .setup()
            .duration
            .unwrap_or(Duration::from_secs(60))
        + Duration::from_secs(10)
        + LANDING_ALLOWANCE;
    let epoch_us = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_micros() as u64);
    let out = args.out.clone().unwrap_or_else(|| {
        PathBuf::from("runs").join(format!("demo-{name}-{}", epoch_us / 1_000_000))
    });
    let recorder = Recorder::create(&out, run.swarm(), epoch_us, RowText::Writer)
        .with_context(|| format!("create the run directory {}", out.display()))?;
    let terminal = std::io::stderr().is_terminal();
    let flight_s = run.swarm().setup().duration.map_or(60, |d| d.as_secs() + 2);
    let mut observer = DemoObserver {
        recorder,
        next_progress: SimTime::ZERO,
        terminal,
        bar: terminal.then(|| DemoObserver::progress_bar(flight_s)),
    };
    let wall = Instant::now();
    let ended =
        |swarm: &Swarm| swarm.is_finished() || matches!(swarm.phase(), SwarmPhase::Ended(_));
    while run.now() < limit && !ended(run.swarm()) {
        let next = run.now() + Duration::from_millis(100);
        run.run_observed(next, &mut observer);
    }
    let wall_s = wall.elapsed().as_secs_f64();
    let (summary, trace) = observer
        .recorder
        .finish(run.swarm(), run.now(), wall_s)
        .with_context(|| format!("write the run directory {}", out.display()))?;
    if !args.no_plots {
        crate::plot::write_all(
            &out,
            &trace,
            &crate::plot::PlotInfo::new(run.swarm(), &name),
        )
        .map_err(|e| anyhow::anyhow!("plots: {e}"))?;
    }
    if let Err(e) = crate::view::mcap::write(&out, epoch_us) {
        eprintln!("flight.mcap not written: {e}");
    }
    if let Some(bar) = &observer.bar {
        bar.finish();
    }
    println!("{}", table(&name, config.envelope.saturation, &summary));
    println!("run directory: {}", out.display());
    crate::error::flight_result(&summary)?;
    if !ended(run.swarm()) {
        bail!(
            "the vehicles had not all landed after {:.0} simulated seconds",
            run.now().as_secs_f64()
        );
    }
    Ok(())
}

struct DemoObserver {
    recorder: Recorder,
    next_progress: SimTime,
    terminal: bool,
    /// On a terminal: simulated seconds of the flight (handshake + duration), then a
    /// spinner while the vehicles land.
    bar: Option<ProgressBar>,
}

impl DemoObserver {
    fn progress_bar(flight_s: u64) -> ProgressBar {
        let bar = ProgressBar::new(flight_s);
        bar.set_style(
            ProgressStyle::with_template(
                "{bar:30.cyan/blue} {pos:>4}/{len} s simulated ({per_sec}) {msg}",
            )
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
        );
        bar
    }
}

impl Observer for DemoObserver {
    fn datagram(&mut self, now: SimTime, _vehicle: VehicleIndex, _to_vehicle: bool, bytes: &[u8]) {
        self.recorder.datagram(now, bytes);
    }

    fn swarm(&mut self, swarm: &Swarm, now: SimTime) {
        self.recorder.sample(swarm, now);
        if now >= self.next_progress {
            // A progress bar on a terminal, one line per 10 s in a log.
            let every = if self.terminal { 1 } else { 10 };
            self.next_progress = now + Duration::from_secs(every);
            if let (Some(bar), Some(s)) = (&self.bar, self.recorder.tracker().latest()) {
                bar.set_position((now.as_secs_f64() as u64).min(bar.length().unwrap_or(u64::MAX)));
                let error = swarm
                    .predicted_final_velocity()
                    .filter(|p| p.norm() > 0.0)
                    .map_or("-".to_owned(), |p| {
                        let v = nalgebra::Vector2::from(s.mean_velocity_mps);
                        format!("{:.2} %", 100.0 * (v - p).norm() / p.norm())
                    });
                bar.set_message(format!(
                    "{}: formation error {:.2} m, velocity error {error}",
                    swarm.phase().name(),
                    s.formation_error_m
                ));
                return;
            }
            if let Some(s) = self.recorder.tracker().latest() {
                let line = format!(
                    "[{:6.1} s simulated] {:<9} formation error {:8.2} m, mean velocity ({:6.2}, {:6.2}) m/s",
                    now.as_secs_f64(),
                    swarm.phase().name(),
                    s.formation_error_m,
                    s.mean_velocity_mps[0],
                    s.mean_velocity_mps[1],
                );
                eprintln!("{line}");
            }
        }
    }
}

/// `--realtime`: the emulated vehicles on PX4's SITL ports in this process, the
/// coordinator flying them over real UDP sockets (like `sitl` + `fly` in two terminals).
fn realtime(name: &str, config: &Config, args: &DemoArgs) -> anyhow::Result<()> {
    use ringswarm_sitl::fleet::{VehicleSpec, bind_fleet, spawn_workers};
    use ringswarm_sitl::udp::SimClock;
    use tokio::sync::watch;

    let setup = config
        .validate()
        .map_err(|e| anyhow::anyhow!("scenario {name}:\n{e}"))?;
    crate::config::warn_if_too_fast(&setup, config.gains.time_scale);
    let (world, vehicle_configs) = config
        .emulator()
        .map_err(|e| anyhow::anyhow!("scenario {name}: {e}"))?;
    let e = &config.emulator;
    if !e.silence.is_empty() {
        eprintln!("note: [[emulator.silence]] applies to lockstep runs only");
    }
    let faults = config
        .link_faults()
        .map_err(|e| anyhow::anyhow!("scenario {name}:\n{e}"))?;
    let transport = config.transport_layout().map_err(anyhow::Error::msg)?;
    let placements = config
        .emulator_placements()
        .map_err(|e| anyhow::anyhow!("scenario {name}: {e}"))?;
    let epoch_s = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("runs").join(format!("demo-{name}-realtime-{epoch_s}")));
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("start the tokio runtime")?;
    let summary = runtime.block_on(async {
        let (stop_tx, stop_rx) = watch::channel(false);
        let clock = SimClock::new(1.0);
        let specs = vehicle_configs
            .into_iter()
            .zip(placements)
            .map(|(config, placement)| VehicleSpec {
                config,
                placement,
                key_file: None,
            })
            .collect();
        let (fleet, _) = bind_fleet(specs, world, faults, e.seed)
            .await
            .map_err(|e| anyhow::anyhow!("emulated {e}"))?;
        let workers = spawn_workers(fleet, crate::driver::cores(), clock, &stop_rx);
        let summary = crate::flight::fly_over_udp(
            Swarm::new(setup),
            &transport,
            &out,
            None,
            &args.live,
            None,
        )
        .await;
        stop_tx.send_replace(true);
        workers.join().await.context("emulated vehicles")?;
        summary
    })?;
    runtime.shutdown_background();
    println!(
        "{}",
        table(
            &format!("{name} (real time, UDP)"),
            config.envelope.saturation,
            &summary
        )
    );
    println!("run directory: {}", out.display());
    crate::error::flight_result(&summary)
}

/// A shipped scenario by name, or a TOML file by path (anything ending in `.toml`).
fn scenario_text(scenario: &str) -> anyhow::Result<(String, String)> {
    if scenario.ends_with(".toml") {
        let text = std::fs::read_to_string(scenario).with_context(|| format!("read {scenario}"))?;
        let name = std::path::Path::new(scenario)
            .file_stem()
            .map_or("custom".to_owned(), |s| s.to_string_lossy().into_owned());
        return Ok((name, text));
    }
    let Some(found) = SCENARIOS.iter().find(|s| s.name == scenario) else {
        let known: Vec<&str> = SCENARIOS.iter().map(|s| s.name).collect();
        bail!(
            "unknown scenario \"{scenario}\" (known: {}; or a path to a .toml file)",
            known.join(", ")
        );
    };
    Ok((found.name.to_owned(), found.toml.to_owned()))
}

/// The summary as a Markdown table.
fn table(name: &str, saturation: SaturationMode, s: &Summary) -> String {
    let pair = |v: Option<[f64; 2]>| {
        v.map_or("-".to_owned(), |v| {
            format!("({:.3}, {:.3}) m/s", v[0], v[1])
        })
    };
    let metres = |v: Option<f64>| v.map_or("-".to_owned(), |v| format!("{v:.3} m"));
    let mut rows = vec![
        (
            "scenario",
            format!(
                "{name} ({} vehicles, {:.0} Hz control, {} saturation)",
                s.vehicles,
                s.control_rate_hz,
                saturation.name()
            ),
        ),
        ("predicted final velocity", pair(s.predicted_final_velocity)),
        ("achieved final velocity", pair(s.achieved_final_velocity)),
        (
            "velocity error",
            s.velocity_error_fraction
                .map_or("-".to_owned(), |e| format!("{:.3} %", 100.0 * e)),
        ),
        (
            "formation error (end of consensus)",
            metres(s.formation_error_m),
        ),
        (
            "altitude error (end of consensus)",
            metres(s.altitude_error_m),
        ),
        ("minimum separation", metres(s.min_separation_m)),
        (
            "time saturated",
            format!("{:.1} % of consensus ticks", 100.0 * s.saturated_fraction),
        ),
    ];
    rows.push((
        "simulated / wall",
        format!(
            "{:.1} s in {:.2} s ({:.0}x real time)",
            s.sim_seconds,
            s.wall_seconds,
            s.sim_seconds / s.wall_seconds.max(1e-9)
        ),
    ));
    let mut out = String::from("| quantity | value |\n|---|---|\n");
    for (k, v) in rows {
        out += &format!("| {k} | {v} |\n");
    }
    out
}
