//! `ringswarm sitl`: run N emulated vehicles on PX4's SITL ports until Ctrl-C, with a
//! refreshing status line per vehicle. This is an I/O edge: it owns the tokio runtime,
//! the sockets and the terminal.

use std::io::{IsTerminal, Write};
use std::time::Duration;

use anyhow::{Context, bail};
use nalgebra::Vector3;
use ringswarm_sitl::autopilot::{Vehicle, VehicleConfig, VehicleStatus};
use ringswarm_sitl::profile::Profile;
use ringswarm_sitl::udp::{LinkFaults, SimClock, VehicleTask, bind, px4_ports, run_vehicle};
use ringswarm_sitl::world::World;
use tokio::sync::watch;

use crate::cli::SitlArgs;

/// Runs the emulator until Ctrl-C.
///
/// # Errors
/// Bad arguments (vehicle count, speed, profile), a port already in use.
pub fn run(args: &SitlArgs) -> anyhow::Result<()> {
    if args.vehicles == 0 || args.vehicles > 250 {
        bail!(
            "--vehicles must be between 1 and 250, got {}",
            args.vehicles
        );
    }
    if !(args.speed.is_finite() && args.speed > 0.0 && args.speed <= 100.0) {
        bail!("--speed must be a number in (0, 100], got {}", args.speed);
    }
    for (name, pct) in [
        ("--loss-pct", args.loss_pct),
        ("--duplicate-pct", args.duplicate_pct),
    ] {
        if !(0.0..=100.0).contains(&pct) {
            bail!("{name} must be a percentage in [0, 100], got {pct}");
        }
    }
    for (name, ms) in [
        ("--latency-ms", args.latency_ms),
        ("--jitter-ms", args.jitter_ms),
    ] {
        if !(ms.is_finite() && (0.0..=10_000.0).contains(&ms)) {
            bail!("{name} must be in [0, 10000] ms, got {ms}");
        }
    }
    let profile: Profile = args.profile.parse()?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("start the tokio runtime")?;
    runtime.block_on(serve(args, profile))
}

async fn serve(args: &SitlArgs, profile: Profile) -> anyhow::Result<()> {
    let world = World::default();
    let faults = LinkFaults {
        loss: args.loss_pct / 100.0,
        latency: Duration::from_secs_f64(args.latency_ms / 1000.0),
        jitter: Duration::from_secs_f64(args.jitter_ms / 1000.0),
        duplicate: args.duplicate_pct / 100.0,
    };
    let (shutdown_tx, shutdown_rx) = watch::channel(false);
    let clock = SimClock::new(args.speed);
    let mut statuses = Vec::new();
    let mut tasks = Vec::new();
    println!(
        "ringswarm sitl: {} x {} vehicle(s), {}x real time",
        args.vehicles, profile.name, args.speed
    );
    for i in 0..args.vehicles {
        let system_id = (i + 1) as u8;
        let mut cfg = VehicleConfig::new(system_id, profile.clone());
        cfg.start.pos_world_ned_m = Vector3::new(0.0, args.spacing_m * f64::from(i), 0.0);
        let vehicle = Vehicle::new(cfg, world).map_err(anyhow::Error::msg)?;
        let plan = px4_ports(i, args.host);
        let sockets = bind(&plan).await?;
        println!(
            "  vehicle {system_id}: offboard/API link udp {} -> {} (MAVSDK: udpin://0.0.0.0:{}), GCS link udp {} -> {}",
            plan.offboard_bind,
            plan.offboard_peer,
            plan.offboard_peer.port(),
            plan.gcs_bind,
            plan.gcs_peer
        );
        let (status_tx, status_rx) = watch::channel(vehicle.status());
        statuses.push(status_rx);
        let task = VehicleTask {
            vehicle,
            sockets,
            default_peers: [plan.offboard_peer, plan.gcs_peer],
            faults: [faults, faults],
            seed: args.seed.wrapping_add(u64::from(i)),
        };
        tasks.push(tokio::spawn(run_vehicle(
            task,
            clock,
            status_tx,
            shutdown_rx.clone(),
        )));
    }
    println!("Ctrl-C stops.");
    let interactive = std::io::stdout().is_terminal();
    let mut every =
        tokio::time::interval(Duration::from_millis(if interactive { 250 } else { 5000 }));
    let mut drawn = 0;
    loop {
        tokio::select! {
            _ = tokio::signal::ctrl_c() => break,
            _ = every.tick() => {
                let lines: Vec<String> = statuses.iter().map(|s| status_line(&s.borrow(), clock.now().as_secs_f64())).collect();
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
    for task in tasks {
        task.await.context("vehicle task")??;
    }
    println!("stopped");
    Ok(())
}

fn status_line(s: &VehicleStatus, now_s: f64) -> String {
    let link = |heard: Option<ringswarm_sitl::time::SimTime>| match heard {
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
