//! `ringswarm view RUN_DIR`: a finished run directory replayed in a browser until Ctrl-C;
//! `ringswarm view --zenoh ENDPOINT --config F`: a distributed swarm watched live from its
//! shards' Zenoh traffic. An I/O edge: it reads the files or the session and owns the
//! server.

use std::sync::Arc;

use crate::cli::ViewArgs;
use crate::view::replay::Replay;
use crate::view::{Content, WebServer};

/// Loads the run directory and serves its replay until Ctrl-C.
///
/// # Errors
/// A run directory that cannot be read (the file and line named), an address that
/// cannot be bound.
pub fn run(args: &ViewArgs) -> anyhow::Result<()> {
    let Some(run_dir) = &args.run_dir else {
        return zenoh(args);
    };
    let replay = Replay::load(run_dir).map_err(anyhow::Error::msg)?;
    let (duration, vehicles) = (replay.duration_s(), replay.setup().vehicles.len());
    let server = WebServer::start(args.web, Content::Replay(Arc::new(replay)))
        .map_err(anyhow::Error::msg)?;
    crate::view::announce(server.addr());
    eprintln!(
        "replaying {} ({vehicles} vehicles, {duration:.1} s); Ctrl-C stops",
        run_dir.display()
    );
    server.serve_until(async {
        if let Err(e) = tokio::signal::ctrl_c().await {
            tracing::warn!(error = %e, "Ctrl-C not watched: stopping");
        }
    });
    Ok(())
}

/// How often the page gets a new state of a watched swarm.
#[cfg(feature = "zenoh")]
const WATCH_PERIOD: std::time::Duration = std::time::Duration::from_millis(100);

/// Watches the distributed swarm of `--config` through `--zenoh` until Ctrl-C.
///
/// # Errors
/// A file that is no valid split, a session that cannot be opened, an address that
/// cannot be bound.
#[cfg(feature = "zenoh")]
fn zenoh(args: &ViewArgs) -> anyhow::Result<()> {
    use anyhow::Context;

    use crate::config::Config;
    use crate::driver::zenoh_bus::ZenohBus;
    use crate::view::distributed::SwarmWatch;
    use crate::view::{LiveFeed, state::ViewState};

    let path = args
        .config
        .as_ref()
        .context("--zenoh needs --config: the swarm's file, with its [distributed] split")?;
    let text = std::fs::read_to_string(path).with_context(|| format!("read {}", path.display()))?;
    let config =
        Config::from_toml(&text).map_err(|e| anyhow::anyhow!("{}:\n{e}", path.display()))?;
    let setup = config
        .validate()
        .map_err(|e| anyhow::anyhow!("{}:\n{e}", path.display()))?;
    let layout = config
        .shard_layout()
        .map_err(|e| anyhow::anyhow!("{}:\n{e}", path.display()))?
        .with_context(|| format!("{}: no [distributed] split to watch", path.display()))?;
    for e in &args.zenoh {
        if let Some(problem) = crate::config::endpoint_problem(e) {
            anyhow::bail!("--zenoh {problem}");
        }
    }
    let mut bus = ZenohBus::watch(&layout, &args.zenoh).map_err(anyhow::Error::msg)?;
    let (feed, states) = LiveFeed::new();
    let content = Content::Live {
        setup: crate::record::RunSetup::of(&crate::swarm::Swarm::new(setup.clone())),
        states,
    };
    let server = WebServer::start(args.web, content).map_err(anyhow::Error::msg)?;
    crate::view::announce(server.addr());
    eprintln!(
        "watching swarm \"{}\" ({} shards, {} vehicles) over Zenoh; Ctrl-C stops",
        layout.swarm,
        layout.names.len(),
        setup.links.len()
    );
    let mut watch = SwarmWatch::new(&setup, layout.names.clone(), layout.owner.clone());
    let unix_us = || {
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_micros() as u64)
    };
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("a runtime for the watch")?;
    runtime.block_on(async {
        let mut tick = tokio::time::interval(WATCH_PERIOD);
        loop {
            tokio::select! {
                _ = tokio::signal::ctrl_c() => break,
                payload = bus.inbound.recv() => match payload {
                    Some(bytes) => match crate::distributed::decode(&bytes) {
                        Ok(message) => watch.handle(unix_us(), &message),
                        Err(e) => tracing::warn!(error = %e, "payload refused"),
                    },
                    None => break,
                },
                _ = tick.tick() => {
                    let now = unix_us();
                    watch.tick(now);
                    let state: ViewState = watch.state(now);
                    feed.publish(state);
                }
            }
        }
    });
    drop(server);
    bus.close();
    Ok(())
}

/// Without Zenoh in the build, `--zenoh` says so.
#[cfg(not(feature = "zenoh"))]
fn zenoh(_args: &ViewArgs) -> anyhow::Result<()> {
    anyhow::bail!(
        "this ringswarm was built without the zenoh feature: view --zenoh is not available"
    )
}
