//! `ringswarm fly`: fly the vehicles of a coordinator config over UDP (real PX4, PX4 SITL
//! or `ringswarm sitl`), with a status line every second and a run directory. An I/O
//! edge: it owns the runtime, the sockets, the terminal and the files.
//!
//! Ctrl-C once: every vehicle lands and disarms (the command returns when they have);
//! twice: return at once.

use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use anyhow::{Context, bail};

use crate::cli::FlyArgs;
use crate::config::Config;
use crate::driver::udp::ShardTransport;
use crate::security::FlightSigning;
use crate::swarm::Swarm;

/// Flies until every vehicle has landed (end of the duration, link-loss policy `land`, or
/// Ctrl-C) and prints the summary.
///
/// # Errors
/// An unreadable or invalid config (every problem listed), a port that cannot be bound,
/// a run directory that cannot be written.
pub fn run(args: &FlyArgs) -> anyhow::Result<()> {
    let text = std::fs::read_to_string(&args.config)
        .with_context(|| format!("read {}", args.config.display()))?;
    let config =
        Config::from_toml(&text).map_err(|e| anyhow::anyhow!("{}:\n{e}", args.config.display()))?;
    let mut setup = config
        .validate()
        .map_err(|e| anyhow::anyhow!("{}:\n{e}", args.config.display()))?;
    if let Some(d) = args.duration_s {
        let max = crate::config::MAX_DURATION_S;
        if !(d.is_finite() && d > 0.0 && d <= max) {
            bail!(
                "--duration-s must be a finite number in (0, {max}] s, got {}",
                crate::config::show(d)
            );
        }
        setup.duration = Some(Duration::from_secs_f64(d));
    }
    crate::config::warn_if_too_fast(&setup, config.gains.time_scale);
    // In real time the places are assigned off the control loop, and the filter's time is
    // limited by the clock (`safety.budget_share`).
    setup.assign_off_tick = true;
    if let Some(safety) = setup.safety.as_mut() {
        safety.wall_clock_budget = true;
    }
    let signing = match &config.security.signing_key_file {
        Some(path) => {
            let signing = FlightSigning::open(path).map_err(anyhow::Error::msg)?;
            signing.apply(&mut setup.links);
            eprintln!(
                "signing every frame with {} (clock kept in {})",
                path.display(),
                signing.store.path().display()
            );
            Some(signing)
        }
        None => None,
    };
    let transport = config.transport_layout().map_err(anyhow::Error::msg)?;
    let (swarm, bus) = match &args.shard {
        None => (Swarm::new(setup), None),
        Some(name) => shard(&config, setup, name)?,
    };
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| default_run_dir(&args.config));
    // One thread: the coordinator is one control loop, and receive tasks on other
    // threads would hand it every batch across threads (a wake-up each).
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("start the tokio runtime")?;
    if let Some(priority) = args.realtime_priority {
        // The runtime is this thread: the control loop runs ahead of ordinary work.
        crate::driver::priority::run_ahead(priority).map_err(anyhow::Error::msg)?;
        tracing::info!("control loop at real-time priority {priority} (SCHED_FIFO)");
    }
    let summary = runtime.block_on(crate::flight::fly_over_udp(
        swarm, &transport, &out, signing, &args.live, bus,
    ))?;
    runtime.shutdown_background();
    println!("{}", serde_json::to_string_pretty(&summary)?);
    println!("run directory: {}", out.display());
    crate::error::flight_result(&summary)
}

/// Shard `name` of the file's split: its swarm machine, and its bus to the others.
///
/// # Errors
/// The split's problems, no such shard, or a Zenoh session that cannot be opened.
#[cfg(feature = "zenoh")]
fn shard(
    config: &Config,
    setup: crate::swarm::SwarmSetup,
    name: &str,
) -> anyhow::Result<(Swarm, Option<Box<dyn ShardTransport + Send>>)> {
    let layout = config
        .shard_layout()
        .map_err(anyhow::Error::msg)?
        .context("--shard needs [distributed] and [[shard]] tables in the file")?;
    let plan = config
        .shard_plan(name, &setup.ring)
        .map_err(anyhow::Error::msg)?;
    let vehicles: Vec<(Option<String>, u8)> = config
        .vehicle
        .iter()
        .map(|v| (v.network.clone(), v.system_id))
        .collect();
    let bus = crate::driver::zenoh_bus::ZenohBus::open(&layout, &plan, &vehicles)
        .map_err(anyhow::Error::msg)?;
    eprintln!(
        "shard \"{name}\": {} of {} vehicles here, the others over Zenoh (watching {})",
        plan.vehicles_of(plan.this()),
        setup.links.len(),
        plan.watch().name()
    );
    let swarm = Swarm::new_shard(setup, plan).map_err(anyhow::Error::msg)?;
    Ok((swarm, Some(Box::new(bus))))
}

/// Without Zenoh, no shard can talk to the others.
#[cfg(not(feature = "zenoh"))]
fn shard(
    _config: &Config,
    _setup: crate::swarm::SwarmSetup,
    name: &str,
) -> anyhow::Result<(Swarm, Option<Box<dyn ShardTransport + Send>>)> {
    bail!("--shard {name}: this ringswarm was built without the zenoh feature")
}

/// `runs/<config stem>-<unix seconds>`.
fn default_run_dir(config: &Path) -> PathBuf {
    let stem = config
        .file_stem()
        .map_or("run".into(), |s| s.to_string_lossy());
    let secs = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    PathBuf::from("runs").join(format!("{stem}-{secs}"))
}
