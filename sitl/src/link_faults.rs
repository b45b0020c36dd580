//! The faults a simulated link injects, in each direction: loss, latency with jitter,
//! duplication, drawn from a seeded RNG. One model for the emulator's UDP driver and the
//! coordinator's lockstep driver.

use std::time::Duration;

use rand::Rng;

/// Faults injected on one link, in both directions.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LinkFaults {
    /// Probability that a datagram is dropped (0..1).
    pub loss: f64,
    /// Fixed one-way latency.
    pub latency: Duration,
    /// Uniform extra latency in `0..jitter`.
    pub jitter: Duration,
    /// Probability that a datagram is delivered twice (0..1).
    pub duplicate: f64,
}

impl LinkFaults {
    /// From the units a user types: percentages and milliseconds.
    pub fn from_percent_and_ms(
        loss_pct: f64,
        latency_ms: f64,
        jitter_ms: f64,
        duplicate_pct: f64,
    ) -> Self {
        Self {
            loss: loss_pct / 100.0,
            latency: Duration::from_secs_f64(latency_ms / 1000.0),
            jitter: Duration::from_secs_f64(jitter_ms / 1000.0),
            duplicate: duplicate_pct / 100.0,
        }
    }

    /// Whether nothing is injected.
    pub fn is_clean(&self) -> bool {
        self.loss == 0.0 && self.latency.is_zero() && self.jitter.is_zero() && self.duplicate == 0.0
    }

    /// The delays of the copies of one datagram that survive the faults, drawn from
    /// `rng` (empty: lost; two: duplicated). A clean link draws nothing; nothing is
    /// allocated.
    pub fn copies(&self, rng: &mut impl Rng) -> std::iter::Take<std::array::IntoIter<Duration, 2>> {
        let mut delays = [Duration::ZERO; 2];
        let n = if self.is_clean() {
            1
        } else if rng.random::<f64>() < self.loss {
            0
        } else {
            let copies = if rng.random::<f64>() < self.duplicate {
                2
            } else {
                1
            };
            for delay in delays.iter_mut().take(copies) {
                let jitter = if self.jitter.is_zero() {
                    Duration::ZERO
                } else {
                    self.jitter.mul_f64(rng.random::<f64>())
                };
                *delay = self.latency + jitter;
            }
            copies
        };
        delays.into_iter().take(n)
    }
}
