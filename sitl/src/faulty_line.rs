//! A simulated link's one way of sending: the seeded draw of each datagram's copies under
//! the link's faults (lost, delayed, duplicated) and the [`DelayLine`] that holds them
//! until they are due. The one fault-send path of the coordinator's lockstep driver (its
//! MAVLink links both ways, and the bus between its shards) and of the emulator's UDP
//! fleet.
//!
//! The RNG belongs to the line, so the draws follow the order of the sends: the same
//! sends give the same copies, bit for bit.

use std::time::Duration;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::delay_line::DelayLine;
use crate::link_faults::LinkFaults;
use crate::time::SimTime;

/// Items sent through seeded link faults and held until due.
#[derive(Debug)]
pub struct FaultyLine<T> {
    line: DelayLine<T>,
    rng: ChaCha8Rng,
}

/// What became of one item sent with [`FaultyLine::send`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Sent {
    /// Copies the faults let through (0: lost; 2: duplicated).
    pub drawn: usize,
    /// Copies the line took (a full line refuses).
    pub held: usize,
}

impl<T> FaultyLine<T> {
    /// An empty line holding at most `capacity` items, its draws seeded with `seed`.
    pub fn new(capacity: usize, seed: u64) -> Self {
        Self {
            line: DelayLine::new(capacity),
            rng: ChaCha8Rng::seed_from_u64(seed),
        }
    }

    /// Sends `item` at `now` through `faults`: each copy that survives is held until its
    /// delay has passed (a copy without delay leaves at the next [`FaultyLine::pop_due`]
    /// of the same instant). The last copy is `item` itself, the others are made by
    /// `duplicate` (a clean link copies nothing); what is lost, or refused by a full
    /// line, goes to `give_back` (its buffer reused).
    pub fn send(
        &mut self,
        now: SimTime,
        faults: &LinkFaults,
        item: T,
        duplicate: impl Fn(&T) -> T,
        mut give_back: impl FnMut(T),
    ) -> Sent {
        if faults.is_clean() {
            // What the draw below gives a clean link (the item itself, due now, nothing
            // drawn from the RNG), without it: every datagram of a clean flight comes here.
            let held = match self.line.push(now, item) {
                Ok(()) => 1,
                Err(refused) => {
                    give_back(refused);
                    0
                }
            };
            return Sent { drawn: 1, held };
        }
        let mut copies = faults.copies(&mut self.rng);
        let drawn = copies.len();
        let mut held = 0;
        let mut item = Some(item);
        while let Some(delay) = copies.next() {
            let copy = if copies.len() == 0 {
                item.take()
            } else {
                item.as_ref().map(&duplicate)
            };
            if let Some(copy) = copy {
                match self.line.push(now + delay, copy) {
                    Ok(()) => held += 1,
                    Err(refused) => give_back(refused),
                }
            }
        }
        if let Some(lost) = item {
            give_back(lost);
        }
        Sent { drawn, held }
    }

    /// The delays of one datagram's surviving copies, for a sender that only borrows it
    /// and hands a copy without delay on at once (the fleet's, where a clean link must
    /// cost no copy); each delayed copy then goes to [`FaultyLine::hold`].
    pub fn draw(
        &mut self,
        faults: &LinkFaults,
    ) -> std::iter::Take<std::array::IntoIter<Duration, 2>> {
        faults.copies(&mut self.rng)
    }

    /// Holds `item` until `due`.
    ///
    /// # Errors
    /// The line is full: the item comes back.
    pub fn hold(&mut self, due: SimTime, item: T) -> Result<(), T> {
        self.line.push(due, item)
    }

    /// The next item due at or before `now`, earliest first (ties in sending order).
    pub fn pop_due(&mut self, now: SimTime) -> Option<T> {
        self.line.pop_due(now)
    }

    /// Items held.
    pub fn len(&self) -> usize {
        self.line.len()
    }

    /// Whether nothing is held.
    pub fn is_empty(&self) -> bool {
        self.line.is_empty()
    }

    /// Items refused because the line was full.
    pub fn refused(&self) -> u64 {
        self.line.refused()
    }

    /// Drops everything held, returning the items.
    pub fn drain(&mut self) -> impl Iterator<Item = T> + '_ {
        self.line.drain()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn faults(loss_pct: f64, latency_ms: u64, duplicate_pct: f64) -> LinkFaults {
        LinkFaults::from_percent_and_ms(
            loss_pct,
            latency_ms as f64,
            0.0,
            duplicate_pct,
            ["loss", "latency", "jitter", "duplicate"],
        )
        .expect("valid faults")
    }

    #[test]
    fn a_clean_link_holds_the_item_itself_due_now() {
        let mut line = FaultyLine::new(4, 1);
        let t = SimTime::from_millis(5);
        let sent = line.send(
            t,
            &LinkFaults::default(),
            vec![1u8],
            |_| panic!("copied"),
            |_| panic!("given back"),
        );
        assert_eq!(sent, Sent { drawn: 1, held: 1 });
        assert_eq!(line.pop_due(t), Some(vec![1]));
    }

    #[test]
    fn a_duplicating_link_copies_once_and_delays_both() {
        let mut line = FaultyLine::new(4, 7);
        let t = SimTime::from_millis(0);
        let sent = line.send(
            t,
            &faults(0.0, 20, 100.0),
            'x',
            |c| c.to_ascii_uppercase(),
            |_| {},
        );
        assert_eq!(sent, Sent { drawn: 2, held: 2 });
        assert_eq!(line.pop_due(SimTime::from_millis(19)), None);
        let due = SimTime::from_millis(20);
        assert_eq!(
            (line.pop_due(due), line.pop_due(due)),
            (Some('X'), Some('x'))
        );
    }

    #[test]
    fn a_lost_or_refused_item_is_given_back() {
        let mut line = FaultyLine::new(1, 3);
        let mut back = Vec::new();
        let lost = line.send(
            SimTime::ZERO,
            &faults(100.0, 0, 0.0),
            1,
            |c| *c,
            |c| back.push(c),
        );
        assert_eq!(lost, Sent { drawn: 0, held: 0 });
        line.send(
            SimTime::ZERO,
            &LinkFaults::default(),
            2,
            |c| *c,
            |c| back.push(c),
        );
        let refused = line.send(
            SimTime::ZERO,
            &LinkFaults::default(),
            3,
            |c| *c,
            |c| back.push(c),
        );
        assert_eq!(refused, Sent { drawn: 1, held: 0 });
        assert_eq!((back, line.refused()), (vec![1, 3], 1));
    }

    #[test]
    fn the_same_seed_draws_the_same_copies() {
        let f = faults(30.0, 10, 30.0);
        let run = |seed| {
            let mut line = FaultyLine::new(1000, seed);
            (0..200)
                .map(|k| line.send(SimTime::ZERO, &f, k, |c| *c, |_| {}).drawn)
                .collect::<Vec<_>>()
        };
        assert_eq!(run(9), run(9));
        assert_ne!(run(9), run(10));
    }
}
