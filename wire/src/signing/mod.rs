//! MAVLink 2 message signing, as the MAVLink C library (and so PX4) does it.
//!
//! A signed frame carries a 13-byte trailer: the sender's link id, a 48-bit timestamp in
//! units of 10 µs since 2015-01-01 00:00:00 UTC, and the first 6 bytes of
//! SHA-256(key ‖ header ‖ payload ‖ CRC ‖ link id ‖ timestamp). A receiver holding the
//! key accepts a frame when the signature matches and its timestamp is newer than the
//! last one accepted on the same stream (link id, system, component); a stream it has
//! not seen yet must not lag the newest timestamp it knows by more than a minute.
//! Every accepted timestamp also moves the receiver's own clock forward, so what it
//! signs next is never older than what it has heard.
//!
//! [`Signing`] is that state, sans IO: the codec computes whether a signature is
//! authentic ([`crate::codec::decode_datagram_with`]) and signs frames
//! ([`crate::codec::Encoder::encode_signed`]); which unsigned messages a side still lets
//! through is the caller's rule (PX4's is [`PX4_UNSIGNED_ALLOWED`]).

mod key;

use std::time::Duration;

pub use key::SigningKey;

/// Messages PX4 accepts unsigned once a key is set (`mavlink_sign_control.cpp`):
/// HEARTBEAT, RADIO_STATUS, ADSB_VEHICLE, COLLISION.
pub const PX4_UNSIGNED_ALLOWED: [u32; 4] = [0, 109, 246, 247];

/// The signing epoch, 2015-01-01 00:00:00 UTC, in Unix seconds.
pub const TIMESTAMP_EPOCH_UNIX_S: u64 = 1_420_070_400;

/// Timestamp units per second (one unit is 10 µs).
pub const TIMESTAMP_UNITS_PER_S: u64 = 100_000;

/// How far a new stream's first timestamp may lag the newest timestamp known
/// (`MAVLINK_SIGNING_TIMESTAMP_LIMIT`, one minute).
pub const NEW_STREAM_WINDOW: u64 = 60 * TIMESTAMP_UNITS_PER_S;

/// Streams remembered at most (`MAVLINK_MAX_SIGNING_STREAMS`); a further stream is
/// refused. Only frames signed with the key create a stream, so an attacker without the
/// key cannot fill the table.
pub const MAX_STREAMS: usize = 16;

/// The largest timestamp a trailer holds (48 bits).
pub const TIMESTAMP_MAX: u64 = (1 << 48) - 1;

/// The signing timestamp of a wall-clock time given as time since the Unix epoch
/// (0 before 2015, saturating at 48 bits).
pub fn timestamp_from_unix(since_unix_epoch: Duration) -> u64 {
    let units = since_unix_epoch
        .as_micros()
        .saturating_sub(u128::from(TIMESTAMP_EPOCH_UNIX_S) * 1_000_000)
        / 10;
    u64::try_from(units).map_or(TIMESTAMP_MAX, |u| u.min(TIMESTAMP_MAX))
}

/// The signing timestamp of the system clock now.
pub fn timestamp_now() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, timestamp_from_unix)
}

/// The signature trailer of a received frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Trailer {
    /// The sender's link id.
    pub link_id: u8,
    /// The sender's timestamp (10 µs units since 2015).
    pub timestamp: u64,
    /// Whether the signature matches the key the frame was decoded with (false when it
    /// was decoded without a key).
    pub authentic: bool,
}

/// Why a frame was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Rejection {
    /// Not signed, and not one of the messages let through unsigned.
    Unsigned {
        /// The message id.
        msgid: u32,
    },
    /// Signed, but not with this key (or altered on the way).
    BadSignature {
        /// The message id.
        msgid: u32,
    },
    /// Not newer than the last frame accepted on its stream: a replay.
    Replayed {
        /// The frame's timestamp.
        timestamp: u64,
        /// The newest timestamp accepted on the stream.
        last: u64,
    },
    /// The first frame of a new stream, more than a minute older than the newest
    /// timestamp known.
    Stale {
        /// The frame's timestamp.
        timestamp: u64,
        /// The newest timestamp known.
        newest: u64,
    },
    /// A new stream while [`MAX_STREAMS`] are already known.
    TooManyStreams,
}

impl std::fmt::Display for Rejection {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Unsigned { msgid } => write!(f, "unsigned message id {msgid}"),
            Self::BadSignature { msgid } => write!(f, "bad signature on message id {msgid}"),
            Self::Replayed { timestamp, last } => write!(
                f,
                "replayed frame: timestamp {timestamp} is not newer than {last} on its stream"
            ),
            Self::Stale { timestamp, newest } => write!(
                f,
                "stale new stream: timestamp {timestamp} is over 60 s older than {newest}"
            ),
            Self::TooManyStreams => write!(f, "more than {MAX_STREAMS} signed streams"),
        }
    }
}

/// One stream's newest accepted timestamp.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Stream {
    link_id: u8,
    system_id: u8,
    component_id: u8,
    timestamp: u64,
}

/// What signing reads of a decoded frame: who sent it, which message, and its signature
/// trailer (none for an unsigned frame).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameStamp {
    /// The message id.
    pub msgid: u32,
    /// The sender's system id.
    pub system_id: u8,
    /// The sender's component id.
    pub component_id: u8,
    /// The signature, checked against the key it was decoded with.
    pub signature: Option<Trailer>,
}

/// One side's signing state: the key, the timestamp it signs with next, and the newest
/// timestamp of every stream it has accepted.
#[derive(Debug, Clone)]
pub struct Signing {
    key: SigningKey,
    timestamp: u64,
    streams: Vec<Stream>,
}

impl Signing {
    /// Signing with `key`, the next frame stamped `initial_timestamp` (clamped to 48 bits).
    pub fn new(key: SigningKey, initial_timestamp: u64) -> Self {
        Self {
            key,
            timestamp: initial_timestamp.min(TIMESTAMP_MAX),
            streams: Vec::new(),
        }
    }

    /// The key.
    pub fn key(&self) -> &SigningKey {
        &self.key
    }

    /// The timestamp the next frame is signed with.
    pub fn timestamp(&self) -> u64 {
        self.timestamp
    }

    /// Moves the clock forward to `timestamp` (never back).
    pub fn advance_to(&mut self, timestamp: u64) {
        self.timestamp = self.timestamp.max(timestamp.min(TIMESTAMP_MAX));
    }

    /// The timestamp for the frame being signed now; the next one is one unit later.
    pub(crate) fn take_timestamp(&mut self) -> u64 {
        let t = self.timestamp;
        self.timestamp = (t + 1).min(TIMESTAMP_MAX);
        t
    }

    /// Whether a frame (decoded with this key; `frame` is what signing reads of it, from
    /// `codec::Frame::stamp`) is accepted: authentic, newer than its stream's last frame,
    /// and a new stream not over a minute stale. Unsigned frames are accepted when
    /// `unsigned_allowed` holds their message id. Accepting moves the stream's and this
    /// side's timestamps forward; a refusal changes nothing.
    ///
    /// # Errors
    /// The reason for refusing.
    pub fn accept(
        &mut self,
        frame: &FrameStamp,
        unsigned_allowed: &[u32],
    ) -> Result<(), Rejection> {
        let msgid = frame.msgid;
        let Some(trailer) = frame.signature else {
            return if unsigned_allowed.contains(&msgid) {
                Ok(())
            } else {
                Err(Rejection::Unsigned { msgid })
            };
        };
        if !trailer.authentic {
            return Err(Rejection::BadSignature { msgid });
        }
        let (system_id, component_id) = (frame.system_id, frame.component_id);
        let known = self.streams.iter().position(|s| {
            s.link_id == trailer.link_id
                && s.system_id == system_id
                && s.component_id == component_id
        });
        match known {
            Some(i) => {
                let last = self.streams[i].timestamp;
                if trailer.timestamp <= last {
                    return Err(Rejection::Replayed {
                        timestamp: trailer.timestamp,
                        last,
                    });
                }
                self.streams[i].timestamp = trailer.timestamp;
            }
            None => {
                if self.streams.len() >= MAX_STREAMS {
                    return Err(Rejection::TooManyStreams);
                }
                if trailer.timestamp + NEW_STREAM_WINDOW < self.timestamp {
                    return Err(Rejection::Stale {
                        timestamp: trailer.timestamp,
                        newest: self.timestamp,
                    });
                }
                self.streams.push(Stream {
                    link_id: trailer.link_id,
                    system_id,
                    component_id,
                    timestamp: trailer.timestamp,
                });
            }
        }
        self.advance_to(trailer.timestamp);
        Ok(())
    }
}

#[cfg(test)]
mod tests;
