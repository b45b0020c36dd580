//! Where the swarm is ([`SwarmPhase`]), why it gave up ([`SwarmFailure`]) and why its
//! flight stopped ([`StopReason`]): what drivers, recorders and exit codes read.

use std::fmt;
use std::time::Duration;

use ringswarm_wire::time::SimTime;

use super::GuardTrip;

/// Where the swarm is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SwarmPhase {
    /// Vehicles are being handshaken; the flying ones hold altitude.
    Handshake,
    /// Planner stage 1: one agent accelerates to its planned velocity, since the given time.
    Retargeting(SimTime),
    /// The consensus law runs, since the given time.
    Consensus(SimTime),
    /// A vehicle was lost: the others hover in place until it flies again.
    Holding(SimTime),
    /// The duration is over; the vehicles hover in place until told to land.
    Ended(SimTime),
    /// Every vehicle was told to land, at the given time.
    Landing(SimTime),
    /// The divergence guard ended the consensus: the vehicles brake and hover in place,
    /// since the given time, until the end of the duration.
    Stopped(SimTime),
}

impl SwarmPhase {
    /// A short lower-case name (`handshake`, `consensus`, `holding`, `ended`, `landing`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Handshake => "handshake",
            Self::Retargeting(_) => "retarget",
            Self::Consensus(_) => "consensus",
            Self::Holding(_) => "holding",
            Self::Ended(_) => "ended",
            Self::Landing(_) => "landing",
            Self::Stopped(_) => "stopped",
        }
    }
}

/// Why the swarm gave up before its flight (the vehicles that flew were landed).
#[derive(Debug, Clone, PartialEq)]
pub enum SwarmFailure {
    /// Not every vehicle was flying in OFFBOARD within the handshake timeout, or one
    /// vehicle's handshake gave up.
    Handshake {
        /// The vehicles not flying: system id and its link phase (with what its handshake
        /// waits for, when it says).
        not_flying: Vec<(u8, String)>,
        /// When the swarm gave up.
        after: Duration,
    },
}

impl fmt::Display for SwarmFailure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Handshake { not_flying, after } => {
                write!(
                    f,
                    "handshake not complete after {:.1} s: ",
                    after.as_secs_f64()
                )?;
                for (j, (id, phase)) in not_flying.iter().enumerate() {
                    let sep = if j == 0 { "" } else { ", " };
                    let what = match phase.as_str() {
                        "discovering" => "never heard",
                        other => other,
                    };
                    write!(f, "{sep}vehicle {id} not flying ({what})")?;
                }
                write!(f, "; the vehicles that flew were landed")
            }
        }
    }
}

/// Why the flight stopped (`summary.json`'s `stop_reason`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum StopReason {
    /// The configured duration is over.
    DurationOver,
    /// The divergence guard ended the consensus.
    Guard(GuardTrip),
    /// The handshake was not complete in time.
    Handshake,
    /// A vehicle was lost and the loss policy is `land`.
    LinkLoss,
    /// Landing was asked for from outside (Ctrl-C, a signal, the live view).
    Requested,
    /// A vehicle could no longer stop inside the fence's margin.
    Fence,
    /// The safety filter could not keep two vehicles apart.
    Separation,
}

impl StopReason {
    /// A short name: `duration`, `guard`, `handshake`, `link_loss`, `requested`, `fence`,
    /// `separation`.
    pub fn name(&self) -> &'static str {
        match self {
            Self::DurationOver => "duration",
            Self::Guard(_) => "guard",
            Self::Handshake => "handshake",
            Self::LinkLoss => "link_loss",
            Self::Requested => "requested",
            Self::Fence => "fence",
            Self::Separation => "separation",
        }
    }
}
