//! The tokio UDP driver of many vehicles: one task (a worker) steps a whole group of vehicles on a
//! common 1 ms tick and, on the same tick, asks the worker's own readiness poller (mio,
//! outside tokio's reactor, polled without waiting) which sockets have something to read,
//! and reads those. The sockets are not in the reactor, so arriving datagrams never wake
//! the worker's thread (at a thousand vehicles a worker's context switches fell from about
//! ten per tick to four), and there is no task or channel hop per datagram; run one worker
//! per core. A datagram waits at most one tick, as it would for the next 1 ms physics step
//! anyway.
//!
//! Each vehicle has one or two links (offboard and GCS), each its own socket. Which peer
//! a link answers follows PX4's `mavlink_receiver.cpp` ([`Partner`]): the default address
//! until the first datagram arrives, then that datagram's sender for good (until a
//! restart); datagrams from anyone are still read. Unlike PX4, which latches before
//! parsing, only a datagram with a frame the vehicle admitted (decoded, and signed with
//! the key when one is set) latches: garbage, a forged frame or an unsigned HEARTBEAT
//! never chooses whom a link answers. Faults are injected per link, in both directions,
//! from a seeded RNG: loss, latency with jitter, duplication.
//!
//! Sends never wait: a datagram the socket cannot take at once is dropped and counted,
//! as a full UDP buffer drops it anyway.

use std::io;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

use mio::{Events, Interest, Poll, Token};
use tokio::sync::{mpsc, watch};
use tokio::time::MissedTickBehavior;

use crate::autopilot::{LinkId, Vehicle, VehicleConfig, VehicleStatus};
use crate::faulty_line::FaultyLine;
use crate::key_writer::{KeyStore, KeyWriter};
use crate::link_faults::LinkFaults;
use crate::time::SimTime;
use crate::udp::{LinkPort, LinkSocket, Partner, Placement, SimClock};
use crate::world::World;

mod slot;
use slot::{Port, Slot};

/// What a test (or an operator) can do to a running vehicle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum VehicleControl {
    /// Power off: the vehicle stops answering and sending (its sockets stay bound).
    Kill,
    /// Power on again: a fresh boot from the configured start state.
    Restart,
}

/// One vehicle of a worker (a task stepping a group of vehicles).
pub struct FleetVehicle {
    /// The machine.
    pub vehicle: Vehicle,
    /// Its links (one or two).
    pub links: Vec<LinkSocket>,
    /// Seed of its fault RNG.
    pub seed: u64,
    /// Where its signing key is stored (see [`crate::keystore`]); `None` keeps a key set
    /// over the wire only until the process ends.
    pub key_file: Option<PathBuf>,
    /// Where its status is published, about ten times a second.
    pub status: watch::Sender<VehicleStatus>,
}

/// One emulated vehicle to start: how it is built, where it sits on UDP, and where it
/// keeps its signing key (`None`: a key set over the wire lasts until the process ends).
#[derive(Debug, Clone)]
pub struct VehicleSpec {
    /// Its configuration.
    pub config: VehicleConfig,
    /// Its ports and peers.
    pub placement: Placement,
    /// Its key file.
    pub key_file: Option<PathBuf>,
}

/// Builds every vehicle of `specs` in `world` and binds its links with `faults` (vehicle
/// `i`'s fault draws seeded `seed + i`): the one place a fleet is made, for `sitl` and
/// `demo --realtime`. Returns the fleet for [`spawn_workers`] and each vehicle's status.
///
/// # Errors
/// A configuration the emulator refuses, or a port that cannot be bound, naming the
/// vehicle (1-based) and its system id.
pub async fn bind_fleet(
    specs: Vec<VehicleSpec>,
    world: World,
    faults: LinkFaults,
    seed: u64,
) -> Result<(Vec<FleetVehicle>, Vec<watch::Receiver<VehicleStatus>>), String> {
    let mut fleet = Vec::with_capacity(specs.len());
    let mut statuses = Vec::with_capacity(specs.len());
    for (i, spec) in specs.into_iter().enumerate() {
        let system_id = spec.config.system_id;
        let named = |e: String| format!("vehicle {} (system id {system_id}): {e}", i + 1);
        let vehicle = Vehicle::new(spec.config, world).map_err(named)?;
        let links = spec
            .placement
            .bind(faults)
            .await
            .map_err(|e| named(format!("bind its ports: {e}")))?;
        let (status, watching) = watch::channel(vehicle.status());
        statuses.push(watching);
        fleet.push(FleetVehicle {
            vehicle,
            links,
            seed: seed.wrapping_add(i as u64),
            key_file: spec.key_file,
            status,
        });
    }
    Ok((fleet, statuses))
}

/// Largest datagram read.
const MAX_DATAGRAM: usize = 2048;

/// Datagrams read from one socket per tick: a flood on one socket delays only its own
/// vehicle, never the worker's other vehicles (what is left is read at the next tick).
const READS_PER_TICK: usize = 64;

/// Datagrams one vehicle holds back under a latency fault, both ways together: 10 s (the
/// longest latency) of a busy link's traffic. A full line drops, as a router's queue does.
const DELAYED_PER_VEHICLE: usize = 4096;

/// Runs a worker's vehicles, each with its boot offset, until `shutdown` turns true.
/// `controls` carries `(index in vehicles, request)`.
async fn run_fleet(
    vehicles: Vec<(std::time::Duration, FleetVehicle)>,
    clock: SimClock,
    mut controls: mpsc::Receiver<(usize, VehicleControl)>,
    mut shutdown: watch::Receiver<bool>,
    keys: KeyStore,
) {
    let (mut poll, mut events) = match Poll::new() {
        Ok(poll) => (poll, Events::with_capacity(EVENTS_PER_POLL)),
        Err(e) => {
            tracing::error!(error = %e, vehicles = vehicles.len(), "no readiness poller: this worker's vehicles do not run");
            return;
        }
    };
    let mut slots = slots_polled_by(&poll, vehicles, &keys);
    let mut buf = vec![0u8; MAX_DATAGRAM];
    // Sockets to read this tick, and those the read cap or an error left with something
    // to read: read again at the next tick (the poller reports a socket again only when a
    // new datagram arrives). Both kept: no allocation per tick.
    let mut ready: Vec<(usize, usize)> = Vec::new();
    let mut retry: Vec<(usize, usize)> = Vec::new();
    let mut tick = tokio::time::interval(Duration::from_millis(1));
    tick.set_missed_tick_behavior(MissedTickBehavior::Skip);
    let mut last_status = SimTime::ZERO;
    loop {
        tokio::select! {
            changed = shutdown.changed() => {
                if changed.is_err() || *shutdown.borrow() { break; }
            }
            Some((s, request)) = controls.recv() => {
                if let Some(slot) = slots.get_mut(s) {
                    let now = slot.time(clock.now());
                    slot.control(request, now);
                    slot.flush(now);
                }
            }
            _ = tick.tick() => {
                let now = clock.now();
                let publish = now.saturating_since(last_status) >= Duration::from_millis(100);
                if publish {
                    last_status = now;
                }
                step_all(&mut slots, now, publish);
                ready.append(&mut retry);
                receive_ready(&mut poll, &mut events, &mut slots, &mut ready, &mut retry, now, &mut buf);
            }
        }
    }
    for slot in &slots {
        slot.close();
    }
}

/// The worker's vehicles as slots, their sockets registered with `poll` (a vehicle whose
/// sockets cannot be is logged and left out).
fn slots_polled_by(
    poll: &Poll,
    vehicles: Vec<(std::time::Duration, FleetVehicle)>,
    keys: &KeyStore,
) -> Vec<Slot> {
    let mut slots: Vec<Slot> = Vec::with_capacity(vehicles.len());
    for (boot_offset, v) in vehicles {
        let ids: Vec<LinkId> = v.links.iter().map(|l| l.id).collect();
        let defaults: Vec<SocketAddr> = v.links.iter().map(|l| l.default_peer).collect();
        let faults: Vec<LinkFaults> = v.links.iter().map(|l| l.faults).collect();
        let mut vehicle = v.vehicle;
        let sysid = vehicle.system_id();
        let sockets = match polled_sockets(poll, slots.len(), v.links.into_iter().map(|l| l.port)) {
            Ok(sockets) => sockets,
            Err(e) => {
                tracing::error!(sysid, error = %e, "its sockets cannot be polled: the vehicle does not run");
                continue;
            }
        };
        for link in [LinkId::Offboard, LinkId::Gcs] {
            vehicle.set_link_wired(link, ids.contains(&link));
        }
        slots.push(Slot {
            vehicle,
            sockets,
            ids,
            partners: defaults.iter().copied().map(Partner::new).collect(),
            default_peers: defaults,
            faults,
            delayed: FaultyLine::new(DELAYED_PER_VEHICLE, v.seed),
            spare: Vec::new(),
            key_file: v.key_file,
            keys: keys.clone(),
            status: v.status,
            alive: true,
            dropped_sends: 0,
            serial_frames: Vec::new(),
            boot_offset,
        });
    }
    slots
}

/// One tick of every live vehicle: the step first, then what arrived during it (taken
/// at the next step, as the physics would anyway): a vehicle's first frames go out before
/// anything it hears can choose whom it answers. `publish`: its status goes out too.
fn step_all(slots: &mut [Slot], now: SimTime, publish: bool) {
    for slot in slots.iter_mut().filter(|s| s.alive) {
        let now = slot.time(now);
        slot.vehicle.handle_timeout(now);
        slot.deliver_delayed(now);
        slot.flush(now);
        if publish {
            slot.status.send_replace(slot.vehicle.status());
        }
    }
}

/// Readiness events taken per poll (more ready sockets take further polls).
const EVENTS_PER_POLL: usize = 1024;

/// The poller's token of slot `slot`'s link `link` (a vehicle has at most two).
fn token(slot: usize, link: usize) -> Token {
    Token(slot * 2 + link)
}

/// A vehicle's sockets taken out of tokio's reactor (so that no datagram wakes the
/// worker's thread) and registered with the worker's poller instead, under [`token`]s for
/// slot `slot`.
fn polled_sockets(
    poll: &Poll,
    slot: usize,
    ports: impl Iterator<Item = LinkPort>,
) -> io::Result<Vec<Port>> {
    let mut polled = Vec::new();
    for (link, port) in ports.enumerate() {
        match port {
            LinkPort::Udp(socket) => {
                // Non-blocking, as tokio leaves it.
                let mut socket = mio::net::UdpSocket::from_std(socket.into_std()?);
                poll.registry()
                    .register(&mut socket, token(slot, link), Interest::READABLE)?;
                polled.push(Port::Udp(socket));
            }
            LinkPort::Pty(pty) => {
                poll.registry().register(
                    &mut mio::unix::SourceFd(&pty.raw_fd()),
                    token(slot, link),
                    Interest::READABLE,
                )?;
                polled.push(Port::Pty(pty));
            }
        }
    }
    Ok(polled)
}

/// Reads the sockets in `ready` (those the read cap or an error left unread) and every socket the poller
/// reports readable (without waiting); `ready` is left empty, and `retry` holds the
/// sockets left unread this time.
fn receive_ready(
    poll: &mut Poll,
    events: &mut Events,
    slots: &mut [Slot],
    ready: &mut Vec<(usize, usize)>,
    retry: &mut Vec<(usize, usize)>,
    now: SimTime,
    buf: &mut [u8],
) {
    loop {
        if let Err(e) = poll.poll(events, Some(Duration::ZERO)) {
            if e.kind() != io::ErrorKind::Interrupted {
                tracing::warn!(error = %e, "readiness poll failed");
            }
            break;
        }
        let taken = events.iter().count();
        ready.extend(events.iter().map(|e| (e.token().0 / 2, e.token().0 % 2)));
        if taken < EVENTS_PER_POLL {
            break;
        }
    }
    for (s, link) in ready.drain(..) {
        let Some(slot) = slots.get_mut(s) else {
            continue;
        };
        let at = slot.time(now);
        if let Read::More(_) = slot.receive(at, link, buf) {
            retry.push((s, link));
        }
    }
}

/// What one [`Slot::receive`] read: the datagrams taken, and whether the socket is left
/// empty or is to be read again at the next tick.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Read {
    Drained(usize),
    More(usize),
}

/// Running workers: their tasks and, per vehicle in the order given, how to reach it.
pub struct Workers {
    /// One task per worker.
    tasks: Vec<tokio::task::JoinHandle<()>>,
    /// Per vehicle: its worker's control channel and its index there.
    controls: Vec<(mpsc::Sender<(usize, VehicleControl)>, usize)>,
    /// Writes the vehicles' keys.
    keys: KeyWriter,
}

impl Workers {
    /// Sends `request` to vehicle `i` (in the order given to [`spawn_workers`]).
    ///
    /// # Errors
    /// No such vehicle, or its worker has stopped.
    pub async fn control(&self, i: usize, request: VehicleControl) -> Result<(), String> {
        let (tx, at) = self
            .controls
            .get(i)
            .ok_or_else(|| format!("no vehicle {i}"))?;
        tx.send((*at, request))
            .await
            .map_err(|_| "the vehicle's task has stopped".to_owned())
    }

    /// Waits for every worker.
    ///
    /// # Errors
    /// A worker that panicked.
    pub async fn join(self) -> io::Result<()> {
        let mut result = Ok(());
        for task in self.tasks {
            if let Err(e) = task.await {
                result = Err(io::Error::other(e));
            }
        }
        // The workers stored their keys as they stopped; wait until they are on disk.
        let keys = self.keys;
        tokio::task::spawn_blocking(move || keys.finish())
            .await
            .map_err(io::Error::other)?;
        result
    }
}

/// Spreads `vehicles` over `workers` tasks (vehicle `i` in worker `i mod workers`) on the
/// current tokio runtime; one per core keeps every core busy.
pub fn spawn_workers(
    vehicles: Vec<FleetVehicle>,
    workers: usize,
    clock: SimClock,
    shutdown: &watch::Receiver<bool>,
) -> Workers {
    let workers = workers.clamp(1, vehicles.len().max(1));
    let mut fleets: Vec<Vec<(std::time::Duration, FleetVehicle)>> =
        (0..workers).map(|_| Vec::new()).collect();
    let mut placed = Vec::with_capacity(vehicles.len());
    for (i, v) in vehicles.into_iter().enumerate() {
        let worker = i % workers;
        placed.push((worker, fleets[worker].len()));
        fleets[worker].push((spread(i), v));
    }
    let keys = KeyWriter::spawn();
    let mut senders = Vec::new();
    let mut tasks = Vec::new();
    for fleet in fleets {
        let (tx, rx) = mpsc::channel(16);
        senders.push(tx);
        let run = run_fleet(fleet, clock, rx, shutdown.clone(), keys.store());
        tasks.push(tokio::spawn(run));
    }
    Workers {
        keys,
        tasks,
        controls: placed
            .into_iter()
            .map(|(worker, at)| (senders[worker].clone(), at))
            .collect(),
    }
}

/// Vehicle `i`'s boot offset in [0, 1 s): the golden-ratio sequence, so that the phases
/// of every stream period (20 ms … 5 s) are spread evenly over any number of vehicles.
fn spread(i: usize) -> std::time::Duration {
    let golden = 0.618_033_988_749_894_9;
    std::time::Duration::from_micros(((i as f64 * golden).fract() * 1e6) as u64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::autopilot::VehicleConfig;
    use crate::profile::Profile;
    use crate::world::World;

    /// A slot on one loopback socket, and a socket to flood it from.
    fn flooded_slot(datagrams: usize) -> (Slot, std::net::UdpSocket) {
        let socket = mio::net::UdpSocket::bind("127.0.0.1:0".parse().unwrap()).unwrap();
        let at = socket.local_addr().unwrap();
        let vehicle =
            Vehicle::new(VehicleConfig::new(1, Profile::x500()), World::default()).unwrap();
        let (status, _) = watch::channel(vehicle.status());
        let peer: SocketAddr = "127.0.0.1:9".parse().unwrap();
        let slot = Slot {
            vehicle,
            sockets: vec![Port::Udp(socket)],
            ids: vec![LinkId::Offboard],
            default_peers: vec![peer],
            partners: vec![Partner::new(peer)],
            faults: vec![LinkFaults::default()],
            delayed: FaultyLine::new(DELAYED_PER_VEHICLE, 1),
            spare: Vec::new(),
            key_file: None,
            keys: KeyWriter::spawn().store(),
            status,
            alive: true,
            dropped_sends: 0,
            serial_frames: Vec::new(),
            boot_offset: Duration::ZERO,
        };
        let flood = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
        for i in 0..datagrams {
            flood.send_to(&[0xAB, i as u8], at).unwrap();
        }
        (slot, flood)
    }

    #[test]
    fn a_flooded_socket_is_read_at_most_the_cap_per_tick() {
        let (mut slot, _flood) = flooded_slot(150);
        let mut buf = vec![0u8; MAX_DATAGRAM];
        let now = SimTime::from_millis(10);
        assert_eq!(slot.receive(now, 0, &mut buf), Read::More(READS_PER_TICK));
        assert_eq!(slot.receive(now, 0, &mut buf), Read::More(READS_PER_TICK));
        assert_eq!(
            slot.receive(now, 0, &mut buf),
            Read::Drained(150 - 2 * READS_PER_TICK)
        );
        assert_eq!(slot.receive(now, 0, &mut buf), Read::Drained(0));
    }
}
