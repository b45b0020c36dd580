//! Frames as raw bytes: where each starts and ends in a datagram or stream, the sender's
//! system id, whether a checksum holds; nothing is decoded into a message.

use mavlink::Message;
use mavlink::dialects::common::MavMessage;

use super::{INCOMPAT_SIGNED, SIGNATURE_LEN, STX_V1, STX_V2, V2_HEADER_LEN, checksum};

/// The complete frames of a datagram as raw bytes (what a `.tlog` records), skipping
/// bytes outside frames and a truncated tail. Checksums are not checked. Allocates
/// nothing.
pub fn raw_frames(bytes: &[u8]) -> RawFrames<'_> {
    RawFrames { bytes, at: 0 }
}

/// The iterator of [`raw_frames`].
#[derive(Debug, Clone)]
pub struct RawFrames<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Iterator for RawFrames<'a> {
    type Item = &'a [u8];

    fn next(&mut self) -> Option<&'a [u8]> {
        let bytes = self.bytes;
        let skip = bytes[self.at..]
            .iter()
            .position(|b| *b == STX_V1 || *b == STX_V2)?;
        self.at += skip;
        match frame_len(&bytes[self.at..]) {
            Some(n) if n <= bytes.len() - self.at => {
                let frame = &bytes[self.at..self.at + n];
                self.at += n;
                Some(frame)
            }
            _ => {
                self.at = bytes.len();
                None
            }
        }
    }
}

/// The sender's system id of a frame [`raw_frames`] returned (`None` for anything
/// shorter than a header).
pub fn frame_system_id(frame: &[u8]) -> Option<u8> {
    match *frame.first()? {
        STX_V2 => frame.get(5).copied(),
        STX_V1 => frame.get(3).copied(),
        _ => None,
    }
}

/// Whether a complete raw frame (as [`raw_frames`] or a stream framer cuts it) holds
/// together: its checksum matches for a known message. `None` for a message this dialect
/// does not know (its checksum cannot be checked), `Some(false)` for a bad checksum.
pub fn frame_checksum_ok(frame: &[u8]) -> Option<bool> {
    let (v2, header_len) = match frame.first() {
        Some(&STX_V2) => (true, V2_HEADER_LEN),
        Some(&STX_V1) => (false, 6),
        _ => return Some(false),
    };
    let total = frame_len(frame)?;
    if frame.len() < total {
        return Some(false);
    }
    let msgid = if v2 {
        u32::from_le_bytes([frame[7], frame[8], frame[9], 0])
    } else {
        u32::from(frame[5])
    };
    let crc_at = header_len + usize::from(frame[1]);
    let received = u16::from_le_bytes([frame[crc_at], frame[crc_at + 1]]);
    if checksum(&frame[1..crc_at], MavMessage::extra_crc(msgid)) == received {
        Some(true)
    } else if MavMessage::default_message_from_id(msgid).is_some() {
        Some(false)
    } else {
        None
    }
}

/// Whether `byte` starts a MAVLink 1 or 2 frame.
pub(crate) fn is_start_byte(byte: u8) -> bool {
    byte == STX_V1 || byte == STX_V2
}

/// Header length and total length of the frame starting at `bytes[0]` (an STX), once
/// the header is there.
pub(crate) fn frame_len(bytes: &[u8]) -> Option<usize> {
    let v2 = bytes[0] == STX_V2;
    let header_len = if v2 { 10 } else { 6 };
    if bytes.len() < header_len {
        return None;
    }
    let payload_len = usize::from(bytes[1]);
    let signed = v2 && bytes[2] & INCOMPAT_SIGNED != 0;
    Some(header_len + payload_len + 2 + if signed { SIGNATURE_LEN } else { 0 })
}
