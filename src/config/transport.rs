//! What a coordinator config means for the transport: each vehicle's UDP endpoints.

use std::net::SocketAddr;

use ringswarm_wire::px4;

use super::Config;

impl Config {
    /// Every vehicle's `(address, bind address)`, in order.
    ///
    /// # Errors
    /// A vehicle whose default port would pass 65535, named.
    pub fn all_udp_endpoints(&self) -> Result<Vec<(SocketAddr, SocketAddr)>, String> {
        (0..self.vehicle.len())
            .map(|i| {
                self.udp_endpoints(i)
                    .ok_or_else(|| format!("vehicle {}: no default port", i + 1))
            })
            .collect()
    }

    /// Vehicle `i`'s address and the coordinator's bind address for it (PX4 SITL
    /// defaults: the vehicle listens on 14580+i and sends to 14540+i).
    pub fn udp_endpoints(&self, i: usize) -> Option<(SocketAddr, SocketAddr)> {
        let v = self.vehicle.get(i)?;
        let port = |base: u16| u16::try_from(i).ok().and_then(|i| base.checked_add(i));
        let peer = match v.address {
            Some(a) => a,
            None => SocketAddr::from(([127, 0, 0, 1], port(px4::OFFBOARD_LISTEN_PORT)?)),
        };
        let bind = match v.bind {
            Some(a) => a,
            None => SocketAddr::from(([0, 0, 0, 0], port(px4::OFFBOARD_PEER_PORT)?)),
        };
        Some((peer, bind))
    }
}
