//! `ringswarm sign-setup --config F`: give every vehicle of a coordinator config the key
//! of its `[security] signing_key_file` with SETUP_SIGNING over its link, and say which
//! took it. An I/O edge around [`crate::link::provision::Provision`].

use std::net::UdpSocket;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use ringswarm_wire::time::SimTime;

use crate::cli::SignSetupArgs;
use crate::config::Config;
use crate::index::VehicleIndex;
use crate::link::provision::{Provision, ProvisionState};
use crate::link::router::Router;
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
    let transport = config.transport_layout().map_err(anyhow::Error::msg)?;
    let mut sockets = Vec::new();
    for plan in &transport.sockets {
        let Some(bind) = plan.udp_bind() else {
            bail!(
                "{}: a vehicle is on a serial port; sign-setup sends keys over UDP only \
                 (set the key of a serial vehicle from its own computer)",
                args.config.display()
            );
        };
        let socket = UdpSocket::bind(bind).with_context(|| format!("bind {bind}"))?;
        socket
            .set_nonblocking(true)
            .context("a non-blocking socket")?;
        sockets.push(socket);
    }
    let mut router = Router::new(&transport);
    let mut links: Vec<(u8, Provision)> = config
        .vehicle
        .iter()
        .map(|v| {
            let provision =
                Provision::new(v.system_id, signing.key.clone(), signing.start, own_ids);
            (v.system_id, provision)
        })
        .collect();
    let start = Instant::now();
    let mut buf = [0u8; 2048];
    let mut pieces = Vec::new();
    while links
        .iter()
        .any(|(_, p)| p.state() == &ProvisionState::Pending)
    {
        let now = SimTime::from_micros(start.elapsed().as_micros() as u64);
        for (i, (_, p)) in VehicleIndex::all(links.len()).zip(links.iter_mut()) {
            p.handle_timeout(now);
            while let Some(bytes) = p.poll_transmit() {
                // A network vehicle not heard from yet has no address: its turn comes
                // with the next attempt.
                let Some((s, to)) = router.destination(i) else {
                    continue;
                };
                if let Err(e) = sockets[s].send_to(&bytes, to) {
                    tracing::warn!(%to, error = %e, "send failed");
                }
            }
        }
        for (s, socket) in sockets.iter().enumerate() {
            while let Ok((n, from)) = socket.recv_from(&mut buf) {
                router.route_inbound(s, from, &buf[..n], &mut pieces);
                for (i, range) in pieces.drain(..) {
                    // Before the key is set nothing can vouch for a sender: the first
                    // frame with the vehicle's id tells where it is (this runs before
                    // a flight, on a trusted network). A datagram without one moves
                    // nothing: the key is never sent to whoever spoke first.
                    let piece = &buf[range];
                    let system_id = links[i.get()].0;
                    if crate::link::raw_frames(piece)
                        .any(|f| crate::link::frame_system_id(f) == Some(system_id))
                    {
                        router.vouched(i, from, now);
                    }
                    links[i.get()].1.handle_datagram(piece);
                }
            }
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    let mut failed = Vec::new();
    for (i, (system_id, p)) in VehicleIndex::all(links.len()).zip(&links) {
        let peer = router
            .destination(i)
            .map_or("address never known".to_owned(), |(_, a)| a.to_string());
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
