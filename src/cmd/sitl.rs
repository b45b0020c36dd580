//! `ringswarm sitl`: run N emulated vehicles on PX4's SITL ports until Ctrl-C, with a
//! refreshing status line per vehicle. This is an I/O edge: it owns the tokio runtime,
//! the sockets, stdin and the terminal.

use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::{Context, bail};
use nalgebra::Vector3;
use ringswarm_sitl::autopilot::LinkId;
use ringswarm_sitl::autopilot::{Personality, VehicleConfig, VehicleStatus};
use ringswarm_sitl::config_file::SitlConfig;
use ringswarm_sitl::fleet::{
    FleetVehicle, VehicleControl, VehicleSpec, Workers, bind_fleet, spawn_workers,
};
use ringswarm_sitl::keystore::{self, StoredKey};
use ringswarm_sitl::profile::Profile;
use ringswarm_sitl::udp::{LinkFaults, LinkPort, LinkSocket, Placement, SimClock, px4_ports};
use ringswarm_sitl::world::World;
use ringswarm_wire::signing::{SigningKey, timestamp_now};
use tokio::io::AsyncBufReadExt;
use tokio::sync::watch;

use crate::cli::SitlArgs;

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

/// PX4 SITL's layout for the vehicles of `setup` on `host` (instance `i` on 14580+i and
/// 18570+i), each named by its system id.
fn px4_layout(
    setup: &SitlConfig,
    host: std::net::IpAddr,
) -> anyhow::Result<(Vec<Placement>, Vec<String>)> {
    let placements = (0..setup.vehicles.len())
        .map(|i| {
            u16::try_from(i)
                .ok()
                .filter(|i| {
                    i.checked_add(ringswarm_wire::px4::GCS_LISTEN_PORT)
                        .is_some()
                })
                .map(|i| Placement::Ports(px4_ports(i, host)))
                .with_context(|| format!("no PX4 port for instance {i}"))
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    let labels = setup
        .vehicles
        .iter()
        .map(|v| v.system_id.to_string())
        .collect();
    Ok((placements, labels))
}

/// The key vehicle `system_id` boots with: `key` when given (stored, with a clock that
/// starts at the later of the wall clock and the stored one), else whatever its store
/// holds from an earlier SETUP_SIGNING or `--signing-key`.
fn boot_key(path: &Path, key: Option<&SigningKey>) -> anyhow::Result<Option<StoredKey>> {
    let stored = keystore::load(path).map_err(anyhow::Error::msg)?;
    let Some(key) = key else {
        return Ok(stored);
    };
    let stored_clock = stored.filter(|s| &s.key == key).map_or(0, |s| s.timestamp);
    let fresh = StoredKey {
        key: key.clone(),
        timestamp: stored_clock.max(timestamp_now()),
    };
    keystore::save(path, Some(&fresh)).map_err(anyhow::Error::msg)?;
    Ok(Some(fresh))
}

/// An emulator file, or a coordinator file (it has `[gains]`): then the emulator flies its
/// `[[vehicle]]` start states in its `[emulator]` world, without faults, where `fly` with
/// the same file reaches them (its own sockets or its `[[network]]`s), so that
/// `ringswarm sitl --config F` and `ringswarm fly --config F` go together; a coordinator
/// file's `[security] signing_key_file` comes back with it.
type Emulated = (
    SitlConfig,
    Option<PathBuf>,
    Option<(Vec<Placement>, Vec<String>)>,
);

fn sitl_config(text: &str, shard: Option<&str>) -> Result<Emulated, String> {
    let is_coordinator = text
        .parse::<toml::Table>()
        .is_ok_and(|t| t.contains_key("gains"));
    if !is_coordinator {
        if shard.is_some() {
            return Err("--shard needs a coordinator file with [[shard]] tables".into());
        }
        return SitlConfig::from_toml(text).map(|c| (c, None, None));
    }
    let config = crate::config::Config::from_toml(text)?;
    let (world, vehicles) = config.emulator()?;
    let placements = config.emulator_placements()?;
    let labels: Vec<String> = config
        .vehicle
        .iter()
        .map(|v| {
            // The same name the coordinator gives the vehicle's files.
            crate::vehicle::LinkConfig {
                network: v.network.clone(),
                ..crate::vehicle::LinkConfig::new(v.system_id)
            }
            .file_label()
        })
        .collect();
    let mut rows: Vec<_> = vehicles.into_iter().zip(placements).zip(labels).collect();
    if let Some(name) = shard {
        let layout = config
            .shard_layout()?
            .ok_or("--shard needs [distributed] and [[shard]] tables in the file")?;
        let this = layout.names.iter().position(|n| n == name).ok_or_else(|| {
            format!(
                "no [[shard]] named \"{name}\"; the file has {}",
                layout.names.join(", ")
            )
        })?;
        let mut owner = layout.owner.iter();
        rows.retain(|_| owner.next() == Some(&this));
    }
    let (rest, labels): (Vec<_>, Vec<String>) = rows.into_iter().unzip();
    let (vehicles, placements): (Vec<_>, Vec<_>) = rest.into_iter().unzip();
    let sitl = SitlConfig {
        world,
        faults: LinkFaults::default(),
        fault_seed: 1,
        vehicles,
    };
    Ok((
        sitl,
        config.security.signing_key_file,
        Some((placements, labels)),
    ))
}

/// The configuration the flags describe: N vehicles of one profile on the ground, 5 m
/// apart along east.
fn config_from_flags(args: &SitlArgs) -> anyhow::Result<SitlConfig> {
    let vehicles = args.vehicles.unwrap_or(1);
    if vehicles == 0 || vehicles > 250 {
        bail!("--vehicles must be between 1 and 250, got {vehicles}");
    }
    let faults = LinkFaults::from_percent_and_ms(
        args.loss_pct,
        args.latency_ms,
        args.jitter_ms,
        args.duplicate_pct,
        [
            "--loss-pct",
            "--latency-ms",
            "--jitter-ms",
            "--duplicate-pct",
        ],
    )
    .map_err(anyhow::Error::msg)?;
    if !args.spacing_m.is_finite() {
        bail!(
            "--spacing-m must be a finite number, got {}",
            args.spacing_m
        );
    }
    let personality = match args.autopilot.as_str() {
        "px4" => Personality::Px4,
        "ardupilot"
            if args.ekf_settle_s.is_finite() && (0.0..=600.0).contains(&args.ekf_settle_s) =>
        {
            Personality::ArduPilot {
                ekf_settle: Duration::from_secs_f64(args.ekf_settle_s),
            }
        }
        "ardupilot" => bail!(
            "--ekf-settle-s must be a finite number in [0, 600] s, got {}",
            args.ekf_settle_s
        ),
        other => bail!("--autopilot must be px4 or ardupilot, got \"{other}\""),
    };
    let default_profile = match personality {
        Personality::Px4 => "x500",
        Personality::ArduPilot { .. } => "arducopter",
    };
    let profile: Profile = args.profile.as_deref().unwrap_or(default_profile).parse()?;
    Ok(SitlConfig {
        world: World::default(),
        faults,
        fault_seed: args.seed,
        vehicles: (0..vehicles)
            .map(|i| {
                let mut cfg = VehicleConfig::new((i + 1) as u8, profile.clone());
                cfg.personality = personality;
                cfg.start.pos_world_ned_m = Vector3::new(0.0, args.spacing_m * f64::from(i), 0.0);
                cfg
            })
            .collect(),
    })
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

/// Each link's socket and where it sends.
fn describe_links(links: &[LinkSocket]) -> String {
    links
        .iter()
        .map(|l| {
            let at = l.port.describe();
            match (l.id, &l.port) {
                (_, LinkPort::Pty(_)) => format!("offboard/API link {at}"),
                (LinkId::Offboard, LinkPort::Udp(_)) => format!(
                    "offboard/API link {at} -> {} (MAVSDK: udpin://0.0.0.0:{})",
                    l.default_peer,
                    l.default_peer.port()
                ),
                (LinkId::Gcs, LinkPort::Udp(_)) => format!("GCS link {at} -> {}", l.default_peer),
            }
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// How many vehicles there are and where they send.
fn placements_summary(fleet: &[FleetVehicle]) -> String {
    let mut peers: Vec<std::net::SocketAddr> = fleet
        .iter()
        .filter_map(|v| v.links.first().map(|l| l.default_peer))
        .collect();
    peers.sort();
    peers.dedup();
    let shown: Vec<String> = peers.iter().take(8).map(ToString::to_string).collect();
    format!(
        "{} vehicles on {} core(s), sending to {} address(es): {}{}",
        fleet.len(),
        crate::driver::cores(),
        peers.len(),
        shown.join(", "),
        if peers.len() > shown.len() {
            ", ..."
        } else {
            ""
        }
    )
}

/// Offboard setpoints each vehicle had taken at the previous fleet line, with the
/// vehicle's time of that count.
#[derive(Default)]
struct SetpointTally {
    taken: Vec<(f64, u64)>,
}

/// One line for a large fleet: how many are armed, in each mode, heard from, and the rate
/// of offboard setpoints each vehicle took since the previous line (lowest and mean).
fn fleet_line(
    statuses: &[watch::Receiver<VehicleStatus>],
    now_s: f64,
    tally: &mut SetpointTally,
) -> String {
    let mut armed = 0;
    let mut heard = 0;
    let mut modes: std::collections::BTreeMap<&'static str, usize> = Default::default();
    let mut lowest = f64::INFINITY;
    let mut highest = f64::NEG_INFINITY;
    let mut taken = Vec::with_capacity(statuses.len());
    for s in statuses {
        let s = s.borrow();
        armed += usize::from(s.armed);
        heard += usize::from(s.last_heard[0].is_some_and(|t| now_s - t.as_secs_f64() < 2.0));
        *modes.entry(s.mode.name()).or_default() += 1;
        lowest = lowest.min(s.height_m);
        highest = highest.max(s.height_m);
        taken.push((s.at.as_secs_f64(), s.counters.setpoints));
    }
    let modes: Vec<String> = modes.iter().map(|(m, n)| format!("{m} {n}")).collect();
    // Each vehicle's count over its own clock between its two snapshots (none on the
    // first line).
    let per: Vec<f64> = if tally.taken.len() == taken.len() {
        taken
            .iter()
            .zip(&tally.taken)
            .filter(|((t1, _), (t0, _))| t1 > t0)
            .map(|((t1, n1), (t0, n0))| n1.saturating_sub(*n0) as f64 / (t1 - t0))
            .collect()
    } else {
        Vec::new()
    };
    let rates = if per.is_empty() {
        String::new()
    } else {
        let low = per.iter().copied().fold(f64::INFINITY, f64::min);
        let mean = per.iter().sum::<f64>() / per.len() as f64;
        format!("  setpoints {low:.1} Hz lowest, {mean:.1} Hz mean")
    };
    *tally = SetpointTally { taken };
    format!(
        "  t {now_s:7.1} s  {} vehicles: {armed} armed, offboard link up {heard}, {}  height {lowest:.1}..{highest:.1} m{rates}",
        statuses.len(),
        modes.join(", ")
    )
}

fn status_line(s: &VehicleStatus, now_s: f64) -> String {
    let link = |heard: Option<ringswarm_wire::time::SimTime>| match heard {
        Some(t) if now_s - t.as_secs_f64() < 2.0 => "up".to_owned(),
        Some(t) => format!("silent {:.0}s", now_s - t.as_secs_f64()),
        None => "none".to_owned(),
    };
    format!(
        "  sys {:>3}  {:<8} {:<8}{}  alt {:>7.2} m  battery {:>5.1} %  offboard link {:<10} gcs link {}",
        s.system_id,
        s.mode.name(),
        if s.armed { "ARMED" } else { "disarmed" },
        if s.failsafe { " FAILSAFE" } else { "" },
        s.height_m,
        s.battery_pct,
        link(s.last_heard[0]),
        link(s.last_heard[1]),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use ringswarm_sitl::autopilot::Vehicle;
    use ringswarm_wire::time::SimTime;

    #[test]
    fn the_fleet_line_shows_each_vehicle_s_setpoint_rate_over_its_own_clock() {
        let vehicle = Vehicle::new(VehicleConfig::new(1, Profile::ideal()), World::default())
            .expect("vehicle");
        let status = |at_ms: u64, setpoints: u64| {
            let mut s = vehicle.status();
            s.at = SimTime::from_millis(at_ms);
            s.counters.setpoints = setpoints;
            s
        };
        let (a_tx, a) = watch::channel(status(1_000, 0));
        let (b_tx, b) = watch::channel(status(1_300, 10));
        let fleet = [a, b];
        let mut tally = SetpointTally::default();
        // The first line has nothing to compare with.
        assert!(!fleet_line(&fleet, 1.0, &mut tally).contains("setpoints"));
        // Vehicle a: 250 setpoints in 5 s, 50 Hz; b: 240 in 4.8 s (its snapshot came
        // 200 ms before the line), also 50 Hz, then 100 in 5 s: 20 Hz.
        a_tx.send_replace(status(6_000, 250));
        b_tx.send_replace(status(6_100, 250));
        let line = fleet_line(&fleet, 6.0, &mut tally);
        assert!(
            line.ends_with("setpoints 50.0 Hz lowest, 50.0 Hz mean"),
            "{line}"
        );
        a_tx.send_replace(status(11_000, 500));
        b_tx.send_replace(status(11_100, 350));
        let line = fleet_line(&fleet, 11.0, &mut tally);
        assert!(
            line.ends_with("setpoints 20.0 Hz lowest, 35.0 Hz mean"),
            "{line}"
        );
    }
}
