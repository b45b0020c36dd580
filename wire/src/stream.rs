//! MAVLink frames out of a byte stream (a serial port): a sans-IO framer that takes the
//! bytes as they come, in pieces of any size, and hands out whole frames.
//!
//! On a datagram link each datagram starts on a frame; a serial line has no such edges,
//! and line noise or a reader that starts mid-frame leaves bytes that are not frames. The
//! framer looks for a start byte, waits for the frame's length, and checks its checksum
//! before handing it out. A start byte whose frame fails its checksum is taken for noise:
//! the framer moves one byte on and looks again, so a real frame behind it is not lost.
//! A frame of a message this dialect does not know cannot be checked; it is handed out
//! as framed, and the link counts it as unknown.

use crate::codec::{MAX_FRAME_LEN, frame_checksum_ok, frame_len, is_start_byte};

/// Bytes kept waiting for the rest of a frame: two whole frames' worth.
const KEPT: usize = 2 * MAX_FRAME_LEN;

/// The framer.
#[derive(Debug, Clone, Default)]
pub struct StreamFramer {
    buf: Vec<u8>,
    at: usize,
    skipped_bytes: u64,
    bad_frames: u64,
}

impl StreamFramer {
    /// An empty framer.
    pub fn new() -> Self {
        Self::default()
    }

    /// Takes the next bytes read from the stream.
    pub fn push(&mut self, bytes: &[u8]) {
        if self.at > 0 {
            self.buf.drain(..self.at);
            self.at = 0;
        }
        self.buf.extend_from_slice(bytes);
        if self.buf.len() > KEPT + bytes.len() {
            // Cannot happen with whole frames (each is at most MAX_FRAME_LEN); kept as a
            // bound for a stream that never frames.
            let drop = self.buf.len() - KEPT;
            self.buf.drain(..drop);
            self.skipped_bytes += drop as u64;
        }
    }

    /// The next whole frame, or `None` until more bytes come.
    pub fn next_frame(&mut self) -> Option<&[u8]> {
        loop {
            let rest = &self.buf[self.at..];
            let Some(start) = rest.iter().position(|b| is_start_byte(*b)) else {
                self.skipped_bytes += rest.len() as u64;
                self.at = self.buf.len();
                return None;
            };
            self.skipped_bytes += start as u64;
            self.at += start;
            let rest = &self.buf[self.at..];
            let len = frame_len(rest)?;
            if rest.len() < len {
                return None;
            }
            if frame_checksum_ok(&rest[..len]) == Some(false) {
                self.bad_frames += 1;
                self.skipped_bytes += 1;
                self.at += 1;
                continue;
            }
            let frame = self.at..self.at + len;
            self.at += len;
            return Some(&self.buf[frame]);
        }
    }

    /// Bytes dropped because they were not part of a frame that checked.
    pub fn skipped_bytes(&self) -> u64 {
        self.skipped_bytes
    }

    /// Start bytes whose frame failed its checksum.
    pub fn bad_frames(&self) -> u64 {
        self.bad_frames
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codec::{Encoder, decode_datagram};
    use mavlink::dialects::common::{HEARTBEAT_DATA, MavMessage};

    fn heartbeat(encoder: &mut Encoder) -> Vec<u8> {
        encoder.encode(&MavMessage::HEARTBEAT(HEARTBEAT_DATA::default()))
    }

    fn frames_of(framer: &mut StreamFramer) -> Vec<Vec<u8>> {
        let mut out = Vec::new();
        while let Some(f) = framer.next_frame() {
            out.push(f.to_vec());
        }
        out
    }

    #[test]
    fn frames_cut_anywhere_come_out_whole() {
        let mut encoder = Encoder::new(1, 1);
        let sent: Vec<Vec<u8>> = (0..5).map(|_| heartbeat(&mut encoder)).collect();
        let stream: Vec<u8> = sent.concat();
        for piece in 1..stream.len() {
            let mut framer = StreamFramer::new();
            let mut got = Vec::new();
            for chunk in stream.chunks(piece) {
                framer.push(chunk);
                got.extend(frames_of(&mut framer));
            }
            assert_eq!(got, sent, "pieces of {piece} bytes");
            assert_eq!(framer.skipped_bytes(), 0);
        }
    }

    #[test]
    fn noise_and_a_false_start_byte_are_skipped_and_counted() {
        let mut encoder = Encoder::new(7, 1);
        let frame = heartbeat(&mut encoder);
        // Noise with a MAVLink 2 start byte whose "frame" cannot check, then a real one.
        let noise = [
            0x00, 0x55, 0xFD, 0x09, 0x00, 0x00, 0x01, 0x02, 0x03, 0x00, 0x00, 0x00,
        ];
        let mut stream = noise.to_vec();
        stream.extend_from_slice(&frame);
        stream.extend(std::iter::repeat_n(0xAA, 40));
        let mut framer = StreamFramer::new();
        framer.push(&stream);
        let got = frames_of(&mut framer);
        assert_eq!(got, vec![frame.clone()]);
        assert_eq!(framer.bad_frames(), 1);
        assert_eq!(framer.skipped_bytes(), noise.len() as u64 + 40);
        let decoded = decode_datagram(&got[0]);
        assert!(matches!(&decoded[..], [Ok(f)] if f.system_id() == 7));
    }

    #[test]
    fn a_stream_that_never_frames_stays_bounded() {
        let mut framer = StreamFramer::new();
        for _ in 0..1000 {
            framer.push(&[0xFD; 100]);
            let _ = frames_of(&mut framer);
        }
        assert!(framer.buf.len() <= KEPT + 100);
    }
}
