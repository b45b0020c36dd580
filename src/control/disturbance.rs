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
//!   variance for white measurements of variance `σ_y²` (learnt from `y`, forgetting
//!   time [`NOISE_TIME_S`]) and `g` its gain per window. A vehicle whose reports are
//!   noisy but whose commands are flown as asked (the emulator with noisy telemetry)
//!   thus gets no compensation of its noise; a real, steady disturbance passes whole.
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
    /// Mean of `y` and of `|y|²` over [`NOISE_TIME_S`], and the estimate's noise (m/s²).
    mean_mps2: Vector2<f64>,
    mean_square: f64,
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
            mean_mps2: Vector2::zeros(),
            mean_square: 0.0,
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
        self.mean_mps2 += forget * (measured_mps2 - self.mean_mps2);
        self.mean_square += forget * (measured_mps2.norm_squared() - self.mean_square);
        let variance = (self.mean_square - self.mean_mps2.norm_squared()).max(0.0);
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
        // What is left of the variance is the start's step, forgotten over 40 s / 5 s:
        // 0.09·e⁻⁸(1 − e⁻⁸), a noise of 0.0024 m/s².
        let noise = steady.noise_mps2();
        assert!(noise < 0.003, "{noise}");
        let flown = steady.significant_mps2();
        assert!(
            (flown - Vector2::new(0.3 - 2.0 * noise, 0.0)).norm() < 1e-9,
            "{flown}"
        );
        // Alternating ±0.35 m/s² (a noisy velocity differenced over 0.2 s): variance
        // 0.1225, the filter's gain per window g = 1 − e^(−0.4) = 0.3297, its output's
        // noise √(0.1225·g/(2 − g)) = 0.1568 m/s², twice that above the estimate: nothing
        // is flown.
        let mut noisy = DisturbanceObserver::new(0.5, DISTURBANCE_LIMIT_MPS2);
        for k in 0..400 {
            let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
            noisy.update(0.2, Vector2::new(0.35 * sign, 0.0));
        }
        let g = 1.0 - (-0.4f64).exp();
        let expected = (0.1225 * g / (2.0 - g)).sqrt();
        assert!(
            (noisy.noise_mps2() - expected).abs() < 2e-3,
            "{}",
            noisy.noise_mps2()
        );
        assert!(noisy.estimate_mps2().norm() < 2.0 * expected);
        assert_eq!(noisy.significant_mps2(), Vector2::zeros());
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
