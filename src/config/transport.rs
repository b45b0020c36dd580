//! What a coordinator config means for the transport: the coordinator's UDP sockets and
//! how each vehicle is reached ([`TransportLayout`]), checked for collisions.

use std::collections::{HashMap, HashSet};
use std::net::SocketAddr;

use ringswarm_wire::px4;

use super::Config;
use super::problems::Problems;
use crate::index::SystemId;
use crate::link::router::{Endpoint, SERIAL_PEER, SocketLayout, TransportLayout, VehicleRoute};

/// Whether two bind/listen addresses take the same port on a common interface
/// (`0.0.0.0` overlaps every address of its family).
fn overlaps(a: SocketAddr, b: SocketAddr) -> bool {
    a.port() == b.port() && (a.ip() == b.ip() || a.ip().is_unspecified() || b.ip().is_unspecified())
}

impl Config {
    /// The coordinator's sockets and every vehicle's route, in ring order.
    ///
    /// # Errors
    /// Every problem, one per line: an unknown or duplicate network, a `bind` on a
    /// networked vehicle, a vehicle without a network whose default port would pass
    /// 65535, two sockets on one port, a coordinator socket on a vehicle's port.
    pub fn transport_layout(&self) -> Result<TransportLayout, String> {
        let mut p = Problems::default();
        let plan = self.transport(&mut p);
        if p.0.is_empty() {
            Ok(plan)
        } else {
            Err(p.0.join("\n"))
        }
    }

    /// Builds the plan, pushing every problem found.
    pub(super) fn transport(&self, p: &mut Problems) -> TransportLayout {
        let (mut sockets, by_name) = self.network_sockets(p);
        let (routes, listening) = self.vehicle_routes(&mut sockets, &by_name, p);
        self.check_binds(&sockets, &routes, &listening, p);
        self.check_system_ids(p);
        TransportLayout { sockets, routes }
    }

    /// A socket per `[[network]]`, and the networks by name.
    fn network_sockets<'a>(
        &'a self,
        p: &mut Problems,
    ) -> (Vec<SocketLayout>, HashMap<&'a str, usize>) {
        let mut sockets = Vec::new();
        let mut by_name = HashMap::new();
        for (j, n) in self.network.iter().enumerate() {
            let plain = |c: char| c.is_ascii_alphanumeric() || c == '-' || c == '_';
            if n.name.is_empty() || !n.name.chars().all(plain) {
                p.push(format!(
                    "network[{j}].name must be letters, digits, '-' or '_' (it names files), got \"{}\"",
                    n.name
                ));
            } else if by_name.insert(n.name.as_str(), sockets.len()).is_some() {
                p.push(format!("network[{j}].name \"{}\" is used twice", n.name));
            }
            sockets.push(SocketLayout {
                endpoint: Endpoint::Udp(n.bind),
                network: Some(n.name.clone()),
            });
        }
        (sockets, by_name)
    }

    /// Each vehicle's route (a socket of its own on PX4's ports, its network's, or its
    /// serial line), and the addresses vehicles listen on.
    fn vehicle_routes(
        &self,
        sockets: &mut Vec<SocketLayout>,
        by_name: &HashMap<&str, usize>,
        p: &mut Problems,
    ) -> (Vec<VehicleRoute>, Vec<(usize, SocketAddr)>) {
        let mut routes = Vec::new();
        let mut listening = Vec::new();
        let mut devices = HashMap::new();
        for (i, v) in self.vehicle.iter().enumerate() {
            if let Some(serial) = &v.serial {
                routes.push(serial_route(i, v, serial, sockets, &mut devices, p));
                continue;
            }
            let route = match &v.network {
                Some(name) => {
                    if v.bind.is_some() {
                        p.push(format!(
                            "vehicle[{i}].bind: a vehicle on network \"{name}\" is reached \
                             through the network's socket (its bind)"
                        ));
                    }
                    let Some(&socket) = by_name.get(name.as_str()) else {
                        p.push(format!(
                            "vehicle[{i}].network \"{name}\" is not a [[network]] name"
                        ));
                        continue;
                    };
                    VehicleRoute {
                        socket,
                        address: v.address,
                        system_id: SystemId(v.system_id),
                    }
                }
                None => {
                    let Some((peer, bind)) = px4_endpoints(i, v.address, v.bind) else {
                        p.push(format!(
                            "vehicle[{i}]: PX4's default port for instance {i} passes 65535; \
                             set its address and bind, or put it on a [[network]]"
                        ));
                        continue;
                    };
                    sockets.push(SocketLayout {
                        endpoint: Endpoint::Udp(bind),
                        network: None,
                    });
                    VehicleRoute {
                        socket: sockets.len() - 1,
                        address: Some(peer),
                        system_id: SystemId(v.system_id),
                    }
                }
            };
            if let Some(address) = route.address {
                listening.push((i, address));
            }
            routes.push(route);
        }
        (routes, listening)
    }

    /// No two sockets bind one port, and none binds where a vehicle on this host
    /// listens.
    fn check_binds(
        &self,
        sockets: &[SocketLayout],
        routes: &[VehicleRoute],
        listening: &[(usize, SocketAddr)],
        p: &mut Problems,
    ) {
        let describe = |s: &SocketLayout, k: usize| match &s.network {
            Some(name) => format!("network \"{name}\""),
            None => format!(
                "the coordinator's socket for vehicle[{}]",
                vehicle_of(routes, k)
            ),
        };
        let udp: Vec<(usize, &SocketLayout, SocketAddr)> = sockets
            .iter()
            .enumerate()
            .filter_map(|(k, s)| s.udp_bind().map(|bind| (k, s, bind)))
            .collect();
        for (n, &(a, sa, bind_a)) in udp.iter().enumerate() {
            for &(b, sb, bind_b) in udp.iter().skip(n + 1) {
                if overlaps(bind_a, bind_b) {
                    p.push(format!(
                        "{} and {} both bind port {} ({} and {})",
                        describe(sa, a),
                        describe(sb, b),
                        bind_a.port(),
                        bind_a,
                        bind_b
                    ));
                }
            }
            // A vehicle on another host listens on its own interface, not ours.
            let here = |l: &SocketAddr| l.ip().is_loopback() || l.ip() == bind_a.ip();
            if let Some(&(i, address)) = listening
                .iter()
                .find(|(_, l)| here(l) && overlaps(bind_a, *l))
            {
                p.push(format!(
                    "{} binds {}, where vehicle[{i}] listens ({address}){}",
                    describe(sa, a),
                    bind_a,
                    if sa.network.is_none() && self.network.is_empty() {
                        ": PX4 SITL's ports collide from the 41st vehicle on; put the \
                         vehicles on a [[network]]"
                    } else {
                        ""
                    }
                ));
            }
        }
    }

    /// System ids: 1..=250 (PX4's MAV_SYS_ID range), unique within each network and
    /// among the vehicles without one, never the coordinator's own.
    fn check_system_ids(&self, p: &mut Problems) {
        let mut seen = HashSet::new();
        for (i, v) in self.vehicle.iter().enumerate() {
            if v.system_id == 0 || v.system_id > 250 {
                p.push(format!(
                    "vehicle[{i}].system_id must be 1..=250, got {}",
                    v.system_id
                ));
            }
            if !seen.insert((v.network.as_deref(), v.system_id)) {
                p.push(match &v.network {
                    Some(name) => format!(
                        "vehicle[{i}].system_id {} is used twice on network \"{name}\"",
                        v.system_id
                    ),
                    None => format!("vehicle[{i}].system_id {} is used twice", v.system_id),
                });
            }
            if v.system_id == self.swarm.gcs_system_id {
                p.push(format!(
                    "vehicle[{i}].system_id {} is the coordinator's own swarm.gcs_system_id",
                    v.system_id
                ));
            }
        }
    }
}

/// The lowest and highest line rates taken (PX4's TELEM ports run 9600 … 3 000 000).
const BAUD_RANGE: std::ops::RangeInclusive<u32> = 1200..=4_000_000;

/// Vehicle `i`'s route over its serial port (a socket of its own), pushing what is wrong
/// with it: a network, address or bind beside it, an empty device, a device another
/// vehicle uses, a line rate out of [`BAUD_RANGE`].
fn serial_route(
    i: usize,
    v: &super::VehicleSection,
    serial: &super::SerialSection,
    sockets: &mut Vec<SocketLayout>,
    devices: &mut HashMap<String, usize>,
    p: &mut Problems,
) -> VehicleRoute {
    for (set, key) in [
        (v.network.is_some(), "network"),
        (v.address.is_some(), "address"),
        (v.bind.is_some(), "bind"),
    ] {
        if set {
            p.push(format!(
                "vehicle[{i}].{key}: a vehicle on a serial port is reached over that port only"
            ));
        }
    }
    if serial.device.trim().is_empty() {
        p.push(format!("vehicle[{i}].serial.device is empty"));
    } else if let Some(other) = devices.insert(serial.device.clone(), i) {
        p.push(format!(
            "vehicle[{i}].serial.device \"{}\" is vehicle[{other}]'s too: a serial port reaches one vehicle",
            serial.device
        ));
    }
    if !BAUD_RANGE.contains(&serial.baud) {
        p.push(format!(
            "vehicle[{i}].serial.baud must be {}..={} bits per second, got {}",
            BAUD_RANGE.start(),
            BAUD_RANGE.end(),
            serial.baud
        ));
    }
    sockets.push(SocketLayout {
        endpoint: Endpoint::Serial {
            device: serial.device.clone(),
            baud: serial.baud,
        },
        network: None,
    });
    VehicleRoute {
        socket: sockets.len() - 1,
        address: Some(SERIAL_PEER),
        system_id: SystemId(v.system_id),
    }
}

/// The vehicle whose own socket is `socket`.
fn vehicle_of(routes: &[VehicleRoute], socket: usize) -> usize {
    routes.iter().position(|r| r.socket == socket).unwrap_or(0)
}

/// Vehicle `i`'s address and the coordinator's bind address for it on PX4 SITL's ports
/// (the vehicle listens on 14580+i and sends to 14540+i), where not configured.
fn px4_endpoints(
    i: usize,
    address: Option<SocketAddr>,
    bind: Option<SocketAddr>,
) -> Option<(SocketAddr, SocketAddr)> {
    let port = |base: u16| u16::try_from(i).ok().and_then(|i| base.checked_add(i));
    let peer = match address {
        Some(a) => a,
        None => SocketAddr::from(([127, 0, 0, 1], port(px4::OFFBOARD_LISTEN_PORT)?)),
    };
    let bind = match bind {
        Some(a) => a,
        None => SocketAddr::from(([0, 0, 0, 0], port(px4::OFFBOARD_PEER_PORT)?)),
    };
    Some((peer, bind))
}
