//! How far behind its own sockets the coordinator is: its own stall told apart from a
//! vehicle's silence.
//!
//! A coordinator that stalls (its host busy, its loop late, its receive queue long) has
//! frames waiting for it that it has not read. Judged at the wall clock, every vehicle
//! would look silent at once and be handed to its own Hold, fragmenting the swarm for a
//! fault that is not theirs. So silence is judged only up to the last instant at which
//! everything received had been read: the *listen lag* is how long ago that was, and a
//! link counts a vehicle's silence from its last frame to `now − lag`
//! ([`crate::swarm::Swarm::set_listen_lag`]).
//!
//! The driver has read everything when its receive queue is empty, no socket's last read
//! stopped at the batch size (more was waiting), and, when the loop woke late (its
//! receivers may not have run either), no socket has a datagram waiting.

use std::time::Duration;

use ringswarm_wire::time::SimTime;

/// A wake-up later than this after its deadline may have kept the receivers from running:
/// the sockets are looked at before the lag is reset.
pub const STALL: Duration = Duration::from_millis(20);

/// A lag at which the driver warns (once per stall).
pub const WARN_LAG: Duration = Duration::from_millis(250);

/// The driver's reading of its sockets.
#[derive(Debug, Clone)]
pub struct Listening {
    /// Per socket: its last read stopped at the batch size.
    full: Vec<bool>,
    full_count: usize,
    heard_through: SimTime,
    /// The largest lag of the current stall, while it lasts.
    stall: Option<Duration>,
    /// The largest lag seen.
    max_lag: Duration,
}

/// What ended a stall: its largest lag.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StallEnded {
    /// The lag at its largest.
    pub max_lag: Duration,
}

impl Listening {
    /// Nothing read yet from `sockets` sockets, at time zero.
    pub fn new(sockets: usize) -> Self {
        Self {
            full: vec![false; sockets],
            full_count: 0,
            heard_through: SimTime::ZERO,
            stall: None,
            max_lag: Duration::ZERO,
        }
    }

    /// A batch read from `socket` was handled; `full`: its read stopped at the batch size.
    pub fn batch(&mut self, socket: usize, full: bool) {
        if let Some(was) = self.full.get_mut(socket)
            && *was != full
        {
            *was = full;
            if full {
                self.full_count += 1;
            } else {
                self.full_count -= 1;
            }
        }
    }

    /// The loop has done its work at `now`; `queue_empty`: nothing received is waiting
    /// to be handled; `sockets_waiting`: some socket has a datagram not read yet (looked
    /// at when the loop woke more than [`STALL`] late; `false` otherwise). Returns the
    /// stall that just ended, if any.
    pub fn settle(
        &mut self,
        now: SimTime,
        queue_empty: bool,
        sockets_waiting: bool,
    ) -> Option<StallEnded> {
        let caught_up = queue_empty && self.full_count == 0 && !sockets_waiting;
        if caught_up {
            self.heard_through = self.heard_through.max(now);
        }
        let lag = self.lag(now);
        self.max_lag = self.max_lag.max(lag);
        if lag >= WARN_LAG {
            let worst = self.stall.get_or_insert(lag);
            *worst = (*worst).max(lag);
            None
        } else if caught_up {
            self.stall.take().map(|max_lag| StallEnded { max_lag })
        } else {
            None
        }
    }

    /// How long ago everything received had last been read.
    pub fn lag(&self, now: SimTime) -> Duration {
        now.saturating_since(self.heard_through)
    }

    /// The largest lag seen.
    pub fn max_lag(&self) -> Duration {
        self.max_lag
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(ms: u64) -> SimTime {
        SimTime::from_millis(ms)
    }

    #[test]
    fn on_time_and_caught_up_means_no_lag() {
        let mut l = Listening::new(2);
        assert_eq!(l.settle(ms(10), true, false), None);
        assert_eq!(l.lag(ms(10)), Duration::ZERO);
        assert_eq!(l.settle(ms(30), true, false), None);
        assert_eq!(l.lag(ms(30)), Duration::ZERO);
    }

    #[test]
    fn a_late_wake_a_waiting_queue_or_a_full_read_hold_the_clock_back() {
        let mut l = Listening::new(2);
        l.settle(ms(100), true, false);
        // The host stalled 600 ms: the timer wakes late, the receivers have not run and
        // the sockets hold what came meanwhile.
        l.settle(ms(700), true, true);
        assert_eq!(l.lag(ms(700)), Duration::from_millis(600));
        // They run: a full batch from socket 1, the queue still holding more.
        l.batch(1, true);
        l.settle(ms(705), false, false);
        assert_eq!(l.lag(ms(705)), Duration::from_millis(605));
        // The queue is empty but socket 1 was left with more to read.
        l.settle(ms(706), true, false);
        assert_eq!(l.lag(ms(706)), Duration::from_millis(606));
        // Its next read is short: everything is read.
        l.batch(1, false);
        let ended = l.settle(ms(707), true, false);
        assert_eq!(l.lag(ms(707)), Duration::ZERO);
        assert_eq!(
            ended,
            Some(StallEnded {
                max_lag: Duration::from_millis(606)
            })
        );
        assert_eq!(l.max_lag(), Duration::from_millis(606));
    }
}
