//! What `sitl` emulates: from a flags line, an emulator file or a coordinator file (its
//! `[[vehicle]]` start states, placed where `fly` with the same file reaches them), and
//! the key each vehicle boots with.

use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::{Context, bail};
use nalgebra::Vector3;
use ringswarm_sitl::autopilot::{Personality, VehicleConfig};
use ringswarm_sitl::config_file::SitlConfig;
use ringswarm_sitl::keystore::{self, StoredKey};
use ringswarm_sitl::profile::Profile;
use ringswarm_sitl::udp::{LinkFaults, Placement, px4_ports};
use ringswarm_sitl::world::World;
use ringswarm_wire::signing::{SigningKey, timestamp_now};

use crate::cli::SitlArgs;

/// PX4 SITL's layout for the vehicles of `setup` on `host` (instance `i` on 14580+i and
/// 18570+i), each named by its system id.
pub(super) fn px4_layout(
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
pub(super) fn boot_key(path: &Path, key: Option<&SigningKey>) -> anyhow::Result<Option<StoredKey>> {
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
pub(super) type Emulated = (
    SitlConfig,
    Option<PathBuf>,
    Option<(Vec<Placement>, Vec<String>)>,
);

pub(super) fn sitl_config(text: &str, shard: Option<&str>) -> Result<Emulated, String> {
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
pub(super) fn config_from_flags(args: &SitlArgs) -> anyhow::Result<SitlConfig> {
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
