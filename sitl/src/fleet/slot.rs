//! One vehicle while its worker runs: its sockets or serial lines, whom each link
//! answers, the latency fault's held datagrams, its key file, and what the worker's
//! operator asked of it.

use std::io;
use std::net::SocketAddr;
use std::path::PathBuf;

use tokio::sync::watch;

use super::{READS_PER_TICK, Read, VehicleControl};
use crate::autopilot::{LinkId, Vehicle, VehicleEvent, VehicleStatus};
use crate::faulty_line::FaultyLine;
use crate::key_writer::KeyStore;
use crate::keystore::StoredKey;
use crate::link_faults::LinkFaults;
use crate::pty::PtyLink;
use crate::time::SimTime;
use crate::udp::Partner;

/// A datagram held back by the latency fault.
pub(super) struct Delayed {
    pub(super) link: usize,
    /// The sender of an inbound datagram; `None` for an outbound one.
    pub(super) from: Option<SocketAddr>,
    pub(super) bytes: Vec<u8>,
}

/// One link's socket or serial line, registered with the worker's poller.
pub(super) enum Port {
    Udp(mio::net::UdpSocket),
    Pty(PtyLink),
}

/// A vehicle while the worker runs.
pub(super) struct Slot {
    pub(super) vehicle: Vehicle,
    pub(super) sockets: Vec<Port>,
    pub(super) ids: Vec<LinkId>,
    pub(super) default_peers: Vec<SocketAddr>,
    pub(super) partners: Vec<Partner>,
    pub(super) faults: Vec<LinkFaults>,
    /// The links' fault draws and the datagrams they hold back.
    pub(super) delayed: FaultyLine<Delayed>,
    /// Buffers of delivered delayed datagrams, for the next ones.
    pub(super) spare: Vec<Vec<u8>>,
    pub(super) key_file: Option<PathBuf>,
    /// Where changed keys go to be written, off the worker's thread.
    pub(super) keys: KeyStore,
    pub(super) status: watch::Sender<VehicleStatus>,
    pub(super) alive: bool,
    /// Datagrams the socket could not take at once.
    pub(super) dropped_sends: u64,
    /// Frames read from a serial line, reused from read to read.
    pub(super) serial_frames: Vec<Vec<u8>>,
    /// How long before the worker's start the vehicle booted: vehicles started together
    /// would send every stream in the same millisecond (a thousand datagrams at once);
    /// PX4 instances boot apart, and so do these.
    pub(super) boot_offset: std::time::Duration,
}

impl Slot {
    /// The vehicle's time when the worker's clock says `now`.
    pub(super) fn time(&self, now: SimTime) -> SimTime {
        now + self.boot_offset
    }

    pub(super) fn control(&mut self, request: VehicleControl, now: SimTime) {
        let sysid = self.vehicle.system_id();
        match request {
            VehicleControl::Kill => {
                self.alive = false;
                self.store_key();
                let spare = &mut self.spare;
                spare.extend(self.delayed.drain().map(|d| d.bytes));
                while self.vehicle.poll_transmit().is_some() {}
                tracing::info!(sysid, "vehicle killed");
            }
            VehicleControl::Restart => {
                self.alive = true;
                self.partners = self
                    .default_peers
                    .iter()
                    .copied()
                    .map(Partner::new)
                    .collect();
                self.vehicle.reboot(now);
                tracing::info!(sysid, "vehicle restarted");
            }
        }
    }

    /// Reads what has arrived on link `link`'s socket, up to [`READS_PER_TICK`]
    /// datagrams, and hands it to the vehicle; a powered-off vehicle's datagrams are read
    /// and dropped. [`Read::More`] when the cap or a socket error (logged) left some
    /// unread: one vehicle's socket never stops the worker.
    pub(super) fn receive(&mut self, now: SimTime, link: usize, buf: &mut [u8]) -> Read {
        if link >= self.sockets.len() {
            return Read::Drained(0);
        }
        if let Port::Pty(_) = self.sockets[link] {
            return self.receive_serial(now, link, buf);
        }
        let mut taken = 0;
        while taken < READS_PER_TICK {
            let Port::Udp(socket) = &mut self.sockets[link] else {
                return Read::Drained(taken);
            };
            let (n, from) = match socket.recv_from(buf) {
                Ok(got) => got,
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => return Read::Drained(taken),
                // ICMP port unreachable from an earlier send (nobody listening at the
                // default peer yet) surfaces here on some systems.
                Err(e) if e.kind() == io::ErrorKind::ConnectionRefused => continue,
                Err(e) => {
                    tracing::warn!(sysid = self.vehicle.system_id(), error = %e, "receive failed");
                    return Read::More(taken);
                }
            };
            taken += 1;
            self.inbound(now, link, from, &buf[..n]);
            self.flush(now);
        }
        Read::More(taken)
    }

    /// Reads a serial line: what is waiting, up to [`READS_PER_TICK`] reads, each whole
    /// frame handed to the vehicle as a datagram from the line's one peer.
    pub(super) fn receive_serial(&mut self, now: SimTime, link: usize, buf: &mut [u8]) -> Read {
        let Some(Port::Pty(pty)) = self.sockets.get_mut(link) else {
            return Read::Drained(0);
        };
        let mut frames = std::mem::take(&mut self.serial_frames);
        frames.clear();
        let result = pty.receive(buf, READS_PER_TICK, |frame| frames.push(frame.to_vec()));
        let peer = self.default_peers[link];
        let taken = frames.len();
        for frame in frames.drain(..) {
            self.inbound(now, link, peer, &frame);
            self.flush(now);
        }
        self.serial_frames = frames;
        match result {
            Ok(false) => Read::Drained(taken),
            Ok(true) => Read::More(taken),
            Err(e) => {
                tracing::warn!(sysid = self.vehicle.system_id(), error = %e, "serial read failed");
                Read::More(taken)
            }
        }
    }

    /// Hands a datagram to the vehicle (or holds its copies back, under a latency
    /// fault); one the vehicle admits latches the link's partner.
    pub(super) fn inbound(&mut self, now: SimTime, link: usize, from: SocketAddr, bytes: &[u8]) {
        if !self.alive || link >= self.sockets.len() {
            return;
        }
        for delay in self.delayed.draw(&self.faults[link]) {
            if delay.is_zero() {
                if self.vehicle.handle_datagram(now, self.ids[link], bytes) {
                    self.partners[link].on_datagram(from);
                }
            } else {
                let copy = self.copy_of(bytes);
                self.hold(now + delay, link, Some(from), copy);
            }
        }
    }

    /// `bytes` in a spare buffer.
    pub(super) fn copy_of(&mut self, bytes: &[u8]) -> Vec<u8> {
        let mut copy = self.spare.pop().unwrap_or_default();
        copy.clear();
        copy.extend_from_slice(bytes);
        copy
    }

    /// Holds a datagram back until `due`; a full line drops it.
    pub(super) fn hold(
        &mut self,
        due: SimTime,
        link: usize,
        from: Option<SocketAddr>,
        bytes: Vec<u8>,
    ) {
        if let Err(dropped) = self.delayed.hold(due, Delayed { link, from, bytes }) {
            self.spare.push(dropped.bytes);
        }
    }

    pub(super) fn deliver_delayed(&mut self, now: SimTime) {
        while let Some(d) = self.delayed.pop_due(now) {
            match d.from {
                Some(from) => {
                    if self
                        .vehicle
                        .handle_datagram(now, self.ids[d.link], &d.bytes)
                    {
                        self.partners[d.link].on_datagram(from);
                    }
                }
                None => self.send(d.link, &d.bytes),
            }
            self.spare.push(d.bytes);
        }
    }

    /// Stores a changed key, then sends (or holds back) everything the vehicle queued.
    pub(super) fn flush(&mut self, now: SimTime) {
        while let Some(event) = self.vehicle.poll_event() {
            if let VehicleEvent::SigningChanged(stored) = event {
                self.save_key(stored);
            }
        }
        while let Some(tx) = self.vehicle.poll_transmit() {
            // A link this vehicle does not serve sends nothing.
            if let Some(link) = self.ids.iter().position(|id| *id == tx.link) {
                for copy in self.delayed.draw(&self.faults[link]) {
                    if copy.is_zero() {
                        self.send(link, &tx.bytes);
                    } else {
                        let held = self.copy_of(&tx.bytes);
                        self.hold(now + copy, link, None, held);
                    }
                }
            }
            self.vehicle.recycle(tx.bytes);
        }
    }

    /// Stores the vehicle's key with its clock as it is now, so that a restart goes on
    /// with newer timestamps (PX4 stores the clock only when a key is set).
    pub(super) fn store_key(&self) {
        if let Some(stored) = self.vehicle.signing_key() {
            self.save_key(Some(stored));
        }
    }

    /// Hands a key (or "no key") to the writer, when the vehicle keeps one in a file.
    pub(super) fn save_key(&self, stored: Option<StoredKey>) {
        if let Some(path) = &self.key_file {
            self.keys
                .save(path.clone(), self.vehicle.system_id(), stored);
        }
    }

    pub(super) fn send(&mut self, link: usize, bytes: &[u8]) {
        let to = self.partners[link].addr();
        let sent = match &mut self.sockets[link] {
            Port::Udp(socket) => socket.send_to(bytes, to).map(|_| ()),
            Port::Pty(pty) => pty.send(bytes),
        };
        match sent {
            Ok(_) => {}
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => self.dropped_sends += 1,
            Err(e) => {
                tracing::debug!(sysid = self.vehicle.system_id(), %to, error = %e, "send failed")
            }
        }
    }

    /// At the worker's end: the key stored, and what was dropped said.
    pub(super) fn close(&self) {
        if self.alive {
            self.store_key();
        }
        if self.delayed.refused() > 0 {
            tracing::info!(
                sysid = self.vehicle.system_id(),
                dropped = self.delayed.refused(),
                "datagrams dropped: the latency fault's line was full"
            );
        }
        if self.dropped_sends > 0 {
            tracing::info!(
                sysid = self.vehicle.system_id(),
                dropped = self.dropped_sends,
                "datagrams dropped: the socket's send buffer was full"
            );
        }
    }
}
