//! The coordinator's MAVLink 2 signing at its I/O edge: the key file of `[security]`, and
//! the signing clock kept across restarts.
//!
//! Frames are stamped from the wall clock (10 µs units since 2015), and a vehicle refuses
//! any frame not newer than the last it accepted from us. So that a restart, or a wall
//! clock set back, never stamps below what was already sent, the clock's high-water mark
//! is kept in `<key file>.timestamp`: at start the clock begins at the later of the wall
//! clock and that mark, and the mark is kept [`RESERVE`] ahead of the newest stamp used
//! (written at start, then whenever the stamps get within half of it). A crash between
//! two writes therefore never lets a stamp repeat, as PX4 and ArduPilot keep theirs.

use std::path::{Path, PathBuf};

use ringswarm_wire::signing::{SigningKey, TIMESTAMP_UNITS_PER_S, timestamp_now};

use crate::vehicle::{LinkConfig, LinkSigning};

/// How far ahead of the newest stamp the stored mark is kept: ten seconds (`fly` checks
/// every second and writes once half of it is used). A restart at once starts at most
/// this far ahead of the wall clock: well inside the minute by which a vehicle's first
/// frames, stamped from its own clock, may lag ours before we would call them stale.
pub const RESERVE: u64 = 10 * TIMESTAMP_UNITS_PER_S;

/// The stored high-water mark of the signing clock.
#[derive(Debug, Clone)]
pub struct TimestampStore {
    path: PathBuf,
    mark: u64,
}

impl TimestampStore {
    /// The store beside `key_file` (`<key file>.timestamp`); nothing is read yet.
    pub fn beside(key_file: &Path) -> Self {
        let mut name = key_file.as_os_str().to_owned();
        name.push(".timestamp");
        Self {
            path: PathBuf::from(name),
            mark: 0,
        }
    }

    /// The file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The stamp to start from: the later of the wall clock and the stored mark. Writes
    /// the new mark.
    ///
    /// # Errors
    /// A store that is not a number, or cannot be written, naming the file.
    pub fn start(&mut self) -> Result<u64, String> {
        self.start_at(timestamp_now())
    }

    /// [`TimestampStore::start`] with the wall clock given.
    ///
    /// # Errors
    /// As [`TimestampStore::start`].
    pub fn start_at(&mut self, wall: u64) -> Result<u64, String> {
        let stored = match std::fs::read_to_string(&self.path) {
            Ok(text) => text.trim().parse::<u64>().map_err(|_| {
                format!(
                    "{}: a signing timestamp is a whole number, got \"{}\"",
                    self.path.display(),
                    text.trim()
                )
            })?,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => 0,
            Err(e) => return Err(format!("{}: {e}", self.path.display())),
        };
        let start = wall.max(stored);
        self.write(start + RESERVE)?;
        Ok(start)
    }

    /// Keeps the mark ahead of `newest`, the newest stamp used: writes when `newest` is
    /// within half the reserve of the mark.
    ///
    /// # Errors
    /// The store cannot be written.
    pub fn keep_ahead(&mut self, newest: u64) -> Result<(), String> {
        if newest + RESERVE / 2 >= self.mark {
            self.write(newest + RESERVE)?;
        }
        Ok(())
    }

    fn write(&mut self, mark: u64) -> Result<(), String> {
        let tmp = self.path.with_extension("timestamp.tmp");
        std::fs::write(&tmp, format!("{mark}\n"))
            .and_then(|()| std::fs::rename(&tmp, &self.path))
            .map_err(|e| format!("write {}: {e}", self.path.display()))?;
        self.mark = mark;
        Ok(())
    }
}

/// Signing set up for a flight: the key, read, and the clock, started.
#[derive(Debug)]
pub struct FlightSigning {
    /// The key.
    pub key: SigningKey,
    /// The clock's store.
    pub store: TimestampStore,
    /// The stamp at the flight's time zero.
    pub start: u64,
}

impl FlightSigning {
    /// Reads `key_file` and starts its clock.
    ///
    /// # Errors
    /// An unreadable key or timestamp store, named.
    pub fn open(key_file: &Path) -> Result<Self, String> {
        let key = SigningKey::read(key_file)?;
        let mut store = TimestampStore::beside(key_file);
        let start = store.start()?;
        Ok(Self { key, store, start })
    }

    /// Signs every link with this key and clock (see [`sign_links`]).
    pub fn apply(&self, links: &mut [LinkConfig]) {
        sign_links(links, &self.key, self.start);
    }
}

/// Signs every link with `key`, stamping from `timestamp_at_zero` at time zero: link `i`
/// gets link id `i mod 256` (each vehicle keeps its own streams, so ids need only differ
/// among one vehicle's peers).
pub fn sign_links(links: &mut [LinkConfig], key: &SigningKey, timestamp_at_zero: u64) {
    for (i, link) in links.iter_mut().enumerate() {
        link.signing = Some(LinkSigning {
            key: key.clone(),
            link_id: (i % 256) as u8,
            timestamp_at_zero,
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_clock_never_goes_back_across_restarts_or_a_clock_set_back() {
        let dir = std::env::temp_dir().join(format!("ringswarm-ts-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let key = dir.join("key.hex");
        let mut store = TimestampStore::beside(&key);
        assert!(store.path().ends_with("key.hex.timestamp"));
        assert_eq!(
            store.start_at(1_000_000).unwrap(),
            1_000_000,
            "no store: the wall clock"
        );
        let stored: u64 = std::fs::read_to_string(store.path())
            .unwrap()
            .trim()
            .parse()
            .unwrap();
        assert_eq!(stored, 1_000_000 + RESERVE, "the mark is reserved ahead");
        // Stamps used up to just below half the reserve: no write; at half: a write.
        store.keep_ahead(1_000_000 + RESERVE / 2 - 1).unwrap();
        assert_eq!(store.mark, 1_000_000 + RESERVE);
        store.keep_ahead(1_000_000 + RESERVE / 2).unwrap();
        assert_eq!(store.mark, 1_000_000 + RESERVE / 2 + RESERVE);
        // A restart with the wall clock set back starts above every stamp used.
        let mut again = TimestampStore::beside(&key);
        let start = again.start_at(5).unwrap();
        assert_eq!(start, 1_000_000 + RESERVE / 2 + RESERVE);
        // A wall clock ahead of the mark wins.
        let mut later = TimestampStore::beside(&key);
        assert_eq!(
            later.start_at(u64::from(u32::MAX) * 1000).unwrap(),
            u64::from(u32::MAX) * 1000
        );
        std::fs::write(later.path(), "soon\n").unwrap();
        let err = TimestampStore::beside(&key).start_at(0).unwrap_err();
        assert!(err.contains("whole number, got \"soon\""), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
