//! `ringswarm keygen FILE`: a new MAVLink 2 signing key, written with mode 0600.

/// Writes a new signing key and says where.
///
/// # Errors
/// No randomness from the system, or the file exists or cannot be written.
pub fn run(path: &std::path::Path) -> anyhow::Result<()> {
    let key = ringswarm_wire::signing::SigningKey::generate().map_err(anyhow::Error::msg)?;
    key.write_new(path).map_err(anyhow::Error::msg)?;
    eprintln!(
        "signing key written to {} (mode 0600); keep it secret",
        path.display()
    );
    Ok(())
}
