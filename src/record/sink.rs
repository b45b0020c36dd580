//! Files written by a thread of their own: the control loop appends to in-memory buffers
//! and hands each full one over through a bounded channel, so it never waits for the
//! disk. Emptied buffers come back for reuse (no allocation in steady state).
//!
//! A write error stops the writer; the next hand-over reports it. A disk that falls so
//! far behind that the channel is full is reported too, rather than waited for: recording
//! stops, the flight goes on.

use std::fs::File;
use std::io::{self, Write};
use std::path::PathBuf;
use std::sync::mpsc::{self, Receiver, SyncSender, TrySendError};
use std::thread::JoinHandle;

/// Full buffers that may wait for the writer.
const IN_FLIGHT: usize = 1024;

/// Turns a chunk as it was appended into the bytes written (on the writer's thread).
pub type Transcode = fn(&[u8], &mut Vec<u8>);

/// The files of a run, each with its buffer.
#[derive(Debug)]
pub struct Sinks {
    buffers: Vec<Vec<u8>>,
    chunk_bytes: Vec<usize>,
    tx: Option<SyncSender<(usize, Vec<u8>)>>,
    spare: Receiver<Vec<u8>>,
    writer: Option<JoinHandle<io::Result<()>>>,
}

impl Sinks {
    /// Creates every file (here, so that a bad path is reported at once) and starts the
    /// writer; file `i` is handed over in chunks of about `chunk_bytes`, and turned into
    /// what is written by its transcoder, if it has one, on the writer's thread.
    ///
    /// # Errors
    /// A file that cannot be created, or a thread that cannot be started.
    pub fn create(files: Vec<(PathBuf, usize, Option<Transcode>)>) -> io::Result<Self> {
        let mut opened = Vec::with_capacity(files.len());
        let mut chunk_bytes = Vec::with_capacity(files.len());
        for (path, chunk, transcode) in files {
            opened.push((File::create(&path)?, transcode));
            chunk_bytes.push(chunk.max(1));
        }
        let (tx, rx) = mpsc::sync_channel::<(usize, Vec<u8>)>(IN_FLIGHT);
        let (spare_tx, spare) = mpsc::channel();
        let writer = std::thread::Builder::new()
            .name("run-directory".into())
            .spawn(move || {
                let mut text = Vec::new();
                for (i, mut buf) in rx {
                    match opened.get_mut(i) {
                        Some((file, Some(transcode))) => {
                            text.clear();
                            transcode(&buf, &mut text);
                            file.write_all(&text)?;
                        }
                        Some((file, None)) => file.write_all(&buf)?,
                        None => {}
                    }
                    buf.clear();
                    // The recorder may be gone (finishing): nothing to give back to.
                    let _ = spare_tx.send(buf);
                }
                opened.iter_mut().try_for_each(|(file, _)| file.flush())
            })?;
        Ok(Self {
            buffers: chunk_bytes.iter().map(|c| Vec::with_capacity(*c)).collect(),
            chunk_bytes,
            tx: Some(tx),
            spare,
            writer: Some(writer),
        })
    }

    /// File `i`'s buffer, to append to; call [`Sinks::appended`] after.
    ///
    /// # Panics
    /// Never for an `i` given to [`Sinks::create`]; a wrong index is a programming error.
    pub fn buffer(&mut self, i: usize) -> &mut Vec<u8> {
        &mut self.buffers[i]
    }

    /// Hands file `i`'s buffer to the writer once it holds a chunk.
    ///
    /// # Errors
    /// The writer's error, or the writer too far behind.
    pub fn appended(&mut self, i: usize) -> io::Result<()> {
        if self.buffers[i].len() >= self.chunk_bytes[i] {
            self.hand_over(i)?;
        }
        Ok(())
    }

    fn hand_over(&mut self, i: usize) -> io::Result<()> {
        let fresh = self
            .spare
            .try_recv()
            .unwrap_or_else(|_| Vec::with_capacity(self.chunk_bytes[i]));
        let full = std::mem::replace(&mut self.buffers[i], fresh);
        let Some(tx) = &self.tx else {
            return Err(io::Error::other("the run directory is closed"));
        };
        match tx.try_send((i, full)) {
            Ok(()) => Ok(()),
            Err(TrySendError::Full(_)) => Err(io::Error::other(format!(
                "the disk fell {IN_FLIGHT} chunks behind the flight"
            ))),
            Err(TrySendError::Disconnected(_)) => Err(self.writer_error()),
        }
    }

    /// The writer's own error, once it has stopped.
    fn writer_error(&mut self) -> io::Error {
        self.tx = None;
        match self.writer.take().map(JoinHandle::join) {
            Some(Ok(Err(err))) => err,
            Some(Err(_)) => io::Error::other("the run-directory writer panicked"),
            _ => io::Error::other("the run-directory writer stopped"),
        }
    }

    /// Hands over what is left (waiting for room if need be), waits for the writer and
    /// flushes every file.
    ///
    /// # Errors
    /// The writer's first error.
    pub fn finish(mut self) -> io::Result<()> {
        // The flight is over: waiting for the disk is fine now.
        if let Some(tx) = self.tx.take() {
            for (i, buf) in self.buffers.drain(..).enumerate() {
                if !buf.is_empty() && tx.send((i, buf)).is_err() {
                    break; // the writer stopped: its error is below
                }
            }
        }
        match self.writer.take().map(JoinHandle::join) {
            Some(Ok(result)) => result,
            Some(Err(_)) => Err(io::Error::other("the run-directory writer panicked")),
            None => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn everything_appended_is_in_the_files_in_order() {
        let dir = std::env::temp_dir().join(format!("ringswarm-sink-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let (a, b) = (dir.join("a"), dir.join("b"));
        let mut sinks =
            Sinks::create(vec![(a.clone(), 10, None), (b.clone(), 1000, None)]).unwrap();
        let mut expected_a = Vec::new();
        for k in 0..500u32 {
            let line = format!("{k}\n");
            sinks.buffer(0).extend_from_slice(line.as_bytes());
            expected_a.extend_from_slice(line.as_bytes());
            sinks.appended(0).unwrap();
            sinks.buffer(1).push(b'x');
            sinks.appended(1).unwrap();
        }
        sinks.finish().unwrap();
        assert_eq!(std::fs::read(&a).unwrap(), expected_a);
        assert_eq!(std::fs::read(&b).unwrap(), vec![b'x'; 500]);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_transcoded_file_gets_its_chunks_transcoded_in_order() {
        let dir = std::env::temp_dir().join(format!("ringswarm-sink-t-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("upper");
        let upper: Transcode = |raw, out| out.extend(raw.iter().map(u8::to_ascii_uppercase));
        let mut sinks = Sinks::create(vec![(path.clone(), 7, Some(upper))]).unwrap();
        for k in 0..300u32 {
            sinks
                .buffer(0)
                .extend_from_slice(format!("a{k}\n").as_bytes());
            sinks.appended(0).unwrap();
        }
        sinks.finish().unwrap();
        let expected: String = (0..300).map(|k| format!("A{k}\n")).collect();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), expected);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_file_that_cannot_be_created_is_reported_at_once() {
        let missing = std::env::temp_dir().join("ringswarm-no-such-dir/x/y");
        let err = Sinks::create(vec![(missing, 10, None)]).unwrap_err();
        assert_eq!(err.kind(), io::ErrorKind::NotFound);
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn a_write_error_is_reported_by_a_later_hand_over() {
        // /dev/full takes every open and fails every write with "no space".
        let mut sinks = Sinks::create(vec![("/dev/full".into(), 4, None)]).unwrap();
        // The writer thread fails on its own time: wait for it generously (10 s), not
        // for a number of yields a loaded machine may use up first.
        let mut failed = None;
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(10);
        while std::time::Instant::now() < deadline {
            sinks.buffer(0).extend_from_slice(b"12345678");
            if let Err(err) = sinks.appended(0) {
                failed = Some(err);
                break;
            }
            std::thread::sleep(std::time::Duration::from_millis(1));
        }
        let err = failed.expect("the writer's error came back");
        assert_eq!(err.kind(), io::ErrorKind::StorageFull, "{err}");
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn a_write_error_of_the_last_chunk_is_reported_by_finish() {
        let mut sinks = Sinks::create(vec![("/dev/full".into(), 1 << 20, None)]).unwrap();
        sinks
            .buffer(0)
            .extend_from_slice(b"never handed over before finish");
        sinks.appended(0).unwrap();
        let err = sinks.finish().unwrap_err();
        assert_eq!(err.kind(), io::ErrorKind::StorageFull, "{err}");
    }
}
