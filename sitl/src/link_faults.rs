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

/// Link conditions between the coordinator and every vehicle (both directions): the
/// emulator's fault model, and the seed of its draws.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinkConditions {
    /// Loss, latency, jitter and duplication.
    pub faults: LinkFaults,
    /// Seed of the draws.
    pub seed: u64,
}

impl Default for LinkConditions {
    fn default() -> Self {
        Self {
            faults: LinkFaults::default(),
            seed: 1,
        }
    }
}

/// The longest latency or jitter a link takes (ms).
pub const MAX_DELAY_MS: f64 = 10_000.0;

impl LinkFaults {
    /// From the units a user types: percentages in [0, 100] and milliseconds in
    /// [0, [`MAX_DELAY_MS`]]. The one place these are checked, for every way they come
    /// in (the coordinator's `[emulator]`, `sitl`'s flags and its `[faults]`).
    ///
    /// # Errors
    /// Every value out of its range (NaN included), one per line, named by `names`
    /// (loss, latency, jitter, duplicate, as the caller's user wrote them).
    pub fn from_percent_and_ms(
        loss_pct: f64,
        latency_ms: f64,
        jitter_ms: f64,
        duplicate_pct: f64,
        names: [&str; 4],
    ) -> Result<Self, String> {
        let mut problems = Vec::new();
        for (name, pct) in [(names[0], loss_pct), (names[3], duplicate_pct)] {
            if !(0.0..=100.0).contains(&pct) {
                problems.push(format!(
                    "{name} must be a percentage in [0, 100], got {pct}"
                ));
            }
        }
        for (name, ms) in [(names[1], latency_ms), (names[2], jitter_ms)] {
            if !(0.0..=MAX_DELAY_MS).contains(&ms) {
                problems.push(format!("{name} must be in [0, 10000] ms, got {ms}"));
            }
        }
        if !problems.is_empty() {
            return Err(problems.join("\n"));
        }
        Ok(Self {
            loss: loss_pct / 100.0,
            latency: Duration::from_secs_f64(latency_ms / 1000.0),
            jitter: Duration::from_secs_f64(jitter_ms / 1000.0),
            duplicate: duplicate_pct / 100.0,
        })
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
