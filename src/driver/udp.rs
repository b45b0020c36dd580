//! The tokio UDP driver of the swarm: one socket per vehicle (so a reply can never come
//! from, or go to, the wrong vehicle), per-socket receive tasks feeding one channel, and a
//! single task that owns the swarm machine and sleeps until its next deadline.
//!
//! Real PX4 or `ringswarm sitl` vehicle `i` listens on `14580+i` and answers whoever
//! talks to it; the coordinator's socket for vehicle `i` may be bound anywhere
//! (PX4's convention is `14540+i`).

use std::io;
use std::net::SocketAddr;
use std::sync::Arc;

use ringswarm_sitl::time::SimTime;
use tokio::net::UdpSocket;
use tokio::sync::{mpsc, watch};
use tokio::task::JoinSet;
use tokio::time::Instant;

use crate::swarm::Swarm;

/// Largest datagram read.
const MAX_DATAGRAM: usize = 2048;

/// Runs `swarm` over `sockets[i]` ↔ `peers[i]` until `shutdown` turns true; returns the
/// swarm for its final state. `observe` is called after every change, with the swarm and
/// the time since start.
///
/// # Errors
/// A send error other than a transient one, or a receive task's error.
pub async fn run_swarm(
    mut swarm: Swarm,
    sockets: Vec<UdpSocket>,
    peers: Vec<SocketAddr>,
    mut shutdown: watch::Receiver<bool>,
    mut observe: impl FnMut(&Swarm, SimTime),
) -> io::Result<Swarm> {
    let start = Instant::now();
    let now = || SimTime::from_micros(start.elapsed().as_micros() as u64);
    let sockets: Vec<Arc<UdpSocket>> = sockets.into_iter().map(Arc::new).collect();
    let (tx, mut rx) = mpsc::channel::<(usize, Vec<u8>)>(1024);
    let mut receivers = JoinSet::new();
    for (i, socket) in sockets.iter().enumerate() {
        let (socket, tx, peer) = (Arc::clone(socket), tx.clone(), peers[i]);
        receivers.spawn(async move {
            let mut buf = [0u8; MAX_DATAGRAM];
            loop {
                let (n, from) = socket.recv_from(&mut buf).await?;
                if from.ip() != peer.ip() || from.port() != peer.port() {
                    tracing::debug!(vehicle = i, %from, "datagram from an unexpected address ignored");
                    continue;
                }
                if tx.send((i, buf[..n].to_vec())).await.is_err() {
                    return Ok::<(), io::Error>(());
                }
            }
        });
    }
    drop(tx);
    loop {
        let deadline = start + std::time::Duration::from_micros(swarm.poll_timeout().as_micros());
        tokio::select! {
            changed = shutdown.changed() => {
                if changed.is_err() || *shutdown.borrow() { break; }
            }
            received = rx.recv() => match received {
                Some((i, bytes)) => swarm.handle_datagram(now(), i, &bytes),
                None => break,
            },
            _ = tokio::time::sleep_until(deadline) => swarm.handle_timeout(now()),
        }
        while let Some((i, bytes)) = swarm.poll_transmit() {
            if let Err(err) = sockets[i].send_to(&bytes, peers[i]).await {
                tracing::warn!(vehicle = i, error = %err, "send failed");
            }
        }
        observe(&swarm, now());
    }
    receivers.abort_all();
    while let Some(joined) = receivers.join_next().await {
        if let Ok(Err(err)) = joined {
            return Err(err);
        }
    }
    Ok(swarm)
}
