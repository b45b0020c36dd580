//! One link's MAVLink 2 signing: the clock we stamp with, the frames we take from the
//! vehicle, and the link id it talks to us on.

use mavlink::dialects::common::MavMessage;
use ringswarm_wire::signing::{Signing, SigningKey};
use ringswarm_wire::time::SimTime;

use super::{Encoder, Frame};

/// How one link signs: every frame it sends is signed, and only authentic, fresh signed
/// frames from the vehicle are taken.
#[derive(Debug, Clone, PartialEq)]
pub struct LinkSigning {
    /// The key.
    pub key: SigningKey,
    /// Our link id in the signatures.
    pub link_id: u8,
    /// The signing timestamp at time zero of the link's clock (10 µs units since 2015):
    /// frames are stamped with this plus the time since, and never the same stamp twice.
    pub timestamp_at_zero: u64,
}

/// The signing state of one link.
#[derive(Debug, Clone)]
pub struct Signer {
    signing: Signing,
    link_id: u8,
    timestamp_at_zero: u64,
    /// The link id the vehicle signs its frames to us with (its first authentic one).
    vehicle_link_id: Option<u8>,
    /// Frames from the vehicle refused.
    pub(crate) refused: u64,
    /// A refusal was reported (once per link).
    pub(crate) reported: bool,
}

impl Signer {
    pub(crate) fn new(cfg: &LinkSigning) -> Self {
        Self {
            signing: Signing::new(cfg.key.clone(), cfg.timestamp_at_zero),
            link_id: cfg.link_id,
            timestamp_at_zero: cfg.timestamp_at_zero,
            vehicle_link_id: None,
            refused: 0,
            reported: false,
        }
    }

    /// The key frames are checked against.
    pub(crate) fn key(&self) -> &SigningKey {
        self.signing.key()
    }

    /// The timestamp the next frame gets.
    pub(crate) fn timestamp(&self) -> u64 {
        self.signing.timestamp()
    }

    /// Moves the clock to `now` (10 µs units past the stamp at time zero).
    pub(crate) fn clock(&mut self, now: SimTime) {
        self.signing
            .advance_to(self.timestamp_at_zero + now.as_micros() / 10);
    }

    /// `msg`, signed, appended to `out`.
    pub(crate) fn encode_into(
        &mut self,
        encoder: &mut Encoder,
        msg: &MavMessage,
        out: &mut Vec<u8>,
    ) {
        encoder.encode_into(msg, Some((&mut self.signing, self.link_id)), out);
    }

    /// Whether a frame from the vehicle's address (from `system_id` or not) is taken: no
    /// unsigned frame; an authentic, fresh one, and from vehicle `system_id` only on the
    /// link id of its first authentic frame (the MAVLink instance it talks to us on; its
    /// frames to another station, replayed to us, are refused).
    pub(crate) fn check(&mut self, frame: &Frame, system_id: u8) -> Result<(), String> {
        let ours = frame.system_id() == system_id;
        if let (Some(t), Some(expected), true) = (frame.signature, self.vehicle_link_id, ours)
            && t.authentic
            && t.link_id != expected
        {
            return Err(format!(
                "signed on link id {}, but the vehicle talks to us on link id {expected}",
                t.link_id
            ));
        }
        self.signing
            .accept(&frame.stamp(), &[])
            .map_err(|why| why.to_string())?;
        if let (Some(t), true) = (frame.signature, ours) {
            self.vehicle_link_id.get_or_insert(t.link_id);
        }
        Ok(())
    }
}
