//! What crosses between shards, and its bytes.
//!
//! A payload is one version byte ([`PAYLOAD_VERSION`]) followed by a [`ShardMessage`] in
//! postcard's form (integers as varints, floats little-endian, enums by their index).
//! A receiver takes only its own version: a payload of another version is refused with
//! [`PayloadError::Version`], never guessed at.
//!
//! Times are on the swarm clock: microseconds since the Unix epoch on a real deployment
//! (each shard's clock, aligned by NTP or PTP), microseconds of virtual time in lockstep.
//! Positions and velocities are in the common frame (ENU, about the `[frame]`
//! reference), as `f32`: at 10 km from the reference a position is resolved to 1 mm, a
//! velocity of 100 m/s to 8 µm/s, far below what a vehicle's own estimate resolves. The
//! sums that decide the prediction are `f64`, so that every shard adds the same numbers
//! to the same value.

use serde::{Deserialize, Serialize};

/// The version of the payload's form; bumped on any change to the types below.
pub const PAYLOAD_VERSION: u8 = 4;

/// Where a vehicle's link is, as another shard needs it: whether it flies on its
/// shard's commands.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum MemberPhase {
    /// Not flying on its shard's commands yet (discovering, handshaking).
    Waiting,
    /// Flying in OFFBOARD on its shard's commands.
    Flying,
    /// Lost: silent, out of OFFBOARD, or handed to its own Hold.
    Lost,
    /// Told to land, or landed and disarmed.
    Landing,
    /// Its handshake gave up (it never flew).
    Failed,
}

impl MemberPhase {
    /// A short lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            Self::Waiting => "waiting",
            Self::Flying => "flying",
            Self::Lost => "lost",
            Self::Landing => "landing",
            Self::Failed => "failed",
        }
    }
}

/// One vehicle's state, published by the shard that flies it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct VehicleReport {
    /// The vehicle's place in the ring (0-based, the `[[vehicle]]` order).
    pub vehicle: u16,
    /// Its shard's control tick that sent it (µs, swarm clock).
    pub sent_us: u64,
    /// How old the position below was at that tick (µs): its shard received it
    /// `sent_us − age_us`. A receiver carries it forward by the hop only (its own
    /// vehicles' states are as old as their telemetry made them, too).
    pub age_us: u32,
    /// Its link.
    pub phase: MemberPhase,
    /// Whether it reports being on the ground.
    pub landed: bool,
    /// Position (m, ENU, common frame).
    pub pos_enu_m: [f32; 3],
    /// Velocity (m/s, ENU).
    pub vel_enu_mps: [f32; 3],
    /// How fast its reported positions move beyond its reported velocities, as its shard
    /// counts it (m/s, ≥ 0; [`crate::control::UnseenMotion`]): every shard counts it as
    /// closing speed in the vehicle's pairs, as its own shard does (version 4).
    pub unseen_mps: f32,
}

/// `Σ wᵢ pᵢ`, `Σ wᵢ vᵢ` and `Σ wᵢ` over a shard's vehicles.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct WeightedSum {
    /// `Σ wᵢ pᵢ` (m, ENU, x and y).
    pub wp_m: [f64; 2],
    /// `Σ wᵢ vᵢ` (m/s, ENU, x and y).
    pub wv_mps: [f64; 2],
    /// `Σ wᵢ`.
    pub w: f64,
}

/// What a shard says of itself every control tick.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ShardReport {
    /// The shard's index (the `[[shard]]` order).
    pub shard: u16,
    /// When it was sent (µs, swarm clock).
    pub sent_us: u64,
    /// How many vehicles it flies.
    pub vehicles: u16,
    /// How many of them fly on its commands with a fresh state.
    pub flying: u16,
    /// How many of them are lost.
    pub lost: u16,
    /// Whether its flight is over (the configured duration elapsed): its vehicles not
    /// flying are then no loss.
    pub ended: bool,
    /// The instant at which it starts (or started) consensus (µs, swarm clock), once
    /// every vehicle it knows of flies: the swarm adopts the earliest one proposed.
    pub start_us: Option<u64>,
    /// Its vehicles' `Σ wᵢ vᵢ` at the first control tick at or after `start_us`: every
    /// shard adds the same partial sums, in shard order, to the same prediction.
    pub start_sum: Option<WeightedSum>,
    /// Its vehicles' `Σ wᵢ vᵢ` over the fresh states of this tick (the mean-velocity
    /// correction and the divergence guard read the swarm's from these).
    pub now_sum: WeightedSum,
    /// The fastest of its vehicles now, as the safety filter measures speed (the
    /// vertical axis scaled; m/s): the other shards size their horizon by it (version 2).
    pub top_speed_mps: f32,
    /// With a `[target]`: whether it has made the flight's plan. The start proposals of
    /// shards that have not (the plan's instant) and of shards that have (consensus) are
    /// never taken for each other (version 2).
    pub planned: bool,
    /// With a `[target]`: its vehicles' velocities at the adopted plan instant, sent until
    /// every other shard reports its plan made (version 2).
    pub plan_velocities: Option<PlanVelocities>,
    /// With interchangeable places: whether it has assigned the places for the current
    /// start of consensus (version 3).
    pub places_assigned: bool,
    /// With interchangeable places: its vehicles' positions at the adopted start, sent
    /// until every other shard reports its places assigned: every shard assigns from all
    /// of them, so every shard makes the same assignment (version 3).
    pub start_positions: Option<StartPositions>,
}

/// A shard's vehicles' horizontal positions at the adopted start of consensus.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct StartPositions {
    /// The adopted start (µs, swarm clock).
    pub at_us: u64,
    /// Its vehicles' horizontal positions then (m, ENU, common frame), in ring order.
    pub pos_m: Vec<[f64; 2]>,
}

/// A shard's vehicles' velocities at the plan instant: every shard plans from all of
/// them, so every shard makes the same plan.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct PlanVelocities {
    /// The adopted plan instant (µs, swarm clock).
    pub at_us: u64,
    /// Its vehicles' horizontal velocities then (m/s, ENU), in ring order.
    pub vel_mps: Vec<[f64; 2]>,
    /// Each one's top speed for the planner (m/s; from its drag as its own shard
    /// estimates it), `None` where there is none.
    pub limit_mps: Vec<Option<f64>>,
}

/// One payload between shards.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum ShardMessage {
    /// A vehicle's state, under `ringswarm/<swarm>/state/<network>/<sysid>`.
    Vehicle(VehicleReport),
    /// A shard's report, under `ringswarm/<swarm>/shard/<name>`.
    Shard(ShardReport),
}

/// Why a payload was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PayloadError {
    /// No byte at all.
    #[error("empty payload")]
    Empty,
    /// A version this build does not read.
    #[error("payload version {got}, this build reads version {PAYLOAD_VERSION}")]
    Version {
        /// The version byte received.
        got: u8,
    },
    /// The bytes after the version do not decode, or bytes are left over.
    #[error("payload does not decode: {0}")]
    Malformed(String),
}

/// Appends `message`'s payload (version byte, then postcard) to `out`.
pub fn encode(message: &ShardMessage, out: &mut Vec<u8>) {
    out.push(PAYLOAD_VERSION);
    // Serialising these plain types into a growing Vec cannot fail.
    if let Ok(bytes) = postcard::to_allocvec(message) {
        out.extend_from_slice(&bytes);
    }
}

/// A payload's message.
///
/// # Errors
/// [`PayloadError`] for an empty payload, another version, or bytes that do not decode
/// exactly.
pub fn decode(bytes: &[u8]) -> Result<ShardMessage, PayloadError> {
    let (&version, body) = bytes.split_first().ok_or(PayloadError::Empty)?;
    if version != PAYLOAD_VERSION {
        return Err(PayloadError::Version { got: version });
    }
    let (message, rest) = postcard::take_from_bytes::<ShardMessage>(body)
        .map_err(|e| PayloadError::Malformed(e.to_string()))?;
    if !rest.is_empty() {
        return Err(PayloadError::Malformed(format!(
            "{} bytes after the message",
            rest.len()
        )));
    }
    Ok(message)
}

/// Appends `message`'s payload to a batch: its length (`u16`, little-endian), then the
/// payload as [`encode`] writes it. A batch carries one shard's vehicle states of one
/// tick in one publication (`watch = "all"`: every shard reads all of them).
pub fn encode_into_batch(message: &ShardMessage, batch: &mut Vec<u8>) {
    let at = batch.len();
    batch.extend_from_slice(&[0, 0]);
    encode(message, batch);
    match u16::try_from(batch.len() - at - 2) {
        Ok(n) => batch[at..at + 2].copy_from_slice(&n.to_le_bytes()),
        // A payload is some fifty bytes; one that does not fit its length is left out.
        Err(_) => batch.truncate(at),
    }
}

/// The payloads of a batch ([`encode_into_batch`]) in order.
///
/// # Errors
/// [`PayloadError::Malformed`] where a length runs past the end (the payloads before it
/// are still given); the iteration stops there.
pub fn split_batch(batch: &[u8]) -> impl Iterator<Item = Result<&[u8], PayloadError>> {
    let mut rest = batch;
    std::iter::from_fn(move || {
        if rest.is_empty() {
            return None;
        }
        let Some((len, body)) = rest.split_first_chunk::<2>() else {
            let left = rest.len();
            rest = &[];
            return Some(Err(PayloadError::Malformed(format!(
                "a batch ends in {left} byte of a length"
            ))));
        };
        let n = usize::from(u16::from_le_bytes(*len));
        if n > body.len() {
            let left = body.len();
            rest = &[];
            return Some(Err(PayloadError::Malformed(format!(
                "a batch's payload of {n} bytes has only {left} left"
            ))));
        }
        let (payload, after) = body.split_at(n);
        rest = after;
        Some(Ok(payload))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vehicle() -> ShardMessage {
        ShardMessage::Vehicle(VehicleReport {
            vehicle: 5,
            sent_us: 1_764_000_000_000_000,
            age_us: 12_000,
            phase: MemberPhase::Flying,
            landed: false,
            pos_enu_m: [120.5, -33.25, 50.0],
            vel_enu_mps: [12.9, 7.48, -0.01],
            unseen_mps: 0.25,
        })
    }

    fn shard() -> ShardMessage {
        ShardMessage::Shard(ShardReport {
            shard: 2,
            sent_us: 1_764_000_000_020_000,
            vehicles: 2,
            flying: 2,
            lost: 0,
            ended: false,
            start_us: Some(1_764_000_001_000_000),
            start_sum: Some(WeightedSum {
                wp_m: [10.0, 20.0],
                wv_mps: [3.5, -1.25],
                w: 7.0,
            }),
            now_sum: WeightedSum {
                wp_m: [1000.0, 2000.0],
                wv_mps: [90.3, 52.3],
                w: 7.0,
            },
            top_speed_mps: 14.9,
            planned: false,
            plan_velocities: Some(PlanVelocities {
                at_us: 1_764_000_000_500_000,
                vel_mps: vec![[12.9, 7.48], [-1.0, 0.25]],
                limit_mps: vec![Some(19.5), None],
            }),
            places_assigned: false,
            start_positions: None,
        })
    }

    #[test]
    fn a_batch_gives_back_each_payload_in_order_and_stops_at_a_cut() {
        let mut batch = Vec::new();
        encode_into_batch(&vehicle(), &mut batch);
        encode_into_batch(&shard(), &mut batch);
        let parts: Vec<_> = split_batch(&batch).collect();
        assert_eq!(parts.len(), 2);
        let decoded: Vec<ShardMessage> = parts
            .iter()
            .map(|p| decode(p.as_ref().expect("whole")).expect("decodes"))
            .collect();
        assert_eq!(decoded, vec![vehicle(), shard()]);
        // The first payload's length: the version byte and the postcard bytes.
        let mut one = Vec::new();
        encode(&vehicle(), &mut one);
        assert_eq!(
            usize::from(u16::from_le_bytes([batch[0], batch[1]])),
            one.len()
        );
        // Cut inside the second payload: the first still comes, then the error.
        let cut = &batch[..batch.len() - 3];
        let parts: Vec<_> = split_batch(cut).collect();
        assert_eq!(parts.len(), 2);
        assert_eq!(parts[0].as_ref().ok(), Some(&one.as_slice()));
        let err = parts[1]
            .as_ref()
            .err()
            .map(ToString::to_string)
            .unwrap_or_default();
        assert!(err.contains("has only"), "{err}");
        // A single stray byte where a length should be.
        let stray: Vec<_> = split_batch(&[7]).collect();
        assert!(matches!(
            stray.as_slice(),
            [Err(PayloadError::Malformed(_))]
        ));
        assert_eq!(split_batch(&[]).count(), 0);
    }

    #[test]
    fn messages_come_back_as_they_went() {
        for m in [vehicle(), shard()] {
            let mut bytes = Vec::new();
            encode(&m, &mut bytes);
            assert_eq!(bytes[0], PAYLOAD_VERSION);
            assert_eq!(decode(&bytes), Ok(m));
        }
    }

    #[test]
    fn a_vehicle_report_is_43_bytes() {
        // version 1 + enum tag 1 + vehicle 1 (varint 5) + time 8 (varint of 1.76e15:
        // 51 bits, 7 per byte) + age 2 (varint of 12 000: 14 bits) + phase 1 + landed 1
        // + seven f32 28 = 43; the same fields in JSON take over 150.
        let mut bytes = Vec::new();
        encode(&vehicle(), &mut bytes);
        assert_eq!(bytes.len(), 43);
        let json = serde_json::to_vec(&vehicle()).unwrap();
        assert!(json.len() > 150, "{}", json.len());
    }

    #[test]
    fn other_versions_and_bad_bytes_are_refused_by_name() {
        let mut bytes = Vec::new();
        encode(&vehicle(), &mut bytes);
        let mut newer = bytes.clone();
        newer[0] = PAYLOAD_VERSION + 1;
        assert_eq!(
            decode(&newer),
            Err(PayloadError::Version {
                got: PAYLOAD_VERSION + 1
            })
        );
        assert_eq!(decode(&[]), Err(PayloadError::Empty));
        assert!(matches!(
            decode(&bytes[..bytes.len() - 1]),
            Err(PayloadError::Malformed(_))
        ));
        let mut longer = bytes.clone();
        longer.push(0);
        assert_eq!(
            decode(&longer),
            Err(PayloadError::Malformed("1 bytes after the message".into()))
        );
        // Every truncation and every single byte changed: an error or a message, never a
        // panic.
        for cut in 0..bytes.len() {
            let _ = decode(&bytes[..cut]);
        }
        for i in 0..bytes.len() {
            for b in [0u8, 0x7f, 0x80, 0xff] {
                let mut changed = bytes.clone();
                changed[i] = b;
                let _ = decode(&changed);
            }
        }
    }
}
