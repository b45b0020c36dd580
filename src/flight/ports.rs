//! Binding every socket of a transport layout (UDP ports, serial lines), naming the one
//! that cannot be bound.

use anyhow::Context;
use tokio::net::UdpSocket;

use crate::driver::serial::SerialLine;
use crate::driver::udp::Port;
use crate::link::router::{Endpoint, TransportLayout};

/// Binds every socket of the layout, naming the one that cannot be bound.
///
/// # Errors
/// The first bind error.
pub async fn bind_all(
    transport: &TransportLayout,
    local: impl Fn(usize) -> bool,
) -> anyhow::Result<Vec<Port>> {
    let mut sockets = Vec::with_capacity(transport.sockets.len());
    for (s, plan) in transport.sockets.iter().enumerate() {
        if !local(s) {
            // Only another shard's vehicles use it: a socket of no consequence, so that
            // the shards of one host do not take each other's ports.
            let unused = UdpSocket::bind((std::net::Ipv4Addr::LOCALHOST, 0))
                .await
                .context("bind a placeholder socket for another shard's vehicle")?;
            sockets.push(Port::Udp(unused));
            continue;
        }
        let bind = match &plan.endpoint {
            Endpoint::Udp(bind) => *bind,
            Endpoint::Serial { device, baud } => {
                let vehicle = transport
                    .routes
                    .iter()
                    .position(|r| r.socket == s)
                    .map_or(0, |i| i + 1);
                let line = SerialLine::open(device, *baud)
                    .with_context(|| format!("vehicle {vehicle}'s serial port"))?;
                sockets.push(Port::Serial(line));
                continue;
            }
        };
        let socket = UdpSocket::bind(bind).await.with_context(|| match &plan.network {
            Some(name) => format!("bind {bind} for network \"{name}\" (another ground station on that port?)"),
            None => format!(
                "bind {bind} for vehicle {} (another ground station on that port? set [[vehicle]] bind)",
                transport.routes.iter().position(|r| r.socket == s).map_or(0, |i| i + 1)
            ),
        })?;
        if plan.network.is_some() {
            grow_receive_buffer(&socket, bind);
        }
        sockets.push(Port::Udp(socket));
    }
    Ok(sockets)
}

/// What a network socket asks the kernel to buffer: about two control periods of a
/// thousand vehicles' telemetry, so a burst (every vehicle's streams falling due
/// together) is not dropped while the swarm is busy. Linux caps it at
/// `net.core.rmem_max`.
const NETWORK_RECEIVE_BUFFER: usize = 4 << 20;

/// Asks for [`NETWORK_RECEIVE_BUFFER`]; says so when the kernel grants less.
fn grow_receive_buffer(socket: &UdpSocket, bind: std::net::SocketAddr) {
    let socket = socket2::SockRef::from(socket);
    if let Err(e) = socket.set_recv_buffer_size(NETWORK_RECEIVE_BUFFER) {
        tracing::warn!(%bind, error = %e, "receive buffer not enlarged");
    }
    // Linux reports twice what it grants (its bookkeeping overhead).
    match socket.recv_buffer_size() {
        Ok(granted) if granted / 2 < NETWORK_RECEIVE_BUFFER => tracing::info!(
            %bind,
            granted = granted / 2,
            wanted = NETWORK_RECEIVE_BUFFER,
            "receive buffer capped by the kernel (net.core.rmem_max): large swarms may lose telemetry in bursts"
        ),
        _ => {}
    }
}
