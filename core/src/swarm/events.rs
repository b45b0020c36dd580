//! The swarm's event log: every link event and every decision of the swarm, with its
//! time, in words an operator reads. Warnings (lost, refused, timeouts, failsafes, origin
//! changes, isolation) are also logged at `warn`, the rest at `info`; the run directory
//! writes the log as `events.csv`.

use ringswarm_wire::time::SimTime;

use crate::vehicle::LinkConfig;

/// Events kept in memory; later ones are counted, logged, and not kept.
pub const MAX_KEPT_EVENTS: usize = 100_000;

/// One event.
#[derive(Debug, Clone, PartialEq)]
pub struct SwarmEvent {
    /// When (the swarm's time).
    pub t: SimTime,
    /// The vehicle's system id, or `None` for the swarm as a whole.
    pub system_id: Option<u8>,
    /// The vehicle's MAVLink network (`None` for a vehicle on its own socket, and for the
    /// swarm): system ids repeat from one network to the next.
    pub network: Option<String>,
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
    /// Logs and keeps an event of the swarm as a whole.
    pub(super) fn push(&mut self, t: SimTime, warning: bool, text: String) {
        self.keep(t, None, None, warning, text);
    }

    /// Logs and keeps an event of the vehicle on `link`.
    pub(super) fn push_vehicle(
        &mut self,
        t: SimTime,
        link: &LinkConfig,
        warning: bool,
        text: String,
    ) {
        self.keep(t, Some(link.system_id), link.network.clone(), warning, text);
    }

    fn keep(
        &mut self,
        t: SimTime,
        system_id: Option<u8>,
        network: Option<String>,
        warning: bool,
        text: String,
    ) {
        let secs = t.as_secs_f64();
        let who = match (system_id, &network) {
            (Some(id), Some(net)) => format!("vehicle {id} on {net}"),
            (Some(id), None) => format!("vehicle {id}"),
            (None, _) => "swarm".to_owned(),
        };
        if warning {
            tracing::warn!("[{secs:.3} s] {who}: {text}");
        } else {
            tracing::info!("[{secs:.3} s] {who}: {text}");
        }
        if self.kept.len() < MAX_KEPT_EVENTS {
            self.kept.push(SwarmEvent {
                t,
                system_id,
                network,
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
