//! The swarm's event log: every link event and every decision of the swarm, with its
//! time, in words an operator reads. Warnings (lost, refused, timeouts, failsafes, origin
//! changes, isolation) are also logged at `warn`, the rest at `info`; the run directory
//! writes the log as `events.csv`.

use ringswarm_wire::time::SimTime;

/// Events kept in memory; later ones are counted, logged, and not kept.
pub const MAX_KEPT_EVENTS: usize = 100_000;

/// One event.
#[derive(Debug, Clone, PartialEq)]
pub struct SwarmEvent {
    /// When (the swarm's time).
    pub t: SimTime,
    /// The vehicle's system id, or `None` for the swarm as a whole.
    pub system_id: Option<u8>,
    /// Whether an operator must see it.
    pub warning: bool,
    /// What happened.
    pub text: String,
}

/// The log.
#[derive(Debug, Clone, Default)]
pub(super) struct EventLog {
    kept: Vec<SwarmEvent>,
    dropped: u64,
}

impl EventLog {
    /// Logs and keeps an event.
    pub(super) fn push(&mut self, t: SimTime, system_id: Option<u8>, warning: bool, text: String) {
        let secs = t.as_secs_f64();
        match (warning, system_id) {
            (true, Some(id)) => tracing::warn!("[{secs:.3} s] vehicle {id}: {text}"),
            (true, None) => tracing::warn!("[{secs:.3} s] swarm: {text}"),
            (false, Some(id)) => tracing::info!("[{secs:.3} s] vehicle {id}: {text}"),
            (false, None) => tracing::info!("[{secs:.3} s] swarm: {text}"),
        }
        if self.kept.len() < MAX_KEPT_EVENTS {
            self.kept.push(SwarmEvent {
                t,
                system_id,
                warning,
                text,
            });
        } else {
            self.dropped += 1;
        }
    }

    pub(super) fn events(&self) -> &[SwarmEvent] {
        &self.kept
    }

    pub(super) fn dropped(&self) -> u64 {
        self.dropped
    }
}
