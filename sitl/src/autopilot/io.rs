//! The vehicle's MAVLink side, as PX4's `mavlink` module instances hold it: one link per
//! instance with its encoder and stream table, the signing state they share, and the
//! frames waiting for the driver.

use std::collections::VecDeque;

use super::{Link, Transmit};

/// What the vehicle sends with and through.
#[derive(Debug, Clone)]
pub(super) struct MavlinkIo {
    /// The offboard (API) and ground-station links.
    pub(super) links: [Link; 2],
    /// MAVLink 2 signing, once a key is set.
    pub(super) signing: Option<ringswarm_wire::signing::Signing>,
    /// Frames for the driver, in order.
    pub(super) outbox: VecDeque<Transmit>,
    /// Sent datagrams' buffers given back by the driver (`Vehicle::recycle`).
    pub(super) spare: crate::codec::FramePool,
    /// The id of the last STATUSTEXT sent in chunks.
    pub(super) statustext_id: u16,
    /// The message ids due on a link, kept between steps (no allocation per step).
    pub(super) due_scratch: Vec<u32>,
}
