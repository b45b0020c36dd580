//! MAVLink framing: bytes ↔ messages, with the `mavlink` crate as the payload codec.
//!
//! The crate's connections are not used (see REFERENCE §5: its `udpin` replies to the last
//! sender only); sockets are ours and this module turns one datagram into frames and one
//! message into bytes. A datagram may carry several frames, MAVLink 1 or 2, signed or
//! not (signatures are not checked). Faulty frames come out as [`FrameError`] values so
//! that the caller can count them, and decoding goes on after a bad frame when its length
//! is known.

use crcxx::crc16::catalog::CRC_16_MCRF4XX;
use crcxx::crc16::{Crc, LookupTable256xN};
use mavlink::dialects::common::MavMessage;
use mavlink::error::ParserError;
use mavlink::{MAVLinkV2MessageRaw, MavHeader, MavlinkVersion, Message};

use crate::signing::{FrameStamp, SigningKey, Trailer};

mod encode;
mod raw;
pub use encode::{Encoder, FramePool};
pub use raw::{RawFrames, frame_checksum_ok, frame_system_id, raw_frames};
pub(crate) use raw::{frame_len, is_start_byte};

/// MAVLink 1 start byte.
const STX_V1: u8 = 0xFE;
/// MAVLink 2 start byte.
const STX_V2: u8 = 0xFD;
/// MAVLink 2 incompatibility flag: the frame is signed (13-byte trailer).
const INCOMPAT_SIGNED: u8 = 0x01;
/// Length of the MAVLink 2 signature trailer.
const SIGNATURE_LEN: usize = 13;
/// Length of the MAVLink 2 start byte and header.
const V2_HEADER_LEN: usize = 10;
/// The longest MAVLink payload.
const MAX_PAYLOAD_LEN: usize = 255;

/// MAVLink's checksum, CRC-16/MCRF4XX (X.25 without the final inversion), by table slices
/// of 16, 8 and 4 bytes: each frame is checksummed once when it is sent and once when it
/// is read.
const X25: Crc<LookupTable256xN<16>> = Crc::<LookupTable256xN<16>>::new(&CRC_16_MCRF4XX);

/// The checksum of a frame's bytes after the start byte, closed with the message's
/// `extra_crc` seed byte.
fn checksum(bytes: &[u8], extra_crc: u8) -> u16 {
    let mut digest = X25.compute_multipart();
    digest.update(bytes);
    digest.update(&[extra_crc]);
    digest.value()
}

/// The longest MAVLink 2 frame: start byte, 9-byte header, 255-byte payload, checksum,
/// signature. A buffer of this capacity takes any frame without growing.
pub const MAX_FRAME_LEN: usize = V2_HEADER_LEN + MAX_PAYLOAD_LEN + 2 + SIGNATURE_LEN;

/// A decoded frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    /// Sender system and component, sequence.
    pub header: MavHeader,
    /// The message.
    pub msg: MavMessage,
    /// MAVLink 1 or 2.
    pub version: MavlinkVersion,
    /// The signature trailer of a signed MAVLink 2 frame.
    pub signature: Option<Trailer>,
}

impl Frame {
    /// The sender's system id. A decoded frame's always fits in a byte (it is one on the
    /// wire); a frame built by hand with a larger one reads as 0, no system.
    pub fn system_id(&self) -> u8 {
        u8::try_from(self.header.system_id).unwrap_or(0)
    }

    /// What signing reads of this frame ([`Signing::accept`]).
    pub fn stamp(&self) -> FrameStamp {
        FrameStamp {
            msgid: mavlink::Message::message_id(&self.msg),
            system_id: self.system_id(),
            component_id: self.header.component_id,
            signature: self.signature,
        }
    }
}

/// Why a frame could not be decoded.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FrameError {
    /// Bytes that do not start a frame were skipped.
    Garbage {
        /// How many bytes.
        skipped: usize,
    },
    /// The datagram ends inside a frame.
    Truncated,
    /// The checksum does not match (corruption, or a message of another dialect).
    BadCrc {
        /// The frame's message id.
        msgid: u32,
    },
    /// A message id the common dialect does not know.
    UnknownMessage {
        /// The id.
        msgid: u32,
    },
    /// The payload did not parse (for example an enum value newer than the dialect).
    BadPayload {
        /// The frame's message id.
        msgid: u32,
    },
}

impl std::fmt::Display for FrameError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Garbage { skipped } => write!(f, "{skipped} bytes outside any frame"),
            Self::Truncated => write!(f, "truncated frame"),
            Self::BadCrc { msgid } => write!(f, "bad checksum on message id {msgid}"),
            Self::UnknownMessage { msgid } => write!(f, "unknown message id {msgid}"),
            Self::BadPayload { msgid } => write!(f, "unparsable payload for message id {msgid}"),
        }
    }
}

/// Decodes every frame in one datagram, without a key (signed frames come out with
/// [`Trailer::authentic`] false).
pub fn decode_datagram(bytes: &[u8]) -> Vec<Result<Frame, FrameError>> {
    decode_datagram_with(bytes, None)
}

/// Decodes every frame in one datagram, checking signatures against `key`: what
/// [`for_each_frame`] hands out, collected.
pub fn decode_datagram_with(
    bytes: &[u8],
    key: Option<&SigningKey>,
) -> Vec<Result<Frame, FrameError>> {
    let mut decoded = Vec::new();
    for_each_frame(bytes, key, |frame| decoded.push(frame.cloned()));
    decoded
}

/// Hands every frame of one datagram, in order, to `visit`: the decoded frame by
/// reference (built once, where it is read: a message is a few hundred bytes to move), or
/// why a frame could not be decoded (bytes before a frame's start come out as one
/// [`FrameError::Garbage`]; decoding goes on after a bad frame whose length is known).
pub fn for_each_frame(
    bytes: &[u8],
    key: Option<&SigningKey>,
    mut visit: impl FnMut(Result<&Frame, FrameError>),
) {
    let mut at = 0;
    while at < bytes.len() {
        let skipped = bytes[at..]
            .iter()
            .position(|b| *b == STX_V1 || *b == STX_V2)
            .unwrap_or(bytes.len() - at);
        if skipped > 0 {
            at += skipped;
            visit(Err(FrameError::Garbage { skipped }));
            continue;
        }
        let (checked, consumed) = check_frame(&bytes[at..], key);
        at = consumed.map_or(bytes.len(), |n| at + n);
        match checked {
            Ok(parts) => match parts.message() {
                Ok(msg) => visit(Ok(&parts.frame(msg))),
                Err(error) => visit(Err(error)),
            },
            Err(error) => visit(Err(error)),
        }
    }
}

/// A frame whose length, header and checksum are good, its payload not parsed yet.
struct Checked<'a> {
    header: MavHeader,
    msgid: u32,
    version: MavlinkVersion,
    payload: &'a [u8],
    signature: Option<Trailer>,
}

impl Checked<'_> {
    /// The payload parsed.
    fn message(&self) -> Result<MavMessage, FrameError> {
        let msgid = self.msgid;
        MavMessage::parse(self.version, msgid, self.payload).map_err(|e| match e {
            // An unknown id whose checksum happened to match with no extra byte.
            ParserError::UnknownMessage { .. } => FrameError::UnknownMessage { msgid },
            _ => FrameError::BadPayload { msgid },
        })
    }

    fn frame(&self, msg: MavMessage) -> Frame {
        Frame {
            header: self.header,
            msg,
            version: self.version,
            signature: self.signature,
        }
    }
}

/// Checks the frame at the start of `bytes` (length, checksum, signature); returns its
/// length when it is known.
fn check_frame<'a>(
    bytes: &'a [u8],
    key: Option<&SigningKey>,
) -> (Result<Checked<'a>, FrameError>, Option<usize>) {
    let v2 = bytes[0] == STX_V2;
    let header_len = if v2 { 10 } else { 6 };
    let Some(total) = frame_len(bytes) else {
        return (Err(FrameError::Truncated), None);
    };
    let payload_len = usize::from(bytes[1]);
    if bytes.len() < total {
        return (Err(FrameError::Truncated), None);
    }
    let (sequence, system_id, component_id, msgid) = if v2 {
        (
            bytes[4],
            bytes[5],
            bytes[6],
            u32::from_le_bytes([bytes[7], bytes[8], bytes[9], 0]),
        )
    } else {
        (bytes[2], bytes[3], bytes[4], u32::from(bytes[5]))
    };
    let crc_at = header_len + payload_len;
    let received_crc = u16::from_le_bytes([bytes[crc_at], bytes[crc_at + 1]]);
    if checksum(&bytes[1..crc_at], MavMessage::extra_crc(msgid)) != received_crc {
        // Only a frame that fails is asked whether its message is known at all (that
        // builds a default message: too dear for every frame).
        let error = if MavMessage::default_message_from_id(msgid).is_some() {
            FrameError::BadCrc { msgid }
        } else {
            FrameError::UnknownMessage { msgid }
        };
        return (Err(error), Some(total));
    }
    let version = if v2 {
        MavlinkVersion::V2
    } else {
        MavlinkVersion::V1
    };
    let signature = (v2 && bytes[2] & INCOMPAT_SIGNED != 0).then(|| trailer(&bytes[..total], key));
    let checked = Checked {
        header: MavHeader {
            system_id: u32::from(system_id),
            component_id,
            sequence,
        },
        msgid,
        version,
        payload: &bytes[header_len..crc_at],
        signature,
    };
    (Ok(checked), Some(total))
}

/// The trailer of the complete signed MAVLink 2 frame `frame`, checked against `key`.
fn trailer(frame: &[u8], key: Option<&SigningKey>) -> Trailer {
    let sig = &frame[frame.len() - SIGNATURE_LEN..];
    let mut timestamp = [0u8; 8];
    timestamp[..6].copy_from_slice(&sig[1..7]);
    let authentic = key.is_some_and(|key| {
        let mut raw = MAVLinkV2MessageRaw::new();
        raw.as_mut_slice()[..frame.len()].copy_from_slice(frame);
        let mut value = [0u8; 6];
        raw.calculate_signature(key.bytes(), &mut value);
        value == sig[7..]
    });
    Trailer {
        link_id: sig[0],
        timestamp: u64::from_le_bytes(timestamp),
        authentic,
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    use mavlink::dialects::common::{
        COMMAND_LONG_DATA, HEARTBEAT_DATA, MavAutopilot, MavCmd, MavModeFlag, MavState, MavType,
    };

    /// A PX4 quadrotor's heartbeat in OFFBOARD, standby.
    pub(crate) fn heartbeat() -> MavMessage {
        MavMessage::HEARTBEAT(HEARTBEAT_DATA {
            custom_mode: 6 << 16,
            mavtype: MavType::MAV_TYPE_QUADROTOR,
            autopilot: MavAutopilot::MAV_AUTOPILOT_PX4,
            base_mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
            system_status: MavState::MAV_STATE_STANDBY,
            mavlink_version: 3,
        })
    }

    #[test]
    fn frame_system_id_reads_both_versions_headers() {
        let v2 = Encoder::new(207, 1).encode(&heartbeat());
        assert_eq!(frame_system_id(&v2), Some(207));
        // MAVLink 1: STX, len, seq, sysid, compid, msgid.
        assert_eq!(frame_system_id(&[STX_V1, 0, 0, 42, 1, 0, 0, 0]), Some(42));
        assert_eq!(frame_system_id(&[STX_V2, 9, 0, 0]), None);
        assert_eq!(frame_system_id(&[0x00, 1, 2, 3, 4, 5]), None);
    }

    #[test]
    fn raw_frames_splits_a_datagram_and_drops_garbage_and_a_truncated_tail() {
        let mut enc = Encoder::new(1, 1);
        let a = enc.encode(&heartbeat());
        let b = enc.encode(&heartbeat());
        let mut datagram = vec![0x00, 0x11];
        datagram.extend_from_slice(&a);
        datagram.extend_from_slice(&b);
        datagram.extend_from_slice(&a[..5]);
        let frames: Vec<&[u8]> = raw_frames(&datagram).collect();
        assert_eq!(frames, vec![a.as_slice(), b.as_slice()]);
        // 10-byte header + 9-byte heartbeat payload + 2-byte CRC.
        assert_eq!(a.len(), 21);
    }

    #[test]
    fn heartbeat_golden_bytes() {
        // MAVLink 2 heartbeat from 1/1, sequence 0: payload custom_mode u32 LE, type 2,
        // autopilot 12, base_mode 1, system_status 3, version 3; CRC extra 50.
        let bytes = Encoder::new(1, 1).encode(&heartbeat());
        let payload = [0x00, 0x00, 0x06, 0x00, 0x02, 0x0C, 0x01, 0x03, 0x03];
        assert_eq!(&bytes[..10], &[0xFD, 9, 0, 0, 0, 1, 1, 0, 0, 0]);
        assert_eq!(&bytes[10..19], &payload);
        let crc = mavlink::calculate_crc(&bytes[1..19], 50);
        assert_eq!(&bytes[19..], &crc.to_le_bytes());
    }

    #[test]
    fn the_checksum_is_the_mavlink_crates_for_every_length_and_seed() {
        let bytes: Vec<u8> = (0..300u32).map(|i| (i * 7919 % 251) as u8).collect();
        for len in 0..bytes.len() {
            for extra in [0, 50, 137, 255] {
                assert_eq!(
                    checksum(&bytes[..len], extra),
                    mavlink::calculate_crc(&bytes[..len], extra),
                    "{len} bytes, extra crc {extra}"
                );
            }
        }
    }

    #[test]
    fn frames_are_byte_for_byte_the_mavlink_crates() {
        let statustext = mavlink::dialects::common::STATUSTEXT_DATA {
            text: [b'x'; 50].into(),
            ..Default::default()
        };
        let messages = [
            heartbeat(),
            // An all-zero payload: MAVLink 2 keeps one byte.
            MavMessage::COMMAND_LONG(COMMAND_LONG_DATA::default()),
            MavMessage::STATUSTEXT(statustext),
            MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
                target_system: 3,
                target_component: 1,
                command: MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
                confirmation: 0,
                param1: 1.0,
                ..COMMAND_LONG_DATA::default()
            }),
        ];
        let mut enc = Encoder::new(42, 1);
        for (sequence, msg) in (0u8..).zip(&messages) {
            let mut ours = vec![0xAA];
            enc.encode_into(msg, None, &mut ours);
            let mut raw = MAVLinkV2MessageRaw::new();
            let header = MavHeader {
                system_id: 42,
                component_id: 1,
                sequence,
            };
            raw.serialize_message(header, msg);
            assert_eq!(&ours[1..], raw.raw_bytes(), "{msg:?}");
            assert_eq!(ours[0], 0xAA, "appended after what the buffer held");
        }
    }

    #[test]
    fn round_trip_and_two_frames_in_one_datagram() {
        let mut enc = Encoder::new(3, 1);
        let cmd = MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
            target_system: 3,
            target_component: 1,
            command: MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            confirmation: 0,
            param1: 1.0,
            param2: 0.0,
            param3: 0.0,
            param4: 0.0,
            param5: 0.0,
            param6: 0.0,
            param7: 0.0,
        });
        let mut datagram = enc.encode(&heartbeat());
        datagram.extend(enc.encode(&cmd));
        let frames = decode_datagram(&datagram);
        assert_eq!(frames.len(), 2);
        let second = frames[1].clone().unwrap();
        assert_eq!(second.msg, cmd);
        assert_eq!(second.header.system_id, 3);
        assert_eq!(second.header.sequence, 1);
    }

    #[test]
    fn corrupt_truncated_and_unknown_frames_are_reported() {
        let mut bytes = Encoder::new(1, 1).encode(&heartbeat());
        bytes[12] ^= 0xFF;
        assert_eq!(
            decode_datagram(&bytes),
            vec![Err(FrameError::BadCrc { msgid: 0 })]
        );
        let bytes = Encoder::new(1, 1).encode(&heartbeat());
        assert_eq!(
            decode_datagram(&bytes[..15]),
            vec![Err(FrameError::Truncated)]
        );
        let mut unknown = bytes.clone();
        unknown[7] = 0x39; // id 0x30039, not in common
        unknown[8] = 0x00;
        unknown[9] = 0x03;
        assert_eq!(
            decode_datagram(&unknown),
            vec![Err(FrameError::UnknownMessage { msgid: 0x30039 })]
        );
        // Its checksum made right (an unknown id has no extra byte): still unknown.
        let crc_at = unknown.len() - 2;
        let crc = checksum(&unknown[1..crc_at], 0).to_le_bytes();
        unknown[crc_at..].copy_from_slice(&crc);
        assert_eq!(
            decode_datagram(&unknown),
            vec![Err(FrameError::UnknownMessage { msgid: 0x30039 })]
        );
        let mut garbage = vec![1, 2, 3];
        garbage.extend(&bytes);
        let frames = decode_datagram(&garbage);
        assert_eq!(frames[0], Err(FrameError::Garbage { skipped: 3 }));
        assert!(frames[1].is_ok());
    }

    #[test]
    fn a_mixed_datagram_comes_out_frame_by_frame_in_order() {
        let mut encoder = Encoder::new(7, 1);
        let good = encoder.encode(&heartbeat());
        let mut corrupt = encoder.encode(&heartbeat());
        corrupt[12] ^= 0xFF;
        // Garbage, a frame, a corrupt frame, garbage, a frame, then a truncated one.
        let mut datagram = vec![9, 9];
        for part in [
            &good[..],
            &corrupt[..],
            &[1, 2, 3][..],
            &good[..],
            &good[..15],
        ] {
            datagram.extend_from_slice(part);
        }
        let mut seen = Vec::new();
        for_each_frame(&datagram, None, |frame| {
            seen.push(frame.map(|f| (f.system_id(), f.header.sequence)));
        });
        assert_eq!(
            seen,
            vec![
                Err(FrameError::Garbage { skipped: 2 }),
                Ok((7, 0)),
                Err(FrameError::BadCrc { msgid: 0 }),
                Err(FrameError::Garbage { skipped: 3 }),
                Ok((7, 0)),
                Err(FrameError::Truncated),
            ]
        );
        assert_eq!(decode_datagram(&datagram).len(), seen.len());
    }
}
