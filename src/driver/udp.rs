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

use ringswarm_wire::time::SimTime;
use tokio::net::UdpSocket;
use tokio::sync::{mpsc, watch};
use tokio::task::JoinSet;
use tokio::time::Instant;

use super::Observer;
use crate::swarm::Swarm;

/// What the owner of a running swarm asks of it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DriverCommand {
    /// Keep flying.
    #[default]
    Fly,
    /// Land every vehicle (Ctrl-C); the driver returns once they are all disarmed.
    Land,
    /// Return at once (a second Ctrl-C, or a test that is done).
    Stop,
}

/// Largest datagram read.
const MAX_DATAGRAM: usize = 2048;

/// Runs `swarm` over `sockets[i]` ↔ `peers[i]` until the swarm has landed every vehicle,
/// or `commands` says [`DriverCommand::Stop`]; returns the swarm and the observer. The
/// observer sees every datagram and the swarm after every change, with the time since
/// start.
///
/// # Errors
/// A receive task's error (send errors are logged: a vehicle may be unreachable for a
/// while).
pub async fn run_swarm<O: Observer>(
    mut swarm: Swarm,
    sockets: Vec<UdpSocket>,
    peers: Vec<SocketAddr>,
    mut commands: watch::Receiver<DriverCommand>,
    mut observer: O,
) -> io::Result<(Swarm, O)> {
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
            changed = commands.changed() => {
                let command = if changed.is_err() { DriverCommand::Stop } else { *commands.borrow() };
                match command {
                    DriverCommand::Fly => {}
                    DriverCommand::Land => swarm.land(now()),
                    DriverCommand::Stop => break,
                }
            }
            received = rx.recv() => match received {
                Some((i, bytes)) => {
                    let t = now();
                    observer.datagram(t, i, false, &bytes);
                    swarm.handle_datagram(t, i, &bytes);
                }
                None => break,
            },
            _ = tokio::time::sleep_until(deadline) => swarm.handle_timeout(now()),
        }
        while let Some((i, bytes)) = swarm.poll_transmit() {
            observer.datagram(now(), i, true, &bytes);
            if let Err(err) = sockets[i].send_to(&bytes, peers[i]).await {
                tracing::warn!(vehicle = i, error = %err, "send failed");
            }
        }
        observer.swarm(&swarm, now());
        if swarm.is_finished() {
            break;
        }
    }
    receivers.abort_all();
    while let Some(joined) = receivers.join_next().await {
        if let Ok(Err(err)) = joined {
            return Err(err);
        }
    }
    Ok((swarm, observer))
}
