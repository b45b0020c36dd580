//! A horizontal acceleration disturbance observer: what moves a vehicle that the command
//! does not explain, low-pass filtered, so that the coordinator can take it off the next
//! commands.
//!
//! Measured on real PX4 SIH vehicles (docs/math.md, "The disturbance observer"): the
//! acceleration a vehicle makes differs from the one it was asked for along its *reported*
//! tilt by 0.2–0.8 m/s² per vehicle, for tens of seconds at a time. The cause is the
//! vehicle's own attitude estimate: SIH's noisy IMU leaves EKF2's tilt a few degrees and its
//! heading up to 0.28 rad off the truth, so the attitude loop holds the wrong attitude
//! exactly. Each vehicle then carries a slowly varying acceleration bias of its own, which
//! the consensus law turns into a formation error (the law only sees velocities). Drag
//! mistaken by `Δd` adds `−Δd·v` to the same term.
//!
//! - Measurement, once per window of the flown model (0.2 s): the acceleration made (from
//!   the reported velocities) less the acceleration delivered along the reported attitude,
//!   net of the drag fed forward: `y = a − (f − d_ff·v̄)`. It does not depend on what the
//!   observer itself subtracted from the command (that is inside `f`), so the observer is
//!   a plain filter of the vehicle's mismatch, not a loop of its own.
//! - Estimate: a first-order low-pass of `y` with time constant `τ` (s), kept within
//!   `limit_mps2` (norm), so that a wrong measurement cannot ask for more than that.
//! - What is flown: the estimate shrunk by twice its own noise,
//!   `b̂·max(0, 1 − 2σ_b/|b̂|)`, where `σ_b² = σ_y²·g/(2 − g)` is the low-pass's output
//!   variance for white measurements of variance `σ_y²` and `g` its gain per window.
//!   `σ_y²` is learnt from successive measurements, `E[(y_k − y_{k−1})²]/2` (forgetting
//!   time [`NOISE_TIME_S`]): white noise counts whole, a disturbance that varies slowly
//!   against the window hardly at all. (The variance of `y` itself would count the
//!   disturbance's own wander as noise: on PX4 SIH at cruise that is 0.45 m/s² against a
//!   white part of 0.28 m/s², and the shrink then took off most of a real 0.3–0.6 m/s²
//!   bias.) A vehicle whose reports are noisy but whose commands are flown as asked (the
//!   emulator with noisy telemetry) thus gets no compensation of its noise; a real,
//!   steady disturbance passes whole.
//!
//! Pure and allocation-free.

use nalgebra::Vector2;

/// Largest disturbance the observer may estimate (m/s²): twice the largest bias measured
/// on PX4 SIH at 4.4 m/s (0.9 m/s²), and a fifth of the horizontal acceleration a 35° tilt
/// gives.
pub const DISTURBANCE_LIMIT_MPS2: f64 = 2.0;

/// Forgetting time of the measurement variance (s).
pub const NOISE_TIME_S: f64 = 5.0;

/// One vehicle's disturbance observer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DisturbanceObserver {
    time_constant_s: f64,
    limit_mps2: f64,
    estimate_mps2: Vector2<f64>,
    /// The last measurement, the mean of `|y_k − y_{k−1}|²` over [`NOISE_TIME_S`], and the
    /// estimate's noise (m/s²).
    last_mps2: Option<Vector2<f64>>,
    mean_square_step: f64,
    noise_mps2: f64,
}

impl DisturbanceObserver {
    /// An observer with time constant `time_constant_s` (s, > 0) whose estimate stays
    /// within `limit_mps2` (m/s², ≥ 0); it starts at zero.
    pub fn new(time_constant_s: f64, limit_mps2: f64) -> Self {
        Self {
            time_constant_s,
            limit_mps2: limit_mps2.max(0.0),
            estimate_mps2: Vector2::zeros(),
            last_mps2: None,
            mean_square_step: 0.0,
            noise_mps2: 0.0,
        }
    }

    /// Fuses one window of `dt_s` seconds whose unexplained acceleration was
    /// `measured_mps2` (m/s²). Non-finite or non-positive inputs are ignored.
    pub fn update(&mut self, dt_s: f64, measured_mps2: Vector2<f64>) {
        let usable =
            dt_s > 0.0 && self.time_constant_s > 0.0 && measured_mps2.iter().all(|x| x.is_finite());
        if !usable {
            return;
        }
        let gain = 1.0 - (-dt_s / self.time_constant_s).exp();
        let forget = 1.0 - (-dt_s / NOISE_TIME_S).exp();
        if let Some(last) = self.last_mps2 {
            let step = (measured_mps2 - last).norm_squared();
            self.mean_square_step += forget * (step - self.mean_square_step);
        }
        self.last_mps2 = Some(measured_mps2);
        // Independent samples of variance σ² per axis differ by 2σ² per axis.
        let variance = 0.5 * self.mean_square_step;
        self.noise_mps2 = (variance * gain / (2.0 - gain)).sqrt();
        let next = self.estimate_mps2 + gain * (measured_mps2 - self.estimate_mps2);
        let norm = next.norm();
        self.estimate_mps2 = if norm > self.limit_mps2 {
            next * (self.limit_mps2 / norm)
        } else {
            next
        };
    }

    /// The disturbance estimated now (m/s², the frame of the measurements).
    pub fn estimate_mps2(&self) -> Vector2<f64> {
        self.estimate_mps2
    }

    /// The standard deviation of the estimate's noise (m/s²).
    pub fn noise_mps2(&self) -> f64 {
        self.noise_mps2
    }

    /// What to take off the commands (m/s²): the estimate shrunk by twice its noise.
    pub fn significant_mps2(&self) -> Vector2<f64> {
        let norm = self.estimate_mps2.norm();
        if norm <= 2.0 * self.noise_mps2 {
            Vector2::zeros()
        } else {
            self.estimate_mps2 * (1.0 - 2.0 * self.noise_mps2 / norm)
        }
    }

    /// Forgets the estimate and its noise (the vehicle left our control).
    pub fn reset(&mut self) {
        *self = Self::new(self.time_constant_s, self.limit_mps2);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_constant_disturbance_is_followed_with_the_time_constant() {
        let mut o = DisturbanceObserver::new(1.0, DISTURBANCE_LIMIT_MPS2);
        let b = Vector2::new(0.4, -0.3);
        for _ in 0..5 {
            o.update(0.2, b);
        }
        // After one time constant (five 0.2 s windows) the estimate is 1 − e⁻¹ of the way.
        let expected = b * (1.0 - (-1.0f64).exp());
        assert!((o.estimate_mps2() - expected).norm() < 1e-12);
        for _ in 0..200 {
            o.update(0.2, b);
        }
        assert!((o.estimate_mps2() - b).norm() < 1e-12);
    }

    #[test]
    fn the_estimate_keeps_within_its_limit_along_the_measurement() {
        let mut o = DisturbanceObserver::new(0.5, 1.0);
        for _ in 0..100 {
            o.update(0.2, Vector2::new(30.0, 40.0));
        }
        let e = o.estimate_mps2();
        assert!((e.norm() - 1.0).abs() < 1e-12);
        assert!((e.x / e.y - 0.75).abs() < 1e-12);
    }

    #[test]
    fn a_steady_disturbance_is_flown_whole_and_noise_alone_not_at_all() {
        let mut steady = DisturbanceObserver::new(0.5, DISTURBANCE_LIMIT_MPS2);
        for _ in 0..200 {
            steady.update(0.2, Vector2::new(0.3, 0.0));
        }
        // Every step after the first is zero: no noise, the estimate flown whole.
        assert_eq!(steady.noise_mps2(), 0.0);
        assert!((steady.significant_mps2() - Vector2::new(0.3, 0.0)).norm() < 1e-12);
        // White noise of 0.35 m/s² per axis (uniform, a deterministic sequence): the
        // filter's gain per window g = 1 − e^(−0.4) = 0.3297, its output's noise
        // √(2·0.1225·g/(2 − g)) = 0.2218 m/s² (two axes), above half the estimate: nothing
        // is flown.
        let mut noisy = DisturbanceObserver::new(0.5, DISTURBANCE_LIMIT_MPS2);
        let mut x: u64 = 7;
        let mut white = || {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((x >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 0.35 * 12f64.sqrt()
        };
        let g = 1.0 - (-0.4f64).exp();
        let expected = (2.0 * 0.1225 * g / (2.0 - g)).sqrt();
        let (mut below, mut windows) = (0, 0);
        for k in 0..2000 {
            noisy.update(0.2, Vector2::new(white(), white()));
            if k >= 100 {
                windows += 1;
                below += usize::from(noisy.significant_mps2() == Vector2::zeros());
                assert!(
                    (noisy.noise_mps2() / expected - 1.0).abs() < 0.25,
                    "window {k}: {} vs {expected}",
                    noisy.noise_mps2()
                );
            }
        }
        // |b̂| is Rayleigh with σ_b/√2 per axis: P(|b̂| ≤ 2σ_b) = 1 − e⁻⁴ = 0.982.
        let share = below as f64 / f64::from(windows);
        assert!((share - 0.982).abs() < 0.01, "{share}");
    }

    #[test]
    fn a_disturbance_that_wanders_slowly_is_not_taken_for_noise() {
        // A bias of 0.4 m/s² turning once every 20 s (PX4 SIH's heading error at cruise,
        // docs/math.md): successive 0.2 s windows differ by at most 0.4·2π·0.2/20 =
        // 0.025 m/s², so the noise stays below 0.025·√(g/(2 − g)) = 0.011 m/s², and the
        // estimate is flown nearly whole (the variance of y itself would have counted
        // the whole wander, 0.4 m/s²·√(g/(2 − g)) = 0.18 m/s², and shrunk it by 0.36).
        let mut o = DisturbanceObserver::new(0.5, DISTURBANCE_LIMIT_MPS2);
        for k in 0..500 {
            let phase = 2.0 * std::f64::consts::PI * 0.2 * f64::from(k) / 20.0;
            o.update(0.2, 0.4 * Vector2::new(phase.cos(), phase.sin()));
        }
        assert!(o.noise_mps2() < 0.011, "{}", o.noise_mps2());
        let flown = o.significant_mps2().norm();
        assert!(flown > 0.4 - 2.0 * 0.011 - 0.01, "{flown}");
    }

    #[test]
    fn bad_inputs_leave_the_estimate_alone() {
        let mut o = DisturbanceObserver::new(1.0, 2.0);
        o.update(0.2, Vector2::new(1.0, 0.0));
        let before = o.estimate_mps2();
        o.update(0.2, Vector2::new(f64::NAN, 0.0));
        o.update(0.0, Vector2::new(5.0, 0.0));
        o.update(-1.0, Vector2::new(5.0, 0.0));
        o.update(f64::NAN, Vector2::new(5.0, 0.0));
        assert_eq!(o.estimate_mps2(), before);
        o.reset();
        assert_eq!(o.estimate_mps2(), Vector2::zeros());
    }
}
