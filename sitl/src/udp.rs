//! The tokio UDP driver: one task per vehicle, one socket per link, PX4's port scheme.
//!
//! Vehicle `i` (0-based, system id `i+1`) binds its offboard link on `14580+i` and sends to
//! `14540+i`, and binds its GCS link on `18570+i` and sends to `14550`. Which peer a link
//! answers follows PX4's `mavlink_receiver.cpp` ([`Partner`]): the default address until
//! the first datagram arrives, then that datagram's sender for good (until a restart);
//! datagrams from anyone are still read. Unlike PX4, which latches before parsing, only
//! a datagram with a frame the vehicle admitted (decoded, and signed with the key when one
//! is set) latches: garbage, a forged frame or an unsigned HEARTBEAT never chooses whom a
//! link answers. Faults are injected per link, in both
//! directions, from a seeded RNG: loss, latency with jitter, duplication.
//!
//! Time: the task keeps a simulated clock running at `speed` times real time and calls the
//! machine's `handle_timeout` on a 1 ms tick; datagrams are handed over as they arrive.

use ringswarm_wire::px4;
use std::collections::VecDeque;
use std::io;
use std::net::{IpAddr, SocketAddr};
use std::time::Duration;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use tokio::net::UdpSocket;
use tokio::sync::watch;
use tokio::time::{Instant, MissedTickBehavior};

pub use crate::link_faults::LinkFaults;

use crate::autopilot::{LinkId, Vehicle, VehicleEvent, VehicleStatus};
use crate::keystore::{self, StoredKey};
use crate::time::SimTime;

/// The four addresses of one vehicle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PortPlan {
    /// Where the offboard link listens.
    pub offboard_bind: SocketAddr,
    /// Where it sends until someone talks to it.
    pub offboard_peer: SocketAddr,
    /// Where the GCS link listens.
    pub gcs_bind: SocketAddr,
    /// Where it sends until someone talks to it.
    pub gcs_peer: SocketAddr,
}

/// PX4's SITL ports for vehicle `instance` (0-based) on `host`.
pub fn px4_ports(instance: u16, host: IpAddr) -> PortPlan {
    PortPlan {
        offboard_bind: SocketAddr::new(host, px4::OFFBOARD_LISTEN_PORT + instance),
        offboard_peer: SocketAddr::new(host, px4::OFFBOARD_PEER_PORT + instance),
        gcs_bind: SocketAddr::new(host, px4::GCS_LISTEN_PORT + instance),
        gcs_peer: SocketAddr::new(host, px4::GCS_PEER_PORT),
    }
}

/// Whom a PX4 UDP link sends to. PX4 starts with `127.0.0.1:<remote port>` and, on the
/// first datagram it receives (before it is even parsed), latches that datagram's
/// source address and port as its partner; it never changes it again. Later datagrams
/// from other senders are handled, but answers and telemetry still go to the partner.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Partner {
    addr: SocketAddr,
    latched: bool,
}

impl Partner {
    /// Not latched, sending to `default`.
    pub fn new(default: SocketAddr) -> Self {
        Self {
            addr: default,
            latched: false,
        }
    }

    /// A datagram arrived from `from`.
    pub fn on_datagram(&mut self, from: SocketAddr) {
        if !self.latched {
            self.addr = from;
            self.latched = true;
        }
    }

    /// Where to send.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }
}

/// A simulated clock running `speed` times faster than real time.
#[derive(Debug, Clone, Copy)]
pub struct SimClock {
    start: Instant,
    speed: f64,
}

impl SimClock {
    /// Starts now.
    pub fn new(speed: f64) -> Self {
        Self {
            start: Instant::now(),
            speed,
        }
    }

    /// Simulated time now.
    pub fn now(&self) -> SimTime {
        SimTime::from_secs_f64(self.start.elapsed().as_secs_f64() * self.speed)
    }
}

/// A datagram held back by the latency fault.
struct Delayed {
    due: SimTime,
    link: usize,
    /// The sender of an inbound datagram; `None` for an outbound one.
    from: Option<SocketAddr>,
    bytes: Vec<u8>,
}

/// What a test (or an operator) can do to a running vehicle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum VehicleControl {
    /// Power off: the vehicle stops answering and sending (its sockets stay bound).
    Kill,
    /// Power on again: a fresh boot from the configured start state.
    Restart,
}

/// What one vehicle task needs.
pub struct VehicleTask {
    /// The machine.
    pub vehicle: Vehicle,
    /// Offboard and GCS sockets, already bound.
    pub sockets: [UdpSocket; 2],
    /// Where each link sends until a peer talks to it.
    pub default_peers: [SocketAddr; 2],
    /// Faults per link.
    pub faults: [LinkFaults; 2],
    /// Seed of the fault RNG.
    pub seed: u64,
    /// Kill and restart requests.
    pub control: tokio::sync::mpsc::Receiver<VehicleControl>,
    /// Where the vehicle's signing key is stored (see [`crate::keystore`]); `None` keeps
    /// a key set over the wire only until the process ends.
    pub key_file: Option<std::path::PathBuf>,
}

/// Runs one vehicle until `shutdown` turns true. Publishes its status about ten times a
/// second on `status`.
///
/// # Errors
/// A socket receive error other than a transient one.
pub async fn run_vehicle(
    task: VehicleTask,
    clock: SimClock,
    status: watch::Sender<VehicleStatus>,
    mut shutdown: watch::Receiver<bool>,
) -> io::Result<()> {
    let VehicleTask {
        mut vehicle,
        sockets,
        default_peers,
        faults,
        seed,
        mut control,
        key_file,
    } = task;
    let mut alive = true;
    let mut partners = default_peers.map(Partner::new);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut delayed: VecDeque<Delayed> = VecDeque::new();
    let mut tick = tokio::time::interval(Duration::from_millis(1));
    tick.set_missed_tick_behavior(MissedTickBehavior::Skip);
    let mut buf = [[0u8; 2048]; 2];
    let mut last_status = SimTime::ZERO;
    let sysid = vehicle.system_id();
    loop {
        let [buf0, buf1] = &mut buf;
        tokio::select! {
            changed = shutdown.changed() => {
                if changed.is_err() || *shutdown.borrow() { break; }
            }
            Some(request) = control.recv() => {
                match request {
                    VehicleControl::Kill => {
                        alive = false;
                        store_key(key_file.as_deref(), &vehicle);
                        delayed.clear();
                        while vehicle.poll_transmit().is_some() {}
                        tracing::info!(sysid, "vehicle killed");
                    }
                    VehicleControl::Restart => {
                        alive = true;
                        partners = default_peers.map(Partner::new);
                        vehicle.reboot(clock.now());
                        tracing::info!(sysid, "vehicle restarted");
                    }
                }
            }
            received = sockets[0].recv_from(buf0) => {
                let (n, from) = received?;
                if alive {
                    let datagram = Datagram { link: 0, from, bytes: &buf0[..n] };
                    inbound(&mut vehicle, &clock, datagram, &faults[0], &mut rng, &mut delayed, &mut partners);
                }
            }
            received = sockets[1].recv_from(buf1) => {
                let (n, from) = received?;
                if alive {
                    let datagram = Datagram { link: 1, from, bytes: &buf1[..n] };
                    inbound(&mut vehicle, &clock, datagram, &faults[1], &mut rng, &mut delayed, &mut partners);
                }
            }
            _ = tick.tick(), if alive => {
                let now = clock.now();
                vehicle.handle_timeout(now);
                deliver_delayed(&mut vehicle, now, &mut delayed, &sockets, &mut partners).await;
                if now - last_status >= Duration::from_millis(100) {
                    last_status = now;
                    status.send_replace(vehicle.status());
                }
            }
        }
        while let Some(event) = vehicle.poll_event() {
            if let VehicleEvent::SigningChanged(stored) = event {
                save_key(key_file.as_deref(), sysid, stored.as_ref());
            }
        }
        let now = clock.now();
        while let Some(tx) = vehicle.poll_transmit() {
            let link = tx.link as usize;
            for copy in faults[link].copies(&mut rng) {
                if copy.is_zero() {
                    send(&sockets[link], &tx.bytes, partners[link].addr(), sysid).await;
                } else {
                    delayed.push_back(Delayed {
                        due: now + copy,
                        link,
                        from: None,
                        bytes: tx.bytes.clone(),
                    });
                }
            }
        }
    }
    if alive {
        store_key(key_file.as_deref(), &vehicle);
    }
    Ok(())
}

/// Stores the vehicle's key with its clock as it is now, so that a restart goes on with
/// newer timestamps (PX4 stores the clock only when a key is set).
fn store_key(key_file: Option<&std::path::Path>, vehicle: &Vehicle) {
    if let Some(stored) = vehicle.signing_key() {
        save_key(key_file, vehicle.system_id(), Some(&stored));
    }
}

fn save_key(key_file: Option<&std::path::Path>, sysid: u8, stored: Option<&StoredKey>) {
    let Some(path) = key_file else { return };
    match keystore::save(path, stored) {
        Ok(()) => tracing::info!(sysid, path = %path.display(), "signing key stored"),
        Err(err) => tracing::error!(sysid, %err, "signing key not stored"),
    }
}

/// A datagram received on link `link` from `from`.
struct Datagram<'a> {
    link: usize,
    from: SocketAddr,
    bytes: &'a [u8],
}

/// Hands a datagram to the vehicle (or holds its copies back, under a latency fault);
/// one the vehicle admits latches the link's partner.
fn inbound(
    vehicle: &mut Vehicle,
    clock: &SimClock,
    datagram: Datagram<'_>,
    faults: &LinkFaults,
    rng: &mut ChaCha8Rng,
    delayed: &mut VecDeque<Delayed>,
    partners: &mut [Partner; 2],
) {
    let now = clock.now();
    let Datagram { link, from, bytes } = datagram;
    for delay in faults.copies(rng) {
        if delay.is_zero() {
            if vehicle.handle_datagram(now, link_id(link), bytes) {
                partners[link].on_datagram(from);
            }
        } else {
            delayed.push_back(Delayed {
                due: now + delay,
                link,
                from: Some(from),
                bytes: bytes.to_vec(),
            });
        }
    }
}

async fn deliver_delayed(
    vehicle: &mut Vehicle,
    now: SimTime,
    delayed: &mut VecDeque<Delayed>,
    sockets: &[UdpSocket; 2],
    partners: &mut [Partner; 2],
) {
    let mut i = 0;
    while i < delayed.len() {
        if delayed[i].due > now {
            i += 1;
            continue;
        }
        let Some(d) = delayed.remove(i) else { break };
        match d.from {
            Some(from) => {
                if vehicle.handle_datagram(now, link_id(d.link), &d.bytes) {
                    partners[d.link].on_datagram(from);
                }
            }
            None => {
                let to = partners[d.link].addr();
                send(&sockets[d.link], &d.bytes, to, vehicle.system_id()).await;
            }
        }
    }
}

async fn send(socket: &UdpSocket, bytes: &[u8], to: SocketAddr, sysid: u8) {
    if let Err(err) = socket.send_to(bytes, to).await {
        tracing::debug!(sysid, %to, error = %err, "send failed");
    }
}

fn link_id(index: usize) -> LinkId {
    if index == 0 {
        LinkId::Offboard
    } else {
        LinkId::Gcs
    }
}

/// Binds both sockets of a port plan.
///
/// # Errors
/// The bind error, with the address that is in use.
pub async fn bind(plan: &PortPlan) -> io::Result<[UdpSocket; 2]> {
    let bind_one = |addr: SocketAddr| async move {
        UdpSocket::bind(addr)
            .await
            .map_err(|e| io::Error::new(e.kind(), format!("cannot bind UDP {addr}: {e}")))
    };
    Ok([
        bind_one(plan.offboard_bind).await?,
        bind_one(plan.gcs_bind).await?,
    ])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_first_sender_becomes_the_partner_for_good() {
        let default: SocketAddr = "127.0.0.1:14540".parse().expect("an address");
        let mavsdk: SocketAddr = "127.0.0.1:14540".parse().expect("an address");
        let other: SocketAddr = "127.0.0.1:40001".parse().expect("an address");
        let mut p = Partner::new(default);
        assert_eq!(p.addr(), default);
        p.on_datagram(other);
        assert_eq!(p.addr(), other, "latched on the first datagram");
        p.on_datagram(mavsdk);
        assert_eq!(p.addr(), other, "never changed again");
    }
}
