//! `ringswarm view RUN_DIR`: a finished run directory replayed in a browser until Ctrl-C.
//! An I/O edge: it reads the files and owns the server.

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
    let replay = Replay::load(&args.run_dir).map_err(anyhow::Error::msg)?;
    let (duration, vehicles) = (replay.duration_s(), replay.setup().vehicles.len());
    let server = WebServer::start(args.web, Content::Replay(Arc::new(replay)))
        .map_err(anyhow::Error::msg)?;
    announce(server.addr());
    eprintln!(
        "replaying {} ({vehicles} vehicles, {duration:.1} s); Ctrl-C stops",
        args.run_dir.display()
    );
    server.serve_until(async {
        if let Err(e) = tokio::signal::ctrl_c().await {
            tracing::warn!(error = %e, "Ctrl-C not watched: stopping");
        }
    });
    Ok(())
}

/// Says where the page is, and that a non-loopback address shows it to the network.
pub fn announce(addr: std::net::SocketAddr) {
    eprintln!("web view: http://{addr}/");
    if !addr.ip().is_loopback() {
        eprintln!(
            "note: the web view listens on {} (not the loopback): anyone who can reach this \
             machine can watch the swarm (the page commands nothing)",
            addr.ip()
        );
    }
}
