//! The pairwise control barrier function for two double integrators that must stay a
//! downwash ellipsoid apart (docs/math.md, "Keeping vehicles apart").
//!
//! Distances are measured in the scaled frame `p̃ = (x, y, ρz)`, `ρ = r_h / r_v`, where
//! the ellipsoid of horizontal radius `r_h` and vertical radius `r_v` is a sphere of
//! radius `r_h`. For a pair with `Δp̃ = p̃ᵢ − p̃ⱼ`, `D = |Δp̃|`, `n = Δp̃/D`, closing rate
//! `s = nᵀΔṽ` and braking authority `A` (m/s², what the two can decelerate their
//! relative motion by), the barrier is
//!
//! ```text
//! h = s + √(2A(D − d))
//! ```
//!
//! (Borrmann, Wang, Ames and Egerstedt 2015): `h ≥ 0` means that braking at `A` stops the
//! pair before `D` falls to `d`. Its derivative is affine in the relative acceleration,
//!
//! ```text
//! ḣ = nᵀΔũ + (|Δṽ|² − s²)/D + A·s/√(2A(D − d)),
//! ```
//!
//! and the filter asks for `ḣ ≥ −γh³`. `d` is the separation grown by how far the pair
//! can close during the age `τ` of what is known of it: `d = r_h + |Δṽ|τ + Aτ²/2`.
//!
//! Pure: no allocation, no clock.

use nalgebra::{Vector2, Vector3};

/// The separation and how hard the barrier may be approached.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Separation {
    /// Horizontal radius of the ellipsoid, centre to centre (m).
    pub horizontal_m: f64,
    /// Vertical radius (m), at least the horizontal one.
    pub vertical_m: f64,
    /// The barrier's class-K gain `γ` in `ḣ ≥ −γh³` (s/m²).
    pub gamma: f64,
}

impl Separation {
    /// `ρ = r_h / r_v`: the scale of the vertical axis.
    pub fn vertical_scale(&self) -> f64 {
        self.horizontal_m / self.vertical_m
    }

    /// A vector in the scaled frame.
    pub fn scaled(&self, v: Vector3<f64>) -> Vector3<f64> {
        Vector3::new(v.x, v.y, v.z * self.vertical_scale())
    }

    /// The ellipsoidal distance between two positions, in horizontal metres: `|Δp̃|`.
    /// Two vehicles at one altitude are their horizontal distance apart; one directly
    /// above another is `Δz·r_h/r_v`.
    pub fn distance_m(&self, a: Vector3<f64>, b: Vector3<f64>) -> f64 {
        self.scaled(a - b).norm()
    }
}

/// One side of a pair: what is known of a vehicle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Side {
    /// Position (m, ENU).
    pub pos_m: Vector3<f64>,
    /// Velocity (m/s, ENU).
    pub vel_mps: Vector3<f64>,
    /// Vertical acceleration it is commanded (m/s², up; not a variable of the filter).
    pub accel_z_mps2: f64,
}

/// The constraint `aᵀ(uᵢ − uⱼ) ≥ b` on the two vehicles' horizontal accelerations
/// (m/s², ENU).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PairRow {
    /// `a`: the horizontal part of `n`.
    pub a: Vector2<f64>,
    /// `b` (m/s²).
    pub b: f64,
    /// `h` (m/s); negative when the pair already closes faster than braking can stop.
    pub h_mps: f64,
    /// `D` (m, scaled).
    pub distance_m: f64,
    /// `D − d` (m): the room left before the age-grown separation.
    pub room_m: f64,
}

/// The room under which a pair is treated as inside its separation (m): the square root
/// in `h` and its derivative are not used so close to `D = d`.
pub const INSIDE_M: f64 = 1e-3;

/// The barrier row of vehicles `i` and `j` with braking authority `braking_mps2` (> 0)
/// and state age `age_s` (≥ 0). `None` when they coincide (no direction to push along).
///
/// Inside the age-grown separation (`D − d < INSIDE_M`) the row asks the pair to open at
/// the full authority while it still closes (`aᵀΔu ≥ A − κ`, `κ` the curvature term) and
/// not to close otherwise (`≥ −κ`).
pub fn pair_row(
    sep: &Separation,
    i: &Side,
    j: &Side,
    braking_mps2: f64,
    age_s: f64,
) -> Option<PairRow> {
    pair_row_spread(sep, i, j, braking_mps2, age_s, 0.0, 0.0)
}

/// [`pair_row`] for a pair that must keep `spread_m` (m, scaled, ≥ 0) more than the
/// separation: how far the two may be from the positions their sides give (a vehicle
/// whose state stopped arriving, as a chain of points along its stopping path:
/// [`super::lost`]), and that may close `unseen_mps` (m/s, ≥ 0) faster than its
/// velocities show (positions that move beyond their velocities:
/// [`crate::control::UnseenMotion`]). The unseen speed is taken as closing: `s` becomes
/// `s − δ` in `h` and its derivative, and the age grows the separation by `δτ` more.
pub fn pair_row_spread(
    sep: &Separation,
    i: &Side,
    j: &Side,
    braking_mps2: f64,
    age_s: f64,
    spread_m: f64,
    unseen_mps: f64,
) -> Option<PairRow> {
    let dp = sep.scaled(i.pos_m - j.pos_m);
    let dv = sep.scaled(i.vel_mps - j.vel_mps);
    let distance = dp.norm();
    if !(distance > 0.0 && distance.is_finite()) {
        return None;
    }
    let n = dp / distance;
    let unseen = unseen_mps.max(0.0);
    let seen = n.dot(&dv);
    let s = seen - unseen;
    let a_brake = braking_mps2;
    let d = sep.horizontal_m
        + spread_m.max(0.0)
        + (dv.norm() + unseen) * age_s
        + 0.5 * a_brake * age_s * age_s;
    let room = distance - d;
    // The turn of the direction between the two (ṅ), from the velocities as reported.
    let curvature = (dv.norm_squared() - seen * seen).max(0.0) / distance;
    // The vertical accelerations are given: their share of nᵀΔũ moves to the bound.
    let vertical = n.z * sep.vertical_scale() * (i.accel_z_mps2 - j.accel_z_mps2);
    Some(barrier_row(
        Vector2::new(n.x, n.y),
        (s, distance, room),
        a_brake,
        sep.gamma,
        curvature + vertical,
    ))
}

/// The row `aᵀu ≥ b` of a barrier `h = s + √(2A·room)` whose derivative is
/// `aᵀu + known + A·s/√(2A·room)` (`known`: what the commands do not change, m/s²), from
/// the closing rate `s`, the `distance` and the `room` left; inside (`room < INSIDE_M`)
/// a closing `s` must turn at the full authority `A`, any other must not close.
pub(super) fn barrier_row(
    a: Vector2<f64>,
    (s, distance_m, room_m): (f64, f64, f64),
    a_brake: f64,
    gamma: f64,
    known: f64,
) -> PairRow {
    if room_m < INSIDE_M {
        let push = if s < 0.0 { a_brake } else { 0.0 };
        return PairRow {
            a,
            b: push - known,
            h_mps: s,
            distance_m,
            room_m,
        };
    }
    let root = (2.0 * a_brake * room_m).sqrt();
    let h = s + root;
    PairRow {
        a,
        b: -gamma * h * h * h - known - a_brake * s / root,
        h_mps: h,
        distance_m,
        room_m,
    }
}

#[cfg(test)]
mod tests {
    use super::super::tests::sep;
    use super::*;

    fn side(p: [f64; 3], v: [f64; 3]) -> Side {
        Side {
            pos_m: Vector3::from(p),
            vel_mps: Vector3::from(v),
            accel_z_mps2: 0.0,
        }
    }

    /// h along a trajectory, from the closed form.
    fn h_of(sep: &Separation, i: &Side, j: &Side, a: f64) -> f64 {
        let dp = sep.scaled(i.pos_m - j.pos_m);
        let dv = sep.scaled(i.vel_mps - j.vel_mps);
        let d = dp.norm();
        dp.dot(&dv) / d + (2.0 * a * (d - sep.horizontal_m)).sqrt()
    }

    #[test]
    fn an_unseen_speed_is_a_closing_speed_the_velocities_do_not_show() {
        // Two vehicles at rest 5 m apart along a tilted line, one of them unseen at
        // 0.8 m/s: their row is the row of the same two closing head-on at 0.8 m/s
        // (no turn of their direction, so no curvature term either way).
        let s = sep();
        let (a, age) = (3.0, 0.25);
        let dir = Vector3::new(0.6, 0.8, 0.0);
        let i = side([0.0, 0.0, 10.0], [0.0; 3]);
        let j = Side {
            pos_m: i.pos_m - 5.0 * dir,
            ..i
        };
        let unseen = pair_row_spread(&s, &i, &j, a, age, 0.0, 0.8).expect("apart");
        let closing = Side {
            vel_mps: 0.8 * dir,
            ..j
        };
        let seen = pair_row(&s, &i, &closing, a, age).expect("apart");
        assert_eq!(unseen.a, seen.a);
        assert!((unseen.b - seen.b).abs() < 1e-12, "{unseen:?} vs {seen:?}");
        assert!((unseen.h_mps - seen.h_mps).abs() < 1e-12);
        assert!((unseen.room_m - seen.room_m).abs() < 1e-12);
        // By hand: d = 3 + 0.8·0.25 + 3·0.25²/2, h = −0.8 + √(2·3·(5 − d)).
        let d = 3.0 + 0.8 * 0.25 + 0.5 * 3.0 * 0.0625;
        assert!((unseen.room_m - (5.0 - d)).abs() < 1e-12);
        assert!((unseen.h_mps - (-0.8 + (6.0 * (5.0 - d)).sqrt())).abs() < 1e-12);
        // None: the plain row of two at rest.
        let none = pair_row_spread(&s, &i, &j, a, age, 0.0, 0.0).expect("apart");
        assert_eq!(Some(none), pair_row(&s, &i, &j, a, age));
        assert!(none.h_mps > unseen.h_mps && none.b < unseen.b);
    }

    #[test]
    fn the_rows_derivative_is_the_barriers_along_a_trajectory() {
        // Two vehicles with given accelerations: ḣ by central differences of the closed
        // form must equal aᵀ(uᵢ − uⱼ) + (the row's drift), i.e. ḣ + γh³ − (aᵀΔu − b) = 0.
        let s = sep();
        let (ui, uj) = (Vector3::new(0.7, -1.1, 0.3), Vector3::new(-0.4, 0.2, -0.5));
        let i0 = side([4.0, 1.0, 10.5], [-2.0, 0.5, 0.2]);
        let j0 = side([-3.0, 0.5, 9.0], [1.5, -0.3, -0.1]);
        let at = |t: f64| {
            let f = |x: &Side, u: Vector3<f64>| Side {
                pos_m: x.pos_m + x.vel_mps * t + 0.5 * u * t * t,
                vel_mps: x.vel_mps + u * t,
                accel_z_mps2: u.z,
            };
            (f(&i0, ui), f(&j0, uj))
        };
        let a = 4.0;
        let dt = 1e-5;
        let (ip, jp) = at(dt);
        let (im, jm) = at(-dt);
        let hdot = (h_of(&s, &ip, &jp, a) - h_of(&s, &im, &jm, a)) / (2.0 * dt);
        let (i, j) = at(0.0);
        let row = pair_row(&s, &i, &j, a, 0.0).expect("apart");
        assert!((row.h_mps - h_of(&s, &i, &j, a)).abs() < 1e-12);
        // ḣ = aᵀΔu_xy + (everything else) and b = −γh³ − (everything else).
        let from_row = row.a.dot(&(ui - uj).xy()) - row.b - s.gamma * row.h_mps.powi(3);
        assert!((hdot - from_row).abs() < 1e-6, "{hdot} vs {from_row}");
    }

    #[test]
    fn the_age_grows_the_separation_by_what_the_pair_can_close_meanwhile() {
        let s = sep();
        let i = side([10.0, 0.0, 5.0], [-3.0, 0.0, 0.0]);
        let j = side([0.0, 0.0, 5.0], [1.0, 0.0, 0.0]);
        let fresh = pair_row(&s, &i, &j, 4.0, 0.0).expect("apart");
        let aged = pair_row(&s, &i, &j, 4.0, 0.1).expect("apart");
        // |Δv| = 4 m/s, A = 4 m/s²: 0.4 m + 0.02 m.
        assert!((fresh.room_m - 7.0).abs() < 1e-12);
        assert!((aged.room_m - (7.0 - 0.42)).abs() < 1e-12);
        // Closing at 4 m/s with 7 m of room: h = −4 + √56.
        assert!((fresh.h_mps - (56f64.sqrt() - 4.0)).abs() < 1e-12);
    }

    #[test]
    fn a_spread_grows_the_separation_by_itself() {
        let s = sep();
        let i = side([10.0, 0.0, 5.0], [-3.0, 0.0, 0.0]);
        let j = side([0.0, 0.0, 5.0], [1.0, 0.0, 0.0]);
        let plain = pair_row(&s, &i, &j, 4.0, 0.1).expect("apart");
        let spread = pair_row_spread(&s, &i, &j, 4.0, 0.1, 1.25, 0.0).expect("apart");
        // 10 m apart, 3 m + 0.42 m of age, 1.25 m more.
        assert!((spread.room_m - (plain.room_m - 1.25)).abs() < 1e-12);
        assert!((spread.room_m - (7.0 - 0.42 - 1.25)).abs() < 1e-12);
        assert!(spread.b > plain.b, "less room asks for more");
    }

    #[test]
    fn inside_the_separation_a_closing_pair_must_open_at_full_authority() {
        let s = sep();
        let i = side([2.0, 0.0, 5.0], [-1.0, 0.0, 0.0]);
        let j = side([0.0, 0.0, 5.0], [0.0, 0.0, 0.0]);
        let row = pair_row(&s, &i, &j, 4.0, 0.0).expect("apart");
        assert_eq!(row.a, Vector2::new(1.0, 0.0));
        assert_eq!(row.b, 4.0);
        let leaving = side([2.0, 0.0, 5.0], [1.0, 0.0, 0.0]);
        assert_eq!(pair_row(&s, &leaving, &j, 4.0, 0.0).expect("apart").b, 0.0);
        assert!(pair_row(&s, &j, &j, 4.0, 0.0).is_none(), "coincident");
    }

    #[test]
    fn the_ellipsoid_counts_vertical_distance_at_its_ratio() {
        let s = sep();
        // 9 m above is exactly the vertical radius: 3 m in the scaled frame.
        let d = s.distance_m(Vector3::new(0.0, 0.0, 9.0), Vector3::zeros());
        assert!((d - 3.0).abs() < 1e-12);
        let d = s.distance_m(Vector3::new(3.0, 4.0, 0.0), Vector3::zeros());
        assert!((d - 5.0).abs() < 1e-12);
    }
}
