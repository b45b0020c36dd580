//! The smooth reference that auto modes (Takeoff, Hold, goto, Return, Mission, Orbit's
//! approach) hand to the position controller: a point that travels toward a target along
//! a straight line with limited speed and acceleration and stops on it, as PX4's auto
//! flight tasks do with their trajectory generator (PX4's also limits jerk,
//! MPC_JERK_AUTO; this one does not, so its acceleration feed-forward steps).
//!
//! Horizontal and vertical motion are planned separately, each with its own speed and
//! acceleration: the reference's speed toward the target is `min(cruise, √(2·a·d))`,
//! reached from the current reference speed at no more than `a`. Frames: local NED,
//! metres and seconds. Pure and deterministic.

use nalgebra::{Vector2, Vector3};

use crate::position_control::TrajectorySetpoint;

/// Speed, acceleration and jerk limits of one leg.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Horizontal cruise speed (m/s).
    pub speed_xy_mps: f64,
    /// Climb speed (m/s).
    pub speed_up_mps: f64,
    /// Descent speed (m/s).
    pub speed_down_mps: f64,
    /// Horizontal acceleration (m/s²).
    pub acc_xy_mps2: f64,
    /// Vertical acceleration (m/s²).
    pub acc_z_mps2: f64,
}

/// One point (plane or line) with its velocity and acceleration.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Axis {
    pos: Vector2<f64>,
    vel: Vector2<f64>,
    acc: Vector2<f64>,
}

/// A reference point moving toward `target`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Approach {
    target: Vector3<f64>,
    xy: Axis,
    z: Axis,
}

impl Approach {
    /// Starts at the vehicle's position and velocity (no acceleration), heading for
    /// `target`.
    pub fn new(pos_ned_m: Vector3<f64>, vel_ned_mps: Vector3<f64>, target: Vector3<f64>) -> Self {
        Self {
            target,
            xy: Axis {
                pos: pos_ned_m.xy(),
                vel: vel_ned_mps.xy(),
                acc: Vector2::zeros(),
            },
            z: Axis {
                pos: Vector2::new(pos_ned_m.z, 0.0),
                vel: Vector2::new(vel_ned_mps.z, 0.0),
                acc: Vector2::zeros(),
            },
        }
    }

    /// Changes the target, keeping the reference's position, velocity and acceleration.
    pub fn retarget(&mut self, target: Vector3<f64>) {
        self.target = target;
    }

    /// The target.
    pub fn target(&self) -> Vector3<f64> {
        self.target
    }

    /// The reference's position.
    pub fn position(&self) -> Vector3<f64> {
        Vector3::new(self.xy.pos.x, self.xy.pos.y, self.z.pos.x)
    }

    /// Whether the reference has stopped on the target.
    pub fn arrived(&self) -> bool {
        self.position() == self.target
            && self.xy.vel == Vector2::zeros()
            && self.z.vel == Vector2::zeros()
    }

    /// Advances the reference by `dt_s` and returns it as position, velocity and
    /// acceleration setpoint (the last two as feed-forward, as PX4's auto modes give).
    pub fn step(&mut self, limits: &Limits, dt_s: f64) -> TrajectorySetpoint {
        self.xy = step_axis(
            self.xy,
            self.target.xy(),
            limits.speed_xy_mps,
            limits.acc_xy_mps2,
            dt_s,
        );
        let z_speed = if self.target.z < self.z.pos.x {
            limits.speed_up_mps
        } else {
            limits.speed_down_mps
        };
        let z_target = Vector2::new(self.target.z, 0.0);
        self.z = step_axis(self.z, z_target, z_speed, limits.acc_z_mps2, dt_s);
        TrajectorySetpoint {
            pos_ned_m: self.position(),
            vel_ned_mps: Vector3::new(self.xy.vel.x, self.xy.vel.y, self.z.vel.x),
            acc_ned_mps2: Vector3::new(self.xy.acc.x, self.xy.acc.y, self.z.acc.x),
            ..TrajectorySetpoint::UNSET
        }
    }
}

/// One step of a point toward `target` (a plane; a line uses its first coordinate).
fn step_axis(s: Axis, target: Vector2<f64>, speed: f64, acc: f64, dt: f64) -> Axis {
    let to_target = target - s.pos;
    let dist = to_target.norm();
    if dist < 1e-6 && s.vel.norm() < acc * dt {
        return Axis {
            pos: target,
            vel: Vector2::zeros(),
            acc: Vector2::zeros(),
        };
    }
    let dir = if dist > 1e-9 {
        to_target / dist
    } else {
        Vector2::zeros()
    };
    let wanted = dir * speed.min((2.0 * acc * dist).sqrt());
    let dv = wanted - s.vel;
    let max_dv = acc * dt;
    let vel = if dv.norm() > max_dv {
        s.vel + dv.normalize() * max_dv
    } else {
        wanted
    };
    let acc_now = (vel - s.vel) / dt;
    let next = s.pos + vel * dt;
    // Never step past the target.
    if (next - s.pos).norm() >= dist && vel.dot(&to_target) > 0.0 {
        let vel = if dist < 1e-6 { Vector2::zeros() } else { vel };
        return Axis {
            pos: target,
            vel,
            acc: acc_now,
        };
    }
    Axis {
        pos: next,
        vel,
        acc: acc_now,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const LIMITS: Limits = Limits {
        speed_xy_mps: 5.0,
        speed_up_mps: 3.0,
        speed_down_mps: 1.0,
        acc_xy_mps2: 3.0,
        acc_z_mps2: 4.0,
    };

    /// Runs until arrival; returns (time, peak horizontal speed, peak climb speed, peak
    /// acceleration, largest distance past the target).
    fn fly(target: Vector3<f64>) -> (f64, f64, f64, f64, f64) {
        let mut a = Approach::new(Vector3::zeros(), Vector3::zeros(), target);
        let (mut t, mut vxy, mut vup, mut acc, mut past) =
            (0.0, 0.0_f64, 0.0_f64, 0.0_f64, 0.0_f64);
        let dir = target.normalize();
        while !a.arrived() && t < 100.0 {
            let sp = a.step(&LIMITS, 0.001);
            vxy = vxy.max(sp.vel_ned_mps.xy().norm());
            vup = vup.max(-sp.vel_ned_mps.z);
            acc = acc
                .max(sp.acc_ned_mps2.xy().norm())
                .max(sp.acc_ned_mps2.z.abs());
            past = past.max(sp.pos_ned_m.dot(&dir) - target.norm());
            t += 0.001;
        }
        (t, vxy, vup, acc, past)
    }

    #[test]
    fn a_long_leg_cruises_and_takes_the_trapezoid_time() {
        // 100 m at 5 m/s with 3 m/s²: ramps of 5/3 s each covering 25/6 m, then
        // (100 − 25/3)/5 s at cruise: 2·5/3 + 18.333 = 21.667 s (+ up to 0.1 s for the
        // 1 ms steps of the final approach).
        let (t, vxy, _, acc, past) = fly(Vector3::new(60.0, 80.0, 0.0));
        assert!((vxy - 5.0).abs() < 1e-9, "peak {vxy}");
        assert!(acc <= 3.0 + 1e-6, "acc {acc}");
        assert!((t - 21.667).abs() < 0.1, "took {t} s");
        assert!(past <= 0.01, "past the target by {past} m");
    }

    #[test]
    fn a_climb_is_limited_to_the_climb_speed() {
        // 10 m up at 3 m/s with 4 m/s²: 2·0.75 + (10 − 2.25)/3 = 4.083 s.
        let (t, _, vup, _, past) = fly(Vector3::new(0.0, 0.0, -10.0));
        assert!((vup - 3.0).abs() < 1e-9);
        assert!((t - 4.083).abs() < 0.1, "took {t} s");
        assert!(past <= 0.01, "past the target by {past} m");
    }

    #[test]
    fn a_short_leg_never_reaches_cruise_and_stops_on_the_target() {
        // 2 m with 3 m/s²: triangle profile, peak √(3·2) = 2.449 m/s, 2·√(2/3) = 1.633 s.
        let (t, vxy, _, _, past) = fly(Vector3::new(2.0, 0.0, 0.0));
        assert!((vxy - 6f64.sqrt()).abs() < 0.01, "peak {vxy}");
        assert!((t - 1.633).abs() < 0.1, "took {t} s");
        assert!(past <= 0.01, "past the target by {past} m");
    }
}
