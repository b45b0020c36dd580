//! A vehicle served on a pseudo-terminal, as an autopilot on a serial port: what a
//! companion computer's shard talks to over its cable, here without hardware.
//!
//! [`PtyLink::open`] makes a pseudo-terminal pair and links the configured device path
//! to its far end (`/dev/pts/N`), so that the coordinator opens the same path it would on
//! the vehicle. The emulator keeps the far end open as well: without that, reading the
//! near end fails until the coordinator opens it. Bytes are framed as a serial line's
//! are ([`StreamFramer`]): noise and a reader that starts mid-frame are skipped.

use std::io::{self, Read, Write};
use std::os::fd::{AsRawFd, RawFd};
use std::os::unix::fs::OpenOptionsExt;
use std::path::{Path, PathBuf};
use std::time::Duration;

use ringswarm_wire::stream::StreamFramer;
use serialport::{SerialPort, TTYPort};

/// One vehicle's serial link on a pseudo-terminal.
pub struct PtyLink {
    near: TTYPort,
    /// The far end, kept open (see the module's doc).
    _far: std::fs::File,
    far_name: String,
    /// The link the emulator made at the configured device path.
    device: PathBuf,
    framer: StreamFramer,
}

impl std::fmt::Debug for PtyLink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} -> {}", self.device.display(), self.far_name)
    }
}

impl PtyLink {
    /// A new pseudo-terminal, its far end linked at `device`. A symbolic link left there
    /// by an earlier run is replaced; anything else at that path is not touched.
    ///
    /// # Errors
    /// No pseudo-terminal could be made, or the link could not be made at `device`
    /// (the message names the path and why).
    pub fn open(device: &Path) -> io::Result<Self> {
        let named = |what: &str, e: &dyn std::fmt::Display| {
            io::Error::other(format!("{what} for {}: {e}", device.display()))
        };
        let (mut near, far) = TTYPort::pair().map_err(|e| named("no pseudo-terminal", &e))?;
        near.set_timeout(Duration::ZERO)
            .map_err(|e| named("pseudo-terminal not pollable", &e))?;
        let far_name = far
            .name()
            .ok_or_else(|| named("pseudo-terminal without a name", &"ptsname"))?;
        // The far end stays open as a plain file: serialport's own handle (which set it
        // raw) holds a lock that would keep the coordinator from opening it.
        let far = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            // Never the emulator's controlling terminal.
            .custom_flags(libc::O_NOCTTY)
            .open(&far_name)
            .map_err(|e| named(&format!("cannot open {far_name}"), &e))?;
        match std::fs::symlink_metadata(device) {
            Ok(meta) if meta.file_type().is_symlink() => std::fs::remove_file(device)?,
            Ok(_) => {
                return Err(io::Error::new(
                    io::ErrorKind::AlreadyExists,
                    format!(
                        "{} exists and is not a link: the emulator serves a serial vehicle by \
                         linking that path to a pseudo-terminal, and does not replace a file",
                        device.display()
                    ),
                ));
            }
            Err(e) if e.kind() == io::ErrorKind::NotFound => {}
            Err(e) => return Err(named("cannot look at the device path", &e)),
        }
        std::os::unix::fs::symlink(&far_name, device)
            .map_err(|e| named(&format!("cannot link {far_name}"), &e))?;
        Ok(Self {
            near,
            _far: far,
            far_name,
            device: device.to_path_buf(),
            framer: StreamFramer::new(),
        })
    }

    /// The configured device path.
    pub fn device(&self) -> &Path {
        &self.device
    }

    /// The pseudo-terminal it links to.
    pub fn far_name(&self) -> &str {
        &self.far_name
    }

    /// The near end's descriptor, for a readiness poller.
    pub fn raw_fd(&self) -> RawFd {
        self.near.as_raw_fd()
    }

    /// Reads what is waiting, up to `max_reads` reads of `buf`, and hands each whole
    /// frame to `each`. Returns whether more may be waiting (the cap was reached).
    ///
    /// # Errors
    /// A read error other than "nothing waiting".
    pub fn receive(
        &mut self,
        buf: &mut [u8],
        max_reads: usize,
        mut each: impl FnMut(&[u8]),
    ) -> io::Result<bool> {
        for _ in 0..max_reads {
            let n = match self.near.read(buf) {
                Ok(0) => return Ok(false),
                Ok(n) => n,
                Err(e) if nothing_waiting(&e) => return Ok(false),
                Err(e) => return Err(e),
            };
            self.framer.push(&buf[..n]);
            while let Some(frame) = self.framer.next_frame() {
                each(frame);
            }
        }
        Ok(true)
    }

    /// Writes one frame without waiting.
    ///
    /// # Errors
    /// `WouldBlock` when the line's buffer cannot take it whole now (nobody reads the
    /// far end, or the reader is slower than the vehicle); other write errors.
    pub fn send(&mut self, bytes: &[u8]) -> io::Result<()> {
        match self.near.write(bytes) {
            Ok(n) if n == bytes.len() => Ok(()),
            // A frame cut short: the reader's framer skips the rest as noise.
            Ok(_) => Err(io::ErrorKind::WouldBlock.into()),
            Err(e) if nothing_waiting(&e) => Err(io::ErrorKind::WouldBlock.into()),
            Err(e) => Err(e),
        }
    }

    /// Bytes read that were not part of a frame that checked.
    pub fn skipped_bytes(&self) -> u64 {
        self.framer.skipped_bytes()
    }
}

/// serialport reports "nothing to read / no room now" as a timeout of its zero-length
/// poll.
fn nothing_waiting(e: &io::Error) -> bool {
    matches!(
        e.kind(),
        io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock | io::ErrorKind::Interrupted
    )
}

impl Drop for PtyLink {
    fn drop(&mut self) {
        // Only our own link: a later run may have replaced it.
        if std::fs::read_link(&self.device).is_ok_and(|to| to == Path::new(&self.far_name)) {
            let _ = std::fs::remove_file(&self.device);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavlink::dialects::common::{HEARTBEAT_DATA, MavMessage};
    use ringswarm_wire::codec::Encoder;

    #[test]
    fn frames_cross_the_pseudo_terminal_both_ways_through_the_linked_path() {
        let dir = std::env::temp_dir().join(format!("ringswarm-pty-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let device = dir.join("ttyTEST0");
        let mut link = PtyLink::open(&device).unwrap();
        assert_eq!(
            std::fs::read_link(&device).unwrap(),
            Path::new(link.far_name())
        );
        let mut port = serialport::new(device.to_string_lossy(), 921_600)
            .timeout(Duration::from_secs(5))
            .open_native()
            .unwrap();
        let mut encoder = Encoder::new(1, 1);
        let frame = encoder.encode(&MavMessage::HEARTBEAT(HEARTBEAT_DATA::default()));
        // Vehicle to coordinator.
        link.send(&frame).unwrap();
        let mut got = vec![0u8; frame.len()];
        port.read_exact(&mut got).unwrap();
        assert_eq!(got, frame);
        // Coordinator to vehicle, behind some noise, in two writes.
        port.write_all(&[0x00, 0x42]).unwrap();
        port.write_all(&frame[..5]).unwrap();
        port.write_all(&frame[5..]).unwrap();
        port.flush().unwrap();
        let mut frames = Vec::new();
        let mut buf = [0u8; 512];
        for _ in 0..500 {
            link.receive(&mut buf, 8, |f| frames.push(f.to_vec()))
                .unwrap();
            if !frames.is_empty() {
                break;
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        assert_eq!(frames, vec![frame]);
        assert_eq!(link.skipped_bytes(), 2);
        drop(link);
        assert!(
            std::fs::symlink_metadata(&device).is_err(),
            "the link is removed"
        );
        // A file that is not a link is never replaced.
        std::fs::write(&device, b"not a tty").unwrap();
        let refused = PtyLink::open(&device).unwrap_err();
        assert!(refused.to_string().contains("is not a link"), "{refused}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
