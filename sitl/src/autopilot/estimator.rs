//! What the vehicle's estimator reports, as opposed to the truth: seeded white noise on
//! position and velocity, a slow GPS-like drift of the position (a first-order
//! Gauss–Markov bias per horizontal axis, as a GNSS receiver wanders), a latency, and
//! telemetry faults that let tests see how a ground station copes with bad reports (NaN
//! positions, positions that stop while the heartbeat goes on, an estimator origin that
//! moves). The vehicle's own controllers fly on the truth; only what it sends is
//! affected. With everything at zero the reports are the truth, and nothing is drawn.

use std::collections::VecDeque;
use std::time::Duration;

use nalgebra::Vector3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use crate::time::SimTime;

/// How wrong the estimate is.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct EstimatorConfig {
    /// White noise on each position axis (m, one standard deviation).
    pub position_noise_m: f64,
    /// White noise on each velocity axis (m/s, one standard deviation).
    pub velocity_noise_mps: f64,
    /// Standard deviation of the slow horizontal position drift (m).
    pub drift_std_m: f64,
    /// Correlation time of the drift (s).
    pub drift_tau_s: f64,
    /// Age of what is reported (the estimator's delay).
    pub latency: Duration,
    /// Faults, each for a while.
    pub faults: Vec<TelemetryFault>,
}

/// A telemetry fault between `from` and `until`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TelemetryFault {
    /// Start.
    pub from: SimTime,
    /// End.
    pub until: SimTime,
    /// What goes wrong.
    pub kind: FaultKind,
}

/// What a telemetry fault does.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FaultKind {
    /// LOCAL_POSITION_NED carries NaN in every field.
    NanPosition,
    /// LOCAL_POSITION_NED is not sent; the heartbeat and everything else go on.
    NoPosition,
    /// The estimator's origin is moved by `shift_ned_m` (GPS_GLOBAL_ORIGIN reports the
    /// new origin at once); with `positions_follow` the local positions shift to match,
    /// as PX4's estimator does, otherwise they do not (the vehicle seems to jump).
    OriginShift {
        /// Where the new origin is, from the old one (m, NED).
        shift_ned_m: Vector3<f64>,
        /// Whether LOCAL_POSITION_NED moves with the origin.
        positions_follow: bool,
    },
    /// The estimator loses its horizontal position and velocity, as PX4's EKF2 does when
    /// its GNSS and sensors stop fitting: ESTIMATOR_STATUS says the attitude alone is good
    /// ([`SOLUTION_ATTITUDE_ONLY`]) while LOCAL_POSITION_NED goes on, dead-reckoned: its
    /// velocity off the truth by [`DEAD_RECKONING_ERROR_MPS`] north and its position
    /// drifting with it. The vehicle's own controllers still fly on the truth.
    PositionLost,
}

/// ESTIMATOR_STATUS flags of a healthy estimate in the air (what PX4 SIH reports:
/// attitude, horizontal and vertical velocity, relative and absolute horizontal position,
/// absolute and above-ground vertical position, and both predicted positions).
pub const SOLUTION_HEALTHY: u16 = 0x37f;
/// Added on the ground: PX4's constant position mode while the vehicle is at rest.
pub const SOLUTION_AT_REST: u16 = 0x80;
/// ESTIMATOR_STATUS flags of an estimate that kept only its attitude.
pub const SOLUTION_ATTITUDE_ONLY: u16 = 0x1;
/// How far off the truth a dead-reckoned velocity is during [`FaultKind::PositionLost`]
/// (m/s, north).
pub const DEAD_RECKONING_ERROR_MPS: f64 = 1.0;

impl EstimatorConfig {
    /// Checks every number.
    ///
    /// # Errors
    /// A message naming the field and its value.
    pub fn validate(&self) -> Result<(), String> {
        let within = |name: &str, v: f64, hi: f64| {
            if v.is_finite() && (0.0..=hi).contains(&v) {
                Ok(())
            } else {
                Err(format!("{name} must be in [0, {hi}], got {v}"))
            }
        };
        within("position_noise_m", self.position_noise_m, 100.0)?;
        within("velocity_noise_mps", self.velocity_noise_mps, 10.0)?;
        within("drift_std_m", self.drift_std_m, 100.0)?;
        if self.drift_std_m > 0.0 && !(self.drift_tau_s.is_finite() && self.drift_tau_s > 0.0) {
            return Err(format!(
                "drift_tau_s must be positive with a drift, got {}",
                self.drift_tau_s
            ));
        }
        if self.latency > Duration::from_secs(2) {
            return Err(format!(
                "latency must be at most 2 s, got {} s",
                self.latency.as_secs_f64()
            ));
        }
        for f in &self.faults {
            if f.until <= f.from {
                return Err("a telemetry fault must end after it starts".to_owned());
            }
            if let FaultKind::OriginShift { shift_ned_m, .. } = f.kind
                && !(shift_ned_m.iter().all(|x| x.is_finite()) && shift_ned_m.norm() <= 1.0e5)
            {
                return Err("an origin shift must be finite and at most 100 km".to_owned());
            }
        }
        Ok(())
    }
}

/// The estimator of one vehicle.
#[derive(Debug, Clone)]
pub(super) struct Estimator {
    cfg: EstimatorConfig,
    rng: ChaCha8Rng,
    drift_ned_m: Vector3<f64>,
    noise_pos_m: Vector3<f64>,
    noise_vel_mps: Vector3<f64>,
    /// Truth (time, position, velocity) kept for the latency.
    history: VecDeque<(SimTime, Vector3<f64>, Vector3<f64>)>,
    idle: bool,
}

impl Estimator {
    pub(super) fn new(cfg: EstimatorConfig, seed: u64) -> Self {
        let idle = cfg.position_noise_m == 0.0
            && cfg.velocity_noise_mps == 0.0
            && cfg.drift_std_m == 0.0
            && cfg.latency.is_zero();
        Self {
            cfg,
            // Its own stream: turning the estimate's errors on never changes the gusts.
            rng: ChaCha8Rng::seed_from_u64(seed ^ 0x6573_7469_6d61_7465),
            drift_ned_m: Vector3::zeros(),
            noise_pos_m: Vector3::zeros(),
            noise_vel_mps: Vector3::zeros(),
            history: VecDeque::new(),
            idle,
        }
    }

    /// One physics step of `dt_s` ending at `now`, with the true local state.
    pub(super) fn step(&mut self, now: SimTime, dt_s: f64, pos_m: Vector3<f64>, vel: Vector3<f64>) {
        if self.idle {
            return;
        }
        let mut normal = || -> f64 { StandardNormal.sample(&mut self.rng) };
        if self.cfg.drift_std_m > 0.0 {
            // Exact discretisation of db = −b/τ dt + σ√(2/τ) dW: stationary std σ.
            let a = (-dt_s / self.cfg.drift_tau_s).exp();
            let s = self.cfg.drift_std_m * (1.0 - a * a).sqrt();
            self.drift_ned_m.x = a * self.drift_ned_m.x + s * normal();
            self.drift_ned_m.y = a * self.drift_ned_m.y + s * normal();
        }
        if self.cfg.position_noise_m > 0.0 {
            let s = self.cfg.position_noise_m;
            self.noise_pos_m = Vector3::new(s * normal(), s * normal(), s * normal());
        }
        if self.cfg.velocity_noise_mps > 0.0 {
            let s = self.cfg.velocity_noise_mps;
            self.noise_vel_mps = Vector3::new(s * normal(), s * normal(), s * normal());
        }
        if !self.cfg.latency.is_zero() {
            self.history.push_back((now, pos_m, vel));
            while self
                .history
                .get(1)
                .is_some_and(|&(t, _, _)| now.saturating_since(t) >= self.cfg.latency)
            {
                self.history.pop_front();
            }
        }
    }

    fn fault(&self, now: SimTime) -> Option<FaultKind> {
        self.active(now).map(|f| f.kind)
    }

    fn active(&self, now: SimTime) -> Option<&TelemetryFault> {
        self.cfg
            .faults
            .iter()
            .find(|f| now >= f.from && now < f.until)
    }

    /// ESTIMATOR_STATUS's flags now ([`SOLUTION_HEALTHY`], with [`SOLUTION_AT_REST`] on
    /// the ground; [`SOLUTION_ATTITUDE_ONLY`] while the position is lost).
    pub(super) fn solution_flags(&self, now: SimTime, landed: bool) -> u16 {
        match self.fault(now) {
            Some(FaultKind::PositionLost) => SOLUTION_ATTITUDE_ONLY,
            _ if landed => SOLUTION_HEALTHY | SOLUTION_AT_REST,
            _ => SOLUTION_HEALTHY,
        }
    }

    /// Where the reported origin is, from the true one (m, NED).
    pub(super) fn origin_shift_ned_m(&self, now: SimTime) -> Vector3<f64> {
        match self.fault(now) {
            Some(FaultKind::OriginShift { shift_ned_m, .. }) => shift_ned_m,
            _ => Vector3::zeros(),
        }
    }

    /// The reported local position and velocity, or `None` when none is sent.
    pub(super) fn report(
        &self,
        now: SimTime,
        pos_m: Vector3<f64>,
        vel: Vector3<f64>,
    ) -> Option<(Vector3<f64>, Vector3<f64>)> {
        let (mut p, mut v) = match self.history.front() {
            Some(&(_, p, v)) => (p, v),
            None => (pos_m, vel),
        };
        p += self.drift_ned_m + self.noise_pos_m;
        v += self.noise_vel_mps;
        match self.fault(now) {
            Some(FaultKind::NoPosition) => None,
            Some(FaultKind::NanPosition) => {
                Some((Vector3::repeat(f64::NAN), Vector3::repeat(f64::NAN)))
            }
            Some(FaultKind::OriginShift {
                shift_ned_m,
                positions_follow: true,
            }) => Some((p - shift_ned_m, v)),
            Some(FaultKind::PositionLost) => {
                let since_s = self
                    .active(now)
                    .map_or(0.0, |f| now.saturating_since(f.from).as_secs_f64());
                let error = Vector3::new(DEAD_RECKONING_ERROR_MPS, 0.0, 0.0);
                Some((p + error * since_s, v + error))
            }
            _ => Some((p, v)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(cfg: EstimatorConfig, seconds: f64) -> Vec<(Vector3<f64>, Vector3<f64>)> {
        let mut e = Estimator::new(cfg, 7);
        let mut out = Vec::new();
        for k in 1..=(seconds * 1000.0) as u64 {
            let t = SimTime::from_millis(k);
            let x = k as f64 * 1e-3; // moving north at 1 m/s
            e.step(
                t,
                1e-3,
                Vector3::new(x, 0.0, 0.0),
                Vector3::new(1.0, 0.0, 0.0),
            );
            if let Some(r) = e.report(t, Vector3::new(x, 0.0, 0.0), Vector3::new(1.0, 0.0, 0.0)) {
                out.push(r);
            }
        }
        out
    }

    #[test]
    fn without_knobs_the_report_is_the_truth() {
        let r = run(EstimatorConfig::default(), 1.0);
        assert_eq!(r.len(), 1000);
        assert_eq!(r[999].0, Vector3::new(1.0, 0.0, 0.0));
    }

    #[test]
    fn noise_has_its_standard_deviation_and_latency_its_age() {
        let cfg = EstimatorConfig {
            position_noise_m: 0.5,
            velocity_noise_mps: 0.1,
            latency: Duration::from_millis(100),
            ..EstimatorConfig::default()
        };
        let r = run(cfg, 20.0);
        // Position error against the truth 100 ms earlier: mean 0, std 0.5 within 3 %
        // (20 000 samples: the standard error of a std estimate is 0.5 %).
        let errors: Vec<f64> = r
            .iter()
            .enumerate()
            .skip(200)
            .map(|(k, (p, _))| p.x - ((k + 1) as f64 * 1e-3 - 0.1))
            .collect();
        let mean = errors.iter().sum::<f64>() / errors.len() as f64;
        let std =
            (errors.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / errors.len() as f64).sqrt();
        assert!(mean.abs() < 0.02, "mean {mean}");
        assert!((std - 0.5).abs() < 0.015, "std {std}");
        let v_std = (r.iter().map(|(_, v)| (v.y).powi(2)).sum::<f64>() / r.len() as f64).sqrt();
        assert!((v_std - 0.1).abs() < 0.003, "velocity std {v_std}");
    }

    #[test]
    fn drift_wanders_with_its_standard_deviation() {
        let cfg = EstimatorConfig {
            drift_std_m: 1.0,
            drift_tau_s: 5.0,
            ..EstimatorConfig::default()
        };
        // 2000 s = 400 correlation times: the spread of the bias is about 1 m (±10 %).
        let r = run(cfg, 2000.0);
        let bias: Vec<f64> = r
            .iter()
            .enumerate()
            .map(|(k, (p, _))| p.x - (k + 1) as f64 * 1e-3)
            .collect();
        let std = (bias.iter().map(|b| b * b).sum::<f64>() / bias.len() as f64).sqrt();
        assert!((std - 1.0).abs() < 0.1, "drift std {std}");
        // Slow: it moves by far less than its spread in 0.1 s.
        let step = (bias[1100] - bias[1000]).abs();
        assert!(step < 0.3, "{step}");
    }

    #[test]
    fn a_lost_position_is_flagged_and_dead_reckoned() {
        let e = Estimator::new(
            EstimatorConfig {
                faults: vec![TelemetryFault {
                    from: SimTime::from_millis(1000),
                    until: SimTime::from_millis(3000),
                    kind: FaultKind::PositionLost,
                }],
                ..EstimatorConfig::default()
            },
            1,
        );
        let (p, v) = (Vector3::new(1.0, 2.0, -3.0), Vector3::new(0.5, 0.0, 0.0));
        let before = SimTime::from_millis(999);
        assert_eq!(e.solution_flags(before, false), 0x37f);
        assert_eq!(e.solution_flags(before, true), 0x3ff);
        assert_eq!(e.report(before, p, v), Some((p, v)));
        // 1.5 s into the fault: attitude only; 1 m/s north off, 1.5 m drifted.
        let during = SimTime::from_millis(2500);
        assert_eq!(e.solution_flags(during, false), 0x001);
        let (rp, rv) = e.report(during, p, v).unwrap();
        assert!((rp - Vector3::new(2.5, 2.0, -3.0)).norm() < 1e-12, "{rp}");
        assert!((rv - Vector3::new(1.5, 0.0, 0.0)).norm() < 1e-12, "{rv}");
        assert_eq!(e.solution_flags(SimTime::from_millis(3000), false), 0x37f);
    }

    #[test]
    fn faults_act_only_while_they_last() {
        let shift = Vector3::new(100.0, 0.0, 0.0);
        let faults = vec![
            TelemetryFault {
                from: SimTime::from_millis(100),
                until: SimTime::from_millis(200),
                kind: FaultKind::NoPosition,
            },
            TelemetryFault {
                from: SimTime::from_millis(300),
                until: SimTime::from_millis(400),
                kind: FaultKind::NanPosition,
            },
            TelemetryFault {
                from: SimTime::from_millis(500),
                until: SimTime::from_millis(600),
                kind: FaultKind::OriginShift {
                    shift_ned_m: shift,
                    positions_follow: true,
                },
            },
        ];
        let e = Estimator::new(
            EstimatorConfig {
                faults,
                ..EstimatorConfig::default()
            },
            1,
        );
        let p = Vector3::new(5.0, 0.0, 0.0);
        let v = Vector3::zeros();
        let at = |ms| e.report(SimTime::from_millis(ms), p, v);
        assert_eq!(at(99), Some((p, v)));
        assert_eq!(at(150), None);
        assert!(at(350).is_some_and(|(p, _)| p.x.is_nan()));
        assert_eq!(at(550), Some((p - shift, v)));
        assert_eq!(e.origin_shift_ned_m(SimTime::from_millis(550)), shift);
        assert_eq!(at(600), Some((p, v)));
    }
}
