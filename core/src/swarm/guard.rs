//! The divergence guard: notices a swarm that runs away from what the law promises, which
//! a wrong model can cause (a drag fed forward that is larger than the vehicle's, PX4's
//! own loops) and the law itself cannot see.
//!
//! Two symptoms, both watched only during consensus, once per control tick:
//!
//! - **Velocity:** the w-weighted mean velocity `v̄_w = Σwᵢvᵢ / Σwᵢ` leaves the predicted
//!   final velocity `v_f` by more than `velocity_error_mps` (or `velocity_error_fraction`
//!   of `|v_f|`, the larger: an airframe's own loops dip a fast swarm's speed by a few
//!   percent while the formation turns) for longer than `velocity_error_s`. The law keeps `w·v` exactly for a vehicle that is the model, so
//!   on the emulator with a matched model the error is zero, and the mean-velocity
//!   correction holds it within a few centimetres a second against model error; a
//!   growing error is positive feedback the correction cannot beat.
//! - **Formation:** the formation error (the largest distance of `pᵢ − dᵢ` from their
//!   mean) stays more than `formation_growth_m` (or `formation_growth_fraction` of it,
//!   the larger) above the lowest it reached in this
//!   consensus for longer than `formation_growth_s`, while the velocities are no closer
//!   together than they were then (the velocity spread, the largest distance of a
//!   velocity from the mean, is not below its value at the lowest formation error).
//!   Vehicles that start at different velocities drift apart until the velocities agree:
//!   the formation error of that transient grows for as long as the slowest velocity
//!   mode takes, but the spread falls all along, so it never trips.
//!
//! ```text
//!  watching ──|e_v| > bound for velocity_error_s──────────────► tripped (velocity)
//!     │    └──formation > lowest + margin for formation_growth_s,
//!     │       velocity spread not below its value at the lowest ──────► tripped (formation)
//!     └── reset() at every start of consensus (new prediction, new lowest formation)
//! ```
//!
//! Pure: no I/O, no clock (time is an argument), no logging.

use std::fmt;
use std::time::Duration;

use nalgebra::Vector2;
use ringswarm_wire::time::SimTime;

/// The guard's bounds, checked once at construction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GuardLimits {
    velocity_error_mps: f64,
    velocity_error_fraction: f64,
    velocity_error_time: Duration,
    formation_growth_m: f64,
    formation_growth_fraction: f64,
    formation_growth_time: Duration,
}

impl GuardLimits {
    /// Bounds from the configuration's numbers; `Err` names the first that cannot be
    /// used (non-finite, not positive, or a time beyond a day).
    ///
    /// # Errors
    /// A message naming the bound and its value.
    pub fn new(
        (velocity_error_mps, velocity_error_fraction, velocity_error_s): (f64, f64, f64),
        (formation_growth_m, formation_growth_fraction, formation_growth_s): (f64, f64, f64),
    ) -> Result<Self, String> {
        let positive = |name: &str, v: f64, hi: f64| {
            if v.is_finite() && v > 0.0 && v <= hi {
                Ok(v)
            } else {
                Err(format!(
                    "{name} must be a finite number in (0, {hi}], got {v}"
                ))
            }
        };
        let day_s = 86_400.0;
        Ok(Self {
            velocity_error_mps: positive("velocity_error_mps", velocity_error_mps, 100.0)?,
            velocity_error_fraction: positive(
                "velocity_error_fraction",
                velocity_error_fraction,
                10.0,
            )?,
            velocity_error_time: Duration::from_secs_f64(positive(
                "velocity_error_s",
                velocity_error_s,
                day_s,
            )?),
            formation_growth_m: positive("formation_growth_m", formation_growth_m, 1.0e4)?,
            formation_growth_fraction: positive(
                "formation_growth_fraction",
                formation_growth_fraction,
                100.0,
            )?,
            formation_growth_time: Duration::from_secs_f64(positive(
                "formation_growth_s",
                formation_growth_s,
                day_s,
            )?),
        })
    }

    /// The velocity bound for a prediction (m/s): `velocity_error_mps`, or
    /// `velocity_error_fraction` of the predicted speed, the larger.
    pub fn velocity_bound_mps(&self, predicted_mps: Vector2<f64>) -> f64 {
        self.velocity_error_mps
            .max(self.velocity_error_fraction * predicted_mps.norm())
    }
}

/// Why the guard tripped.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum GuardTrip {
    /// The mean velocity left the prediction.
    Velocity {
        /// `v̄_w` when it tripped (m/s, ENU).
        mean_mps: Vector2<f64>,
        /// The prediction (m/s, ENU).
        predicted_mps: Vector2<f64>,
        /// The bound (m/s).
        bound_mps: f64,
        /// How long the error had been beyond it.
        for_s: f64,
    },
    /// The formation error kept growing.
    Formation {
        /// The formation error when it tripped (m).
        now_m: f64,
        /// The lowest it had been since consensus started (m).
        lowest_m: f64,
        /// How long ago that was (s).
        for_s: f64,
    },
}

impl GuardTrip {
    /// `velocity` or `formation`.
    pub fn cause(&self) -> &'static str {
        match self {
            Self::Velocity { .. } => "velocity",
            Self::Formation { .. } => "formation",
        }
    }
}

impl fmt::Display for GuardTrip {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Velocity {
                mean_mps,
                predicted_mps,
                bound_mps,
                for_s,
            } => write!(
                f,
                "divergence guard: the mean velocity ({:.2}, {:.2}) m/s is {:.2} m/s off the predicted ({:.2}, {:.2}) m/s, beyond {bound_mps:.2} m/s for {for_s:.1} s",
                mean_mps.x,
                mean_mps.y,
                (mean_mps - predicted_mps).norm(),
                predicted_mps.x,
                predicted_mps.y,
            ),
            Self::Formation {
                now_m,
                lowest_m,
                for_s,
            } => write!(
                f,
                "divergence guard: the formation error grew from {lowest_m:.2} m to {now_m:.2} m and has not come back for {for_s:.1} s"
            ),
        }
    }
}

/// The guard's state over one consensus run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DivergenceGuard {
    limits: GuardLimits,
    velocity_beyond_since: Option<SimTime>,
    /// When the formation error was lowest, that error (m) and the velocity spread then
    /// (m/s).
    lowest_formation: Option<(SimTime, f64, f64)>,
}

impl DivergenceGuard {
    /// A guard with these bounds, watching nothing yet.
    pub fn new(limits: GuardLimits) -> Self {
        Self {
            limits,
            velocity_beyond_since: None,
            lowest_formation: None,
        }
    }

    /// Forgets the past: call at every start of consensus.
    pub fn reset(&mut self) {
        self.velocity_beyond_since = None;
        self.lowest_formation = None;
    }

    /// Forgets the lowest formation error: the formation watch starts again from the next
    /// tick. While the safety filter's jams are being broken, vehicles are turned past
    /// each other on purpose and the formation error grows meanwhile; the velocity watch
    /// goes on (the turn keeps `Σ wᵢuᵢ`).
    pub fn restart_formation(&mut self) {
        self.lowest_formation = None;
    }

    /// One consensus tick: the w-weighted mean velocity and the prediction (m/s, ENU), the
    /// formation error (m) and the velocity spread (the largest distance of a velocity
    /// from the mean, m/s). Returns why it trips, if it does. A non-finite mean velocity
    /// counts as beyond the bound.
    pub fn observe(
        &mut self,
        now: SimTime,
        mean_mps: Vector2<f64>,
        predicted_mps: Vector2<f64>,
        (formation_m, spread_mps): (f64, f64),
    ) -> Option<GuardTrip> {
        let error = (mean_mps - predicted_mps).norm();
        let bound = self.limits.velocity_bound_mps(predicted_mps);
        if error > bound || !error.is_finite() {
            let since = *self.velocity_beyond_since.get_or_insert(now);
            let for_time = now.saturating_since(since);
            if for_time >= self.limits.velocity_error_time {
                return Some(GuardTrip::Velocity {
                    mean_mps,
                    predicted_mps,
                    bound_mps: bound,
                    for_s: for_time.as_secs_f64(),
                });
            }
        } else {
            self.velocity_beyond_since = None;
        }
        if !(formation_m.is_finite() && spread_mps.is_finite()) {
            return None;
        }
        match self.lowest_formation {
            Some((_, lowest, _)) if formation_m > lowest => {}
            _ => self.lowest_formation = Some((now, formation_m, spread_mps)),
        }
        let (at, lowest, spread_then) = self.lowest_formation?;
        let for_time = now.saturating_since(at);
        // Velocities that come together explain a growing formation error (they drift
        // apart until they agree); only growth while they do not is divergence.
        let margin = self
            .limits
            .formation_growth_m
            .max(self.limits.formation_growth_fraction * lowest);
        if formation_m > lowest + margin
            && for_time >= self.limits.formation_growth_time
            && spread_mps >= spread_then
        {
            return Some(GuardTrip::Formation {
                now_m: formation_m,
                lowest_m: lowest,
                for_s: for_time.as_secs_f64(),
            });
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn limits() -> GuardLimits {
        GuardLimits::new((1.0, 0.1, 1.0), (2.0, 0.5, 5.0)).unwrap()
    }

    fn at(ms: u64) -> SimTime {
        SimTime::from_micros(ms * 1000)
    }

    #[test]
    fn bad_bounds_are_refused_by_name() {
        let e = GuardLimits::new((f64::NAN, 0.1, 1.0), (2.0, 0.5, 5.0)).unwrap_err();
        assert!(e.starts_with("velocity_error_mps"), "{e}");
        let e = GuardLimits::new((1.0, 0.1, 0.0), (2.0, 0.5, 5.0)).unwrap_err();
        assert!(e.starts_with("velocity_error_s"), "{e}");
        let e = GuardLimits::new((1.0, -0.1, 1.0), (2.0, 0.5, 5.0)).unwrap_err();
        assert!(e.starts_with("velocity_error_fraction"), "{e}");
        let e = GuardLimits::new((1.0, 0.1, 1.0), (-2.0, 0.5, 5.0)).unwrap_err();
        assert!(e.starts_with("formation_growth_m"), "{e}");
        let e = GuardLimits::new((1.0, 0.1, 1.0), (2.0, f64::INFINITY, 5.0)).unwrap_err();
        assert!(e.starts_with("formation_growth_fraction"), "{e}");
        let e = GuardLimits::new((1.0, 0.1, 1.0), (2.0, 0.5, 1e9)).unwrap_err();
        assert!(e.starts_with("formation_growth_s"), "{e}");
    }

    #[test]
    fn a_velocity_error_trips_after_its_time_and_not_before() {
        let mut g = DivergenceGuard::new(limits());
        let v_f = Vector2::new(3.0, 0.0);
        // 1.5 m/s off from 0 s: not at 0.98 s, tripped at 1.0 s.
        for ms in (0..1000).step_by(20) {
            assert_eq!(
                g.observe(at(ms), Vector2::new(4.5, 0.0), v_f, (1.0, 0.5)),
                None
            );
        }
        let trip = g
            .observe(at(1000), Vector2::new(4.5, 0.0), v_f, (1.0, 0.5))
            .unwrap();
        assert_eq!(trip.cause(), "velocity");
        let GuardTrip::Velocity { for_s, .. } = trip else {
            unreachable!()
        };
        assert_eq!(for_s, 1.0);
    }

    #[test]
    fn a_fast_swarm_gets_a_proportional_velocity_bound() {
        let mut g = DivergenceGuard::new(limits());
        // At 14 m/s the bound is 1.4 m/s: 1.3 m/s off never trips, 1.5 m/s does.
        let v_f = Vector2::new(14.0, 0.0);
        for ms in (0..3000).step_by(20) {
            assert_eq!(
                g.observe(at(ms), Vector2::new(12.7, 0.0), v_f, (1.0, 0.5)),
                None
            );
        }
        assert_eq!(
            g.observe(at(3000), Vector2::new(12.5, 0.0), v_f, (1.0, 0.5)),
            None
        );
        assert!(
            g.observe(at(4000), Vector2::new(12.5, 0.0), v_f, (1.0, 0.5))
                .is_some()
        );
    }

    #[test]
    fn a_velocity_error_that_comes_back_restarts_the_clock() {
        let mut g = DivergenceGuard::new(limits());
        let v_f = Vector2::zeros();
        assert_eq!(
            g.observe(at(0), Vector2::new(0.0, 1.2), v_f, (1.0, 0.5)),
            None
        );
        assert_eq!(
            g.observe(at(900), Vector2::new(0.0, 1.2), v_f, (1.0, 0.5)),
            None
        );
        // Back within 1 m/s (0.99 off) at 0.92 s.
        assert_eq!(
            g.observe(at(920), Vector2::new(0.0, 0.99), v_f, (1.0, 0.5)),
            None
        );
        assert_eq!(
            g.observe(at(940), Vector2::new(0.0, 1.2), v_f, (1.0, 0.5)),
            None
        );
        assert_eq!(
            g.observe(at(1900), Vector2::new(0.0, 1.2), v_f, (1.0, 0.5)),
            None
        );
        assert!(
            g.observe(at(1940), Vector2::new(0.0, 1.2), v_f, (1.0, 0.5))
                .is_some()
        );
    }

    #[test]
    fn a_non_finite_mean_counts_as_beyond_the_bound() {
        let mut g = DivergenceGuard::new(limits());
        let nan = Vector2::new(f64::NAN, 0.0);
        assert_eq!(g.observe(at(0), nan, Vector2::zeros(), (1.0, 0.5)), None);
        assert!(
            g.observe(at(1000), nan, Vector2::zeros(), (1.0, 0.5))
                .is_some()
        );
    }

    #[test]
    fn formation_growth_trips_only_when_it_lasts_and_exceeds_the_margin() {
        let mut g = DivergenceGuard::new(limits());
        let v = Vector2::zeros();
        // Falls from 10 m to 3 m over 7 s (lowest 3 m at 7 s), then grows by 1 m/s.
        for s in 0..=7u64 {
            assert_eq!(g.observe(at(s * 1000), v, v, (10.0 - s as f64, 0.5)), None);
        }
        // 5.0 m at 9 s: 2 m above the lowest (not beyond), 2 s on.
        assert_eq!(g.observe(at(9000), v, v, (5.0, 0.5)), None);
        // 8.5 m at 11.9 s: beyond the margin, but only 4.9 s since the lowest.
        assert_eq!(g.observe(at(11_900), v, v, (8.5, 0.5)), None);
        let trip = g.observe(at(12_000), v, v, (8.6, 0.5)).unwrap();
        assert_eq!(
            trip,
            GuardTrip::Formation {
                now_m: 8.6,
                lowest_m: 3.0,
                for_s: 5.0
            }
        );
    }

    #[test]
    fn a_large_formation_error_needs_a_proportional_growth() {
        let mut g = DivergenceGuard::new(limits());
        let v = Vector2::zeros();
        // Lowest 100 m: 2 m is not enough, half of it (50 m) is the margin.
        assert_eq!(g.observe(at(0), v, v, (100.0, 1.0)), None);
        assert_eq!(g.observe(at(6000), v, v, (150.0, 1.0)), None);
        assert!(g.observe(at(6020), v, v, (150.1, 1.0)).is_some());
    }

    #[test]
    fn growth_while_the_velocities_come_together_never_trips() {
        let mut g = DivergenceGuard::new(limits());
        let v = Vector2::zeros();
        // The formation error grows from 10 m to 60 m over 20 s while the spread falls
        // from 30 m/s to 1 m/s (velocities converging from far apart).
        for s in 0..=20u64 {
            let e = 10.0 + 2.5 * s as f64;
            let spread = 30.0 - 1.45 * s as f64;
            assert_eq!(g.observe(at(s * 1000), v, v, (e, spread)), None, "{s} s");
        }
        // The same growth with the spread back at 30 m/s trips.
        assert!(g.observe(at(21_000), v, v, (62.0, 30.0)).is_some());
    }

    #[test]
    fn a_transient_that_comes_back_below_its_lowest_never_trips() {
        let mut g = DivergenceGuard::new(limits());
        let v = Vector2::zeros();
        // Grows from 4 m to 9 m within 4 s, then back below 4 m by 4.8 s.
        let trace = [(0, 4.0), (2000, 9.0), (4000, 9.0), (4800, 3.9), (9000, 3.0)];
        for (ms, e) in trace {
            assert_eq!(g.observe(at(ms), v, v, (e, 0.5)), None);
        }
        // The reset forgets the lowest: a new consensus starts from 20 m.
        g.reset();
        assert_eq!(g.observe(at(10_000), v, v, (20.0, 0.5)), None);
        assert_eq!(g.observe(at(16_000), v, v, (21.0, 0.5)), None);
    }
}
