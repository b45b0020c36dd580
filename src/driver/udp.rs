//! The tokio UDP driver of the swarm: the coordinator's sockets (one per vehicle in PX4
//! SITL's layout, one per MAVLink network otherwise), a receive task per socket feeding
//! one channel, and a single task that owns the swarm machine and sleeps until its next
//! deadline. Which vehicle a datagram is for, and where a vehicle's datagrams go, is the
//! [`Router`]'s business.
//!
//! Real PX4 or `ringswarm sitl` vehicle `i` listens on `14580+i` and answers whoever
//! talks to it; on a network it sends to the network's socket from a port of its own.

use std::io;
use std::net::SocketAddr;
use std::sync::Arc;

use ringswarm_wire::time::SimTime;
use tokio::net::UdpSocket;
use tokio::sync::{mpsc, watch};
use tokio::task::JoinSet;
use tokio::time::Instant;

use super::Observer;
use crate::link::router::Router;
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

/// Runs `swarm` over `sockets` (bound as `router`'s plan says) until the swarm has
/// landed every vehicle, or `commands` says [`DriverCommand::Stop`]; returns the swarm
/// and the observer. The observer sees every datagram (a network datagram once per
/// vehicle frame in it) and the swarm after every change, with the time since start.
///
/// # Errors
/// A receive task's error (send errors are logged: a vehicle may be unreachable for a
/// while).
pub async fn run_swarm<O: Observer>(
    mut swarm: Swarm,
    sockets: Vec<UdpSocket>,
    mut router: Router,
    mut commands: watch::Receiver<DriverCommand>,
    mut observer: O,
) -> io::Result<(Swarm, O)> {
    let start = Instant::now();
    let now = || SimTime::from_micros(start.elapsed().as_micros() as u64);
    let sockets: Vec<Arc<UdpSocket>> = sockets.into_iter().map(Arc::new).collect();
    let (tx, mut rx) = mpsc::channel::<(usize, SocketAddr, Vec<u8>)>(1024);
    let mut receivers = JoinSet::new();
    for (s, socket) in sockets.iter().enumerate() {
        let (socket, tx) = (Arc::clone(socket), tx.clone());
        receivers.spawn(async move {
            let mut buf = [0u8; MAX_DATAGRAM];
            loop {
                let (n, from) = socket.recv_from(&mut buf).await?;
                if tx.send((s, from, buf[..n].to_vec())).await.is_err() {
                    return Ok::<(), io::Error>(());
                }
            }
        });
    }
    let mut pieces = Vec::new();
    let mut unsent = vec![0u64; swarm.links().len()];
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
                Some((socket, from, bytes)) => {
                    let t = now();
                    router.route_inbound(socket, from, &bytes, &mut pieces);
                    for (i, range) in pieces.drain(..) {
                        let piece = &bytes[range];
                        observer.datagram(t, i, false, piece);
                        if swarm.handle_datagram(t, i, piece)
                            && let Some(learned) = router.vouched(i, from, t)
                        {
                            tracing::info!(
                                vehicle = i,
                                before = ?learned.before,
                                address = %learned.now,
                                "vehicle address learned from its frames"
                            );
                        }
                    }
                }
                None => break,
            },
            _ = tokio::time::sleep_until(deadline) => swarm.handle_timeout(now()),
        }
        while let Some((i, bytes)) = swarm.poll_transmit() {
            observer.datagram(now(), i, true, &bytes);
            let Some((socket, to)) = router.destination(i) else {
                // A network vehicle not heard from yet: nowhere to send.
                unsent[i] += 1;
                continue;
            };
            if let Err(err) = sockets[socket].send_to(&bytes, to).await {
                tracing::warn!(vehicle = i, error = %err, "send failed");
            }
        }
        observer.swarm(&swarm, now());
        if swarm.is_finished() {
            break;
        }
    }
    for (i, n) in unsent.iter().enumerate().filter(|(_, n)| **n > 0) {
        tracing::info!(
            vehicle = i,
            datagrams = n,
            "not sent: the vehicle's address was not known yet"
        );
    }
    receivers.abort_all();
    while let Some(joined) = receivers.join_next().await {
        if let Ok(Err(err)) = joined {
            return Err(err);
        }
    }
    Ok((swarm, observer))
}
