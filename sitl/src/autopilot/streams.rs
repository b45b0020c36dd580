//! One link's telemetry schedule, as PX4's `mavlink` module keeps it per instance: a
//! message id and its interval per stream, SET_MESSAGE_INTERVAL changing one, and which
//! are due at a given time. It builds nothing and sends nothing.

use std::time::Duration;

use crate::time::SimTime;

/// One telemetry stream.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Stream {
    msg_id: u32,
    default_interval: Option<Duration>,
    interval: Option<Duration>,
    next_due: SimTime,
}

/// The streams of one link and when each is next due.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct StreamTable {
    streams: Vec<Stream>,
    /// No stream is due before this (a lower bound: the table is scanned only then).
    due: SimTime,
}

impl StreamTable {
    /// Streams at `(message id, rate in Hz)`, all due at time zero; a rate is finite and
    /// positive (the vehicle's configuration checks it).
    pub(super) fn at_rates(rates: &[(u32, f64)]) -> Self {
        let streams = rates
            .iter()
            .map(|&(msg_id, hz)| {
                let interval = Some(Duration::from_secs_f64(1.0 / hz));
                Stream {
                    msg_id,
                    default_interval: interval,
                    interval,
                    next_due: SimTime::ZERO,
                }
            })
            .collect();
        Self {
            streams,
            due: SimTime::ZERO,
        }
    }

    /// Every stream due at `now`, in table order, pushed onto `out`; each is then due one
    /// interval later (or one interval after `now`, when it fell behind by more than one).
    pub(super) fn take_due(&mut self, now: SimTime, out: &mut Vec<u32>) {
        if self.due > now {
            return;
        }
        let mut earliest = SimTime::MAX;
        for stream in &mut self.streams {
            let Some(interval) = stream.interval else {
                continue;
            };
            if stream.next_due > now {
                earliest = earliest.min(stream.next_due);
                continue;
            }
            out.push(stream.msg_id);
            let next = stream.next_due + interval;
            stream.next_due = if next <= now { now + interval } else { next };
            earliest = earliest.min(stream.next_due);
        }
        self.due = earliest;
    }

    /// Sets a stream's interval, due at once: `Some(None)` stops it, `None` restores its
    /// default (none for a stream the table did not start with).
    pub(super) fn set_interval(
        &mut self,
        now: SimTime,
        msg_id: u32,
        interval: Option<Option<Duration>>,
    ) {
        let index = match self.streams.iter().position(|s| s.msg_id == msg_id) {
            Some(i) => i,
            None => {
                self.streams.push(Stream {
                    msg_id,
                    default_interval: None,
                    interval: None,
                    next_due: now,
                });
                self.streams.len() - 1
            }
        };
        let stream = &mut self.streams[index];
        stream.interval = interval.unwrap_or(stream.default_interval);
        stream.next_due = now;
        self.due = self.due.min(now);
    }

    /// Every stream due at `now` (after a reboot at `now`).
    pub(super) fn restart_at(&mut self, now: SimTime) {
        for stream in &mut self.streams {
            stream.next_due = now;
        }
        self.due = now;
    }

    /// The interval of a message's stream (`None`: not streamed).
    #[cfg(test)]
    pub(super) fn interval(&self, msg_id: u32) -> Option<Duration> {
        self.streams
            .iter()
            .find(|s| s.msg_id == msg_id)
            .and_then(|s| s.interval)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(v: u64) -> SimTime {
        SimTime::ZERO + Duration::from_millis(v)
    }

    /// The ids due at each millisecond from `from` to `to` inclusive.
    fn due_over(table: &mut StreamTable, from: u64, to: u64) -> Vec<(u64, u32)> {
        let mut seen = Vec::new();
        let mut out = Vec::new();
        for t in from..=to {
            out.clear();
            table.take_due(ms(t), &mut out);
            seen.extend(out.iter().map(|&id| (t, id)));
        }
        seen
    }

    #[test]
    fn streams_fire_at_their_rates_in_table_order() {
        // 1 Hz and 4 Hz over 1 s inclusive: the 4 Hz one at 0, 250, 500, 750, 1000 ms.
        let mut table = StreamTable::at_rates(&[(0, 1.0), (32, 4.0)]);
        let seen = due_over(&mut table, 0, 1000);
        assert_eq!(
            seen,
            vec![
                (0, 0),
                (0, 32),
                (250, 32),
                (500, 32),
                (750, 32),
                (1000, 0),
                (1000, 32)
            ]
        );
    }

    #[test]
    fn a_late_scan_skips_ahead_instead_of_bursting() {
        let mut table = StreamTable::at_rates(&[(32, 10.0)]);
        let mut out = Vec::new();
        table.take_due(ms(0), &mut out);
        // Scanned again only at 350 ms: one message, the next one 100 ms later, not at
        // the 100 ms grid's 400.
        table.take_due(ms(350), &mut out);
        assert_eq!(out, vec![32, 32]);
        out.clear();
        assert_eq!(due_over(&mut table, 351, 450), vec![(450, 32)]);
    }

    #[test]
    fn set_interval_stops_restores_and_adds() {
        let mut table = StreamTable::at_rates(&[(30, 50.0)]);
        table.set_interval(ms(0), 30, Some(None));
        assert_eq!(table.interval(30), None);
        assert!(due_over(&mut table, 0, 100).is_empty());
        table.set_interval(ms(200), 30, None);
        assert_eq!(table.interval(30), Some(Duration::from_millis(20)));
        // A stream not in the table is added, due at once; its default is none.
        table.set_interval(ms(200), 147, Some(Some(Duration::from_millis(500))));
        assert_eq!(
            due_over(&mut table, 200, 220),
            vec![(200, 30), (200, 147), (220, 30)]
        );
        table.set_interval(ms(300), 147, None);
        assert_eq!(table.interval(147), None);
    }

    #[test]
    fn restart_makes_every_stream_due() {
        let mut table = StreamTable::at_rates(&[(0, 1.0), (1, 2.0)]);
        let mut out = Vec::new();
        table.take_due(ms(0), &mut out);
        out.clear();
        table.restart_at(ms(10));
        table.take_due(ms(10), &mut out);
        assert_eq!(out, vec![0, 1]);
    }
}
