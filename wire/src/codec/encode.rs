//! MAVLink 2 encoding: messages into frames (signed once a key is set), into buffers a
//! pool keeps for the next frames.

use mavlink::dialects::common::MavMessage;
use mavlink::{MAVLinkV2MessageRaw, MavHeader, MavlinkVersion, Message};

use super::{MAX_FRAME_LEN, MAX_PAYLOAD_LEN, STX_V2, V2_HEADER_LEN, X25};
use crate::signing::Signing;

/// Buffers of sent frames kept for the next ones: whoever encodes takes a buffer here and
/// its driver gives it back once sent, so that steady traffic allocates nothing. At most
/// [`FramePool::KEPT`] are kept.
#[derive(Debug, Clone, Default)]
pub struct FramePool {
    spare: Vec<Vec<u8>>,
}

impl FramePool {
    /// Buffers kept (more than a step's or a tick's worth of frames).
    pub const KEPT: usize = 32;

    /// An empty buffer that takes any frame without growing.
    pub fn take(&mut self) -> Vec<u8> {
        let mut buf = self
            .spare
            .pop()
            .unwrap_or_else(|| Vec::with_capacity(MAX_FRAME_LEN));
        buf.clear();
        buf
    }

    /// A buffer back for reuse.
    pub fn give(&mut self, buf: Vec<u8>) {
        if self.spare.len() < Self::KEPT {
            self.spare.push(buf);
        }
    }
}

/// Encodes messages from one system and component as MAVLink 2, counting sequence numbers.
#[derive(Debug, Clone)]
pub struct Encoder {
    system_id: u8,
    component_id: u8,
    sequence: u8,
}

impl Encoder {
    /// An encoder for `system_id`/`component_id`, starting at sequence 0.
    pub fn new(system_id: u8, component_id: u8) -> Self {
        Self {
            system_id,
            component_id,
            sequence: 0,
        }
    }

    /// One unsigned MAVLink 2 frame.
    pub fn encode(&mut self, msg: &MavMessage) -> Vec<u8> {
        let mut out = Vec::new();
        self.encode_into(msg, None, &mut out);
        out
    }

    /// One MAVLink 2 frame signed with `signing`'s key and next timestamp, from link
    /// `link_id`.
    pub fn encode_signed(
        &mut self,
        msg: &MavMessage,
        signing: &mut Signing,
        link_id: u8,
    ) -> Vec<u8> {
        let mut out = Vec::new();
        self.encode_into(msg, Some((signing, link_id)), &mut out);
        out
    }

    /// One frame, signed when `signing` is given, appended to `out` (a buffer kept for
    /// reuse allocates nothing).
    pub fn encode_into(
        &mut self,
        msg: &MavMessage,
        signing: Option<(&mut Signing, u8)>,
        out: &mut Vec<u8>,
    ) {
        let header = self.next_header();
        let Some((signing, link_id)) = signing else {
            encode_unsigned(header, msg, out);
            return;
        };
        let mut raw = MAVLinkV2MessageRaw::new();
        raw.serialize_message_for_signing(header, msg);
        *raw.signature_link_id_mut() = link_id;
        let timestamp = signing.take_timestamp().to_le_bytes();
        raw.signature_timestamp_bytes_mut()
            .copy_from_slice(&timestamp[..6]);
        let mut value = [0u8; 6];
        raw.calculate_signature(signing.key().bytes(), &mut value);
        raw.signature_value_mut().copy_from_slice(&value);
        out.extend_from_slice(raw.raw_bytes());
    }

    fn next_header(&mut self) -> MavHeader {
        let header = MavHeader {
            system_id: u32::from(self.system_id),
            component_id: self.component_id,
            sequence: self.sequence,
        };
        self.sequence = self.sequence.wrapping_add(1);
        header
    }
}

/// Appends an unsigned MAVLink 2 frame: the payload serialised in place after the header
/// (trailing zeros cut, as MAVLink 2 requires), then the checksum.
fn encode_unsigned(header: MavHeader, msg: &MavMessage, out: &mut Vec<u8>) {
    let start = out.len();
    out.resize(start + V2_HEADER_LEN + MAX_PAYLOAD_LEN, 0);
    let payload_len = msg.ser(MavlinkVersion::V2, &mut out[start + V2_HEADER_LEN..]);
    let msgid = msg.message_id();
    let id = msgid.to_le_bytes();
    out[start..start + V2_HEADER_LEN].copy_from_slice(&[
        STX_V2,
        // A payload is at most 255 bytes: the generated serialisers write into 255.
        payload_len as u8,
        0, // incompatibility flags: not signed
        0, // compatibility flags
        header.sequence,
        // The encoder's system id is a u8.
        header.system_id as u8,
        header.component_id,
        id[0],
        id[1],
        id[2],
    ]);
    out.truncate(start + V2_HEADER_LEN + payload_len);
    // The message's seed byte closes the checksum: appended for it (one pass over the
    // frame), then replaced by the checksum.
    out.push(MavMessage::extra_crc(msgid));
    let crc = X25.compute(&out[start + 1..]);
    out.pop();
    out.extend_from_slice(&crc.to_le_bytes());
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_frame_pool_hands_out_empty_buffers_that_fit_any_frame_and_keeps_a_few() {
        let mut pool = FramePool::default();
        let mut buf = pool.take();
        assert!(buf.is_empty() && buf.capacity() >= MAX_FRAME_LEN);
        buf.extend_from_slice(b"a sent frame");
        let at = buf.as_ptr();
        pool.give(buf);
        let again = pool.take();
        assert!(again.is_empty());
        assert_eq!(again.as_ptr(), at, "the same buffer came back");
        for _ in 0..FramePool::KEPT + 5 {
            pool.give(Vec::new());
        }
        assert_eq!(pool.spare.len(), FramePool::KEPT);
    }
}
