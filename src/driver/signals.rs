//! The ordinary termination signals a flight answers as it answers Ctrl-C: SIGINT
//! (Ctrl-C), SIGTERM (what `timeout`, systemd and `docker stop` send) and SIGHUP (a closed
//! terminal or SSH session). The first asks the swarm to land, the second to stop now.

/// Waits for the termination signals, one at a time.
#[derive(Debug)]
pub struct Terminations {
    #[cfg(unix)]
    streams: [(tokio::signal::unix::Signal, &'static str); 3],
}

impl Terminations {
    /// Installs the handlers (from now on those signals no longer end the process).
    ///
    /// # Errors
    /// When the runtime cannot install a handler.
    pub fn new() -> std::io::Result<Self> {
        #[cfg(unix)]
        {
            use tokio::signal::unix::{SignalKind, signal};
            Ok(Self {
                streams: [
                    (signal(SignalKind::interrupt())?, "Ctrl-C (SIGINT)"),
                    (signal(SignalKind::terminate())?, "SIGTERM"),
                    (signal(SignalKind::hangup())?, "SIGHUP"),
                ],
            })
        }
        #[cfg(not(unix))]
        {
            Ok(Self {})
        }
    }

    /// The next termination signal's name; `None` when no more can come.
    pub async fn next(&mut self) -> Option<&'static str> {
        #[cfg(unix)]
        {
            let [(int, a), (term, b), (hup, c)] = &mut self.streams;
            tokio::select! {
                got = int.recv() => got.map(|()| *a),
                got = term.recv() => got.map(|()| *b),
                got = hup.recv() => got.map(|()| *c),
            }
        }
        #[cfg(not(unix))]
        {
            tokio::signal::ctrl_c().await.ok().map(|()| "Ctrl-C")
        }
    }
}
