//! Which links need the swarm's attention: the ones with output queued, served in turn
//! (one datagram a turn), and each link's next deadline, earliest first. A datagram costs
//! O(1) and a timer event visits only the links that are due, not every link; nothing is
//! allocated in steady state (each queue holds every link at most once, plus stale heap
//! entries that are skipped).

use super::VehicleIndex;
use std::cmp::Reverse;
use std::collections::{BinaryHeap, VecDeque};
use std::time::Duration;

use ringswarm_wire::time::SimTime;

/// The output queue and the deadlines of `n` links.
#[derive(Debug, Clone)]
pub(super) struct LinkScheduler {
    /// Links that may have output queued, each once, in the order they got it.
    ready: VecDeque<VehicleIndex>,
    /// Whether a link is in `ready`.
    queued: Vec<bool>,
    /// `(deadline, link)`, earliest first; an entry whose deadline is not
    /// `scheduled[link]` any more is stale and skipped.
    timers: BinaryHeap<Reverse<(SimTime, VehicleIndex)>>,
    /// Each link's deadline as the heap has it.
    scheduled: Vec<SimTime>,
}

impl LinkScheduler {
    /// `n` links, every one due at time zero.
    pub(super) fn new(n: usize) -> Self {
        Self {
            ready: VecDeque::with_capacity(n),
            queued: vec![false; n],
            timers: VehicleIndex::all(n)
                .map(|i| Reverse((SimTime::ZERO, i)))
                .collect(),
            scheduled: vec![SimTime::ZERO; n],
        }
    }

    /// Link `i` has output: served after those already waiting (once, however often
    /// told).
    pub(super) fn has_output(&mut self, i: VehicleIndex) {
        if !self.queued[i] {
            self.queued[i] = true;
            self.ready.push_back(i);
        }
    }

    /// Whether some link may have output.
    pub(super) fn any_output(&self) -> bool {
        !self.ready.is_empty()
    }

    /// The next link to serve; it leaves the queue (put it back with
    /// [`LinkScheduler::has_output`] if it still has output).
    pub(super) fn next_output(&mut self) -> Option<VehicleIndex> {
        let i = self.ready.pop_front()?;
        self.queued[i] = false;
        Some(i)
    }

    /// Link `i`'s deadline is now `t`.
    pub(super) fn schedule(&mut self, i: VehicleIndex, t: SimTime) {
        if t != self.scheduled[i] {
            self.scheduled[i] = t;
            self.timers.push(Reverse((t, i)));
        }
    }

    /// The earliest deadline (possibly a stale one: never later than needed).
    pub(super) fn next_deadline(&self) -> Option<SimTime> {
        self.timers.peek().map(|Reverse((t, _))| *t)
    }

    /// The next link due at `now`, taken off the deadlines (schedule it again after it
    /// ran); stale entries are skipped.
    pub(super) fn next_due(&mut self, now: SimTime) -> Option<VehicleIndex> {
        while let Some(&Reverse((t, i))) = self.timers.peek() {
            if t > now {
                return None;
            }
            self.timers.pop();
            if self.scheduled[i] != t {
                continue; // stale: the link's deadline moved
            }
            self.scheduled[i] = SimTime::MAX;
            return Some(i);
        }
        None
    }

    /// After link `i` ran at `now`: a deadline that stays due (nothing for the link to do
    /// about it) is looked at again `granularity` later, not in a loop.
    pub(super) fn defer_if_still_due(
        &mut self,
        i: VehicleIndex,
        now: SimTime,
        granularity: Duration,
    ) {
        if self.scheduled[i] <= now {
            let later = now + granularity;
            self.scheduled[i] = later;
            self.timers.push(Reverse((later, i)));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const V: fn(usize) -> VehicleIndex = VehicleIndex;

    fn ms(ms: u64) -> SimTime {
        SimTime::from_millis(ms)
    }

    #[test]
    fn output_is_served_in_turn_and_each_link_queued_once() {
        let mut s = LinkScheduler::new(3);
        assert!(!s.any_output());
        for i in [2, 0, 2, 1] {
            s.has_output(V(i));
        }
        assert_eq!(s.next_output(), Some(V(2)));
        s.has_output(V(2)); // still has output: behind the others
        assert_eq!(
            [
                s.next_output(),
                s.next_output(),
                s.next_output(),
                s.next_output()
            ],
            [Some(V(0)), Some(V(1)), Some(V(2)), None]
        );
    }

    #[test]
    fn deadlines_come_due_earliest_first_and_moved_ones_are_skipped() {
        let mut s = LinkScheduler::new(3);
        // Every link is due at zero, then each says when next.
        let mut first: Vec<usize> =
            std::iter::from_fn(|| s.next_due(ms(0)).map(VehicleIndex::get)).collect();
        first.sort_unstable();
        assert_eq!(first, [0, 1, 2]);
        s.schedule(V(0), ms(30));
        s.schedule(V(1), ms(10));
        s.schedule(V(2), ms(20));
        s.schedule(V(2), ms(5)); // moved earlier: its 20 ms entry is stale
        assert_eq!(s.next_deadline(), Some(ms(5)));
        assert_eq!(s.next_due(ms(4)), None);
        assert_eq!(s.next_due(ms(25)), Some(V(2)));
        assert_eq!(s.next_due(ms(25)), Some(V(1)));
        assert_eq!(s.next_due(ms(25)), None); // the stale 20 ms entry is skipped
        // A link that, having run, is still due (it says 25 ms at 25 ms) is looked at
        // again a granule later.
        s.schedule(V(1), ms(25));
        s.defer_if_still_due(V(1), ms(25), Duration::from_millis(1));
        // (The entry at 25 ms is stale now: the deadline asked for may come early, and
        // then finds nothing due.)
        assert_eq!(s.next_deadline(), Some(ms(25)));
        assert_eq!(s.next_due(ms(25)), None);
        assert_eq!(s.next_deadline(), Some(ms(26)));
        assert_eq!(s.next_due(ms(26)), Some(V(1)));
        assert_eq!(s.next_due(ms(30)), Some(V(0)));
    }
}
