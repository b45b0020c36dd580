//! Where a vehicle whose state stopped arriving may be: its stopping path.
//!
//! A vehicle without a fresh state is handed to its own Hold (docs/dense.md, "A vehicle
//! that goes quiet"). Until the Hold brakes it, it flies on what it was last sent: the
//! commands still on their way, then level flight (the swarm sends no acceleration to a
//! vehicle it cannot place). From its last state (position `p₀`, horizontal velocity
//! `v₀`, at `t₀`) it is therefore somewhere along a bounded path:
//!
//! - its speed never exceeds `V = |v₀| + Δv`, `Δv` what the commands on their way may
//!   add;
//! - it may coast at up to `V` for `T` (from `t₀` until its Hold has surely started to
//!   brake: the Hold confirmed, or still not, and the Hold's own onset), then brakes to
//!   rest at no less than `a_b` and stays;
//! - along `v₀` it goes at most `S = V·T + V²/(2·a_b)`; across it (or back), at most
//!   `ρ = Δv·(T + V/(2·a_b))`, since no more than `Δv` of its velocity points off `v₀`
//!   and braking takes that share down with the rest;
//! - while it coasts it goes on along `v₀` at no less than `|v₀| − Δv`: the first
//!   `S₀ = (|v₀| − Δv)·T` of the path it passes once, by `s/(|v₀| − Δv)` at `s`, and so
//!   no more than `Δv·s/(|v₀| − Δv)` across it there. The capsule narrows towards its
//!   start: a neighbour beside where the vehicle was last seen is not pushed as far as
//!   one beside where it may stop.
//!
//! So it stays within `ρ(s)` of the segment from `p₀` to `p₀ + S·v̂₀`, and within
//! [`HOLD_SPREAD_M`] more once there: the Hold keeps its place on its own estimate. The
//! filter keeps its neighbours out of it: a chain of points along the segment, each an
//! uncontrolled agent at rest whose spread covers its stretch
//! ([`super::Agent::spread_m`]). A neighbour then brakes for where the vehicle may stop,
//! not for where it was last seen, and not for a point that goes on at its last velocity.
//!
//! Pure: no allocation, no clock.

use nalgebra::{Vector2, Vector3};

/// The least braking counted for a vehicle in its own Hold (m/s²): PX4's Hold brakes
/// at MPC_ACC_HOR (3 m/s² by default) once its jerk limit has ramped up, ArduCopter's
/// BRAKE at 7.5 m/s² (BRAKE_MODE_DECEL_RATE); two thirds of PX4's default leave room
/// for a vehicle tuned gentler.
pub const HOLD_BRAKING_MPS2: f64 = 2.0;

/// The time a Hold takes to start braking once in the mode (s), counted as coasting:
/// PX4's ramp to MPC_ACC_HOR at MPC_JERK_AUTO (3 m/s² at 4 m/s³: 0.75 s).
pub const HOLD_ONSET_S: f64 = 0.75;

/// How far a vehicle in its Hold may wander from where it stopped (m): its own position
/// control on its own estimate.
pub const HOLD_SPREAD_M: f64 = 0.25;

/// The spacing of the points that stand for a path (m): each covers half of it either
/// side, so every pair keeps a quarter of a metre more than the capsule asks.
pub const POINT_SPACING_M: f64 = 0.5;

/// The most points a path is given; a longer path is covered by fewer, wider ones.
pub const MAX_POINTS: usize = 64;

/// What is known of a vehicle whose state stopped arriving.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LostVehicle {
    /// Its last known position (m, ENU).
    pub pos_m: Vector3<f64>,
    /// Its last known horizontal velocity (m/s, ENU).
    pub vel_mps: Vector2<f64>,
    /// How long it may coast from its last state before it brakes (s): until its Hold
    /// was confirmed (or until now, not yet), and the Hold's onset.
    pub coast_s: f64,
    /// What the commands still on their way when it was last seen may add to its speed
    /// (m/s).
    pub speed_margin_mps: f64,
    /// The least it brakes at in its Hold (m/s²).
    pub braking_mps2: f64,
}

/// The capsule a lost vehicle stays in: within [`StoppingPath::radius_at_m`] of the
/// segment from `start_m` along `direction` for `length_m` (horizontal; the altitude is
/// its last one).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StoppingPath {
    /// Where it was last seen (m, ENU).
    pub start_m: Vector3<f64>,
    /// The unit direction of its last velocity (east when it had none).
    pub direction: Vector2<f64>,
    /// How far along it may go (m).
    pub length_m: f64,
    /// How far off the segment it may be, at most (m).
    pub radius_m: f64,
    /// The stretch it passes once while coasting (m from the start).
    pub narrow_m: f64,
    /// How far off it may be per metre along that stretch.
    pub narrow_per_m: f64,
}

impl LostVehicle {
    /// Its stopping path; `None` when a number is not finite, a time or margin is
    /// negative, or the braking is not positive (then nothing bounds where it is).
    pub fn path(&self) -> Option<StoppingPath> {
        let finite = self
            .pos_m
            .iter()
            .chain(self.vel_mps.iter())
            .all(|x| x.is_finite())
            && self.coast_s.is_finite()
            && self.speed_margin_mps.is_finite()
            && self.braking_mps2.is_finite();
        if !finite || self.coast_s < 0.0 || self.speed_margin_mps < 0.0 || self.braking_mps2 <= 0.0
        {
            return None;
        }
        let speed = self.vel_mps.norm();
        let top = speed + self.speed_margin_mps;
        // Coasting, then braking to rest: the time that scales each share of the speed.
        let reach_s = self.coast_s + top / (2.0 * self.braking_mps2);
        let direction = if speed > 0.0 {
            self.vel_mps / speed
        } else {
            Vector2::x()
        };
        let slowest = speed - self.speed_margin_mps;
        let (narrow_m, narrow_per_m) = if slowest > 0.0 {
            (slowest * self.coast_s, self.speed_margin_mps / slowest)
        } else {
            (0.0, 0.0)
        };
        Some(StoppingPath {
            start_m: self.pos_m,
            direction,
            length_m: top * reach_s,
            radius_m: self.speed_margin_mps * reach_s + HOLD_SPREAD_M,
            narrow_m,
            narrow_per_m,
        })
    }
}

impl StoppingPath {
    /// How far off the segment it may be at `along_m` from the start (m).
    pub fn radius_at_m(&self, along_m: f64) -> f64 {
        if along_m < self.narrow_m {
            (HOLD_SPREAD_M + self.narrow_per_m * along_m.max(0.0)).min(self.radius_m)
        } else {
            self.radius_m
        }
    }

    /// The points that stand for it, each with its spread (m): evenly along the segment,
    /// [`POINT_SPACING_M`] apart or, on a path longer than [`MAX_POINTS`] of them, wider;
    /// each point's spread is half the gap to the next and the radius at the far end of
    /// its stretch.
    pub fn points(&self) -> impl Iterator<Item = (Vector3<f64>, f64)> + '_ {
        let gaps = (self.length_m / POINT_SPACING_M).ceil();
        let gaps = if gaps.is_finite() {
            (gaps as usize).min(MAX_POINTS - 1)
        } else {
            MAX_POINTS - 1
        };
        let gap_m = if gaps == 0 {
            0.0
        } else {
            self.length_m / gaps as f64
        };
        (0..=gaps).map(move |k| {
            let s = gap_m * k as f64;
            let along = self.direction * s;
            (
                self.start_m + Vector3::new(along.x, along.y, 0.0),
                self.radius_at_m(s + 0.5 * gap_m) + 0.5 * gap_m,
            )
        })
    }

    /// How far `p` lies outside the capsule across it, at its own place along it (m,
    /// horizontal; 0 inside).
    pub fn distance_m(&self, p: Vector2<f64>) -> f64 {
        let d = p - self.start_m.xy();
        let along = d.dot(&self.direction).clamp(0.0, self.length_m);
        ((d - self.direction * along).norm() - self.radius_at_m(along)).max(0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lost(v: Vector2<f64>, coast_s: f64, margin: f64) -> LostVehicle {
        LostVehicle {
            pos_m: Vector3::new(10.0, -4.0, 20.0),
            vel_mps: v,
            coast_s,
            speed_margin_mps: margin,
            braking_mps2: 1.0,
        }
    }

    #[test]
    fn a_vehicle_coasts_then_brakes_to_rest_along_its_velocity() {
        // 1 m/s north, coasting 1.05 s, braking at 1 m/s², nothing on its way:
        // 1.05 m + 1²/2 m = 1.55 m along north, the Hold's 0.25 m across.
        let path = lost(Vector2::new(0.0, 1.0), 1.05, 0.0)
            .path()
            .expect("bounded");
        assert!((path.length_m - 1.55).abs() < 1e-12, "{}", path.length_m);
        assert!((path.radius_m - HOLD_SPREAD_M).abs() < 1e-12);
        assert_eq!(path.direction, Vector2::new(0.0, 1.0));
        // 15 m/s with 0.2 m/s on its way, coasting 0.6 s: V = 15.2 m/s, reach time
        // 0.6 + 15.2/2 = 8.2 s, so 124.64 m along and 0.2·8.2 + 0.25 = 1.89 m across.
        let fast = lost(Vector2::new(15.0, 0.0), 0.6, 0.2)
            .path()
            .expect("bounded");
        assert!((fast.length_m - 124.64).abs() < 1e-9, "{}", fast.length_m);
        assert!((fast.radius_m - 1.89).abs() < 1e-12, "{}", fast.radius_m);
    }

    #[test]
    fn every_motion_the_model_allows_stays_in_the_capsule() {
        // Simulated motions inside the assumptions: commands on their way add up to Δv in
        // any direction over the first 0.3 s, the vehicle coasts until T, then brakes at
        // any rate from a_b to 3·a_b. Every position stays within the capsule.
        let mut seed = 7u64;
        let mut next = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..400 {
            let angle = std::f64::consts::TAU * next();
            let speed = 4.0 * next();
            let v0 = Vector2::new(angle.cos(), angle.sin()) * speed;
            let margin = 0.8 * next();
            let coast = 1.5 * next();
            let model = lost(v0, coast, margin);
            let path = model.path().expect("bounded");
            let push_angle = std::f64::consts::TAU * next();
            let push = Vector2::new(push_angle.cos(), push_angle.sin()) * (margin / 0.3);
            let brake = 1.0 + 2.0 * next();
            let (mut p, mut v) = (model.pos_m.xy(), v0);
            let dt = 1e-3;
            let mut t = 0.0;
            while t < 30.0 {
                let a = if t < 0.3_f64.min(coast) {
                    push
                } else if t < coast {
                    Vector2::zeros()
                } else if v.norm() > brake * dt {
                    -v / v.norm() * brake
                } else {
                    v = Vector2::zeros();
                    Vector2::zeros()
                };
                v += a * dt;
                p += v * dt;
                t += dt;
                let off = path.distance_m(p);
                assert!(off <= 1e-6, "{off} m outside at {t} s ({model:?})");
            }
        }
    }

    #[test]
    fn its_points_cover_the_capsule() {
        let path = lost(Vector2::new(3.0, 4.0), 0.5, 0.1)
            .path()
            .expect("bounded");
        let points: Vec<_> = path.points().collect();
        // 5 m/s + 0.1: 5.1·(0.5 + 2.55) = 15.555 m, in 32 gaps of 0.486 m.
        assert_eq!(points.len(), 33);
        let gap = 15.555 / 32.0;
        // It narrows over the first (5 − 0.1)·0.5 = 2.45 m, by 0.1/4.9 per metre.
        assert!((path.narrow_m - 2.45).abs() < 1e-12);
        assert!((path.radius_at_m(1.0) - (0.25 + 0.1 / 4.9)).abs() < 1e-12);
        assert_eq!(path.radius_at_m(2.5), path.radius_m);
        for (k, (p, spread)) in points.iter().enumerate() {
            let s = gap * k as f64;
            assert!((spread - (path.radius_at_m(s + 0.5 * gap) + 0.5 * gap)).abs() < 1e-12);
            let expected = path.start_m.xy() + path.direction * (gap * k as f64);
            assert!((p.xy() - expected).norm() < 1e-9);
            assert_eq!(p.z, 20.0);
        }
        // Any point of the capsule is within some point's spread.
        for k in 0..=1000 {
            let along = path.length_m * k as f64 / 1000.0;
            let across =
                Vector2::new(-path.direction.y, path.direction.x) * path.radius_at_m(along);
            let q = path.start_m.xy() + path.direction * along + across;
            let nearest = points
                .iter()
                .map(|(p, s)| (p.xy() - q).norm() - s)
                .fold(f64::INFINITY, f64::min);
            assert!(nearest <= 1e-9, "{nearest}");
        }
        // A long path is covered by MAX_POINTS wider points.
        let long = lost(Vector2::new(15.0, 0.0), 0.6, 0.2)
            .path()
            .expect("bounded");
        let points: Vec<_> = long.points().collect();
        assert_eq!(points.len(), MAX_POINTS);
        let last = points.last().expect("points").0;
        assert!((last.x - (10.0 + long.length_m)).abs() < 1e-9);
    }

    #[test]
    fn at_rest_it_is_a_disc_and_a_bad_number_bounds_nothing() {
        let path = lost(Vector2::zeros(), 0.5, 0.0).path().expect("bounded");
        assert_eq!(path.length_m, 0.0);
        let points: Vec<_> = path.points().collect();
        assert_eq!(points, vec![(path.start_m, HOLD_SPREAD_M)]);
        assert!(lost(Vector2::new(f64::NAN, 0.0), 0.5, 0.0).path().is_none());
        assert!(lost(Vector2::zeros(), -0.1, 0.0).path().is_none());
        let mut no_brakes = lost(Vector2::zeros(), 0.5, 0.0);
        no_brakes.braking_mps2 = 0.0;
        assert!(no_brakes.path().is_none());
    }
}
