//! The live view and the replay in a browser: what the swarm looks like at an instant
//! ([`state`]), a run directory replayed ([`replay`]), a distributed swarm watched from its shards'
//! messages ([`distributed`]), the web server ([`server`]), and the run directory as one
//! MCAP file for Foxglove ([`mcap`]).
//! See `docs/live-view.md` for the page and the API.

pub mod distributed;
pub mod mcap;
pub mod replay;
pub mod server;
pub mod state;

pub use server::{Content, LiveFeed, WebServer};
pub use state::ViewState;

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
