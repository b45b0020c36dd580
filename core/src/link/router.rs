//! Which coordinator socket and address reach each vehicle, and which vehicle a received
//! datagram is for: a sans-IO router between UDP sockets and the swarm's links.
//!
//! Two kinds of socket:
//! - **Own socket** (PX4 SITL's layout): one socket per vehicle. Every datagram it
//!   receives is handed to that vehicle's link, which judges each frame (its system id,
//!   its signature). The vehicle's address (PX4's default 127.0.0.1:14580+i, or the
//!   configured one) is contacted first and then learned from the frames the link takes,
//!   as on a network: ArduPilot SITL's `--serial0 udpclient:IP:PORT` sends from an
//!   ephemeral port and takes only datagrams from the port it sends to, so the
//!   coordinator answers where its frames come from.
//! - **Network socket** (a ground station on 14550): one socket for many vehicles, told
//!   apart by the system id in each frame's header; system ids are unique within a
//!   network, not across networks. A vehicle's address is learned from the frames it
//!   sends, like QGroundControl and MAVSDK do: the first frame its link takes (decoded,
//!   from its system id, authentic when signing is on) sets it. An address known from the
//!   config is used until then, so such a vehicle is contacted first. Afterwards only
//!   an address silent for [`RELEARN_AFTER`] gives way to a new one (a restarted vehicle
//!   on another port); a frame from elsewhere meanwhile is still handed to the link,
//!   which judges it, but moves nothing.

use std::collections::HashMap;
use std::net::SocketAddr;
use std::ops::Range;
use std::time::Duration;

use ringswarm_wire::codec::{frame_system_id, raw_frames};
use ringswarm_wire::time::SimTime;

use crate::index::{SystemId, VehicleIndex};

/// How long a learned address must stay silent before another takes its place.
pub const RELEARN_AFTER: Duration = Duration::from_secs(2);

/// Where one coordinator socket is.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Endpoint {
    /// A UDP socket bound at this address.
    Udp(SocketAddr),
    /// A serial port to one vehicle (a companion computer's cable to its autopilot): a
    /// byte stream, read as if each frame were a datagram from [`SERIAL_PEER`].
    Serial {
        /// The device (`/dev/ttyAMA0`, `/dev/serial/by-id/…`).
        device: String,
        /// Its line rate, bits per second.
        baud: u32,
    },
}

/// The "address" every frame read from a serial port comes from, and where its vehicle
/// is sent to: a serial port has one peer.
pub const SERIAL_PEER: SocketAddr =
    SocketAddr::new(std::net::IpAddr::V4(std::net::Ipv4Addr::UNSPECIFIED), 0);

/// One coordinator socket.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SocketLayout {
    /// Where it is.
    pub endpoint: Endpoint,
    /// The network's name, for a network socket.
    pub network: Option<String>,
}

impl SocketLayout {
    /// Where a UDP socket is bound; `None` for a serial port.
    pub fn udp_bind(&self) -> Option<SocketAddr> {
        match self.endpoint {
            Endpoint::Udp(bind) => Some(bind),
            Endpoint::Serial { .. } => None,
        }
    }
}

/// How a vehicle is reached.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct VehicleRoute {
    /// Index of its socket in [`TransportLayout::sockets`].
    pub socket: usize,
    /// Its address: fixed on an own socket, the first to try on a network.
    pub address: Option<SocketAddr>,
    /// Its system id (what a network socket demultiplexes on).
    pub system_id: SystemId,
}

/// The coordinator's sockets and each vehicle's route, in ring order.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TransportLayout {
    /// The sockets to bind.
    pub sockets: Vec<SocketLayout>,
    /// One route per vehicle.
    pub routes: Vec<VehicleRoute>,
}

/// A vehicle's address changed (first learned, or replaced after silence).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AddressLearned {
    /// The vehicle.
    pub vehicle: VehicleIndex,
    /// The address before, if any.
    pub before: Option<SocketAddr>,
    /// The address now.
    pub now: SocketAddr,
}

#[derive(Debug, Clone)]
enum Demux {
    /// An own socket: its one vehicle.
    Own(VehicleIndex),
    /// A network socket: system id → vehicle.
    Network(HashMap<SystemId, VehicleIndex>),
}

#[derive(Debug, Clone, Copy)]
struct Route {
    socket: usize,
    address: Option<SocketAddr>,
    /// Whether frames can move the address (network sockets).
    learns: bool,
    /// When a frame the link took last came from `address`.
    last_vouched: Option<SimTime>,
}

/// The router.
#[derive(Debug, Clone)]
pub struct Router {
    demux: Vec<Demux>,
    routes: Vec<Route>,
    unroutable: Vec<u64>,
}

impl Router {
    /// A router for `plan` (a route's socket index must be in range: the config checks).
    pub fn new(plan: &TransportLayout) -> Self {
        let mut demux: Vec<Demux> = plan
            .sockets
            .iter()
            .map(|s| match s.network {
                Some(_) => Demux::Network(HashMap::new()),
                None => Demux::Own(VehicleIndex(usize::MAX)),
            })
            .collect();
        let mut routes = Vec::with_capacity(plan.routes.len());
        for (i, r) in VehicleIndex::all(plan.routes.len()).zip(&plan.routes) {
            let learns = match demux.get_mut(r.socket) {
                Some(Demux::Network(by_id)) => {
                    by_id.insert(r.system_id, i);
                    true
                }
                Some(Demux::Own(vehicle)) => {
                    *vehicle = i;
                    true
                }
                None => false,
            };
            routes.push(Route {
                socket: r.socket,
                address: r.address,
                learns,
                last_vouched: None,
            });
        }
        Self {
            unroutable: vec![0; demux.len()],
            demux,
            routes,
        }
    }

    /// The pieces of a datagram received on `socket` from `from`, each as the vehicle it
    /// is for and its byte range, in `out` (cleared first): the whole datagram on an
    /// own socket (its link judges the frames), each frame on a network
    /// socket whose system id belongs to one of its vehicles. Anything else is counted
    /// in [`Router::unroutable`]. Allocates nothing once `out` has grown.
    pub fn route_inbound(
        &mut self,
        socket: usize,
        _from: SocketAddr,
        bytes: &[u8],
        out: &mut Vec<(VehicleIndex, Range<usize>)>,
    ) {
        out.clear();
        match self.demux.get(socket) {
            Some(Demux::Own(vehicle)) => match self.routes.get(vehicle.get()) {
                Some(_) => out.push((*vehicle, 0..bytes.len())),
                None => self.unroutable[socket] += 1,
            },
            Some(Demux::Network(by_id)) => {
                let base = bytes.as_ptr() as usize;
                for frame in raw_frames(bytes) {
                    let start = frame.as_ptr() as usize - base;
                    match frame_system_id(frame).and_then(|id| by_id.get(&SystemId(id))) {
                        Some(&vehicle) => out.push((vehicle, start..start + frame.len())),
                        None => self.unroutable[socket] += 1,
                    }
                }
            }
            None => {}
        }
    }

    /// Vehicle `vehicle`'s link took a frame that came from `from` at `now`: on a network,
    /// that may set its address.
    pub fn vouched(
        &mut self,
        vehicle: VehicleIndex,
        from: SocketAddr,
        now: SimTime,
    ) -> Option<AddressLearned> {
        let route = self.routes.get_mut(vehicle.get())?;
        if !route.learns {
            return None;
        }
        if route.address == Some(from) {
            route.last_vouched = Some(now);
            // A configured address answering for the first time is news too.
            return None;
        }
        let silent = route
            .last_vouched
            .is_none_or(|last| now.saturating_since(last) >= RELEARN_AFTER);
        if !silent {
            return None;
        }
        let before = route.address;
        route.address = Some(from);
        route.last_vouched = Some(now);
        Some(AddressLearned {
            vehicle,
            before,
            now: from,
        })
    }

    /// Where a datagram for `vehicle` goes: its socket and address, or `None` while a
    /// network vehicle's address is unknown (nothing has come from it and none was
    /// configured).
    pub fn destination(&self, vehicle: VehicleIndex) -> Option<(usize, SocketAddr)> {
        let route = self.routes.get(vehicle.get())?;
        Some((route.socket, route.address?))
    }

    /// Datagrams (own sockets) or frames (network sockets) received on `socket` that
    /// belonged to no vehicle.
    pub fn unroutable(&self, socket: usize) -> u64 {
        self.unroutable.get(socket).copied().unwrap_or(0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ringswarm_wire::codec::Encoder;

    fn addr(port: u16) -> SocketAddr {
        SocketAddr::from(([127, 0, 0, 1], port))
    }

    fn heartbeat(system_id: u8) -> Vec<u8> {
        Encoder::new(system_id, 1).encode(&crate::link::gcs_heartbeat())
    }

    /// Two networks whose system ids overlap (1 and 2 on each) and one own socket.
    fn plan() -> TransportLayout {
        let network = |name: &str, port| SocketLayout {
            endpoint: Endpoint::Udp(addr(port)),
            network: Some(name.to_owned()),
        };
        TransportLayout {
            sockets: vec![
                network("a", 14550),
                network("b", 14551),
                SocketLayout {
                    endpoint: Endpoint::Udp(addr(14540)),
                    network: None,
                },
            ],
            routes: vec![
                VehicleRoute {
                    socket: 0,
                    address: None,
                    system_id: SystemId(1),
                },
                VehicleRoute {
                    socket: 0,
                    address: Some(addr(30002)),
                    system_id: SystemId(2),
                },
                VehicleRoute {
                    socket: 1,
                    address: None,
                    system_id: SystemId(1),
                },
                VehicleRoute {
                    socket: 1,
                    address: None,
                    system_id: SystemId(2),
                },
                VehicleRoute {
                    socket: 2,
                    address: Some(addr(14580)),
                    system_id: SystemId(1),
                },
            ],
        }
    }

    #[test]
    fn the_same_system_id_on_two_networks_reaches_two_vehicles() {
        let mut router = Router::new(&plan());
        let mut out = Vec::new();
        let hb = heartbeat(1);
        router.route_inbound(0, addr(30001), &hb, &mut out);
        assert_eq!(out, vec![(VehicleIndex(0), 0..hb.len())]);
        router.route_inbound(1, addr(31001), &hb, &mut out);
        assert_eq!(out, vec![(VehicleIndex(2), 0..hb.len())]);
        // An unknown system id on a network is nobody's.
        router.route_inbound(1, addr(31009), &heartbeat(9), &mut out);
        assert!(out.is_empty());
        assert_eq!(router.unroutable(1), 1);
    }

    #[test]
    fn a_datagram_with_frames_of_two_vehicles_is_split() {
        let mut router = Router::new(&plan());
        let (one, two) = (heartbeat(1), heartbeat(2));
        let both = [one.clone(), two.clone()].concat();
        let mut out = Vec::new();
        router.route_inbound(0, addr(30001), &both, &mut out);
        assert_eq!(
            out,
            vec![
                (VehicleIndex(0), 0..one.len()),
                (VehicleIndex(1), one.len()..both.len())
            ]
        );
        assert_eq!(&both[out[1].1.clone()], two.as_slice());
    }

    #[test]
    fn an_own_socket_answers_where_its_vehicle_speaks_from() {
        let mut router = Router::new(&plan());
        let hb = heartbeat(1);
        let mut out = Vec::new();
        let t = |s: f64| SimTime::from_secs_f64(s);
        // PX4's port is contacted first.
        assert_eq!(router.destination(VehicleIndex(4)), Some((2, addr(14580))));
        router.route_inbound(2, addr(14580), &hb, &mut out);
        assert_eq!(out, vec![(VehicleIndex(4), 0..hb.len())]);
        // From anywhere, the datagram goes to the link, which judges its frames.
        router.route_inbound(2, addr(45123), &hb, &mut out);
        assert_eq!(out, vec![(VehicleIndex(4), 0..hb.len())]);
        assert_eq!(router.unroutable(2), 0);
        // Frames the link took from an ephemeral port (ArduPilot SITL's udpclient) move
        // the address there, since PX4's port never answered.
        assert_eq!(
            router.vouched(VehicleIndex(4), addr(45123), t(1.0)),
            Some(AddressLearned {
                vehicle: VehicleIndex(4),
                before: Some(addr(14580)),
                now: addr(45123)
            })
        );
        assert_eq!(router.destination(VehicleIndex(4)), Some((2, addr(45123))));
        // Another sender while it speaks moves nothing.
        assert_eq!(router.vouched(VehicleIndex(4), addr(14580), t(1.5)), None);
        assert_eq!(router.destination(VehicleIndex(4)), Some((2, addr(45123))));
    }

    #[test]
    fn an_own_socket_keeps_a_configured_address_that_answers() {
        let mut router = Router::new(&plan());
        let t = |s: f64| SimTime::from_secs_f64(s);
        assert_eq!(router.vouched(VehicleIndex(4), addr(14580), t(1.0)), None);
        assert_eq!(router.vouched(VehicleIndex(4), addr(45123), t(1.5)), None);
        assert_eq!(router.destination(VehicleIndex(4)), Some((2, addr(14580))));
    }

    #[test]
    fn a_network_address_is_learned_once_and_replaced_only_after_silence() {
        let mut router = Router::new(&plan());
        let t = |s: f64| SimTime::from_secs_f64(s);
        // Unknown until the vehicle is heard; a configured one is contacted first.
        assert_eq!(router.destination(VehicleIndex(0)), None);
        assert_eq!(router.destination(VehicleIndex(1)), Some((0, addr(30002))));
        let learned = router.vouched(VehicleIndex(0), addr(30001), t(1.0));
        assert_eq!(
            learned,
            Some(AddressLearned {
                vehicle: VehicleIndex(0),
                before: None,
                now: addr(30001)
            })
        );
        assert_eq!(router.destination(VehicleIndex(0)), Some((0, addr(30001))));
        // Another sender while the first is alive moves nothing.
        assert_eq!(router.vouched(VehicleIndex(0), addr(40000), t(1.5)), None);
        assert_eq!(router.vouched(VehicleIndex(0), addr(30001), t(2.0)), None);
        assert_eq!(router.vouched(VehicleIndex(0), addr(40000), t(3.9)), None);
        assert_eq!(router.destination(VehicleIndex(0)), Some((0, addr(30001))));
        // Silent for RELEARN_AFTER: the new one takes over.
        assert_eq!(
            router.vouched(VehicleIndex(0), addr(40000), t(4.0)),
            Some(AddressLearned {
                vehicle: VehicleIndex(0),
                before: Some(addr(30001)),
                now: addr(40000)
            })
        );
        // A configured address that answers keeps its place; another one replaces it
        // only when it never answered.
        assert_eq!(router.vouched(VehicleIndex(1), addr(30002), t(1.0)), None);
        assert_eq!(router.vouched(VehicleIndex(1), addr(30003), t(1.5)), None);
        assert_eq!(router.destination(VehicleIndex(1)), Some((0, addr(30002))));
    }
}
