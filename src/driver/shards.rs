//! Several shards of one swarm in one process, in lockstep with the emulated vehicles:
//! each shard is a swarm machine flying its own vehicles over MAVLink, and what the
//! shards tell each other crosses a bus with its own seeded latency, jitter and loss
//! (the link-fault model of the MAVLink links), as the payload bytes the Zenoh
//! transport carries (encoded, then decoded). Same seed, same inputs: the same flight,
//! bit for bit.
//!
//! Vehicle `i` talks to its shard's link `i` (PX4 SITL's ports, one socket each).

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use ringswarm_sitl::autopilot::{LinkId, PHYSICS_STEP, Vehicle};
use ringswarm_sitl::delay_line::DelayLine;
use ringswarm_sitl::link_faults::LinkConditions;
use ringswarm_wire::time::SimTime;

use crate::distributed::{ShardMessage, ShardPlan, decode, encode};
use crate::swarm::Swarm;

/// Datagrams and payloads in flight at once: a full line drops (and counts) what comes
/// next.
const IN_FLIGHT_CAPACITY: usize = 1 << 20;

/// A MAVLink datagram in flight between vehicle `index` and its shard.
#[derive(Debug)]
struct Datagram {
    to_vehicle: bool,
    index: usize,
    bytes: Vec<u8>,
}

/// A payload in flight to shard `to`.
#[derive(Debug)]
struct Payload {
    to: usize,
    bytes: Vec<u8>,
}

/// Counts of the bus between shards.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct BusCounts {
    /// Payloads sent (one per receiving shard).
    pub sent: u64,
    /// Their bytes.
    pub bytes: u64,
    /// Payloads lost on the way (the bus's loss, or a shard that was down).
    pub lost: u64,
    /// Payloads that did not decode (none, unless the codec is broken).
    pub refused: u64,
}

/// The shards and the vehicles in one virtual world.
#[derive(Debug)]
pub struct ShardedLockstep {
    shards: Vec<Swarm>,
    vehicles: Vec<Vehicle>,
    owner: Vec<usize>,
    now: SimTime,
    mavlink: DelayLine<Datagram>,
    mavlink_conditions: LinkConditions,
    mavlink_rng: ChaCha8Rng,
    bus: DelayLine<Payload>,
    bus_conditions: LinkConditions,
    bus_rng: ChaCha8Rng,
    /// When each shard is down (its process gone): it neither runs nor hears anything.
    down: Vec<Vec<(SimTime, SimTime)>>,
    /// Pairs of shards that cannot reach each other, and when (a broken mesh).
    cuts: Vec<(usize, usize, SimTime, SimTime)>,
    counts: BusCounts,
    scratch: Vec<u8>,
}

impl ShardedLockstep {
    /// Shards (each built with [`Swarm::new_shard`] over the same ring) and every
    /// vehicle of the ring; `mavlink` on each vehicle's link, `bus` between shards.
    ///
    /// # Errors
    /// When the shards' plans do not agree on who flies whom, or a vehicle is missing.
    pub fn new(
        shards: Vec<Swarm>,
        mut vehicles: Vec<Vehicle>,
        mavlink: LinkConditions,
        bus: LinkConditions,
    ) -> Result<Self, String> {
        let n = vehicles.len();
        let plans: Vec<&ShardPlan> = shards
            .iter()
            .map(|s| {
                s.shard_plan()
                    .ok_or("a swarm of one process among the shards")
            })
            .collect::<Result<_, _>>()?;
        let owner: Vec<usize> = (0..n)
            .map(|i| plans.first().and_then(|p| p.owner(i)))
            .collect::<Option<_>>()
            .ok_or(format!("the shards' plans do not cover the {n} vehicles"))?;
        for (s, p) in plans.iter().enumerate() {
            if p.this() != s || p.shards() != shards.len() {
                return Err(format!(
                    "shard {s}'s plan is shard {} of {}",
                    p.this(),
                    p.shards()
                ));
            }
            if (0..n).any(|i| p.owner(i) != Some(owner[i])) {
                return Err(format!("shard {s}'s plan gives the vehicles other owners"));
            }
        }
        for v in &mut vehicles {
            v.set_link_wired(LinkId::Gcs, false);
        }
        let count = shards.len();
        Ok(Self {
            shards,
            vehicles,
            owner,
            now: SimTime::ZERO,
            mavlink: DelayLine::new(IN_FLIGHT_CAPACITY),
            mavlink_rng: ChaCha8Rng::seed_from_u64(mavlink.seed),
            mavlink_conditions: mavlink,
            bus: DelayLine::new(IN_FLIGHT_CAPACITY),
            bus_rng: ChaCha8Rng::seed_from_u64(bus.seed),
            bus_conditions: bus,
            down: vec![Vec::new(); count],
            cuts: Vec::new(),
            counts: BusCounts::default(),
            scratch: Vec::new(),
        })
    }

    /// Virtual time.
    pub fn now(&self) -> SimTime {
        self.now
    }

    /// The shards' swarm machines.
    pub fn shards(&self) -> &[Swarm] {
        &self.shards
    }

    /// The emulated vehicles.
    pub fn vehicles(&self) -> &[Vehicle] {
        &self.vehicles
    }

    /// What crossed the bus.
    pub fn bus_counts(&self) -> BusCounts {
        self.counts
    }

    /// Takes shard `s` down over `[from, until)`: it runs nothing, sends nothing, and
    /// what is sent to it (MAVLink or bus) is lost, as when its process is killed. (It
    /// comes back with its state as it was, as a process paused rather than restarted.)
    pub fn take_down(&mut self, s: usize, from: SimTime, until: SimTime) {
        if let Some(d) = self.down.get_mut(s) {
            d.push((from, until));
        }
    }

    /// Cuts the bus between shards `a` and `b` (both ways) over `[from, until)`: each
    /// still hears the others, as a mesh with one broken link.
    pub fn cut(&mut self, a: usize, b: usize, from: SimTime, until: SimTime) {
        self.cuts.push((a, b, from, until));
    }

    fn is_cut(&self, from: usize, to: usize) -> bool {
        self.cuts.iter().any(|&(a, b, t0, t1)| {
            ((a, b) == (from, to) || (a, b) == (to, from)) && self.now >= t0 && self.now < t1
        })
    }

    fn is_down(&self, s: usize) -> bool {
        self.down[s]
            .iter()
            .any(|&(from, until)| self.now >= from && self.now < until)
    }

    /// Runs until virtual time `end`, calling `observe` after every step.
    pub fn run_until(&mut self, end: SimTime, mut observe: impl FnMut(&Self)) {
        while self.now < end {
            self.step();
            observe(self);
        }
    }

    /// Advances by one physics step.
    pub fn step(&mut self) {
        self.now = self.now + PHYSICS_STEP;
        let now = self.now;
        for v in &mut self.vehicles {
            v.handle_timeout(now);
        }
        for i in 0..self.vehicles.len() {
            while let Some(tx) = self.vehicles[i].poll_transmit() {
                if tx.link == LinkId::Offboard {
                    self.send_mavlink(false, i, tx.bytes);
                } else {
                    self.vehicles[i].recycle(tx.bytes);
                }
            }
            while self.vehicles[i].poll_event().is_some() {}
        }
        self.deliver(now);
        for s in 0..self.shards.len() {
            if self.is_down(s) {
                continue;
            }
            if now >= self.shards[s].poll_timeout() {
                self.shards[s].handle_timeout(now);
            }
            while let Some((i, bytes)) = self.shards[s].poll_transmit() {
                self.send_mavlink(true, i, bytes);
            }
            while let Some(message) = self.shards[s].poll_shard_message() {
                self.publish(s, &message);
            }
        }
        self.deliver(now);
    }

    /// Encodes a shard's message once and puts it on the bus to every shard that reads
    /// it (each copy with its own delay and loss draw).
    fn publish(&mut self, from: usize, message: &ShardMessage) {
        self.scratch.clear();
        encode(message, &mut self.scratch);
        for to in 0..self.shards.len() {
            if to == from {
                continue;
            }
            let reads = match message {
                // As its Zenoh subscriptions would: a watched neighbour, or a state
                // in a tile it reads.
                ShardMessage::Vehicle(v) => self.shards[to].shard_reads(v),
                ShardMessage::Shard(_) => true,
            };
            if !reads {
                continue;
            }
            if self.is_cut(from, to) {
                self.counts.sent += 1;
                self.counts.lost += 1;
                continue;
            }
            let mut arrived = false;
            for delay in self.bus_conditions.faults.copies(&mut self.bus_rng) {
                self.counts.sent += 1;
                self.counts.bytes += self.scratch.len() as u64;
                let payload = Payload {
                    to,
                    bytes: self.scratch.clone(),
                };
                arrived |= self.bus.push(self.now + delay, payload).is_ok();
            }
            if !arrived {
                self.counts.lost += 1;
            }
        }
    }

    fn send_mavlink(&mut self, to_vehicle: bool, index: usize, bytes: Vec<u8>) {
        let shard = self.owner[index];
        if self.is_down(shard) {
            self.recycle(to_vehicle, index, bytes);
            return;
        }
        let mut copies = self.mavlink_conditions.faults.copies(&mut self.mavlink_rng);
        let mut bytes = Some(bytes);
        while let Some(delay) = copies.next() {
            let copy = if copies.len() == 0 {
                bytes.take()
            } else {
                bytes.clone()
            };
            if let Some(bytes) = copy {
                let held = Datagram {
                    to_vehicle,
                    index,
                    bytes,
                };
                if let Err(dropped) = self.mavlink.push(self.now + delay, held) {
                    self.recycle(to_vehicle, index, dropped.bytes);
                }
            }
        }
        if let Some(bytes) = bytes {
            self.recycle(to_vehicle, index, bytes);
        }
    }

    fn recycle(&mut self, to_vehicle: bool, index: usize, bytes: Vec<u8>) {
        if to_vehicle {
            let shard = self.owner[index];
            self.shards[shard].recycle(index, bytes);
        } else if let Some(v) = self.vehicles.get_mut(index) {
            v.recycle(bytes);
        }
    }

    fn deliver(&mut self, now: SimTime) {
        while let Some(d) = self.mavlink.pop_due(now) {
            let shard = self.owner[d.index];
            if d.to_vehicle {
                self.vehicles[d.index].handle_datagram(now, LinkId::Offboard, &d.bytes);
            } else if !self.is_down(shard) {
                self.shards[shard].handle_datagram(now, d.index, &d.bytes);
            }
            self.recycle(d.to_vehicle, d.index, d.bytes);
        }
        while let Some(p) = self.bus.pop_due(now) {
            if self.is_down(p.to) {
                self.counts.lost += 1;
                continue;
            }
            match decode(&p.bytes) {
                Ok(message) => self.shards[p.to].handle_shard_message(now, &message),
                Err(_) => self.counts.refused += 1,
            }
        }
    }
}
