//! Stores vehicles' signing keys on a thread of its own, so that a slow disk (each file is
//! written with `fsync`) never stalls the worker whose 1 ms tick steps many vehicles. Keys
//! are written in the order they were handed over; [`KeyWriter::finish`] waits for the
//! last one.

use std::path::PathBuf;
use std::sync::mpsc;
use std::thread::JoinHandle;

use crate::keystore::{self, StoredKey};

/// One key to store: where, for which system id, and what (`None`: PX4's "no key").
type Job = (PathBuf, u8, Option<StoredKey>);

/// The writer thread, owned by whoever waits for it at the end.
#[derive(Debug)]
pub struct KeyWriter {
    tx: Option<mpsc::Sender<Job>>,
    thread: Option<JoinHandle<()>>,
}

/// A handle that hands keys to a [`KeyWriter`]; cheap to clone, one per worker.
#[derive(Debug, Clone)]
pub struct KeyStore {
    tx: Option<mpsc::Sender<Job>>,
}

impl KeyWriter {
    /// Starts the writer. Should the thread not start, keys are written where they are
    /// asked for (and that is logged).
    pub fn spawn() -> Self {
        let (tx, rx) = mpsc::channel::<Job>();
        match std::thread::Builder::new()
            .name("key-writer".into())
            .spawn(move || {
                for (path, sysid, stored) in rx {
                    write(&path, sysid, stored.as_ref());
                }
            }) {
            Ok(thread) => Self {
                tx: Some(tx),
                thread: Some(thread),
            },
            Err(e) => {
                tracing::warn!(error = %e, "no key-writer thread: keys are stored on the vehicles' own thread");
                Self {
                    tx: None,
                    thread: None,
                }
            }
        }
    }

    /// A handle for a worker.
    pub fn store(&self) -> KeyStore {
        KeyStore {
            tx: self.tx.clone(),
        }
    }

    /// Waits until every key handed over (by this writer's handles, all dropped by now or
    /// later) is written.
    pub fn finish(mut self) {
        self.tx = None;
        if let Some(thread) = self.thread.take()
            && thread.join().is_err()
        {
            tracing::error!("the key-writer thread panicked: some keys may not be stored");
        }
    }
}

impl KeyStore {
    /// Stores `stored` as vehicle `sysid`'s key at `path`, without waiting.
    pub fn save(&self, path: PathBuf, sysid: u8, stored: Option<StoredKey>) {
        let job = (path, sysid, stored);
        let job = match &self.tx {
            Some(tx) => match tx.send(job) {
                Ok(()) => return,
                Err(mpsc::SendError(job)) => job,
            },
            None => job,
        };
        write(&job.0, job.1, job.2.as_ref());
    }
}

fn write(path: &std::path::Path, sysid: u8, stored: Option<&StoredKey>) {
    match keystore::save(path, stored) {
        Ok(()) => tracing::info!(sysid, path = %path.display(), "signing key stored"),
        Err(err) => tracing::error!(sysid, %err, "signing key not stored"),
    }
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use ringswarm_wire::signing::SigningKey;

    use super::*;

    /// A key file that blocks its writer: a FIFO nobody reads yet (opening one for writing
    /// waits for a reader), as a stalled disk would.
    #[cfg(unix)]
    #[test]
    fn a_stalled_key_file_does_not_stall_the_caller_and_is_written_in_the_end() {
        let dir = std::env::temp_dir().join(format!("ringswarm-keywriter-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("key.bin");
        let _ = std::fs::remove_file(&path);
        let made = std::process::Command::new("mkfifo").arg(&path).status();
        if !made.is_ok_and(|s| s.success()) {
            eprintln!("skipped: mkfifo unavailable");
            return;
        }
        let stored = StoredKey {
            key: SigningKey::from_bytes([7; 32]),
            timestamp: 0x0102_0304_0506,
        };
        let writer = KeyWriter::spawn();
        let store = writer.store();
        let (done_tx, done_rx) = mpsc::channel();
        let (to_store, at) = (stored.clone(), path.clone());
        std::thread::spawn(move || {
            store.save(at, 7, Some(to_store));
            let _ = done_tx.send(());
        });
        let returned = done_rx.recv_timeout(Duration::from_secs(10));
        // Now read the FIFO: this releases the writer whatever happened above.
        let bytes = std::fs::read(&path).unwrap();
        writer.finish();
        let _ = std::fs::remove_dir_all(&dir);
        assert!(returned.is_ok(), "saving a key waited for the disk");
        assert_eq!(bytes.len(), 40);
        assert_eq!(&bytes[..32], &[7; 32]);
        assert_eq!(&bytes[32..], &0x0102_0304_0506_u64.to_le_bytes());
    }
}
