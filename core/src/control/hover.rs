//! An in-flight estimate of each vehicle's hover thrust: PX4's zero-order hover thrust
//! EKF (mc_hover_thrust_estimator), one state, fed with the vertical acceleration seen in
//! telemetry and the vertical thrust the coordinator commanded.
//!
//! - State: the normalised hover thrust `Tₕ`, constant but for a process noise `Q`.
//! - Measurement: the upward acceleration `a = g·T/Tₕ − g`, where `T` is the vertical part
//!   of the normalised thrust command (`thrust·cos tilt`); `H = −g·T/Tₕ²`.
//! - The measurement noise `R` is learnt from the residuals (forgetting time 2 s,
//!   clamped to [1, 400] m²/s⁴); an innovation beyond the 3-sigma gate is not fused, and a
//!   run of them (the filtered signed test ratio above 0.2) bumps the state variance so
//!   the estimate can follow a sudden change.
//! - Fast vertical or horizontal motion (drag, prop wash) doubles the noise, as PX4 does
//!   beyond HTE_VZ_THR = 2 m/s and HTE_VXY_THR = 10 m/s.
//!
//! The coordinator measures `a` by differencing the reported vertical velocity between
//! two position reports; that measurement is noisier than PX4's own, which the learnt `R`
//! absorbs. Pure and allocation-free.

/// Process noise of the hover thrust (1/s, PX4's HTE_HT_NOISE default).
pub const HOVER_PROCESS_NOISE: f64 = 0.0036;
/// Initial standard deviation of the hover thrust (PX4's HTE_HT_ERR_INIT default).
pub const HOVER_INITIAL_STD: f64 = 0.1;
/// Innovation gate (standard deviations, PX4's HTE_ACC_GATE default).
pub const HOVER_GATE: f64 = 3.0;
/// Vertical speed above which a measurement counts as noisier (m/s).
pub const NOISY_VZ_MPS: f64 = 2.0;
/// Horizontal speed above which a measurement counts as noisier (m/s).
pub const NOISY_VXY_MPS: f64 = 10.0;

const G: f64 = super::GRAVITY_MPS2;
const NOISE_LEARNING_TIME_S: f64 = 2.0;
const LPF_TIME_S: f64 = 1.0;

/// The hover thrust estimator of one vehicle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HoverThrustEkf {
    hover: f64,
    state_var: f64,
    process_var: f64,
    acc_var: f64,
    acc_var_scale: f64,
    residual_lpf: f64,
    signed_ratio_lpf: f64,
    dt_s: f64,
    min: f64,
    max: f64,
}

impl HoverThrustEkf {
    /// Starts at `initial` (the model's hover throttle), kept within `[min, max]`.
    pub fn new(initial: f64, min: f64, max: f64) -> Self {
        Self {
            hover: initial.clamp(min, max),
            state_var: HOVER_INITIAL_STD * HOVER_INITIAL_STD,
            process_var: HOVER_PROCESS_NOISE * HOVER_PROCESS_NOISE,
            acc_var: 5.0,
            acc_var_scale: 1.0,
            residual_lpf: 0.0,
            signed_ratio_lpf: 0.0,
            dt_s: 0.02,
            min,
            max,
        }
    }

    /// The estimate.
    pub fn hover_throttle(&self) -> f64 {
        self.hover
    }

    /// Its standard deviation.
    pub fn std(&self) -> f64 {
        self.state_var.sqrt()
    }

    /// Time passes (s).
    pub fn predict(&mut self, dt_s: f64) {
        if dt_s.is_finite() && dt_s > 0.0 {
            self.state_var += self.process_var * dt_s * dt_s;
            self.dt_s = dt_s;
        }
    }

    /// Fuses an upward acceleration (m/s²) measured while the vertical normalised thrust
    /// `thrust_up` was commanded, at speeds `vz_mps` (vertical) and `vxy_mps`
    /// (horizontal). Non-finite inputs are ignored.
    pub fn fuse(&mut self, acc_up_mps2: f64, thrust_up: f64, vz_mps: f64, vxy_mps: f64) {
        if !(acc_up_mps2.is_finite() && thrust_up.is_finite() && thrust_up > 0.0) {
            return;
        }
        let noisy = vz_mps.abs() > NOISY_VZ_MPS || vxy_mps > NOISY_VXY_MPS;
        self.acc_var_scale = if noisy { 4.0 } else { 1.0 };
        let h = -G * thrust_up / (self.hover * self.hover);
        let r = self.acc_var * self.acc_var_scale;
        let innov_var = (h * self.state_var * h + r).max(r);
        let innov = acc_up_mps2 - (G * thrust_up / self.hover - G);
        let k = self.state_var * h / innov_var;
        let ratio = innov * innov / (HOVER_GATE * HOVER_GATE * innov_var);
        let mut residual = innov;
        if ratio < 1.0 {
            self.hover = (self.hover + k * innov).clamp(self.min, self.max);
            self.state_var = ((1.0 - k * h) * self.state_var).clamp(1e-10, 1.0);
            residual = acc_up_mps2 - (G * thrust_up / self.hover - G);
        } else if self.signed_ratio_lpf.abs() > 0.2 {
            self.state_var += 1e3 * self.process_var * self.dt_s;
        }
        let alpha = self.dt_s / (LPF_TIME_S + self.dt_s);
        self.residual_lpf = (1.0 - alpha) * self.residual_lpf + alpha * residual;
        self.signed_ratio_lpf = (1.0 - alpha) * self.signed_ratio_lpf
            + alpha * (innov.signum() * ratio).clamp(-1.0, 1.0);
        let beta = self.dt_s / (NOISE_LEARNING_TIME_S + self.dt_s);
        let unbiased = residual - self.residual_lpf;
        self.acc_var = ((1.0 - beta) * self.acc_var
            + beta * (unbiased * unbiased + h * self.state_var * h))
            .clamp(1.0, 400.0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, Normal};

    /// A vehicle whose true hover throttle is `truth`, held at hover by a thrust that
    /// follows the estimate (as the coordinator's does), measured at 50 Hz with
    /// acceleration noise `noise` (m/s²).
    fn converge(start: f64, truth: f64, noise: f64, seconds: f64) -> HoverThrustEkf {
        let mut ekf = HoverThrustEkf::new(start, 0.1, 0.9);
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let n = Normal::new(0.0, noise).unwrap();
        for k in 0..(seconds * 50.0) as usize {
            // A small vertical manoeuvre so the thrust varies: ±0.5 m/s².
            let wanted = 0.5 * (k as f64 * 0.05).sin();
            let thrust = ekf.hover_throttle() * (1.0 + wanted / G);
            let acc = G * thrust / truth - G + n.sample(&mut rng);
            ekf.predict(0.02);
            ekf.fuse(acc, thrust, 0.0, 0.0);
        }
        ekf
    }

    #[test]
    fn a_ten_percent_error_is_found_within_a_percent_in_ten_seconds() {
        for (start, truth) in [(0.45, 0.5), (0.55, 0.5), (0.2, 0.22)] {
            let ekf = converge(start, truth, 0.5, 10.0);
            let err = (ekf.hover_throttle() - truth).abs() / truth;
            assert!(
                err < 0.01,
                "start {start}, truth {truth}: {}",
                ekf.hover_throttle()
            );
        }
    }

    #[test]
    fn with_noisy_differentiated_velocity_it_still_converges() {
        // Velocity noise 0.05 m/s differentiated over 20 ms: about 3.5 m/s² of noise.
        let ekf = converge(0.45, 0.5, 3.5, 30.0);
        let err = (ekf.hover_throttle() - 0.5).abs() / 0.5;
        assert!(err < 0.02, "{}", ekf.hover_throttle());
    }

    #[test]
    fn bad_numbers_change_nothing_and_the_estimate_stays_in_its_bounds() {
        let mut ekf = HoverThrustEkf::new(0.5, 0.1, 0.9);
        let before = ekf;
        ekf.fuse(f64::NAN, 0.5, 0.0, 0.0);
        ekf.fuse(1.0, f64::INFINITY, 0.0, 0.0);
        ekf.fuse(1.0, 0.0, 0.0, 0.0);
        ekf.predict(f64::NAN);
        assert_eq!(ekf, before);
        // A vehicle that "falls" forever at full thrust: the estimate saturates at 0.9.
        for _ in 0..5000 {
            ekf.predict(0.02);
            ekf.fuse(-5.0, 0.8, 0.0, 0.0);
        }
        assert!((0.1..=0.9).contains(&ekf.hover_throttle()));
        assert!(ekf.hover_throttle() > 0.85, "{}", ekf.hover_throttle());
    }
}
