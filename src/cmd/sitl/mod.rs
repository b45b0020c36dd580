//! `ringswarm sitl`: run N emulated vehicles on PX4's SITL ports until Ctrl-C, with a
//! refreshing status line per vehicle. This is an I/O edge: it owns the tokio runtime,
//! the sockets, stdin and the terminal.

use std::io::{IsTerminal, Write};
use std::path::PathBuf;
use std::time::Duration;

use anyhow::{Context, bail};
use ringswarm_sitl::config_file::SitlConfig;
use ringswarm_sitl::fleet::{VehicleControl, VehicleSpec, Workers, bind_fleet, spawn_workers};
use ringswarm_sitl::keystore;
use ringswarm_sitl::udp::{Placement, SimClock};
use ringswarm_wire::signing::SigningKey;
use tokio::io::AsyncBufReadExt;
use tokio::sync::watch;

use crate::cli::SitlArgs;

mod lines;
mod setup;
use lines::{SetpointTally, describe_links, fleet_line, placements_summary, status_line};
use setup::{boot_key, config_from_flags, px4_layout, sitl_config};

/// Runs the emulator until Ctrl-C.
///
/// # Errors
/// Bad arguments or configuration (vehicle count, speed, profile, faults), a port
/// already in use.
pub fn run(args: &SitlArgs) -> anyhow::Result<()> {
    let mut key_file = args.signing_key.clone();
    let mut placements = None;
    let mut setup = match &args.config {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("read {}", path.display()))?;
            let (config, security_key, config_placements) =
                sitl_config(&text, args.shard.as_deref())
                    .map_err(|e| anyhow::anyhow!("{}:\n{e}", path.display()))?;
            key_file = key_file.or(security_key);
            placements = config_placements;
            if let Some(n) = args
                .vehicles
                .filter(|n| usize::from(*n) != config.vehicles.len())
            {
                bail!(
                    "--vehicles {n} disagrees with the {} [[vehicle]] tables of {}",
                    config.vehicles.len(),
                    path.display()
                );
            }
            config
        }
        None if args.shard.is_some() => {
            bail!("--shard needs a coordinator --config with [[shard]] tables")
        }
        None => config_from_flags(args)?,
    };
    if !(args.speed.is_finite() && args.speed > 0.0 && args.speed <= 100.0) {
        bail!("--speed must be a number in (0, 100], got {}", args.speed);
    }
    let key = key_file
        .as_deref()
        .map(SigningKey::read)
        .transpose()
        .map_err(anyhow::Error::msg)?;
    let (placements, labels) = match placements {
        Some(from_config) => from_config,
        None => px4_layout(&setup, args.host)?,
    };
    let key_files: Vec<PathBuf> = labels
        .iter()
        .map(|label| keystore::key_path(&args.state_dir, label))
        .collect();
    for (cfg, path) in setup.vehicles.iter_mut().zip(&key_files) {
        cfg.signing = boot_key(path, key.as_ref())?;
    }
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("start the tokio runtime")?;
    let result = runtime.block_on(serve(args, setup, placements, key_files));
    // The stdin reader is a blocking read that only ends with the next line; do not wait
    // for it (every vehicle task has already been awaited).
    runtime.shutdown_background();
    result
}

async fn serve(
    args: &SitlArgs,
    setup: SitlConfig,
    placements: Vec<Placement>,
    key_files: Vec<PathBuf>,
) -> anyhow::Result<()> {
    let (shutdown_tx, shutdown_rx) = watch::channel(false);
    let clock = SimClock::new(args.speed);
    let system_ids: Vec<u8> = setup.vehicles.iter().map(|v| v.system_id).collect();
    let n = setup.vehicles.len();
    let verbose = n <= STATUS_LINES_UP_TO;
    println!("ringswarm sitl: {n} vehicle(s), {}x real time", args.speed);
    let described: Vec<(u8, &str, bool)> = setup
        .vehicles
        .iter()
        .map(|c| (c.system_id, c.profile.name, c.signing.is_some()))
        .collect();
    let specs = setup
        .vehicles
        .iter()
        .cloned()
        .zip(placements)
        .zip(key_files.iter().cloned())
        .map(|((config, placement), key_file)| VehicleSpec {
            config,
            placement,
            key_file: Some(key_file),
        })
        .collect();
    let (fleet, statuses) = bind_fleet(specs, setup.world, setup.faults, setup.fault_seed)
        .await
        .map_err(anyhow::Error::msg)?;
    if verbose {
        for ((system_id, profile, signed), (v, key_file)) in
            described.iter().zip(fleet.iter().zip(&key_files))
        {
            if *signed {
                println!(
                    "  vehicle {system_id}: MAVLink 2 signing on (key stored in {}): unsigned frames refused but HEARTBEAT, RADIO_STATUS, ADSB_VEHICLE, COLLISION",
                    key_file.display()
                );
            }
            println!(
                "  vehicle {system_id} ({profile}): {}",
                describe_links(&v.links)
            );
        }
    } else {
        println!("  {}", placements_summary(&fleet));
    }
    let workers = spawn_workers(fleet, crate::driver::cores(), clock, &shutdown_rx);
    println!(
        "Ctrl-C stops; on stdin, \"kill N\" powers vehicle N off and \"restart N\" boots it again."
    );
    let mut stdin = tokio::io::BufReader::new(tokio::io::stdin()).lines();
    let mut stdin_open = true;
    let interactive = std::io::stdout().is_terminal();
    let mut every =
        tokio::time::interval(Duration::from_millis(if interactive { 250 } else { 5000 }));
    let mut drawn = 0;
    let mut tally = SetpointTally::default();
    // One listener for the whole run: a future made anew on every turn of the loop would
    // miss a signal that arrives while the loop body runs. SIGTERM and SIGHUP end the
    // emulator as Ctrl-C does (workers stopped, the fleet line printed).
    let mut terminations = crate::driver::signals::Terminations::new()
        .context("install the handlers of SIGINT, SIGTERM and SIGHUP")?;
    loop {
        tokio::select! {
            _ = terminations.next() => break,
            line = stdin.next_line(), if stdin_open => match line {
                Ok(Some(line)) => {
                    if let Err(err) = apply_control(&line, &system_ids, &workers).await {
                        eprintln!("{err:#}");
                    }
                }
                _ => stdin_open = false,
            },
            _ = every.tick() => {
                let now_s = clock.now().as_secs_f64();
                let lines: Vec<String> = if verbose {
                    statuses.iter().map(|s| status_line(&s.borrow(), now_s)).collect()
                } else {
                    vec![fleet_line(&statuses, now_s, &mut tally)]
                };
                let mut out = std::io::stdout().lock();
                if interactive && drawn > 0 {
                    write!(out, "\x1b[{drawn}A")?;
                }
                for line in &lines {
                    writeln!(out, "\x1b[2K{line}")?;
                }
                drawn = lines.len();
                out.flush()?;
            }
        }
    }
    shutdown_tx.send_replace(true);
    workers.join().await.context("vehicle task")?;
    println!("stopped");
    Ok(())
}

/// Parses `kill N` / `restart N` and sends it to the vehicle with system id N (the
/// first with that id, when networks repeat it).
async fn apply_control(line: &str, system_ids: &[u8], workers: &Workers) -> anyhow::Result<()> {
    let words: Vec<&str> = line.split_whitespace().collect();
    let (request, id) = match words.as_slice() {
        [] => return Ok(()),
        ["kill", id] => (VehicleControl::Kill, *id),
        ["restart", id] => (VehicleControl::Restart, *id),
        _ => bail!("unknown request \"{line}\" (expected \"kill N\" or \"restart N\")"),
    };
    let id: u8 = id
        .parse()
        .with_context(|| format!("\"{id}\" is not a system id"))?;
    let Some(index) = system_ids.iter().position(|s| *s == id) else {
        bail!("no vehicle with system id {id}");
    };
    workers
        .control(index, request)
        .await
        .map_err(anyhow::Error::msg)
}

/// Up to this many vehicles, one status line each; above, one line for the fleet.
const STATUS_LINES_UP_TO: usize = 16;
