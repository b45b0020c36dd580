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
        /// The vehicles not flying, in the ring's order.
        not_flying: Vec<NotFlying>,
        /// When the swarm gave up.
        after: Duration,
    },
}

/// A vehicle not flying when the handshake gave up.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NotFlying {
    /// Its MAVLink system id.
    pub system_id: u8,
    /// Its MAVLink network (`None` on a socket of its own).
    pub network: Option<String>,
    /// Its link phase, with what its handshake waits for when it says (`discovering`,
    /// `failed: …`, `streaming: waiting for …`).
    pub phase: String,
}

impl NotFlying {
    /// What its phase means to an operator (`discovering`: never heard).
    fn what(&self) -> &str {
        match self.phase.as_str() {
            "discovering" => "never heard",
            other => other,
        }
    }
}

impl fmt::Display for NotFlying {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.network {
            Some(net) => write!(
                f,
                "vehicle {} on {net} not flying ({})",
                self.system_id,
                self.what()
            ),
            None => write!(f, "vehicle {} not flying ({})", self.system_id, self.what()),
        }
    }
}

/// The most vehicles a handshake failure names one by one; beyond, the rest are counted
/// by what they were doing.
pub const NAMED_NOT_FLYING: usize = 8;

impl fmt::Display for SwarmFailure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Handshake { not_flying, after } => {
                write!(
                    f,
                    "handshake not complete after {:.1} s: ",
                    after.as_secs_f64()
                )?;
                if not_flying.len() <= NAMED_NOT_FLYING {
                    for (j, v) in not_flying.iter().enumerate() {
                        let sep = if j == 0 { "" } else { ", " };
                        write!(f, "{sep}{v}")?;
                    }
                    return write!(f, "; the vehicles that flew were landed");
                }
                // Many: the ones whose own handshake gave up first (the likely cause),
                // then the rest counted by what they were doing.
                let mut named: Vec<&NotFlying> = not_flying
                    .iter()
                    .filter(|v| v.phase.starts_with("failed"))
                    .take(NAMED_NOT_FLYING)
                    .collect();
                for v in not_flying {
                    if named.len() >= NAMED_NOT_FLYING {
                        break;
                    }
                    if !named.iter().any(|n| std::ptr::eq(*n, v)) {
                        named.push(v);
                    }
                }
                write!(f, "{} vehicles not flying: ", not_flying.len())?;
                for (j, v) in named.iter().enumerate() {
                    let sep = if j == 0 { "" } else { ", " };
                    write!(f, "{sep}{v}")?;
                }
                let mut rest: Vec<(&str, usize)> = Vec::new();
                for v in not_flying
                    .iter()
                    .filter(|v| !named.iter().any(|n| std::ptr::eq(*n, *v)))
                {
                    // Counted by the phase's first word: `failed: …` reasons differ per
                    // vehicle only in detail.
                    let what = v.what().split(':').next().unwrap_or_default();
                    match rest.iter_mut().find(|(w, _)| *w == what) {
                        Some((_, n)) => *n += 1,
                        None => rest.push((what, 1)),
                    }
                }
                let counts: Vec<String> = rest.iter().map(|(w, n)| format!("{n} {w}")).collect();
                write!(
                    f,
                    ", and {} more ({}); the vehicles that flew were landed",
                    not_flying.len() - named.len(),
                    counts.join(", ")
                )
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn v(system_id: u8, network: Option<&str>, phase: &str) -> NotFlying {
        NotFlying {
            system_id,
            network: network.map(str::to_owned),
            phase: phase.to_owned(),
        }
    }

    #[test]
    fn a_few_vehicles_not_flying_are_each_named() {
        let failure = SwarmFailure::Handshake {
            not_flying: vec![v(4, None, "discovering"), v(7, Some("n1"), "arming")],
            after: Duration::from_secs(3),
        };
        assert_eq!(
            failure.to_string(),
            "handshake not complete after 3.0 s: vehicle 4 not flying (never heard), \
             vehicle 7 on n1 not flying (arming); the vehicles that flew were landed"
        );
    }

    #[test]
    fn many_vehicles_not_flying_name_the_failed_first_and_count_the_rest() {
        // 1024 vehicles on 8 networks of 128: two failed far down the ring, the rest
        // never heard or waiting for their shards.
        let mut not_flying = Vec::new();
        for i in 0..1024_u16 {
            let net = format!("n{}", i / 128);
            let id = (i % 128 + 1) as u8;
            let phase = match i {
                700 | 900 => "failed: MAV_CMD_DO_SET_MODE not accepted after 4 attempts",
                0..=599 => "discovering",
                _ => "its shard not all flying",
            };
            not_flying.push(v(id, Some(&net), phase));
        }
        let text = SwarmFailure::Handshake {
            not_flying,
            after: Duration::from_millis(9500),
        }
        .to_string();
        // Vehicle 700 is id 61 on n5, 900 is id 5 on n7; then the first six of the ring.
        assert_eq!(
            text,
            "handshake not complete after 9.5 s: 1024 vehicles not flying: \
             vehicle 61 on n5 not flying (failed: MAV_CMD_DO_SET_MODE not accepted after 4 attempts), \
             vehicle 5 on n7 not flying (failed: MAV_CMD_DO_SET_MODE not accepted after 4 attempts), \
             vehicle 1 on n0 not flying (never heard), vehicle 2 on n0 not flying (never heard), \
             vehicle 3 on n0 not flying (never heard), vehicle 4 on n0 not flying (never heard), \
             vehicle 5 on n0 not flying (never heard), vehicle 6 on n0 not flying (never heard), \
             and 1016 more (594 never heard, 422 its shard not all flying); \
             the vehicles that flew were landed"
        );
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
