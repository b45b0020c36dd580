//! The model each vehicle is flown with: its configured mass, and a hover thrust
//! estimated in flight ([`HoverThrustEkf`]) so that a wrong `hover_throttle` neither
//! costs altitude nor scales the vehicle's horizontal acceleration (which would break the
//! conservation of `w·v`). Fed once per new position report while the vehicle flies in
//! OFFBOARD in the air: the upward acceleration is the difference of two reported
//! vertical velocities [`WINDOW_S`] apart, the thrust the mean of the commanded thrust
//! times the cosine of the reported tilt in between (the commanded tilt would bias the
//! estimate by a percent while a vehicle tilts to 45° in a few tenths of a second: its
//! attitude lags, its motors hardly). The known drag is added back to the measured
//! acceleration.
//!
//! The configured model is flown until the estimate disagrees with it significantly:
//! by more than [`SIGNIFICANT_FRACTION`] of it and three standard deviations, with the
//! estimate settled (standard deviation below [`SETTLED_STD`]). From then on the estimate
//! is flown. A vehicle whose model is right is never flown on an estimate's transient
//! error; one whose model is 10 % off is corrected within seconds.

use ringswarm_wire::time::SimTime;

use crate::control::{HoverThrustEkf, VehicleModel};

/// The acceleration is measured over this window (s): differencing noisy velocities over
/// one report interval (20 ms) would multiply their noise by 70; over 0.2 s by 7, about
/// what PX4's own estimator gives its hover thrust EKF.
pub const WINDOW_S: f64 = 0.2;
/// Longest window that still gives an acceleration (s).
const MAX_GAP_S: f64 = 0.5;
/// A disagreement smaller than this fraction of the configured hover thrust is kept.
pub const SIGNIFICANT_FRACTION: f64 = 0.03;
/// The estimate is settled below this standard deviation.
pub const SETTLED_STD: f64 = 0.025;

/// One vehicle's flown model.
#[derive(Debug, Clone)]
pub(super) struct FlownModel {
    configured: VehicleModel,
    drag_per_s: f64,
    ekf: HoverThrustEkf,
    estimate: bool,
    trusted: bool,
    last: Option<(SimTime, f64)>,
    thrust_sum: f64,
    thrust_ticks: u32,
}

impl FlownModel {
    /// Starts from the configured model; `estimate` turns the estimator on.
    pub(super) fn new(
        configured: VehicleModel,
        drag_per_s: f64,
        estimate: bool,
        (min, max): (f64, f64),
    ) -> Self {
        Self {
            configured,
            drag_per_s,
            ekf: HoverThrustEkf::new(configured.hover_throttle(), min, max),
            estimate,
            trusted: false,
            last: None,
            thrust_sum: 0.0,
            thrust_ticks: 0,
        }
    }

    /// Whether the estimate is flown (it disagreed significantly with the configuration).
    pub(super) fn trusted(&self) -> bool {
        self.trusted
    }

    /// The model to fly now.
    pub(super) fn model(&self) -> VehicleModel {
        if self.trusted {
            VehicleModel::from_hover_throttle(self.configured.mass_kg(), self.ekf.hover_throttle())
                .unwrap_or(self.configured)
        } else {
            self.configured
        }
    }

    /// The hover thrust estimate and its standard deviation.
    pub(super) fn hover_estimate(&self) -> (f64, f64) {
        (self.ekf.hover_throttle(), self.ekf.std())
    }

    /// The vertical part of the normalised thrust on this tick (commanded thrust times
    /// the cosine of the reported tilt).
    pub(super) fn commanded(&mut self, thrust_up: f64) {
        if thrust_up.is_finite() {
            self.thrust_sum += thrust_up;
            self.thrust_ticks += 1;
        }
    }

    /// The latest report: when it arrived, the upward and horizontal speeds, and
    /// whether the vehicle flew on our commands in the air since the previous one.
    pub(super) fn observe(&mut self, at: SimTime, vz_up_mps: f64, vxy_mps: f64, ours: bool) {
        if !self.estimate || self.last.is_some_and(|(t, _)| t == at) {
            return;
        }
        let usable = ours;
        if let Some((t0, _)) = self.last
            && usable
            && (at - t0).as_secs_f64() < WINDOW_S
        {
            return; // the window goes on
        }
        if let Some((t0, vz0)) = self.last
            && usable
            && self.thrust_ticks > 0
        {
            let dt = (at - t0).as_secs_f64();
            if dt > 0.0 && dt <= MAX_GAP_S {
                self.ekf.predict(dt);
                let thrust = self.thrust_sum / f64::from(self.thrust_ticks);
                let acc = (vz_up_mps - vz0) / dt + self.drag_per_s * 0.5 * (vz_up_mps + vz0);
                self.ekf.fuse(acc, thrust, vz_up_mps, vxy_mps);
                let (hover, std) = (self.ekf.hover_throttle(), self.ekf.std());
                let configured = self.configured.hover_throttle();
                let gap = (hover - configured).abs();
                if std < SETTLED_STD && gap > (SIGNIFICANT_FRACTION * configured).max(2.0 * std) {
                    self.trusted = true;
                }
            }
        }
        self.last = Some((at, vz_up_mps));
        self.thrust_sum = 0.0;
        self.thrust_ticks = 0;
    }
}
