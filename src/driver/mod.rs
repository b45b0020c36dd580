//! Drivers: what moves bytes and time between the sans-IO machines.
//!
//! - [`lockstep`]: the coordinator and N emulated vehicles in one process, virtual time,
//!   encoded MAVLink frames in between, seeded latency and loss. Deterministic.
//! - [`udp`]: tokio, one socket per vehicle, for real PX4 or `ringswarm sitl` vehicles.

#[cfg(feature = "emulator")]
pub mod lockstep;
pub mod udp;

use ringswarm_wire::time::SimTime;

use crate::swarm::Swarm;

/// What a driver reports while it runs: every datagram (both directions, as sent or as
/// received) and the swarm after every change. A plain `FnMut(&Swarm, SimTime)` closure is
/// an observer of the swarm only.
pub trait Observer {
    /// A datagram to (`to_vehicle`) or from vehicle `vehicle` at `now`.
    fn datagram(&mut self, _now: SimTime, _vehicle: usize, _to_vehicle: bool, _bytes: &[u8]) {}
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
