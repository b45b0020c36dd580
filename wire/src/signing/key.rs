//! MAVLink 2 signing keys and key files.
//!
//! A key file holds the 32-byte secret as 64 hexadecimal characters and a newline. It is
//! created with mode 0600 (owner read/write only) and never overwritten: losing a key
//! that vehicles were provisioned with locks them out of a ground station that signs.

use std::fs::OpenOptions;
use std::io::Write;
use std::path::Path;

use rand::TryRngCore;
use rand::rngs::OsRng;

/// A 32-byte MAVLink 2 signing key.
#[derive(Clone, PartialEq, Eq)]
pub struct SigningKey([u8; 32]);

impl std::fmt::Debug for SigningKey {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // Never print the secret.
        f.write_str("SigningKey(…)")
    }
}

impl SigningKey {
    /// A fresh key from the operating system's random source.
    ///
    /// # Errors
    /// The random source failing.
    pub fn generate() -> Result<Self, String> {
        let mut key = [0u8; 32];
        OsRng
            .try_fill_bytes(&mut key)
            .map_err(|e| format!("the system's random source failed: {e}"))?;
        Ok(Self(key))
    }

    /// A key from its 32 bytes.
    pub fn from_bytes(bytes: [u8; 32]) -> Self {
        Self(bytes)
    }

    /// Whether every byte is zero (PX4's "no key").
    pub fn is_blank(&self) -> bool {
        self.0 == [0; 32]
    }

    /// The key's bytes.
    pub fn bytes(&self) -> &[u8; 32] {
        &self.0
    }

    /// The key as 64 lower-case hexadecimal characters.
    pub fn to_hex(&self) -> String {
        self.0.iter().map(|b| format!("{b:02x}")).collect()
    }

    /// A key from 64 hexadecimal characters (surrounding whitespace ignored).
    ///
    /// # Errors
    /// Anything but 64 hexadecimal characters, named.
    pub fn from_hex(text: &str) -> Result<Self, String> {
        let t = text.trim();
        if t.len() != 64 || !t.is_ascii() {
            return Err(format!(
                "a signing key is 64 hexadecimal characters (32 bytes), got {} characters",
                t.chars().count()
            ));
        }
        let mut key = [0u8; 32];
        for (i, byte) in key.iter_mut().enumerate() {
            *byte = u8::from_str_radix(&t[2 * i..2 * i + 2], 16).map_err(|_| {
                format!(
                    "a signing key is 64 hexadecimal characters: \"{}\" at position {} is not",
                    &t[2 * i..2 * i + 2],
                    2 * i
                )
            })?;
        }
        Ok(Self(key))
    }

    /// Reads a key file.
    ///
    /// # Errors
    /// An unreadable file or one that is not a key, naming the file.
    pub fn read(path: &Path) -> Result<Self, String> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| format!("signing key {}: {e}", path.display()))?;
        Self::from_hex(&text).map_err(|e| format!("signing key {}: {e}", path.display()))
    }

    /// Writes the key to a new file, mode 0600; an existing file is never overwritten.
    ///
    /// # Errors
    /// The file exists (refused), or cannot be created or written.
    pub fn write_new(&self, path: &Path) -> Result<(), String> {
        let mut options = OpenOptions::new();
        options.write(true).create_new(true);
        #[cfg(unix)]
        {
            use std::os::unix::fs::OpenOptionsExt;
            options.mode(0o600);
        }
        let mut file = options.open(path).map_err(|e| {
            if e.kind() == std::io::ErrorKind::AlreadyExists {
                format!(
                    "{} exists: a key is never overwritten (vehicles provisioned with it would be locked out)",
                    path.display()
                )
            } else {
                format!("create {}: {e}", path.display())
            }
        })?;
        writeln!(file, "{}", self.to_hex())
            .and_then(|()| file.sync_all())
            .map_err(|e| format!("write {}: {e}", path.display()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hex_round_trips_and_bad_text_is_named() {
        let key = SigningKey::generate().unwrap();
        assert_eq!(SigningKey::from_hex(&key.to_hex()).unwrap(), key);
        assert_eq!(key.to_hex().len(), 64);
        assert!(
            SigningKey::from_hex("abc")
                .unwrap_err()
                .contains("got 3 characters")
        );
        let bad = format!("zz{}", "0".repeat(62));
        assert!(
            SigningKey::from_hex(&bad)
                .unwrap_err()
                .contains("\"zz\" at position 0")
        );
        assert_eq!(format!("{key:?}"), "SigningKey(…)");
        assert_ne!(
            SigningKey::generate().unwrap(),
            key,
            "two keys are never the same"
        );
    }
}
