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

use nalgebra::{UnitQuaternion, Vector2, Vector3};
use ringswarm_wire::time::SimTime;

use crate::control::{
    AttitudeResponse, DISTURBANCE_LIMIT_MPS2, DisturbanceObserver, DragKf, GRAVITY_MPS2,
    HoverThrustEkf, ResponseFit, VehicleModel, roll_pitch_ned_frd,
};

/// What drives a vehicle horizontally on one tick, as far as the coordinator can tell.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum HorizontalDrive {
    /// The specific thrust commanded along the reported tilt, horizontal part (m/s², ENU).
    Acceleration(Vector2<f64>),
    /// The reported thrust direction's horizontal part over its vertical part (ENU): the
    /// vehicle chose the thrust (acceleration setpoints).
    TiltPerVertical(Vector2<f64>),
}

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
/// The drag estimate is settled below this standard deviation (1/s).
pub const SETTLED_DRAG_STD: f64 = 0.05;
/// A drag estimate closer to the configuration than this fraction of it (or 0.02 1/s)
/// is no news.
pub const SIGNIFICANT_DRAG_FRACTION: f64 = 0.25;

/// One vehicle's flown model.
#[derive(Debug, Clone)]
pub(super) struct FlownModel {
    configured: VehicleModel,
    drag_per_s: f64,
    ekf: HoverThrustEkf,
    drag: DragKf,
    /// The acceleration the command does not explain (`None`: off).
    disturbance: Option<DisturbanceObserver>,
    /// The observer's latest estimate while the vehicle flew on our commands (m/s², ENU).
    disturbance_seen: Vector2<f64>,
    /// The attitude response fitted so far, and the latest attitude report (a new one is
    /// told from the same by its value).
    response: ResponseFit,
    last_attitude: Option<UnitQuaternion<f64>>,
    /// How much more drag than the estimate's lower bound may be fed forward (1/s).
    drag_allowance_per_s: f64,
    estimate: bool,
    estimate_drag: bool,
    trusted: bool,
    drag_trusted: bool,
    last: Option<(SimTime, Vector3<f64>)>,
    thrust_sum: f64,
    /// The horizontal acceleration asked for as delivered, summed over the window's ticks
    /// (m/s², ENU), or with acceleration setpoints the thrust's horizontal direction per
    /// unit of its vertical part (the vehicle chooses the thrust, its tilt shows it).
    force_sum: Vector2<f64>,
    /// Whether `force_sum` holds tilts (acceleration setpoints) instead of accelerations.
    tilt_only: bool,
    thrust_ticks: u32,
    /// The hover estimator's bounds (normalised thrust).
    hover_bounds: (f64, f64),
}

impl FlownModel {
    /// Starts from the configured model; `estimate` turns the hover thrust estimator on,
    /// `estimate_drag` the drag estimator, a positive `disturbance_time_constant_s` the
    /// disturbance observer. The drag fed forward may exceed the estimate's lower
    /// confidence bound by `drag_allowance_per_s` (half the mean-velocity gain:
    /// docs/math.md). Commands are sent every `control_period_s`.
    pub(super) fn new(
        configured: VehicleModel,
        (drag_per_s, drag_allowance_per_s): (f64, f64),
        (estimate, estimate_drag, disturbance_time_constant_s): (bool, bool, f64),
        (min, max): (f64, f64),
        control_period_s: f64,
    ) -> Self {
        Self {
            configured,
            drag_per_s,
            ekf: HoverThrustEkf::new(configured.hover_throttle(), min, max),
            drag: DragKf::new(drag_per_s),
            disturbance: (disturbance_time_constant_s > 0.0).then(|| {
                DisturbanceObserver::new(disturbance_time_constant_s, DISTURBANCE_LIMIT_MPS2)
            }),
            disturbance_seen: Vector2::zeros(),
            response: ResponseFit::new(control_period_s),
            last_attitude: None,
            drag_allowance_per_s,
            estimate,
            estimate_drag,
            trusted: false,
            drag_trusted: false,
            last: None,
            thrust_sum: 0.0,
            force_sum: Vector2::zeros(),
            tilt_only: false,
            thrust_ticks: 0,
            hover_bounds: (min, max),
        }
    }

    /// The hover throttle the estimate started from: the configured one, or the one the
    /// vehicle reported of itself.
    pub(super) fn start_hover(&self) -> f64 {
        self.configured.hover_throttle()
    }

    /// Starts over from the hover throttle the vehicle reports of itself (ArduPilot's
    /// learnt MOT_THST_HOVER), which then stands for the configured one: flown until the
    /// estimator disagrees with it. Refused (`false`) outside the estimator's bounds.
    pub(super) fn seed_hover(&mut self, hover_throttle: f64) -> bool {
        let (min, max) = self.hover_bounds;
        if !(min..=max).contains(&hover_throttle) {
            return false;
        }
        let Ok(model) =
            VehicleModel::from_hover_throttle(self.configured.mass_kg(), hover_throttle)
        else {
            return false;
        };
        self.configured = model;
        self.ekf = HoverThrustEkf::new(hover_throttle, min, max);
        self.trusted = false;
        true
    }

    /// Whether the drag estimate is flown (it disagreed significantly with the
    /// configuration).
    pub(super) fn drag_trusted(&self) -> bool {
        self.drag_trusted
    }

    /// The drag estimate and its standard deviation (1/s).
    pub(super) fn drag_estimate(&self) -> (f64, f64) {
        (self.drag.drag_per_s(), self.drag.std())
    }

    /// The best guess of the drag (1/s): the estimate once it is flown, the configuration
    /// before.
    pub(super) fn drag_best_per_s(&self) -> f64 {
        if self.drag_trusted {
            self.drag.drag_per_s()
        } else {
            self.drag_per_s
        }
    }

    /// The drag to feed forward (1/s): the best guess, never above the estimate's lower
    /// confidence bound plus the allowance (the configuration as it is while the
    /// estimator is off).
    pub(super) fn drag_fed_forward_per_s(&self) -> f64 {
        if self.estimate_drag {
            self.drag_best_per_s()
                .min(self.drag.lower_bound_per_s() + self.drag_allowance_per_s)
        } else {
            self.drag_per_s
        }
    }

    /// The drag a vehicle left to drift is surely slowed by (1/s): the estimate's lower
    /// confidence bound while the estimator runs (zero until it knows), the configured
    /// drag otherwise.
    pub(super) fn drift_drag_per_s(&self) -> f64 {
        if self.estimate_drag {
            self.drag.lower_bound_per_s()
        } else {
            self.drag_per_s
        }
    }

    /// The acceleration the commands do not explain, to take off the next command
    /// (m/s², ENU; zero while the observer is off).
    pub(super) fn disturbance_mps2(&self) -> Vector2<f64> {
        self.disturbance
            .map_or(Vector2::zeros(), |o| o.significant_mps2())
    }

    /// The observer's latest estimate while the vehicle flew on our commands in the air
    /// (m/s², ENU; kept after it landed, for the summary).
    pub(super) fn disturbance_seen_mps2(&self) -> Vector2<f64> {
        self.disturbance_seen
    }

    /// Forgets the disturbance (the vehicle is not flown on our commands in the air).
    pub(super) fn forget_disturbance(&mut self) {
        if let Some(o) = &mut self.disturbance {
            o.reset();
        }
    }

    /// One control tick of the attitude response fit: the attitude commanded on it, the
    /// latest attitude report (taken as new when it differs from the last one), and
    /// whether the vehicle flies our attitude commands in the air.
    pub(super) fn attitude_tick(
        &mut self,
        now_s: f64,
        commanded: &UnitQuaternion<f64>,
        reported: Option<UnitQuaternion<f64>>,
        usable: bool,
    ) {
        let new = reported.filter(|q| Some(*q) != self.last_attitude);
        if new.is_some() {
            self.last_attitude = new;
        }
        let (sp_roll, sp_pitch) = roll_pitch_ned_frd(commanded);
        self.response.tick(
            new.map(|q| {
                let (roll, pitch) = roll_pitch_ned_frd(&q);
                ([roll, pitch], now_s)
            }),
            [sp_roll, sp_pitch],
            usable,
        );
    }

    /// The attitude response fitted so far (`None` before enough commanded motion).
    pub(super) fn attitude_response(&self) -> Option<AttitudeResponse> {
        self.response.fit()
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

    /// This tick's command as delivered: the vertical part of the normalised thrust
    /// (commanded thrust times the cosine of the reported tilt) and what drives the
    /// vehicle horizontally.
    pub(super) fn commanded(&mut self, thrust_up: f64, horizontal: HorizontalDrive) {
        let (value, tilt_only) = match horizontal {
            HorizontalDrive::Acceleration(a) => (a, false),
            HorizontalDrive::TiltPerVertical(t) => (t, true),
        };
        if thrust_up.is_finite() && value.iter().all(|x| x.is_finite()) {
            self.thrust_sum += thrust_up;
            self.force_sum += value;
            self.tilt_only = tilt_only;
            self.thrust_ticks += 1;
        }
    }

    /// The latest report: when it arrived, the velocity (m/s, ENU), and whether the
    /// vehicle flew on our commands in the air since the previous one.
    pub(super) fn observe(&mut self, at: SimTime, vel_enu_mps: Vector3<f64>, ours: bool) {
        if !ours {
            self.forget_disturbance();
        }
        let horizontal = self.estimate_drag || self.disturbance.is_some();
        if !(self.estimate || horizontal) || self.last.is_some_and(|(t, _)| t == at) {
            return;
        }
        let usable = ours;
        if let Some((t0, _)) = self.last
            && usable
            && at.saturating_since(t0).as_secs_f64() < WINDOW_S
        {
            return; // the window goes on
        }
        if let Some((t0, v0)) = self.last
            && usable
            && self.thrust_ticks > 0
        {
            let dt = at.saturating_since(t0).as_secs_f64();
            if dt > 0.0 && dt <= MAX_GAP_S {
                let ticks = f64::from(self.thrust_ticks);
                let mean_v = 0.5 * (vel_enu_mps + v0);
                if self.estimate {
                    self.fuse_hover(dt, self.thrust_sum / ticks, vel_enu_mps, v0);
                }
                if horizontal {
                    let made = (vel_enu_mps.xy() - v0.xy()) / dt;
                    let asked = if self.tilt_only {
                        // The vertical specific force is what held the climb: g plus the
                        // upward acceleration made plus the vertical drag.
                        let up = GRAVITY_MPS2
                            + (vel_enu_mps.z - v0.z) / dt
                            + self.drag_best_per_s() * mean_v.z;
                        self.force_sum / ticks * up
                    } else {
                        self.force_sum / ticks
                    };
                    let fed_forward = self.drag_fed_forward_per_s() * mean_v.xy();
                    if let Some(o) = &mut self.disturbance {
                        o.update(dt, made - (asked - fed_forward));
                        self.disturbance_seen = o.significant_mps2();
                    }
                    if self.estimate_drag {
                        self.fuse_drag(dt, asked - made, mean_v.xy());
                    }
                }
            }
        }
        self.last = Some((at, vel_enu_mps));
        self.thrust_sum = 0.0;
        self.force_sum = Vector2::zeros();
        self.thrust_ticks = 0;
    }

    /// One window of the drag estimator: the acceleration asked for less the one made,
    /// per axis, against the mean velocity.
    fn fuse_drag(&mut self, dt: f64, shortfall: Vector2<f64>, mean_v: Vector2<f64>) {
        self.drag.predict(dt);
        self.drag.fuse(shortfall.x, mean_v.x);
        self.drag.fuse(shortfall.y, mean_v.y);
        let (d, std) = (self.drag.drag_per_s(), self.drag.std());
        let gap = (d - self.drag_per_s).abs();
        let significant = (SIGNIFICANT_DRAG_FRACTION * self.drag_per_s).max(0.02);
        if std < SETTLED_DRAG_STD && gap > significant.max(3.0 * std) {
            self.drag_trusted = true;
        }
    }

    /// One window of the hover thrust estimator: the upward acceleration made, with the
    /// drag's share added back, against the vertical thrust commanded.
    fn fuse_hover(&mut self, dt: f64, thrust: f64, v: Vector3<f64>, v0: Vector3<f64>) {
        self.ekf.predict(dt);
        let acc = (v.z - v0.z) / dt + self.drag_best_per_s() * 0.5 * (v.z + v0.z);
        self.ekf.fuse(acc, thrust, v.z, v.xy().norm());
        let (hover, std) = (self.ekf.hover_throttle(), self.ekf.std());
        let configured = self.configured.hover_throttle();
        let gap = (hover - configured).abs();
        if std < SETTLED_STD && gap > (SIGNIFICANT_FRACTION * configured).max(2.0 * std) {
            self.trusted = true;
        }
    }
}
