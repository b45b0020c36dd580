//! The bus between the shards of one swarm flown in one process: what a shard publishes
//! crosses it as the payload bytes the Zenoh transport carries (encoded, then decoded),
//! with its own seeded latency, jitter and loss (the MAVLink links' fault model). A
//! shard can be taken down (its process gone) and a pair of shards cut apart (a broken
//! mesh).

use ringswarm_sitl::faulty_line::FaultyLine;
use ringswarm_sitl::link_faults::LinkConditions;
use ringswarm_wire::time::SimTime;

use crate::distributed::{ShardMessage, decode, encode};
use crate::swarm::Swarm;

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

/// A payload in flight to shard `to`.
#[derive(Debug)]
struct Payload {
    to: usize,
    bytes: Vec<u8>,
}

/// The bus, and when each shard is down or cut off.
#[derive(Debug)]
pub(super) struct ShardBus {
    line: FaultyLine<Payload>,
    conditions: LinkConditions,
    /// When each shard is down: it neither runs nor hears anything.
    down: Vec<Vec<(SimTime, SimTime)>>,
    /// Pairs of shards that cannot reach each other, and when.
    cuts: Vec<(usize, usize, SimTime, SimTime)>,
    counts: BusCounts,
    /// Reused: one message encoded once for every shard that reads it.
    scratch: Vec<u8>,
}

impl ShardBus {
    /// A bus between `shards` shards, with `conditions` on every payload.
    pub(super) fn new(shards: usize, conditions: LinkConditions, capacity: usize) -> Self {
        Self {
            line: FaultyLine::new(capacity, conditions.seed),
            conditions,
            down: vec![Vec::new(); shards],
            cuts: Vec::new(),
            counts: BusCounts::default(),
            scratch: Vec::new(),
        }
    }

    pub(super) fn counts(&self) -> BusCounts {
        self.counts
    }

    pub(super) fn take_down(&mut self, s: usize, from: SimTime, until: SimTime) {
        if let Some(d) = self.down.get_mut(s) {
            d.push((from, until));
        }
    }

    pub(super) fn cut(&mut self, a: usize, b: usize, from: SimTime, until: SimTime) {
        self.cuts.push((a, b, from, until));
    }

    /// Whether shard `s` is down at `now`.
    pub(super) fn is_down(&self, s: usize, now: SimTime) -> bool {
        self.down
            .get(s)
            .is_some_and(|d| d.iter().any(|&(from, until)| now >= from && now < until))
    }

    fn is_cut(&self, from: usize, to: usize, now: SimTime) -> bool {
        self.cuts.iter().any(|&(a, b, t0, t1)| {
            ((a, b) == (from, to) || (a, b) == (to, from)) && now >= t0 && now < t1
        })
    }

    /// Encodes shard `from`'s message once and puts it on the bus to every shard that
    /// reads it (each copy with its own delay and loss draw).
    pub(super) fn publish(
        &mut self,
        now: SimTime,
        from: usize,
        message: &ShardMessage,
        shards: &[Swarm],
    ) {
        self.scratch.clear();
        encode(message, &mut self.scratch);
        for (to, shard) in shards.iter().enumerate() {
            if to == from {
                continue;
            }
            let reads = match message {
                // As its Zenoh subscriptions would: a watched neighbour, or a state in a
                // tile it reads.
                ShardMessage::Vehicle(v) => shard.shard_reads(v),
                ShardMessage::Shard(_) => true,
            };
            if !reads {
                continue;
            }
            if self.is_cut(from, to, now) {
                self.counts.sent += 1;
                self.counts.lost += 1;
                continue;
            }
            let payload = Payload {
                to,
                bytes: self.scratch.clone(),
            };
            let duplicate = |p: &Payload| Payload {
                to: p.to,
                bytes: p.bytes.clone(),
            };
            let sent = self
                .line
                .send(now, &self.conditions.faults, payload, duplicate, drop);
            self.counts.sent += sent.drawn as u64;
            self.counts.bytes += (sent.drawn * self.scratch.len()) as u64;
            if sent.held == 0 {
                self.counts.lost += 1;
            }
        }
    }

    /// Hands every payload due at `now` to its shard (lost if the shard is down).
    pub(super) fn deliver(&mut self, now: SimTime, shards: &mut [Swarm]) {
        while let Some(p) = self.line.pop_due(now) {
            if self.is_down(p.to, now) {
                self.counts.lost += 1;
                continue;
            }
            match decode(&p.bytes) {
                Ok(message) => shards[p.to].handle_shard_message(now, &message),
                Err(_) => self.counts.refused += 1,
            }
        }
    }
}
