//! Where emulated vehicles sit on UDP: PX4 SITL's port scheme, a MAVLink network, whom
//! a link answers ([`Partner`]), and the simulated clock. `crate::fleet` runs them.
//!
//! PX4's layout: vehicle `i` (0-based, system id `i+1`) binds its offboard link on
//! `14580+i` and sends to `14540+i`, and binds its GCS link on `18570+i` and sends to
//! `14550`. On a network, a vehicle has one link (PX4's onboard instance) on a port of its
//! own and sends to the network's address, as PX4 instances behind a router.

use ringswarm_wire::px4;
use std::io;
use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::path::PathBuf;

use tokio::net::UdpSocket;
use tokio::time::Instant;

pub use crate::link_faults::LinkFaults;

use crate::autopilot::LinkId;
use crate::pty::PtyLink;
use crate::time::SimTime;

/// What carries one link.
pub enum LinkPort {
    /// A UDP socket, already bound.
    Udp(UdpSocket),
    /// A serial line on a pseudo-terminal.
    Pty(PtyLink),
}

impl LinkPort {
    /// Where it is, for the operator: the bound address, or the device path and its
    /// pseudo-terminal.
    pub fn describe(&self) -> String {
        match self {
            LinkPort::Udp(socket) => socket
                .local_addr()
                .map_or("udp ?".to_owned(), |a| format!("udp {a}")),
            LinkPort::Pty(pty) => {
                format!("serial {} -> {}", pty.device().display(), pty.far_name())
            }
        }
    }
}

/// One link of a vehicle: its socket, where it sends until a peer talks to it, and its
/// faults.
pub struct LinkSocket {
    /// Which of the vehicle's MAVLink instances this is.
    pub id: LinkId,
    /// The socket or serial line.
    pub port: LinkPort,
    /// Where the link sends until a peer talks to it.
    pub default_peer: SocketAddr,
    /// Faults on this link, both directions.
    pub faults: LinkFaults,
}

/// The four addresses of one vehicle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PortLayout {
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
pub fn px4_ports(instance: u16, host: IpAddr) -> PortLayout {
    PortLayout {
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

/// Where one emulated vehicle's links are.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Placement {
    /// Offboard and GCS links on the given ports (PX4 SITL's layout).
    Ports(PortLayout),
    /// One offboard link bound at `bind` (port 0: any free port), sending to `peer` (the
    /// network's ground station).
    Network {
        /// Where the link listens.
        bind: SocketAddr,
        /// Where it sends until someone talks to it.
        peer: SocketAddr,
    },
    /// One offboard link on a serial line: a pseudo-terminal linked at `device`, as a
    /// flight controller's TELEM port on a companion computer's cable.
    Serial {
        /// The path the coordinator opens.
        device: PathBuf,
    },
}

impl Placement {
    /// Binds the placement's sockets, as links of `faults`.
    ///
    /// # Errors
    /// The bind error, with the address that is in use.
    pub async fn bind(&self, faults: LinkFaults) -> io::Result<Vec<LinkSocket>> {
        let link = |id, port, default_peer| LinkSocket {
            id,
            port,
            default_peer,
            faults,
        };
        match self {
            Placement::Ports(plan) => {
                let [offboard, gcs] = bind(plan).await?;
                Ok(vec![
                    link(
                        LinkId::Offboard,
                        LinkPort::Udp(offboard),
                        plan.offboard_peer,
                    ),
                    link(LinkId::Gcs, LinkPort::Udp(gcs), plan.gcs_peer),
                ])
            }
            Placement::Network { bind, peer } => {
                let socket = bind_one(*bind).await?;
                Ok(vec![link(LinkId::Offboard, LinkPort::Udp(socket), *peer)])
            }
            Placement::Serial { device } => {
                let pty = PtyLink::open(device)?;
                // A serial line has one peer: no address to send to.
                let peer = SocketAddr::new(IpAddr::V4(Ipv4Addr::UNSPECIFIED), 0);
                Ok(vec![link(LinkId::Offboard, LinkPort::Pty(pty), peer)])
            }
        }
    }
}

async fn bind_one(addr: SocketAddr) -> io::Result<UdpSocket> {
    UdpSocket::bind(addr)
        .await
        .map_err(|e| io::Error::new(e.kind(), format!("cannot bind UDP {addr}: {e}")))
}

/// Binds both sockets of a port plan.
///
/// # Errors
/// The bind error, with the address that is in use.
pub async fn bind(plan: &PortLayout) -> io::Result<[UdpSocket; 2]> {
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
