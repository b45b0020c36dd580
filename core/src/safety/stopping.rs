//! Whether two vehicles stay apart if both stop: the check behind the filter's answer
//! when its time runs out.
//!
//! A vehicle's plan is its net horizontal acceleration for `hold_s` (the command, until
//! the next one can act), then braking along its velocity at its braking share until it
//! is at rest; or braking from now. If every pair's plans keep the separation and every
//! vehicle that fails a check brakes instead, then at the next tick braking from there is
//! the tail of a plan already checked: all vehicles braking is always a safe answer, and
//! the check never needs the optimum (docs/dense.md, "The filter inside the period").
//!
//! A vehicle the filter does not command keeps its velocity (it does not stop for us).
//! Distances are scaled ([`super::Separation::scaled`]); the vertical gap is taken as
//! closed by the pair's vertical speed over the horizontal horizon, never opened.
//!
//! Pure: no allocation, no clock.

use nalgebra::{Vector2, Vector3};

/// The longest a vertical closing speed is counted for (s).
const VERTICAL_HORIZON_S: f64 = 3.0;

/// One vehicle's plan.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plan {
    /// Scaled position (m).
    pub pos_m: Vector3<f64>,
    /// Horizontal velocity (m/s, ENU).
    pub vel_mps: Vector2<f64>,
    /// Scaled vertical velocity (m/s).
    pub vz_mps: f64,
    /// Its net horizontal acceleration (m/s²) until the new command acts, over each half
    /// of the delay: the commands already on their way.
    pub before_mps2: [Vector2<f64>; 2],
    /// What it does once the new command acts.
    pub first: First,
    /// Its braking (m/s²); zero: it never stops (a vehicle not ours).
    pub braking_mps2: f64,
}

/// What a plan does once the new command acts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum First {
    /// Its net horizontal acceleration (m/s²) for the hold, then braking.
    Command(Vector2<f64>),
    /// Braking.
    Brake,
}

/// When the new command acts and how long it holds (s).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Timing {
    /// From what is known until the new command acts.
    pub delay_s: f64,
    /// How long the new command holds before the next can act.
    pub hold_s: f64,
}

/// A piece of motion at constant acceleration from `t0_s`.
#[derive(Debug, Clone, Copy)]
struct Piece {
    t0_s: f64,
    pos: Vector2<f64>,
    vel: Vector2<f64>,
    acc: Vector2<f64>,
}

impl Piece {
    fn at(&self, t_s: f64) -> (Vector2<f64>, Vector2<f64>) {
        let dt = t_s - self.t0_s;
        (
            self.pos + self.vel * dt + self.acc * (0.5 * dt * dt),
            self.vel + self.acc * dt,
        )
    }
}

/// A plan's horizontal motion as pieces (the last lasts for ever).
#[derive(Debug, Clone, Copy)]
pub struct Motion {
    pieces: [Piece; 5],
    count: usize,
    /// When it comes to rest (s; infinite: it does not).
    rest_s: f64,
}

impl Motion {
    fn push(&mut self, piece: Piece) {
        self.pieces[self.count] = piece;
        self.count += 1;
    }

    fn pieces(&self) -> &[Piece] {
        &self.pieces[..self.count]
    }

    /// Braking from `t0_s` at `pos` and `vel`, then at rest (or cruising for ever).
    fn brake_from(&mut self, plan: &Plan, t0_s: f64, pos: Vector2<f64>, vel: Vector2<f64>) {
        let speed = vel.norm();
        if speed > 0.0 && plan.braking_mps2 > 0.0 {
            let stop_s = speed / plan.braking_mps2;
            let piece = Piece {
                t0_s,
                pos,
                vel,
                acc: -vel * (plan.braking_mps2 / speed),
            };
            let (end, _) = piece.at(t0_s + stop_s);
            self.push(piece);
            self.push(still(t0_s + stop_s, end));
            self.rest_s = t0_s + stop_s;
        } else if speed > 0.0 {
            self.push(Piece {
                t0_s,
                pos,
                vel,
                acc: Vector2::zeros(),
            });
            self.rest_s = f64::INFINITY;
        } else {
            self.push(still(t0_s, pos));
            self.rest_s = t0_s;
        }
    }

    /// The plan's motion.
    pub fn of(plan: &Plan, timing: Timing) -> Self {
        let start = plan.pos_m.xy();
        let mut out = Self {
            pieces: [still(0.0, start); 5],
            count: 0,
            rest_s: 0.0,
        };
        let (mut t, mut pos, mut vel) = (0.0, start, plan.vel_mps);
        let mut hold = |acc: Vector2<f64>, length_s: f64, out: &mut Self| {
            if length_s > 0.0 {
                let piece = Piece {
                    t0_s: t,
                    pos,
                    vel,
                    acc,
                };
                out.push(piece);
                t += length_s;
                (pos, vel) = piece.at(t);
            }
        };
        for b in plan.before_mps2 {
            hold(b, 0.5 * timing.delay_s, &mut out);
        }
        if let First::Command(acc) = plan.first {
            hold(acc, timing.hold_s, &mut out);
        }
        out.brake_from(plan, t, pos, vel);
        out
    }

    /// Its piece at `t_s`.
    fn at(&self, t_s: f64) -> Piece {
        let pieces = self.pieces();
        pieces
            .iter()
            .rev()
            .find(|p| p.t0_s <= t_s)
            .copied()
            .unwrap_or(pieces[0])
    }
}

fn still(t0_s: f64, pos: Vector2<f64>) -> Piece {
    Piece {
        t0_s,
        pos,
        vel: Vector2::zeros(),
        acc: Vector2::zeros(),
    }
}

impl Motion {
    /// How far it goes from now at most (m; infinite for one that never stops): exact for
    /// pieces along a line, bounded by speed and acceleration for the others.
    pub fn path_m(&self) -> f64 {
        if self.rest_s.is_infinite() {
            return f64::INFINITY;
        }
        let pieces = self.pieces();
        let mut length = 0.0;
        for (k, p) in pieces.iter().enumerate() {
            let t1 = pieces.get(k + 1).map_or(p.t0_s, |q| q.t0_s);
            let dt = t1 - p.t0_s;
            let cross = p.vel.x * p.acc.y - p.vel.y * p.acc.x;
            let straight = cross.abs() <= 1e-12 * (1.0 + p.vel.norm() * p.acc.norm())
                && p.at(t1).1.dot(&p.vel) >= 0.0;
            length += if straight {
                // Along one line without turning back (braking stops at its end): exact.
                (p.at(t1).0 - p.pos).norm()
            } else {
                p.vel.norm() * dt + 0.5 * p.acc.norm() * dt * dt
            };
        }
        length
    }
}

/// The closest (scaled, m) two plans come from now on.
pub fn closest_m(a: &Plan, b: &Plan, timing: Timing) -> f64 {
    let timing = Timing {
        delay_s: timing.delay_s.max(0.0),
        hold_s: timing.hold_s.max(0.0),
    };
    closest_between((a, &Motion::of(a, timing)), (b, &Motion::of(b, timing)))
}

/// The closest (scaled, m) two plans come from now on, each with its motion
/// ([`Motion::of`] with the same timing).
pub fn closest_between((a, ma): (&Plan, &Motion), (b, mb): (&Plan, &Motion)) -> f64 {
    let horizon_s = ma.rest_s.max(mb.rest_s);
    let closing_z = (a.vz_mps - b.vz_mps).abs()
        * if horizon_s.is_finite() {
            horizon_s.min(VERTICAL_HORIZON_S)
        } else {
            VERTICAL_HORIZON_S
        };
    let gap_z = ((a.pos_m.z - b.pos_m.z).abs() - closing_z).max(0.0);
    // The times at which either changes its piece: the two sorted lists merged.
    let mut times = [0.0; 10];
    let (pa, pb) = (ma.pieces(), mb.pieces());
    let (mut x, mut y) = (0, 0);
    while x < pa.len() || y < pb.len() {
        let take_a = y == pb.len() || (x < pa.len() && pa[x].t0_s <= pb[y].t0_s);
        times[x + y] = if take_a { pa[x].t0_s } else { pb[y].t0_s };
        if take_a {
            x += 1;
        } else {
            y += 1;
        }
    }
    let times = &times[..pa.len() + pb.len()];
    let mut best = f64::INFINITY;
    for (k, &t0) in times.iter().enumerate() {
        let t1 = times.get(k + 1).copied().unwrap_or(f64::INFINITY);
        if t1 <= t0 {
            continue;
        }
        let (qa, qb) = (ma.at(t0), mb.at(t0));
        let (xa, va) = qa.at(t0);
        let (xb, vb) = qb.at(t0);
        let d2 = closest_squared(xa - xb, va - vb, qa.acc - qb.acc, t1 - t0);
        best = best.min(d2);
    }
    (best + gap_z * gap_z).sqrt()
}

/// The least `|r + v t + a t²/2|²` over `0 ≤ t ≤ length_s` (`length_s` may be
/// infinite only when `a` is zero).
fn closest_squared(r: Vector2<f64>, v: Vector2<f64>, a: Vector2<f64>, length_s: f64) -> f64 {
    let f = |t: f64| (r + v * t + a * (0.5 * t * t)).norm_squared();
    let mut best = f(0.0);
    if length_s.is_infinite() {
        // No acceleration on the last piece: the nearest point of a line or a point.
        let vv = v.norm_squared();
        if vv > 0.0 {
            let t = (-r.dot(&v) / vv).max(0.0);
            best = best.min(f(t));
        }
        return best;
    }
    best = best.min(f(length_s));
    // f'/2 = c3 t³ + c2 t² + c1 t + c0; its minima inside lie where it rises through 0,
    // inside the stretches between the roots of its own derivative.
    let c3 = 0.5 * a.norm_squared();
    let c2 = 1.5 * v.dot(&a);
    let c1 = r.dot(&a) + v.norm_squared();
    let c0 = r.dot(&v);
    let g = |t: f64| ((c3 * t + c2) * t + c1) * t + c0;
    let mut cuts = [0.0, length_s, length_s, length_s];
    let mut count = 1;
    // 3c3 t² + 2c2 t + c1 = 0.
    let (qa, qb, qc) = (3.0 * c3, 2.0 * c2, c1);
    if qa.abs() > 1e-12 {
        let disc = qb * qb - 4.0 * qa * qc;
        if disc > 0.0 {
            let s = disc.sqrt();
            let mut roots = [(-qb - s) / (2.0 * qa), (-qb + s) / (2.0 * qa)];
            roots.sort_by(f64::total_cmp);
            for t in roots {
                if t > 0.0 && t < length_s {
                    cuts[count] = t;
                    count += 1;
                }
            }
        }
    } else if qb.abs() > 1e-12 {
        let t = -qc / qb;
        if t > 0.0 && t < length_s {
            cuts[count] = t;
            count += 1;
        }
    }
    cuts[count] = length_s;
    for w in cuts[..=count].windows(2) {
        let (mut lo, mut hi) = (w[0], w[1]);
        if !(g(lo) < 0.0 && g(hi) > 0.0) {
            continue;
        }
        // Newton's steps kept inside the bracket, halving it where a step leaves it.
        let dg = |t: f64| (3.0 * c3 * t + 2.0 * c2) * t + c1;
        let mut t = 0.5 * (lo + hi);
        for _ in 0..60 {
            let value = g(t);
            if value < 0.0 {
                lo = t;
            } else {
                hi = t;
            }
            if hi - lo < 1e-9 {
                break;
            }
            let slope = dg(t);
            let step = t - value / slope;
            if (step - t).abs() < 1e-12 {
                t = step.clamp(lo, hi);
                break;
            }
            t = if slope > 0.0 && step > lo && step < hi {
                step
            } else {
                0.5 * (lo + hi)
            };
        }
        best = best.min(f(t));
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plan(p: [f64; 3], v: [f64; 2], first: First, braking: f64) -> Plan {
        Plan {
            pos_m: Vector3::new(p[0], p[1], p[2]),
            vel_mps: Vector2::new(v[0], v[1]),
            vz_mps: 0.0,
            before_mps2: [Vector2::zeros(); 2],
            first,
            braking_mps2: braking,
        }
    }

    /// The closest two plans come, sampled every microsecond-scale step over 20 s.
    fn sampled(a: &Plan, b: &Plan, timing: Timing) -> f64 {
        let (ma, mb) = (Motion::of(a, timing), Motion::of(b, timing));
        let mut best = f64::INFINITY;
        for k in 0..=200_000 {
            let t = k as f64 * 1e-4;
            best = best.min((ma.at(t).at(t).0 - mb.at(t).at(t).0).norm());
        }
        best
    }

    fn hold(hold_s: f64) -> Timing {
        Timing {
            delay_s: 0.0,
            hold_s,
        }
    }

    #[test]
    fn head_on_vehicles_braking_from_now_stop_their_stopping_distances_apart() {
        // 20 m apart closing at 4 m/s each, braking at 2 m/s²: each stops in 4 m, so
        // 12 m apart.
        let a = plan([0.0, 0.0, 0.0], [4.0, 0.0], First::Brake, 2.0);
        let b = plan([20.0, 0.0, 0.0], [-4.0, 0.0], First::Brake, 2.0);
        assert!((closest_m(&a, &b, hold(0.1)) - 12.0).abs() < 1e-9);
        // Holding 1 m/s² towards each other for 1 s first: 4.5 m each, then
        // (5 m/s)²/4 = 6.25 m each: 20 − 21.5 < 0, they meet (closest 0).
        let a = plan(
            [0.0, 0.0, 0.0],
            [4.0, 0.0],
            First::Command(Vector2::new(1.0, 0.0)),
            2.0,
        );
        let b = plan(
            [20.0, 0.0, 0.0],
            [-4.0, 0.0],
            First::Command(Vector2::new(-1.0, 0.0)),
            2.0,
        );
        assert!(closest_m(&a, &b, hold(1.0)) < 1e-6);
    }

    #[test]
    fn the_command_on_its_way_is_flown_before_braking() {
        // As the first case, but each still accelerating towards the other at 1 m/s² for
        // 1 s before the brake can act: 4.5 m, then (5 m/s)²/4 = 6.25 m each: they meet.
        let mut a = plan([0.0, 0.0, 0.0], [4.0, 0.0], First::Brake, 2.0);
        let mut b = plan([20.0, 0.0, 0.0], [-4.0, 0.0], First::Brake, 2.0);
        a.before_mps2 = [Vector2::new(1.0, 0.0); 2];
        b.before_mps2 = [Vector2::new(-1.0, 0.0); 2];
        let on_its_way = Timing {
            delay_s: 1.0,
            hold_s: 0.02,
        };
        assert!(closest_m(&a, &b, on_its_way) < 1e-6);
        // Each goes 4.5 + 6.25 m at most.
        assert!((Motion::of(&a, on_its_way).path_m() - 10.75).abs() < 1e-9);
        // 30 m apart instead: 30 − 21.5 = 8.5 m.
        b.pos_m.x = 30.0;
        assert!((closest_m(&a, &b, on_its_way) - 8.5).abs() < 1e-9);
    }

    #[test]
    fn vehicles_moving_alike_keep_their_distance_whatever_their_speed() {
        // A column 4 m apart at 6 m/s, braking alike: 4 m throughout.
        let a = plan([0.0, 0.0, 0.0], [6.0, 0.0], First::Brake, 3.0);
        let b = plan([4.0, 0.0, 0.0], [6.0, 0.0], First::Brake, 3.0);
        assert!((closest_m(&a, &b, hold(0.02)) - 4.0).abs() < 1e-9);
    }

    #[test]
    fn a_vehicle_not_ours_keeps_its_velocity() {
        // Ours at rest at the origin; the other passes 2 m north at 5 m/s and never
        // stops: 2 m.
        let a = plan([0.0, 0.0, 0.0], [0.0, 0.0], First::Brake, 3.0);
        let b = plan(
            [-30.0, 2.0, 0.0],
            [5.0, 0.0],
            First::Command(Vector2::zeros()),
            0.0,
        );
        assert!((closest_m(&a, &b, hold(0.02)) - 2.0).abs() < 1e-9);
        // Passing behind us instead, moving away: now is the closest.
        let b = plan(
            [3.0, 4.0, 0.0],
            [5.0, 0.0],
            First::Command(Vector2::zeros()),
            0.0,
        );
        assert!((closest_m(&a, &b, hold(0.02)) - 5.0).abs() < 1e-9);
    }

    #[test]
    fn the_vertical_gap_counts_only_as_far_as_it_cannot_close() {
        // Head on as the first test but 4 m apart in scaled height, the gap closing at
        // 0.5 m/s over the 2 s both take to stop: 3 m, with 12 m horizontal.
        let mut a = plan([0.0, 0.0, 4.0], [4.0, 0.0], First::Brake, 2.0);
        a.vz_mps = -0.5;
        let b = plan([20.0, 0.0, 0.0], [-4.0, 0.0], First::Brake, 2.0);
        assert!((closest_m(&a, &b, hold(0.1)) - (144.0f64 + 9.0).sqrt()).abs() < 1e-9);
    }

    #[test]
    fn crossing_plans_match_a_fine_sampling() {
        let mut next = super::super::tests::uniform(3);
        for _ in 0..200 {
            let mut v = || 8.0 * next() - 4.0;
            let first = |x: f64, y: f64, brake: bool| {
                if brake {
                    First::Brake
                } else {
                    First::Command(Vector2::new(x, y))
                }
            };
            let (ax, ay, bx, by) = (v(), v(), v(), v());
            let (ux, uy, wx, wy) = (v(), v(), v(), v());
            let brake_a = ux > 2.0;
            let mut a = plan([v(), v(), 0.0], [ax, ay], first(ux, uy, brake_a), 2.5);
            a.before_mps2 = [Vector2::new(v(), v()), Vector2::new(v(), v())];
            let b = plan([v(), v(), 0.0], [bx, by], first(wx, wy, false), 1.5);
            let timing = Timing {
                delay_s: 0.1 + 0.05 * v(),
                hold_s: 0.5,
            };
            let exact = closest_m(&a, &b, timing);
            let fine = sampled(&a, &b, timing);
            // The sampling can only miss the true least by what the pair closes in half a
            // step, and never finds less.
            assert!(exact <= fine + 1e-9, "{exact} {fine}");
            assert!(fine - exact < 2e-3, "{exact} {fine}");
        }
    }
}
