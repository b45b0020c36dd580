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
//!
//! Pure and allocation-free.

use nalgebra::Vector2;

/// Largest disturbance the observer may estimate (m/s²): twice the largest bias measured
/// on PX4 SIH at 4.4 m/s (0.9 m/s²), and a fifth of the horizontal acceleration a 35° tilt
/// gives.
pub const DISTURBANCE_LIMIT_MPS2: f64 = 2.0;

/// One vehicle's disturbance observer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DisturbanceObserver {
    time_constant_s: f64,
    limit_mps2: f64,
    estimate_mps2: Vector2<f64>,
}

impl DisturbanceObserver {
    /// An observer with time constant `time_constant_s` (s, > 0) whose estimate stays
    /// within `limit_mps2` (m/s², ≥ 0); it starts at zero.
    pub fn new(time_constant_s: f64, limit_mps2: f64) -> Self {
        Self {
            time_constant_s,
            limit_mps2: limit_mps2.max(0.0),
            estimate_mps2: Vector2::zeros(),
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

    /// Forgets the estimate (the vehicle left our control).
    pub fn reset(&mut self) {
        self.estimate_mps2 = Vector2::zeros();
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
