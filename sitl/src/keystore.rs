//! Where a vehicle keeps its MAVLink signing key across restarts, in PX4's format: the
//! 32-byte key followed by the 8-byte little-endian timestamp, in
//! `<state dir>/vehicle-<system id>/mavlink/mavlink-signing-key.bin`, mode 0600 (PX4 keeps
//! `mavlink/mavlink-signing-key.bin` under each instance's root). An all-zero key with
//! timestamp 0 means "no key".

use std::io::Write;
use std::path::{Path, PathBuf};

use ringswarm_wire::signing::SigningKey;

/// A key and the timestamp to sign with after a restart.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StoredKey {
    /// The key.
    pub key: SigningKey,
    /// The signing timestamp (10 µs units since 2015).
    pub timestamp: u64,
}

/// Length of PX4's key file.
const FILE_LEN: usize = 40;

/// The key file of vehicle `label` under `state_dir`: its system id, or
/// `<network>-<system id>` where networks repeat ids.
pub fn key_path(state_dir: &Path, label: &str) -> PathBuf {
    state_dir
        .join(format!("vehicle-{label}"))
        .join("mavlink")
        .join("mavlink-signing-key.bin")
}

/// Reads a key file: `None` when there is none, or it holds PX4's "no key".
///
/// # Errors
/// An unreadable file, or one that is not 40 bytes, naming the file.
pub fn load(path: &Path) -> Result<Option<StoredKey>, String> {
    let bytes = match std::fs::read(path) {
        Ok(bytes) => bytes,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(format!("signing key store {}: {e}", path.display())),
    };
    if bytes.len() != FILE_LEN {
        return Err(format!(
            "signing key store {}: {} bytes, expected {FILE_LEN} (32-byte key, 8-byte timestamp)",
            path.display(),
            bytes.len()
        ));
    }
    let mut key = [0u8; 32];
    key.copy_from_slice(&bytes[..32]);
    let mut timestamp = [0u8; 8];
    timestamp.copy_from_slice(&bytes[32..]);
    let stored = StoredKey {
        key: SigningKey::from_bytes(key),
        timestamp: u64::from_le_bytes(timestamp),
    };
    Ok((stored.timestamp != 0 || !stored.key.is_blank()).then_some(stored))
}

/// Writes a key file (PX4's "no key" for `None`), creating its directory; mode 0600.
///
/// # Errors
/// The directory or the file cannot be written, naming the path.
pub fn save(path: &Path, stored: Option<&StoredKey>) -> Result<(), String> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|e| format!("create {}: {e}", dir.display()))?;
    }
    let mut bytes = [0u8; FILE_LEN];
    if let Some(s) = stored {
        bytes[..32].copy_from_slice(s.key.bytes());
        bytes[32..].copy_from_slice(&s.timestamp.to_le_bytes());
    }
    let mut options = std::fs::OpenOptions::new();
    options.write(true).create(true).truncate(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.mode(0o600);
    }
    options
        .open(path)
        .and_then(|mut f| f.write_all(&bytes).and_then(|()| f.sync_all()))
        .map_err(|e| format!("write {}: {e}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_key_round_trips_in_px4s_40_byte_format_and_blank_means_none() {
        let dir = std::env::temp_dir().join(format!("ringswarm-keystore-{}", std::process::id()));
        let path = key_path(&dir, "7");
        assert!(path.ends_with("vehicle-7/mavlink/mavlink-signing-key.bin"));
        assert_eq!(load(&path), Ok(None), "no file, no key");
        let stored = StoredKey {
            key: SigningKey::from_bytes([0xAB; 32]),
            timestamp: 0x0102_0304_0506,
        };
        save(&path, Some(&stored)).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(bytes.len(), 40);
        assert_eq!(
            &bytes[32..],
            &[6, 5, 4, 3, 2, 1, 0, 0],
            "timestamp little-endian"
        );
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let mode = std::fs::metadata(&path).unwrap().permissions().mode();
            assert_eq!(mode & 0o777, 0o600);
        }
        assert_eq!(load(&path), Ok(Some(stored)));
        save(&path, None).unwrap();
        assert_eq!(load(&path), Ok(None), "PX4's all-zero file is no key");
        std::fs::write(&path, [1u8; 12]).unwrap();
        assert!(load(&path).unwrap_err().contains("12 bytes, expected 40"));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
