//! `ringswarm sign-setup --config F`: give every vehicle of a coordinator config the key
//! of its `[security] signing_key_file` with SETUP_SIGNING over its link, and say which
//! took it. An I/O edge around [`crate::link::provision::Provision`].

use std::net::UdpSocket;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use ringswarm_wire::time::SimTime;

use crate::cli::SignSetupArgs;
use crate::config::Config;
use crate::link::provision::{Provision, ProvisionState};
use crate::security::FlightSigning;

/// Provisions every vehicle; an error names those that did not take the key.
///
/// # Errors
/// A config without `[security] signing_key_file`, an unreadable key, a port in use, or
/// a vehicle that refused or never answered.
pub fn run(args: &SignSetupArgs) -> anyhow::Result<()> {
    let text = std::fs::read_to_string(&args.config)
        .with_context(|| format!("read {}", args.config.display()))?;
    let config =
        Config::from_toml(&text).map_err(|e| anyhow::anyhow!("{}:\n{e}", args.config.display()))?;
    let Some(key_file) = &config.security.signing_key_file else {
        bail!(
            "{}: no [security] signing_key_file: which key should the vehicles get?",
            args.config.display()
        );
    };
    let signing = FlightSigning::open(key_file).map_err(anyhow::Error::msg)?;
    let own_ids = (config.swarm.gcs_system_id, config.swarm.gcs_component_id);
    let endpoints = config.all_udp_endpoints().map_err(anyhow::Error::msg)?;
    let mut links = Vec::new();
    for ((peer, bind), vehicle) in endpoints.into_iter().zip(&config.vehicle) {
        let socket = UdpSocket::bind(bind)
            .with_context(|| format!("bind {bind} for vehicle {}", vehicle.system_id))?;
        socket
            .set_nonblocking(true)
            .context("a non-blocking socket")?;
        let provision = Provision::new(
            vehicle.system_id,
            signing.key.clone(),
            signing.start,
            own_ids,
        );
        links.push((vehicle.system_id, socket, peer, provision));
    }
    let start = Instant::now();
    let mut buf = [0u8; 2048];
    while links
        .iter()
        .any(|(_, _, _, p)| p.state() == &ProvisionState::Pending)
    {
        let now = SimTime::from_micros(start.elapsed().as_micros() as u64);
        for (_, socket, peer, p) in &mut links {
            p.handle_timeout(now);
            while let Some(bytes) = p.poll_transmit() {
                if let Err(e) = socket.send_to(&bytes, *peer) {
                    tracing::warn!(%peer, error = %e, "send failed");
                }
            }
            while let Ok((n, from)) = socket.recv_from(&mut buf) {
                if from == *peer {
                    p.handle_datagram(&buf[..n]);
                }
            }
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    let mut failed = Vec::new();
    for (system_id, _, peer, p) in &links {
        match p.state() {
            ProvisionState::Provisioned => {
                println!("vehicle {system_id} ({peer}): key taken, its frames are signed with it");
            }
            ProvisionState::Refused(why) => failed.push(format!("vehicle {system_id}: {why}")),
            _ => failed.push(format!(
                "vehicle {system_id} ({peer}): no frame signed with the key after {} attempts \
                 (not running, or holding another key?)",
                crate::link::provision::ATTEMPTS
            )),
        }
    }
    if !failed.is_empty() {
        bail!("not provisioned:\n  {}", failed.join("\n  "));
    }
    Ok(())
}
