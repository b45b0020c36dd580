//! How fast the formation error grows or decays over a consensus (1/s): the least-squares
//! slope of its natural logarithm over the later half of the stretch in which it could
//! be measured.
//!
//! For a ring flown within its envelopes the error is a sum of the closed loop's modes,
//! `Σ cᵢ·e^{λᵢt}`, and late in the consensus the slowest one dominates: the slope tends
//! to the spectral abscissa `max Re λᵢ` over the non-zero modes, `analyze`'s
//! `closed_loop_abscissa`. It is negative when the formation closes and positive when it
//! opens, and it crosses zero where the theory's stability boundary lies, where the end
//! state of a short flight hardly changes. A swarm that saturates its envelope grows
//! slower than its modes; the sign stays.
//!
//! The stretch ends when the error first falls below [`FLOOR_M`], where MAVLink's
//! single-precision positions and the altitude loop's coupling, not the modes, make it.
//! A consensus that starts again (after a hold) starts a new stretch.
//!
//! Pure: fed samples, no clock.

/// Below this formation error (m) the log is no longer the modes' sum: single-precision
/// positions (6e-5 m at 1 km) and the coupling to the altitude loop leave a floor of a
/// few tenths of a millimetre on an ideal link.
pub const FLOOR_M: f64 = 0.01;

/// Samples are taken this far apart (s): ten a second, whatever the control rate.
pub const SAMPLE_INTERVAL_S: f64 = 0.1;

/// A rate is fitted from at least this many samples (one second of them).
pub const MIN_SAMPLES: usize = 10;

/// The samples of the current consensus, `(t_s, ln e)`, up to the floor.
#[derive(Debug, Clone, Default)]
pub struct GrowthFit {
    /// When the consensus being sampled started (s).
    since_s: Option<f64>,
    /// The next sample is due at or after this time (s).
    next_s: f64,
    /// The error fell below the floor: the stretch is over.
    ended: bool,
    samples: Vec<(f64, f64)>,
}

impl GrowthFit {
    /// Takes the formation error `error_m` at `t_s` of a consensus that started at
    /// `since_s` (both s since the flight started).
    pub fn observe(&mut self, since_s: f64, t_s: f64, error_m: f64) {
        if self.since_s != Some(since_s) {
            self.since_s = Some(since_s);
            self.next_s = t_s;
            self.ended = false;
            self.samples.clear();
        }
        if self.ended || t_s < self.next_s {
            return;
        }
        // The next sample is due a whole interval on, not an interval after this one, so
        // that a control rate that is no multiple of ten a second keeps the spacing.
        while self.next_s <= t_s {
            self.next_s += SAMPLE_INTERVAL_S;
        }
        if !(error_m.is_finite() && error_m >= FLOOR_M) {
            self.ended = true;
            return;
        }
        self.samples.push((t_s, error_m.ln()));
    }

    /// The slope of `ln e` over the later half (in time) of the stretch (1/s); `None`
    /// with fewer than [`MIN_SAMPLES`] samples there.
    pub fn rate_per_s(&self) -> Option<f64> {
        let (first, last) = (self.samples.first()?.0, self.samples.last()?.0);
        let from = first + 0.5 * (last - first);
        let half = &self.samples[self.samples.partition_point(|(t, _)| *t < from)..];
        slope(half)
    }
}

/// The least-squares slope of `y` over `t`; `None` with fewer than [`MIN_SAMPLES`]
/// points or no spread in `t`.
fn slope(points: &[(f64, f64)]) -> Option<f64> {
    if points.len() < MIN_SAMPLES {
        return None;
    }
    let n = points.len() as f64;
    let (mt, my) = points
        .iter()
        .fold((0.0, 0.0), |(a, b), (t, y)| (a + t / n, b + y / n));
    let (mut stt, mut sty) = (0.0, 0.0);
    for (t, y) in points {
        stt += (t - mt) * (t - mt);
        sty += (t - mt) * (y - my);
    }
    (stt > 0.0).then(|| sty / stt)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fed(since: f64, until: f64, dt: f64, e: impl Fn(f64) -> f64) -> GrowthFit {
        let mut fit = GrowthFit::default();
        let mut t = since;
        while t <= until {
            fit.observe(since, t, e(t));
            t += dt;
        }
        fit
    }

    #[test]
    fn a_single_mode_gives_its_rate() {
        // 250 Hz ticks, an error of 5·e^{−0.05 (t−2)} from t = 2 s to 62 s.
        let fit = fed(2.0, 62.0, 0.004, |t| 5.0 * (-0.05 * (t - 2.0)).exp());
        let rate = fit.rate_per_s().expect("a rate");
        assert!((rate + 0.05).abs() < 1e-9, "{rate}");
        // Ten a second: 60 s of samples, the later half 30 s of them.
        assert!(
            (fit.samples.len() as i64 - 601).abs() <= 1,
            "{}",
            fit.samples.len()
        );
    }

    #[test]
    fn late_in_the_consensus_the_slowest_mode_sets_the_rate() {
        // A fast mode (−2 1/s) ten times larger than a slowly growing one (+0.03 1/s),
        // the slow one oscillating at 1 rad/s: over the later half (30 to 60 s) only the
        // slow one is left. Its oscillation is even about the half's middle (45 s), so it
        // has no covariance with time there and the slope is the envelope's; the samples'
        // grid (0.1 s, ends included) is symmetric about it to rounding.
        let e = |t: f64| 10.0 * (-2.0 * t).exp() + (0.03 * t).exp() * (1.5 + (t - 45.0).cos());
        let rate = fed(0.0, 60.0, 0.004, e).rate_per_s().expect("a rate");
        assert!((rate - 0.03).abs() < 1e-3, "{rate}");
    }

    #[test]
    fn the_stretch_ends_at_the_floor() {
        // −1 1/s from 1 m: the floor (0.01 m) at ln(100) = 4.6 s; what follows (a floor
        // of noise that comes back above it) is not fitted.
        let e = |t: f64| {
            if t < 10.0 { (-t).exp() } else { 0.02 }
        };
        let fit = fed(0.0, 60.0, 0.004, e);
        assert!(fit.ended);
        assert!(fit.samples.last().expect("samples").0 < 4.61);
        let rate = fit.rate_per_s().expect("a rate");
        assert!((rate + 1.0).abs() < 1e-9, "{rate}");
    }

    #[test]
    fn a_consensus_started_again_is_fitted_alone() {
        let mut fit = fed(0.0, 30.0, 0.004, |t| (0.1 * t).exp());
        for k in 0..=7500 {
            let t = 40.0 + k as f64 * 0.004;
            fit.observe(40.0, t, 3.0 * (-0.2 * (t - 40.0)).exp());
        }
        let rate = fit.rate_per_s().expect("a rate");
        assert!((rate + 0.2).abs() < 1e-9, "{rate}");
    }

    #[test]
    fn too_few_samples_or_none_above_the_floor_give_no_rate() {
        assert_eq!(GrowthFit::default().rate_per_s(), None);
        assert_eq!(fed(0.0, 60.0, 0.004, |_| 0.001).rate_per_s(), None);
        // 1.5 s above the floor: 15 samples, the later half 8 of them.
        let short = fed(0.0, 60.0, 0.004, |t| if t < 1.5 { 1.0 } else { 0.0 });
        assert_eq!(short.rate_per_s(), None);
        assert_eq!(fed(0.0, 60.0, 0.004, |_| f64::NAN).rate_per_s(), None);
    }
}
