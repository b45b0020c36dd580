//! The flight runner: flies a swarm machine over real sockets in real time, with its run
//! directory, live view, mirrors and signal handling, until every vehicle has landed.
//! What `fly` and `demo --realtime` both run, so that no subcommand imports another.
//!
//! - [`fly_over_udp`] (this file): binds, records, serves and drives to the end;
//! - `ports`: binding every socket of a transport layout;
//! - `observer`: what the driver tells each tick (run directory, live view, mirrors, the
//!   status line).

mod observer;
mod ports;

use std::path::Path;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use anyhow::Context;
use ringswarm_wire::time::SimTime;
use tokio::sync::watch;

use crate::cli::LiveArgs;
use crate::driver::mirror::Mirrors;
use crate::driver::udp::{DriverCommand, ShardTransport, run_swarm};
use crate::link::router::{Router, TransportLayout};
use crate::record::metrics::Summary;
use crate::record::{Recorder, RowText, RunSetup};
use crate::security::FlightSigning;
use crate::swarm::Swarm;
use crate::view::{Content, LiveFeed, ViewState, WebServer};
use observer::FlyObserver;
pub use ports::bind_all;

/// Flies `swarm` over UDP until it has landed (or a second Ctrl-C), recording into `out`,
/// with the live view and the mirrors `live` asks for; returns the summary. What `fly` and
/// `demo --realtime` run.
///
/// # Errors
/// A port that cannot be bound (the vehicles', the web view's), a mirror's socket, a run
/// directory that cannot be written.
pub async fn fly_over_udp(
    swarm: Swarm,
    transport: &TransportLayout,
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
    let (feed, web) = start_live_view(live, &swarm)?;
    let epoch_us = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_micros() as u64);
    let recorder = Recorder::create(out, &swarm, epoch_us, RowText::Inline)
        .with_context(|| format!("create the run directory {}", out.display()))?;
    eprintln!(
        "flying {} vehicles; Ctrl-C (or SIGTERM, SIGHUP) lands them, twice stops at once. Run directory: {}",
        swarm.vehicle_count(),
        out.display()
    );
    let command_rx = watch_terminations()?;
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
    let epoch_us = observer.recorder.epoch_us();
    let (summary, trace) = observer
        .recorder
        .finish(&swarm, now, wall.elapsed().as_secs_f64())
        .with_context(|| format!("write the run directory {}", out.display()))?;
    if let Err(e) = crate::plot::write_all(out, &trace, &crate::plot::PlotInfo::new(&swarm, "fly"))
    {
        eprintln!("plots not written: {e}");
    }
    if let Err(e) = crate::view::mcap::write(out, epoch_us) {
        eprintln!("flight.mcap not written: {e}");
    }
    Ok(summary)
}

/// With `--web`: the live view's feed and its server, started and announced.
///
/// # Errors
/// An address that cannot be bound.
fn start_live_view(
    live: &LiveArgs,
    swarm: &Swarm,
) -> anyhow::Result<(Option<LiveFeed>, Option<WebServer>)> {
    let Some(addr) = live.web else {
        return Ok((None, None));
    };
    let (feed, states) = LiveFeed::new();
    let content = Content::Live {
        setup: RunSetup::of(swarm),
        states,
    };
    let server = WebServer::start(addr, content).map_err(anyhow::Error::msg)?;
    crate::view::announce(server.addr());
    Ok((Some(feed), Some(server)))
}

/// The driver's commands from the signals: the first SIGINT, SIGTERM or SIGHUP lands
/// every vehicle, the second stops at once.
///
/// # Errors
/// The handlers cannot be installed.
fn watch_terminations() -> anyhow::Result<watch::Receiver<DriverCommand>> {
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
    Ok(command_rx)
}

/// How long the live view's clients are given, after the flight, to receive its last state.
const WEB_GOODBYE: Duration = Duration::from_millis(300);
