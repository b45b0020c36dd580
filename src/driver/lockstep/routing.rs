//! Datagrams of the lockstep driver through the same [`Router`] as over UDP, between
//! virtual addresses: each vehicle sits at its route's address (or a unique one in
//! 10.0.0.0/8) and sends to its route's socket.

use std::collections::HashMap;
use std::net::{IpAddr, SocketAddr};
use std::ops::Range;

use crate::link::router::{Router, TransportLayout};
use crate::swarm::VehicleIndex;

/// The router and the vehicles' virtual addresses.
#[derive(Debug)]
pub(super) struct Routing {
    pub(super) router: Router,
    /// Vehicle `j`'s address.
    pub(super) addresses: Vec<SocketAddr>,
    /// And back.
    vehicle_at: HashMap<SocketAddr, usize>,
    /// Whether every vehicle has an address of its own.
    unique: bool,
    /// The coordinator socket vehicle `j` sends to.
    pub(super) socket_of: Vec<usize>,
    /// Reused: the pieces of one datagram.
    pub(super) pieces: Vec<(VehicleIndex, Range<usize>)>,
}

impl Routing {
    /// Vehicle `j` at its route's address, or at a unique virtual one.
    pub(super) fn new(plan: &TransportLayout) -> Self {
        let addresses: Vec<SocketAddr> = plan
            .routes
            .iter()
            .enumerate()
            .map(|(j, r)| {
                r.address.unwrap_or_else(|| {
                    let [_, a, b, c] = (j as u32).to_be_bytes();
                    SocketAddr::new(IpAddr::from([10, a, b, c]), 14580)
                })
            })
            .collect();
        let vehicle_at: HashMap<SocketAddr, usize> =
            addresses.iter().enumerate().map(|(j, a)| (*a, j)).collect();
        Self {
            router: Router::new(plan),
            unique: vehicle_at.len() == addresses.len(),
            vehicle_at,
            addresses,
            socket_of: plan.routes.iter().map(|r| r.socket).collect(),
            pieces: Vec::new(),
        }
    }

    /// The vehicle a datagram for link `i` reaches, if the router has an address for it.
    pub(super) fn vehicle_reached_by(&self, i: VehicleIndex) -> Option<usize> {
        let (_, to) = self.router.destination(i)?;
        // Link i usually reaches vehicle i: checked before the map, which is hashed on
        // every datagram the coordinator sends (when no two vehicles share an address).
        if self.unique && self.addresses.get(i.get()) == Some(&to) {
            return Some(i.get());
        }
        self.vehicle_at.get(&to).copied()
    }
}
