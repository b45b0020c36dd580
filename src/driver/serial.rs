//! A coordinator "socket" that is a serial port: companion mode, a shard on the vehicle's
//! own computer with a cable to the flight controller's TELEM port.
//!
//! A serial port is a byte stream to one vehicle. A reader thread frames it
//! ([`StreamFramer`]: noise and a start mid-frame are skipped) and hands whole frames on
//! as if each were a datagram from [`SERIAL_PEER`]; a writer thread takes frames from a
//! bounded queue, so that a line slower than the control loop (a 57 600 baud radio)
//! drops frames, counted, and never holds a tick back. Both are plain threads: a
//! blocking port read is what the serial crate offers, and the control loop stays on its
//! own thread.

use std::io::{self, Read, Write};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{self, SyncSender, TrySendError};
use std::time::Duration;

use ringswarm_wire::stream::StreamFramer;
use serialport::TTYPort;

/// How long a read waits before the reader looks whether the flight is over.
const READ_TIMEOUT: Duration = Duration::from_millis(100);

/// Frames queued for the line: a quarter second of a 50 Hz setpoint stream and its
/// commands. A fuller queue means the line is slower than the traffic.
const WRITE_QUEUE: usize = 64;

/// An open serial port, not yet running.
pub struct SerialLine {
    port: TTYPort,
    device: String,
}

impl std::fmt::Debug for SerialLine {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "serial {}", self.device)
    }
}

impl SerialLine {
    /// Opens `device` at `baud`, raw, 8N1, no flow control.
    ///
    /// # Errors
    /// The device cannot be opened or set up, with its path in the message.
    pub fn open(device: &str, baud: u32) -> io::Result<Self> {
        let port = serialport::new(device, baud)
            .timeout(READ_TIMEOUT)
            .open_native()
            .map_err(|e| {
                io::Error::other(format!("open serial port {device} at {baud} baud: {e}"))
            })?;
        Ok(Self {
            port,
            device: device.to_owned(),
        })
    }

    /// Starts the reader and the writer. The reader hands each batch of whole frames to
    /// `deliver`, and stops when `deliver` says the flight is over (returns `false`) or
    /// the port fails.
    ///
    /// # Errors
    /// The port cannot be shared between the two threads.
    pub fn spawn(
        self,
        mut deliver: impl FnMut(&mut Vec<Vec<u8>>) -> bool + Send + 'static,
    ) -> io::Result<SerialWriter> {
        let mut writer_port = self
            .port
            .try_clone_native()
            .map_err(|e| io::Error::other(format!("serial port {}: {e}", self.device)))?;
        let (queue, frames) = mpsc::sync_channel::<Vec<u8>>(WRITE_QUEUE);
        let device = self.device.clone();
        let failed = Arc::new(AtomicU64::new(0));
        let write_failures = Arc::clone(&failed);
        std::thread::Builder::new()
            .name("serial-writer".into())
            .spawn(move || {
                for frame in frames {
                    if let Err(e) = writer_port.write_all(&frame)
                        && write_failures.fetch_add(1, Ordering::Relaxed) == 0
                    {
                        tracing::warn!(device, error = %e, "serial write failed");
                    }
                }
            })?;
        let mut port = self.port;
        let device = self.device.clone();
        std::thread::Builder::new()
            .name("serial-reader".into())
            .spawn(move || {
                let mut framer = StreamFramer::new();
                let mut buf = [0u8; 1024];
                let mut batch: Vec<Vec<u8>> = Vec::new();
                loop {
                    match port.read(&mut buf) {
                        Ok(0) => {}
                        Ok(n) => {
                            framer.push(&buf[..n]);
                            while let Some(frame) = framer.next_frame() {
                                batch.push(frame.to_vec());
                            }
                        }
                        Err(e) if e.kind() == io::ErrorKind::TimedOut => {}
                        Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                        Err(e) => {
                            tracing::warn!(device, error = %e, "serial read failed: the vehicle's link is lost");
                            return;
                        }
                    }
                    // An empty batch too: the reader learns that the flight is over.
                    if !deliver(&mut batch) {
                        return;
                    }
                    batch.clear();
                }
            })?;
        Ok(SerialWriter {
            queue,
            dropped: 0,
            failed,
            device: self.device,
        })
    }
}

/// The sending side of a running serial port.
pub struct SerialWriter {
    queue: SyncSender<Vec<u8>>,
    dropped: u64,
    failed: Arc<AtomicU64>,
    device: String,
}

impl SerialWriter {
    /// Queues one frame without waiting; a full queue drops it (counted).
    pub fn send(&mut self, bytes: &[u8]) {
        match self.queue.try_send(bytes.to_vec()) {
            Ok(()) => {}
            Err(TrySendError::Full(_)) => {
                if self.dropped == 0 {
                    tracing::warn!(
                        device = self.device,
                        "serial line slower than the traffic: frames dropped (is the baud rate right?)"
                    );
                }
                self.dropped += 1;
            }
            Err(TrySendError::Disconnected(_)) => self.dropped += 1,
        }
    }

    /// Frames dropped: the queue was full or the writer had stopped.
    pub fn dropped(&self) -> u64 {
        self.dropped
    }

    /// Frames the port refused.
    pub fn failed(&self) -> u64 {
        self.failed.load(Ordering::Relaxed)
    }
}
