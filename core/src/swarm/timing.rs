//! How punctual the control loop is: each tick's start against its schedule, and the age
//! of each flying vehicle's position report when the law uses it. Fixed-size histograms:
//! recording costs a division and an increment, and nothing is allocated after
//! construction, however long the flight.

use std::time::Duration;

use ringswarm_wire::time::SimTime;
use serde::Serialize;

/// Durations counted in log-linear bins: exact to the microsecond below 1.024 ms, within
/// 0.2 % above (512 bins per octave), up to 2⁴² µs (50 days); the longest is kept exactly.
#[derive(Debug, Clone, PartialEq)]
pub struct Histogram {
    counts: Vec<u64>,
    /// Samples beyond the last bin.
    overflow: u64,
    total: u64,
    max_us: u64,
}

/// Values below this are counted exactly.
const LINEAR_US: u64 = 1024;
/// Bins per octave above [`LINEAR_US`].
const PER_OCTAVE: u64 = 512;
/// Octaves above [`LINEAR_US`] (2¹⁰ … 2⁴² µs).
const OCTAVES: u64 = 32;

impl Default for Histogram {
    fn default() -> Self {
        Self::new()
    }
}

impl Histogram {
    /// An empty histogram (136 KiB, allocated once).
    pub fn new() -> Self {
        Self {
            counts: vec![0; (LINEAR_US + OCTAVES * PER_OCTAVE) as usize],
            overflow: 0,
            total: 0,
            max_us: 0,
        }
    }

    /// The bin of `us`.
    fn bin(us: u64) -> u64 {
        if us < LINEAR_US {
            return us;
        }
        let octave = u64::from(63 - us.leading_zeros()); // ≥ 10
        let shift = octave - 9; // (us >> shift) in [512, 1024)
        LINEAR_US + (octave - 10) * PER_OCTAVE + ((us >> shift) - PER_OCTAVE)
    }

    /// The largest value in bin `b`.
    fn bin_top(b: u64) -> u64 {
        if b < LINEAR_US {
            return b;
        }
        let octave = (b - LINEAR_US) / PER_OCTAVE + 10;
        let shift = octave - 9;
        let mantissa = (b - LINEAR_US) % PER_OCTAVE + PER_OCTAVE;
        ((mantissa + 1) << shift) - 1
    }

    /// Counts one duration.
    pub fn record(&mut self, d: Duration) {
        let us = u64::try_from(d.as_micros()).unwrap_or(u64::MAX);
        let bin = usize::try_from(Self::bin(us)).unwrap_or(usize::MAX);
        match self.counts.get_mut(bin) {
            Some(c) => *c += 1,
            None => self.overflow += 1,
        }
        self.total += 1;
        self.max_us = self.max_us.max(us);
    }

    /// Samples counted.
    pub fn total(&self) -> u64 {
        self.total
    }

    /// The longest sample.
    pub fn max(&self) -> Duration {
        Duration::from_micros(self.max_us)
    }

    /// The median, the 99th percentile and the longest, in ms.
    pub fn quantiles(&self) -> Quantiles {
        let ms = |d: Option<Duration>| d.map(|d| d.as_secs_f64() * 1e3);
        Quantiles {
            samples: self.total(),
            p50_ms: ms(self.quantile(0.5)),
            p99_ms: ms(self.quantile(0.99)),
            max_ms: ms((self.total() > 0).then(|| self.max())),
        }
    }

    /// The `q`-quantile (0 ≤ q ≤ 1): the smallest value with at least ⌈q·n⌉ samples at or
    /// below it, exact below 1.024 ms, the top of its bin above (never below the true
    /// quantile, at most 0.2 % above it); `None` before any sample.
    pub fn quantile(&self, q: f64) -> Option<Duration> {
        if self.total == 0 {
            return None;
        }
        let rank = ((q.clamp(0.0, 1.0) * self.total as f64).ceil() as u64).max(1);
        let mut seen = 0;
        for (bin, count) in self.counts.iter().enumerate() {
            seen += count;
            if seen >= rank {
                let top = Self::bin_top(bin as u64).min(self.max_us);
                return Some(Duration::from_micros(top));
            }
        }
        Some(self.max())
    }
}

/// The control loop's punctuality, fed by the swarm each tick.
#[derive(Debug, Clone)]
pub struct TickTiming {
    period: Duration,
    lateness: Histogram,
    state_age: Histogram,
    remote_state_age: Histogram,
    /// Ticks that started more than half a period late (counted exactly).
    late: u64,
    /// When the latest tick started (scheduled time, s), and how late.
    worst: Option<(SimTime, Duration)>,
}

impl TickTiming {
    /// Timing of a loop scheduled every `period`.
    pub fn new(period: Duration) -> Self {
        Self {
            period,
            lateness: Histogram::new(),
            state_age: Histogram::new(),
            remote_state_age: Histogram::new(),
            late: 0,
            worst: None,
        }
    }

    /// A tick scheduled for `due` started at `now`; how late, and the count of late ticks
    /// so far, when it is one (over half a period).
    pub fn tick(&mut self, due: SimTime, now: SimTime) -> Option<(Duration, u64)> {
        let late = now.saturating_since(due);
        let is_late = late > self.period / 2;
        self.late += u64::from(is_late);
        if self.worst.is_none_or(|(_, worst)| late > worst) {
            self.worst = Some((due, late));
        }
        self.lateness.record(late);
        is_late.then_some((late, self.late))
    }

    /// A vehicle's position, reported at `at`, used at `now`.
    pub fn state_age(&mut self, at: SimTime, now: SimTime) {
        self.state_age.record(now.saturating_since(at));
    }

    /// Another shard's vehicle's position, measured at `at` (its shard's arrival, on
    /// this shard's clock), used at `now`: the hop between shards and the ticks on
    /// both sides.
    pub fn remote_state_age(&mut self, at: SimTime, now: SimTime) {
        self.remote_state_age.record(now.saturating_since(at));
    }

    /// The figures so far.
    pub fn report(&self) -> TimingReport {
        let quantiles = Histogram::quantiles;
        let late = self.late;
        TimingReport {
            control_period_ms: self.period.as_secs_f64() * 1e3,
            late_ticks: late,
            latest_tick_due_s: self.worst.map(|(due, _)| due.as_secs_f64()),
            late_fraction: if self.lateness.total() == 0 {
                0.0
            } else {
                late as f64 / self.lateness.total() as f64
            },
            lateness: quantiles(&self.lateness),
            state_age: quantiles(&self.state_age),
            remote_state_age: quantiles(&self.remote_state_age),
        }
    }
}

/// Quantiles of one histogram (ms; `null` before any sample).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Quantiles {
    /// Samples counted.
    pub samples: u64,
    /// Median (exact below 1.024 ms, within 0.2 % above).
    pub p50_ms: Option<f64>,
    /// 99th percentile, likewise.
    pub p99_ms: Option<f64>,
    /// The longest.
    pub max_ms: Option<f64>,
}

/// The control loop's punctuality over a flight, as `summary.json` has it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TimingReport {
    /// The control period (ms).
    pub control_period_ms: f64,
    /// Control ticks that started more than half a period after their schedule.
    pub late_ticks: u64,
    /// `late_ticks` over all ticks.
    pub late_fraction: f64,
    /// When the latest tick was due (s since start): where to look for what held it up.
    pub latest_tick_due_s: Option<f64>,
    /// How long after its schedule each control tick started.
    pub lateness: Quantiles,
    /// Age of each flying vehicle's latest position report at each tick (the report's
    /// arrival, not its timestamp: it includes the time on the wire after the vehicle
    /// sent it only as far as the coordinator can see it).
    pub state_age: Quantiles,
    /// With shards: the age of each other shard's vehicle's position at each tick it is
    /// flown on, from its arrival at its own shard (the hop between shards and the
    /// ticks on both sides); no samples in one process.
    pub remote_state_age: Quantiles,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(v: f64) -> Duration {
        Duration::from_secs_f64(v / 1e3)
    }

    #[test]
    fn bins_are_exact_below_a_millisecond_and_within_0_2_percent_above() {
        for us in [0, 1, 999, 1023] {
            assert_eq!(Histogram::bin(us), us);
            assert_eq!(Histogram::bin_top(us), us);
        }
        // 1024 µs opens the first octave: bins 2 µs wide up to 2048.
        assert_eq!(Histogram::bin(1024), 1024);
        assert_eq!(Histogram::bin(1025), 1024);
        assert_eq!(Histogram::bin_top(1024), 1025);
        assert_eq!(Histogram::bin(2048), 1024 + 512);
        assert_eq!(Histogram::bin_top(1024 + 512), 2051);
        // Every value lies in its bin, whose top is at most 1/512 above it.
        let mut us = 1u64;
        while us < 1 << 42 {
            for v in [us, us + us / 3, 2 * us - 1] {
                let top = Histogram::bin_top(Histogram::bin(v));
                assert!(
                    top >= v && (top - v) as f64 <= v as f64 / 512.0,
                    "{v} → {top}"
                );
                assert!(Histogram::bin(top) == Histogram::bin(v));
            }
            us *= 2;
        }
    }

    #[test]
    fn quantiles_are_exact_below_a_millisecond() {
        let mut h = Histogram::new();
        assert_eq!(h.quantile(0.5), None);
        // 10, 20, …, 1000 µs: the 50th is 500 µs, the 99th 990 µs.
        for i in 1..=100u64 {
            h.record(Duration::from_micros(10 * i));
        }
        assert_eq!(h.total(), 100);
        assert_eq!(h.quantile(0.5), Some(Duration::from_micros(500)));
        assert_eq!(h.quantile(0.99), Some(Duration::from_micros(990)));
        assert_eq!(h.quantile(0.0), Some(Duration::from_micros(10)));
        assert_eq!(h.quantile(1.0), Some(Duration::from_micros(1000)));
    }

    #[test]
    fn quantiles_above_a_millisecond_are_bin_tops_capped_at_the_maximum() {
        let mut h = Histogram::new();
        // 20 000 µs lies in the octave [16 384, 32 768): bins 32 µs wide, its bin is
        // [20 000, 20 032) (20 000 = 625 × 32), top 20 031; the maximum caps it.
        h.record(Duration::from_micros(20_000));
        h.record(Duration::from_micros(20_001));
        assert_eq!(h.quantile(0.5), Some(Duration::from_micros(20_001)));
        h.record(Duration::from_micros(30_000));
        assert_eq!(h.quantile(0.5), Some(Duration::from_micros(20_031)));
        assert_eq!(h.quantile(1.0), Some(Duration::from_micros(30_000)));
        // Beyond 2^42 µs: counted, the maximum kept.
        h.record(Duration::from_secs(100 * 86_400));
        assert_eq!(h.total(), 4);
        assert_eq!(h.quantile(1.0), Some(Duration::from_secs(100 * 86_400)));
    }

    #[test]
    fn late_ticks_are_those_over_half_a_period() {
        let mut t = TickTiming::new(ms(20.0));
        let due = SimTime::from_micros(1_000_000);
        let said: Vec<_> = [0, 500, 9_950, 10_000, 10_050, 40_000]
            .into_iter()
            .filter_map(|late_us| t.tick(due, due + Duration::from_micros(late_us)))
            .collect();
        // Each late one says how late, and how many so far.
        assert_eq!(said, vec![(ms(10.05), 1), (ms(40.0), 2)]);
        // A tick that starts before its schedule counts as on time.
        assert_eq!(t.tick(due, SimTime::from_micros(999_000)), None);
        let r = t.report();
        assert_eq!(r.lateness.samples, 7);
        // Strictly more than 10 ms: 10.05 ms and 40 ms.
        assert_eq!(r.late_ticks, 2);
        assert!((r.late_fraction - 2.0 / 7.0).abs() < 1e-12);
        assert_eq!(r.lateness.max_ms, Some(40.0));
        assert_eq!(r.latest_tick_due_s, Some(1.0));
        assert_eq!(r.control_period_ms, 20.0);
        assert_eq!(r.state_age.p50_ms, None);
    }
}
