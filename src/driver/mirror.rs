//! Traffic mirrors: every datagram the coordinator sends or receives, forwarded unchanged
//! to extra UDP addresses, so that pymavlink, MAVProxy or QGroundControl can watch the
//! whole swarm live (as mavlink-router's extra endpoints). Read-only: what a mirror sends
//! back is read, counted and dropped. Never blocks: a datagram the kernel will not take at
//! once is counted as not sent.

use std::io::ErrorKind;
use std::net::{SocketAddr, UdpSocket};
use std::time::Duration;

use ringswarm_wire::time::SimTime;

use crate::record::metrics::MirrorReport;

/// How often what came back from the mirrors is read (and dropped).
const DRAIN_PERIOD: Duration = Duration::from_millis(100);

/// One mirror: its address and a socket of its own (so what comes back is its own).
#[derive(Debug)]
struct Mirror {
    to: SocketAddr,
    socket: UdpSocket,
    report: MirrorReport,
}

/// Every mirror of a flight.
#[derive(Debug)]
pub struct Mirrors {
    mirrors: Vec<Mirror>,
    next_drain: SimTime,
    /// Reused for what comes back.
    buf: Vec<u8>,
}

impl Mirrors {
    /// A socket for each address (bound to an ephemeral port of the matching family).
    ///
    /// # Errors
    /// A socket that cannot be opened, named by its mirror.
    pub fn open(addresses: &[SocketAddr]) -> Result<Self, String> {
        let mirrors = addresses
            .iter()
            .map(|&to| {
                let any: SocketAddr = if to.is_ipv4() {
                    ([0, 0, 0, 0], 0).into()
                } else {
                    (std::net::Ipv6Addr::UNSPECIFIED, 0).into()
                };
                let socket = UdpSocket::bind(any)
                    .and_then(|s| s.set_nonblocking(true).map(|()| s))
                    .map_err(|e| format!("mirror {to}: open a socket: {e}"))?;
                Ok(Mirror {
                    to,
                    socket,
                    report: MirrorReport {
                        address: to.to_string(),
                        forwarded_datagrams: 0,
                        not_sent_datagrams: 0,
                        dropped_inbound_datagrams: 0,
                    },
                })
            })
            .collect::<Result<_, String>>()?;
        Ok(Self {
            mirrors,
            next_drain: SimTime::ZERO,
            buf: vec![0; 65_536],
        })
    }

    /// Whether there is no mirror.
    pub fn is_empty(&self) -> bool {
        self.mirrors.is_empty()
    }

    /// Sends `bytes` to every mirror.
    pub fn forward(&mut self, bytes: &[u8]) {
        for m in &mut self.mirrors {
            match m.socket.send_to(bytes, m.to) {
                Ok(_) => m.report.forwarded_datagrams += 1,
                Err(e) => {
                    if m.report.not_sent_datagrams == 0 && e.kind() != ErrorKind::WouldBlock {
                        tracing::warn!(mirror = %m.to, error = %e, "mirror: datagram not sent");
                    }
                    m.report.not_sent_datagrams += 1;
                }
            }
        }
    }

    /// Reads and drops what the mirrors sent back, every `DRAIN_PERIOD` at most.
    pub fn drain_due(&mut self, now: SimTime) {
        if now < self.next_drain {
            return;
        }
        self.next_drain = now + DRAIN_PERIOD;
        self.drain();
    }

    /// Reads and drops what the mirrors sent back.
    pub fn drain(&mut self) {
        for m in &mut self.mirrors {
            // Until nothing more (or an ICMP error of an earlier send: nobody listens).
            while m.socket.recv_from(&mut self.buf).is_ok() {
                m.report.dropped_inbound_datagrams += 1;
            }
        }
    }

    /// What each mirror carried.
    pub fn reports(&self) -> Vec<MirrorReport> {
        self.mirrors.iter().map(|m| m.report.clone()).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn forwards_unchanged_and_counts_and_drops_what_comes_back() {
        let listener = UdpSocket::bind("127.0.0.1:0").expect("bind");
        listener
            .set_read_timeout(Some(Duration::from_secs(5)))
            .expect("timeout");
        let mut mirrors = Mirrors::open(&[listener.local_addr().expect("addr")]).expect("open");
        mirrors.forward(b"\xfd\x09frame one");
        mirrors.forward(b"\xfd\x09frame two");
        let mut buf = [0u8; 64];
        let (n, from) = listener.recv_from(&mut buf).expect("first");
        assert_eq!(&buf[..n], b"\xfd\x09frame one");
        let (n, _) = listener.recv_from(&mut buf).expect("second");
        assert_eq!(&buf[..n], b"\xfd\x09frame two");
        // Two datagrams back from the listener: read and dropped.
        listener.send_to(b"command", from).expect("send back");
        listener.send_to(b"command", from).expect("send back");
        let deadline = std::time::Instant::now() + Duration::from_secs(5);
        while mirrors.reports()[0].dropped_inbound_datagrams < 2
            && std::time::Instant::now() < deadline
        {
            mirrors.drain();
            std::thread::sleep(Duration::from_millis(5));
        }
        let report = &mirrors.reports()[0];
        assert_eq!(report.forwarded_datagrams, 2);
        assert_eq!(report.not_sent_datagrams, 0);
        assert_eq!(report.dropped_inbound_datagrams, 2);
    }
}
