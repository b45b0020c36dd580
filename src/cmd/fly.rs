//! `ringswarm fly`: fly the vehicles of a coordinator config over UDP (real PX4, PX4 SITL
//! or `ringswarm sitl`), with a status line every second and a run directory. An I/O
//! edge: it owns the runtime, the sockets, the terminal and the files.
//!
//! Ctrl-C once: every vehicle lands and disarms (the command returns when they have);
//! twice: return at once.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use anyhow::{Context, bail};
use ringswarm_wire::time::SimTime;
use tokio::net::UdpSocket;
use tokio::sync::watch;

use crate::cli::{FlyArgs, LiveArgs};
use crate::config::Config;
use crate::driver::Observer;
use crate::driver::mirror::Mirrors;
use crate::driver::serial::SerialLine;
use crate::driver::udp::{DriverCommand, Port, ShardTransport, run_swarm};
use crate::link::router::{Endpoint, Router, TransportPlan};
use crate::record::metrics::Summary;
use crate::record::{Recorder, RowText, RunSetup};
use crate::security::FlightSigning;
use crate::swarm::{StopReason, Swarm, SwarmPhase};
use crate::vehicle::Phase;
use crate::view::{Content, LiveFeed, ViewState, WebServer};

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
    let transport = config.transport_plan().map_err(anyhow::Error::msg)?;
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
    let summary = runtime.block_on(fly(swarm, &transport, &out, signing, &args.live, bus))?;
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

/// Flies `swarm` over UDP until it has landed (or a second Ctrl-C), recording into `out`,
/// with the live view and the mirrors `live` asks for; returns the summary. Shared by
/// `fly` and `demo --realtime`.
///
/// # Errors
/// A port that cannot be bound (the vehicles', the web view's), a mirror's socket, a run
/// directory that cannot be written.
pub(crate) async fn fly(
    swarm: Swarm,
    transport: &TransportPlan,
    out: &Path,
    signing: Option<FlightSigning>,
    live: &LiveArgs,
    mut bus: Option<Box<dyn ShardTransport + Send>>,
) -> anyhow::Result<Summary> {
    let local = |s: usize| {
        swarm.shard_plan().is_none_or(|plan| {
            transport
                .routes
                .iter()
                .enumerate()
                .any(|(i, r)| r.socket == s && plan.is_local(i))
        })
    };
    let sockets = bind_all(transport, local).await?;
    let mirrors = Mirrors::open(&live.mirror).map_err(anyhow::Error::msg)?;
    for m in &live.mirror {
        eprintln!("mirroring every datagram to udp {m}");
    }
    let (feed, web) = match live.web {
        Some(addr) => {
            let (feed, states) = LiveFeed::new();
            let content = Content::Live {
                setup: RunSetup::of(&swarm),
                states,
            };
            let server = WebServer::start(addr, content).map_err(anyhow::Error::msg)?;
            crate::cmd::view::announce(server.addr());
            (Some(feed), Some(server))
        }
        None => (None, None),
    };
    let epoch_us = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_micros() as u64);
    let recorder = Recorder::create(out, &swarm, epoch_us, RowText::Inline)
        .with_context(|| format!("create the run directory {}", out.display()))?;
    eprintln!(
        "flying {} vehicles; Ctrl-C (or SIGTERM, SIGHUP) lands them, twice stops at once. Run directory: {}",
        swarm.links().len(),
        out.display()
    );
    let (command_tx, command_rx) = watch::channel(DriverCommand::Fly);
    let mut terminations = crate::driver::signals::Terminations::new()
        .context("install the handlers of SIGINT, SIGTERM and SIGHUP")?;
    tokio::spawn(async move {
        for command in [DriverCommand::Land, DriverCommand::Stop] {
            let Some(signal) = terminations.next().await else {
                return;
            };
            eprintln!(
                "\n{signal}: {}",
                match command {
                    DriverCommand::Land => "landing every vehicle (again to stop now)",
                    _ => "stopping",
                }
            );
            command_tx.send_replace(command);
        }
    });
    let observer = FlyObserver {
        recorder,
        next_status: SimTime::ZERO,
        last: SimTime::ZERO,
        signing,
        feed,
        mirrors,
    };
    let wall = Instant::now();
    let router = Router::new(transport);
    let (swarm, mut observer) = run_swarm(
        swarm,
        sockets,
        router,
        command_rx,
        observer,
        bus.as_deref_mut(),
    )
    .await?;
    if let Some(bus) = bus {
        bus.close();
    }
    observer.keep_signing_clock(&swarm);
    let now = observer.last;
    if let Some(feed) = observer.feed.take() {
        feed.publish(ViewState::of_swarm(
            &swarm,
            now,
            observer.recorder.tracker().latest(),
        ));
        // The feed gone, each stream sends the last state and a close frame: a moment
        // for them before the server stops.
        drop(feed);
        tokio::time::sleep(WEB_GOODBYE).await;
    }
    drop(web);
    observer.mirrors.drain();
    let mirrors = observer.mirrors.reports();
    for m in &mirrors {
        eprintln!(
            "mirror {}: {} datagrams forwarded, {} not sent, {} from it dropped",
            m.address, m.forwarded_datagrams, m.not_sent_datagrams, m.dropped_inbound_datagrams
        );
    }
    observer.recorder.set_mirrors(mirrors);
    let (summary, trace) = observer
        .recorder
        .finish(&swarm, now, wall.elapsed().as_secs_f64())
        .with_context(|| format!("write the run directory {}", out.display()))?;
    if let Err(e) = crate::plot::write_all(out, &trace, &crate::plot::PlotInfo::new(&swarm, "fly"))
    {
        eprintln!("plots not written: {e}");
    }
    Ok(summary)
}

/// How long the live view's clients are given, after the flight, to receive its last state.
const WEB_GOODBYE: Duration = Duration::from_millis(300);

/// Binds every socket of the plan, naming the one that cannot be bound.
///
/// # Errors
/// The first bind error.
pub(crate) async fn bind_all(
    transport: &TransportPlan,
    local: impl Fn(usize) -> bool,
) -> anyhow::Result<Vec<Port>> {
    let mut sockets = Vec::with_capacity(transport.sockets.len());
    for (s, plan) in transport.sockets.iter().enumerate() {
        if !local(s) {
            // Only another shard's vehicles use it: a socket of no consequence, so that
            // the shards of one host do not take each other's ports.
            let unused = UdpSocket::bind((std::net::Ipv4Addr::LOCALHOST, 0))
                .await
                .context("bind a placeholder socket for another shard's vehicle")?;
            sockets.push(Port::Udp(unused));
            continue;
        }
        let bind = match &plan.endpoint {
            Endpoint::Udp(bind) => *bind,
            Endpoint::Serial { device, baud } => {
                let vehicle = transport
                    .routes
                    .iter()
                    .position(|r| r.socket == s)
                    .map_or(0, |i| i + 1);
                let line = SerialLine::open(device, *baud)
                    .with_context(|| format!("vehicle {vehicle}'s serial port"))?;
                sockets.push(Port::Serial(line));
                continue;
            }
        };
        let socket = UdpSocket::bind(bind).await.with_context(|| match &plan.network {
            Some(name) => format!("bind {bind} for network \"{name}\" (another ground station on that port?)"),
            None => format!(
                "bind {bind} for vehicle {} (another ground station on that port? set [[vehicle]] bind)",
                transport.routes.iter().position(|r| r.socket == s).map_or(0, |i| i + 1)
            ),
        })?;
        if plan.network.is_some() {
            grow_receive_buffer(&socket, bind);
        }
        sockets.push(Port::Udp(socket));
    }
    Ok(sockets)
}

/// What a network socket asks the kernel to buffer: about two control periods of a
/// thousand vehicles' telemetry, so a burst (every vehicle's streams falling due
/// together) is not dropped while the swarm is busy. Linux caps it at
/// `net.core.rmem_max`.
const NETWORK_RECEIVE_BUFFER: usize = 4 << 20;

/// Asks for [`NETWORK_RECEIVE_BUFFER`]; says so when the kernel grants less.
fn grow_receive_buffer(socket: &UdpSocket, bind: std::net::SocketAddr) {
    let socket = socket2::SockRef::from(socket);
    if let Err(e) = socket.set_recv_buffer_size(NETWORK_RECEIVE_BUFFER) {
        tracing::warn!(%bind, error = %e, "receive buffer not enlarged");
    }
    // Linux reports twice what it grants (its bookkeeping overhead).
    match socket.recv_buffer_size() {
        Ok(granted) if granted / 2 < NETWORK_RECEIVE_BUFFER => tracing::info!(
            %bind,
            granted = granted / 2,
            wanted = NETWORK_RECEIVE_BUFFER,
            "receive buffer capped by the kernel (net.core.rmem_max): large swarms may lose telemetry in bursts"
        ),
        _ => {}
    }
}

struct FlyObserver {
    recorder: Recorder,
    next_status: SimTime,
    last: SimTime,
    signing: Option<FlightSigning>,
    /// The live view's feed, with `--web`.
    feed: Option<LiveFeed>,
    mirrors: Mirrors,
}

impl FlyObserver {
    /// Keeps the stored signing clock ahead of the newest stamp any link used.
    fn keep_signing_clock(&mut self, swarm: &Swarm) {
        let Some(signing) = self.signing.as_mut() else {
            return;
        };
        let newest = swarm
            .links()
            .iter()
            .filter_map(crate::vehicle::VehicleLink::signing_timestamp)
            .max()
            .unwrap_or(signing.start);
        if let Err(e) = signing.store.keep_ahead(newest) {
            eprintln!("signing clock not stored: {e}");
        }
    }
}

impl Observer for FlyObserver {
    fn datagram(&mut self, now: SimTime, _vehicle: usize, _to_vehicle: bool, bytes: &[u8]) {
        self.recorder.datagram(now, bytes);
        self.mirrors.forward(bytes);
    }

    fn swarm(&mut self, swarm: &Swarm, now: SimTime) {
        self.last = now;
        self.recorder.sample(swarm, now);
        if let Some(feed) = &mut self.feed {
            feed.offer(swarm, now, self.recorder.tracker().latest());
        }
        self.mirrors.drain_due(now);
        if now >= self.next_status {
            self.next_status = now + Duration::from_secs(1);
            self.keep_signing_clock(swarm);
            eprintln!("{}", status_line(swarm, &self.recorder, now));
        }
    }
}

/// One line: time, phase, each link's phase, and the figures.
fn status_line(swarm: &Swarm, recorder: &Recorder, now: SimTime) -> String {
    let phase = match swarm.phase() {
        SwarmPhase::Holding(_) => "HOLDING (a vehicle is lost)",
        SwarmPhase::Ended(_) => "ended (hovering)",
        SwarmPhase::Stopped(_) => match swarm.stop_reason() {
            Some(StopReason::Fence) => "STOPPED at the fence (hovering)",
            Some(StopReason::Separation) => "STOPPED: two vehicles too close (hovering)",
            _ => "STOPPED by the divergence guard (hovering)",
        },
        other => other.name(),
    };
    let links: String = swarm
        .links()
        .iter()
        .map(|l| match l.phase() {
            Phase::Discovering => '?',
            Phase::Streaming(_) => 's',
            Phase::Arming => 'a',
            Phase::Offboarding => 'o',
            Phase::Flying => 'F',
            Phase::Lost => 'X',
            Phase::Failed => '!',
            Phase::Landing => 'L',
            Phase::Disarming => 'd',
            Phase::Done => '.',
            Phase::Overridden => 'P',
            Phase::VehicleHold => 'H',
        })
        .collect();
    let mut line = format!("[{:7.1} s] {phase:<10} links {links}", now.as_secs_f64());
    if let Some(s) = recorder.tracker().latest() {
        line += &format!(
            " | v ({:6.2}, {:6.2}) m/s | formation {:7.2} m | altitude ±{:5.2} m",
            s.mean_velocity_mps[0], s.mean_velocity_mps[1], s.formation_error_m, s.altitude_error_m
        );
    }
    if let Some(p) = swarm.predicted_final_velocity() {
        line += &format!(" | predicted ({:.2}, {:.2})", p.x, p.y);
    }
    if let Some((i, j, d)) = swarm.closest_pair() {
        let id = |k: usize| swarm.setup().links[k].system_id;
        line += &format!(" | closest {}-{} {d:.1} m", id(i), id(j));
    }
    if matches!(swarm.phase(), SwarmPhase::Handshake) {
        // What the handshake waits for (ArduPilot's EKF, a fence upload, …): the first
        // vehicle waiting, and how many more.
        let mut waiting = swarm
            .links()
            .iter()
            .zip(&swarm.setup().links)
            .filter_map(|(l, cfg)| l.waiting_for().map(|what| (cfg.system_id, what)));
        if let Some((id, what)) = waiting.next() {
            line += &format!(" | vehicle {id} {what}");
            let more = waiting.count();
            if more > 0 {
                line += &format!(" (+{more} more waiting)");
            }
        }
    }
    line
}
