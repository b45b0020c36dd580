//! An in-flight estimate of a vehicle's linear drag, in the spirit of PX4's hover thrust
//! estimator ([`super::HoverThrustEkf`]): one state, a scalar Kalman filter.
//!
//! - State: the linear drag `d` (1/s, force per mass per speed), constant but for a small
//!   process noise [`DRAG_PROCESS_NOISE`].
//! - Measurement, once per axis of a window: the horizontal acceleration the vehicle was
//!   asked for as it was delivered (`f`: the commanded thrust along the reported tilt, or
//!   the acceleration setpoint itself), less the acceleration it made (`a`, from its
//!   reported velocities): `y = f − a = d·v`, so `H = v`, the mean velocity over the
//!   window (m/s).
//! - The prior is the configured drag with a standard deviation as large as the drag
//!   itself (at least [`DRAG_MIN_PRIOR_STD`]): the configuration is a guess, and its lower
//!   confidence bound `d − 2σ` starts below zero.
//! - The measurement noise `R` is learnt from the residuals (forgetting time 2 s, clamped
//!   to [[`MIN_ACC_VAR`], [`MAX_ACC_VAR`]]); an innovation beyond the 3-sigma gate is not
//!   fused, and a run of them bumps the state variance so the estimate can follow a change.
//!
//! A hovering vehicle (`v ≈ 0`) tells nothing about its drag, and the filter learns
//! nothing from it: its variance stays where it was. That is harmless, because the drag
//! feed-forward `d·v` is then zero too.
//!
//! Pure and allocation-free.

/// Process noise of the drag (1/s per √s).
pub const DRAG_PROCESS_NOISE: f64 = 0.01;
/// Smallest standard deviation of the prior (1/s).
pub const DRAG_MIN_PRIOR_STD: f64 = 0.2;
/// Innovation gate (standard deviations).
pub const DRAG_GATE: f64 = 3.0;
/// Bounds of the learnt measurement noise variance ((m/s²)²).
pub const MIN_ACC_VAR: f64 = 0.01;
/// See [`MIN_ACC_VAR`].
pub const MAX_ACC_VAR: f64 = 100.0;
/// Largest drag the estimate may reach (1/s): ten times PX4 SIH's.
pub const MAX_DRAG_PER_S: f64 = 10.0;

const NOISE_LEARNING_TIME_S: f64 = 2.0;
const LPF_TIME_S: f64 = 1.0;

/// The drag estimator of one vehicle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DragKf {
    drag: f64,
    state_var: f64,
    acc_var: f64,
    signed_ratio_lpf: f64,
    dt_s: f64,
    fused: u64,
}

impl DragKf {
    /// Starts at the configured drag (1/s; a non-finite or negative one starts at 0),
    /// with a standard deviation as large as it, at least [`DRAG_MIN_PRIOR_STD`].
    pub fn new(configured_per_s: f64) -> Self {
        let d = if configured_per_s.is_finite() {
            configured_per_s.clamp(0.0, MAX_DRAG_PER_S)
        } else {
            0.0
        };
        let std = d.max(DRAG_MIN_PRIOR_STD);
        Self {
            drag: d,
            state_var: std * std,
            acc_var: 1.0,
            signed_ratio_lpf: 0.0,
            dt_s: 0.2,
            fused: 0,
        }
    }

    /// The estimate (1/s).
    pub fn drag_per_s(&self) -> f64 {
        self.drag
    }

    /// Its standard deviation (1/s).
    pub fn std(&self) -> f64 {
        self.state_var.sqrt()
    }

    /// The lower confidence bound `max(0, d − 2σ)` (1/s): a feed-forward of this much drag
    /// is positive velocity feedback only if the estimate is two standard deviations off.
    pub fn lower_bound_per_s(&self) -> f64 {
        (self.drag - 2.0 * self.std()).max(0.0)
    }

    /// Measurements fused so far.
    pub fn fused(&self) -> u64 {
        self.fused
    }

    /// Time passes (s).
    pub fn predict(&mut self, dt_s: f64) {
        if dt_s.is_finite() && dt_s > 0.0 {
            self.state_var += DRAG_PROCESS_NOISE * DRAG_PROCESS_NOISE * dt_s;
            self.dt_s = dt_s;
        }
    }

    /// Fuses one axis: the acceleration asked for as delivered less the one made
    /// (`f − a`, m/s²) at the mean velocity `vel_mps` along that axis. Non-finite inputs
    /// are ignored.
    pub fn fuse(&mut self, shortfall_mps2: f64, vel_mps: f64) {
        if !(shortfall_mps2.is_finite() && vel_mps.is_finite()) {
            return;
        }
        let h = vel_mps;
        let r = self.acc_var;
        let innov_var = h * self.state_var * h + r;
        let innov = shortfall_mps2 - self.drag * h;
        let ratio = innov * innov / (DRAG_GATE * DRAG_GATE * innov_var);
        let mut residual = innov;
        if ratio < 1.0 {
            let k = self.state_var * h / innov_var;
            self.drag = (self.drag + k * innov).clamp(0.0, MAX_DRAG_PER_S);
            self.state_var = ((1.0 - k * h) * self.state_var).max(1e-12);
            residual = shortfall_mps2 - self.drag * h;
            self.fused += 1;
        } else if self.signed_ratio_lpf.abs() > 0.2 {
            self.state_var += 1e3 * DRAG_PROCESS_NOISE * DRAG_PROCESS_NOISE * self.dt_s;
        }
        let alpha = self.dt_s / (LPF_TIME_S + self.dt_s);
        self.signed_ratio_lpf = (1.0 - alpha) * self.signed_ratio_lpf
            + alpha * (innov.signum() * ratio).clamp(-1.0, 1.0);
        let beta = self.dt_s / (NOISE_LEARNING_TIME_S + self.dt_s);
        self.acc_var = ((1.0 - beta) * self.acc_var
            + beta * (residual * residual + h * self.state_var * h))
            .clamp(MIN_ACC_VAR, MAX_ACC_VAR);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// Feeds `n` windows of 0.2 s at speeds cycling through `speeds` with the true drag
    /// and Gaussian noise of `noise` m/s² on the shortfall.
    fn run(configured: f64, truth: f64, speeds: &[f64], noise: f64, n: usize) -> DragKf {
        let mut kf = DragKf::new(configured);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let normal = Normal::new(0.0, noise).unwrap();
        for j in 0..n {
            let v = speeds[j % speeds.len()];
            kf.predict(0.2);
            kf.fuse(truth * v + normal.sample(&mut rng), v);
        }
        kf
    }

    #[test]
    fn the_prior_bound_starts_at_zero_whatever_is_configured() {
        for d in [0.0, 0.1, 1.0, 5.0] {
            let kf = DragKf::new(d);
            assert_eq!(kf.drag_per_s(), d);
            assert_eq!(kf.lower_bound_per_s(), 0.0, "{d}");
        }
        // Nonsense starts at zero, not at a guess.
        assert_eq!(DragKf::new(f64::NAN).drag_per_s(), 0.0);
        assert_eq!(DragKf::new(-1.0).drag_per_s(), 0.0);
    }

    #[test]
    fn a_ten_times_overestimate_is_learnt_within_seconds() {
        // Truth 0.1/s, configured 1.0/s, speeds 1..4 m/s, 0.3 m/s² of noise: 50 axes, as
        // 25 windows of two axes give in 5 s of flight.
        let kf = run(1.0, 0.1, &[1.0, -2.0, 3.0, 4.0], 0.3, 50);
        assert!((kf.drag_per_s() - 0.1).abs() < 0.05, "{kf:?}");
        assert!(kf.std() < 0.05, "{kf:?}");
        assert!(kf.lower_bound_per_s() <= 0.1, "{kf:?}");
    }

    #[test]
    fn an_underestimate_is_learnt_too() {
        let kf = run(0.5, 1.0, &[2.0, 5.0, -3.0], 0.3, 50);
        assert!((kf.drag_per_s() - 1.0).abs() < 0.03, "{kf:?}");
    }

    #[test]
    fn noiseless_measurements_converge_to_the_truth() {
        let kf = run(0.3, 0.7, &[2.0, -1.0], 0.0, 200);
        assert!((kf.drag_per_s() - 0.7).abs() < 1e-6, "{kf:?}");
    }

    #[test]
    fn hovering_teaches_nothing() {
        let kf = run(1.0, 0.1, &[0.0], 0.3, 100);
        assert_eq!(kf.drag_per_s(), 1.0);
        // Only the process noise added: 100 windows of 0.2 s.
        let expected_var = 1.0 + 100.0 * 0.2 * DRAG_PROCESS_NOISE * DRAG_PROCESS_NOISE;
        assert!((kf.std() * kf.std() - expected_var).abs() < 1e-12);
    }

    #[test]
    fn non_finite_input_is_ignored() {
        let mut kf = DragKf::new(0.4);
        kf.fuse(f64::NAN, 3.0);
        kf.fuse(1.0, f64::INFINITY);
        assert_eq!(kf, DragKf::new(0.4));
    }
}
