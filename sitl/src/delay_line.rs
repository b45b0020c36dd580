//! A bounded line of items held back until a due time: the latency of a simulated link.
//! One for the emulator's UDP fleet and the coordinator's lockstep driver.
//!
//! Items leave in order of (due time, arrival): the earliest due first, and among items
//! due at the same instant, the first pushed. An item due no earlier than the last one
//! queued in order (a link of constant latency, the usual case) is queued in order at
//! O(1); any other waits in a heap at O(log n), and taking compares the two heads. A full
//! line refuses an item (handing it back to the caller, and counting it) rather than
//! growing without limit, as a router's full queue drops a datagram.

use std::cmp::{Ordering, Reverse};
use std::collections::{BinaryHeap, VecDeque};

use crate::time::SimTime;

/// Items held until their due time, at most `capacity` at once.
#[derive(Debug)]
pub struct DelayLine<T> {
    /// Items in (due, arrival) order: each due no earlier than the one before.
    in_order: VecDeque<Held<T>>,
    /// The others.
    heap: BinaryHeap<Reverse<Held<T>>>,
    capacity: usize,
    /// Arrival order, the tie-break between items due together.
    next_seq: u64,
    refused: u64,
}

#[derive(Debug)]
struct Held<T> {
    due: SimTime,
    seq: u64,
    item: T,
}

impl<T> PartialEq for Held<T> {
    fn eq(&self, other: &Self) -> bool {
        (self.due, self.seq) == (other.due, other.seq)
    }
}
impl<T> Eq for Held<T> {}
impl<T> PartialOrd for Held<T> {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl<T> Ord for Held<T> {
    fn cmp(&self, other: &Self) -> Ordering {
        (self.due, self.seq).cmp(&(other.due, other.seq))
    }
}

impl<T> DelayLine<T> {
    /// An empty line that holds at most `capacity` items (at least one).
    pub fn new(capacity: usize) -> Self {
        Self {
            in_order: VecDeque::new(),
            heap: BinaryHeap::new(),
            capacity: capacity.max(1),
            next_seq: 0,
            refused: 0,
        }
    }

    /// Holds `item` until `due`.
    ///
    /// # Errors
    /// The line is full: the item comes back (and is counted in [`DelayLine::refused`]).
    pub fn push(&mut self, due: SimTime, item: T) -> Result<(), T> {
        if self.len() >= self.capacity {
            self.refused += 1;
            return Err(item);
        }
        let seq = self.next_seq;
        self.next_seq += 1;
        let held = Held { due, seq, item };
        // Later in arrival than everything queued in order, so in order when due no
        // earlier than its last.
        if self.in_order.back().is_none_or(|last| last.due <= due) {
            self.in_order.push_back(held);
        } else {
            self.heap.push(Reverse(held));
        }
        Ok(())
    }

    /// The next item due at or before `now`, earliest first.
    pub fn pop_due(&mut self, now: SimTime) -> Option<T> {
        let first = self.in_order.front().map(|h| (h.due, h.seq));
        let other = self.heap.peek().map(|Reverse(h)| (h.due, h.seq));
        let in_order_first = match (first, other) {
            (Some(a), Some(b)) => a < b,
            (Some(_), None) => true,
            (None, _) => false,
        };
        if in_order_first {
            match self.in_order.front() {
                Some(h) if h.due <= now => self.in_order.pop_front().map(|h| h.item),
                _ => None,
            }
        } else if self.heap.peek().is_some_and(|Reverse(h)| h.due <= now) {
            self.heap.pop().map(|Reverse(h)| h.item)
        } else {
            None
        }
    }

    /// Items held.
    pub fn len(&self) -> usize {
        self.in_order.len() + self.heap.len()
    }

    /// Whether nothing is held.
    pub fn is_empty(&self) -> bool {
        self.in_order.is_empty() && self.heap.is_empty()
    }

    /// Drops everything held, returning the items (a powered-off vehicle's traffic).
    pub fn drain(&mut self) -> impl Iterator<Item = T> + '_ {
        self.in_order
            .drain(..)
            .chain(self.heap.drain().map(|Reverse(h)| h))
            .map(|h| h.item)
    }

    /// Items refused because the line was full, since it was made.
    pub fn refused(&self) -> u64 {
        self.refused
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(ms: u64) -> SimTime {
        SimTime::from_millis(ms)
    }

    #[test]
    fn earliest_due_first_and_ties_in_arrival_order() {
        let mut line = DelayLine::new(10);
        for (due, item) in [(5, 'a'), (3, 'b'), (5, 'c'), (3, 'd'), (9, 'e')] {
            line.push(ms(due), item).unwrap();
        }
        assert_eq!(line.pop_due(ms(2)), None);
        let mut out = Vec::new();
        while let Some(x) = line.pop_due(ms(6)) {
            out.push(x);
        }
        assert_eq!(out, ['b', 'd', 'a', 'c']);
        assert_eq!(line.len(), 1);
        assert_eq!(line.pop_due(ms(9)), Some('e'));
        assert!(line.is_empty());
    }

    #[test]
    fn a_full_line_refuses_and_counts_rather_than_grows() {
        let mut line = DelayLine::new(3);
        for i in 0..3 {
            line.push(ms(1), i).unwrap();
        }
        assert_eq!(line.push(ms(0), 99), Err(99));
        assert_eq!(line.push(ms(0), 98), Err(98));
        assert_eq!((line.len(), line.refused()), (3, 2));
        assert_eq!(line.pop_due(ms(1)), Some(0));
        line.push(ms(0), 7).unwrap();
        assert_eq!(line.pop_due(ms(1)), Some(7));
        assert_eq!(line.drain().count(), 2);
        assert!(line.is_empty());
    }

    #[test]
    fn mixed_in_order_and_late_pushes_leave_as_the_earliest_due_then_arrival() {
        // A pseudo-random mix of dues, some repeating, many earlier than the one before,
        // against a reference that takes the least (due, arrival) due by `now` each time.
        let mut line = DelayLine::new(1000);
        let mut reference: Vec<(u64, usize)> = Vec::new();
        let mut x: u64 = 12345;
        let mut now = 0;
        let mut late = 0;
        let mut last_due = 0;
        for k in 0..400 {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let due = now + (x >> 33) % 7;
            late += usize::from(due < last_due);
            last_due = due;
            line.push(ms(due), k).unwrap();
            reference.push((due, k));
            if k % 3 == 0 {
                now += 1;
                loop {
                    let expected = reference.iter().copied().filter(|&(d, _)| d <= now).min();
                    assert_eq!(line.pop_due(ms(now)), expected.map(|e| e.1), "at {now} ms");
                    let Some(e) = expected else { break };
                    reference.retain(|&r| r != e);
                }
            }
        }
        assert_eq!(line.len(), reference.len());
        assert!(late > 50, "{late} pushes earlier than the one before");
    }
}
