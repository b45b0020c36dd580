//! Drivers: what moves bytes and time between the sans-IO machines.
//!
//! - [`lockstep`]: the coordinator (or the shards of one swarm, their messages on a
//!   simulated bus) and N emulated vehicles in one process, virtual time, encoded
//!   MAVLink frames in between, seeded latency and loss. Deterministic.
//! - [`udp`]: tokio, a socket per vehicle or per MAVLink network, for real PX4 or
//!   `ringswarm sitl` vehicles.
//! - [`serial`]: a coordinator socket that is a serial port to one vehicle (companion
//!   mode), read and written by threads of its own.
//! - [`mirror`]: every datagram of a UDP flight copied to extra addresses, read-only.
//! - `zenoh_bus` (feature `zenoh`): the messages between shards over a Zenoh peer
//!   session, on a thread of its own.
//! - [`priority`]: the control loop's thread at real-time priority (`fly
//!   --realtime-priority`).
//! - [`listening`]: how far behind its sockets the UDP driver is, so that its own stall
//!   is not taken for vehicles going silent.
//!
//! Both hand received datagrams to the swarm through one `Intake` (router, links,
//! address learning) when they route.

pub mod listening;
#[cfg(feature = "emulator")]
pub mod lockstep;
pub mod mirror;
pub mod priority;
pub mod serial;
pub mod signals;
pub mod udp;
#[cfg(feature = "zenoh")]
pub mod zenoh_bus;

use std::net::SocketAddr;
use std::ops::Range;

use ringswarm_wire::time::SimTime;

use crate::link::router::Router;
use crate::swarm::{Swarm, VehicleIndex};

/// The way in for a received datagram, the same in every driver that routes: the router
/// splits it, each piece goes to its vehicle's link, and a frame a link takes may teach
/// the router the vehicle's address.
pub(crate) struct Intake<'a> {
    pub(crate) swarm: &'a mut Swarm,
    pub(crate) router: &'a mut Router,
    /// Reused: the pieces of one datagram (no allocation per datagram).
    pub(crate) pieces: &'a mut Vec<(VehicleIndex, Range<usize>)>,
}

impl Intake<'_> {
    /// Hands `bytes`, received on `socket` from `from` at `t`, to the swarm.
    pub(crate) fn deliver<O: Observer>(
        &mut self,
        socket: usize,
        from: SocketAddr,
        bytes: &[u8],
        t: SimTime,
        observer: &mut O,
    ) {
        self.router.route_inbound(socket, from, bytes, self.pieces);
        for (i, range) in self.pieces.drain(..) {
            let piece = &bytes[range];
            observer.datagram(t, i, false, piece);
            if self.swarm.handle_datagram(t, i, piece)
                && let Some(learned) = self.router.vouched(i, from, t)
            {
                tracing::info!(
                    vehicle = i.get(),
                    before = ?learned.before,
                    address = %learned.now,
                    "vehicle address learned from its frames"
                );
            }
        }
    }
}

/// What a driver reports while it runs: every datagram (both directions, as sent or as
/// received) and the swarm after every change. A plain `FnMut(&Swarm, SimTime)` closure is
/// an observer of the swarm only.
pub trait Observer {
    /// A datagram to (`to_vehicle`) or from vehicle `vehicle` at `now`.
    fn datagram(
        &mut self,
        _now: SimTime,
        _vehicle: VehicleIndex,
        _to_vehicle: bool,
        _bytes: &[u8],
    ) {
    }
    /// The swarm after the driver handed it something.
    fn swarm(&mut self, _swarm: &Swarm, _now: SimTime) {}
}

impl<F: FnMut(&Swarm, SimTime)> Observer for F {
    fn swarm(&mut self, swarm: &Swarm, now: SimTime) {
        self(swarm, now);
    }
}

/// Observes nothing.
impl Observer for () {}

/// The cores to step emulated vehicles on: the machine's parallelism.
pub fn cores() -> usize {
    std::thread::available_parallelism().map_or(1, usize::from)
}
