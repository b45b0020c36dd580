//! Landing clear of the others. A vehicle told to land comes straight down where it is.
//! Two vehicles closer than the horizontal separation are kept apart in the air only by
//! their altitudes (one passing a jam on the layer above the other, or on its way back
//! from it), and coming straight down would put the upper one on, or beside, the lower
//! one on the ground. So the upper one of such a pair waits: it first flies, at its own
//! altitude, to the nearest spot clear of every other vehicle's way down, and lands once
//! nobody is within the clearance of it horizontally.
//!
//! Positions are ENU (m, z up). Pure and synchronous.

use nalgebra::{Vector2, Vector3};

use super::Fence;

/// Spacing of the candidate spots, along a ring and from one ring to the next (m).
const SPOT_STEP_M: f64 = 0.5;
/// How far from where it is a spot is looked for, in clearances.
pub const SPOT_REACH_CLEARANCES: f64 = 4.0;

/// The nearest other vehicle to `k` for which `within` gives a distance (its index and
/// that distance); `None` when there is none or `k`'s position is unknown. A vehicle
/// whose position is unknown is not counted.
fn nearest<P: Copy>(
    k: usize,
    positions: &[Option<P>],
    within: impl Fn(P, P) -> Option<f64>,
) -> Option<(usize, f64)> {
    let p = positions.get(k).copied().flatten()?;
    positions
        .iter()
        .enumerate()
        .filter(|&(j, _)| j != k)
        .filter_map(|(j, q)| within(p, (*q)?).map(|d| (j, d)))
        .min_by(|a, b| a.1.total_cmp(&b.1))
}

/// Whether vehicle `k` must wait before it comes down: the nearest vehicle below it
/// closer than `horizontal_m` horizontally (its index and the horizontal distance, m),
/// `None` when there is none or `k`'s position is unknown.
pub fn below_within(
    horizontal_m: f64,
    k: usize,
    positions_m: &[Option<Vector3<f64>>],
) -> Option<(usize, f64)> {
    nearest(k, positions_m, |p, q| {
        let d = (q.xy() - p.xy()).norm();
        (q.z < p.z && d < horizontal_m).then_some(d)
    })
}

/// The nearest other vehicle horizontally closer than `clear_m` to `k` (index and
/// distance, m); `None` when nobody is that close or `k`'s position is unknown.
pub fn nearest_within(
    clear_m: f64,
    k: usize,
    positions_m: &[Option<Vector2<f64>>],
) -> Option<(usize, f64)> {
    nearest(k, positions_m, |p, q| {
        let d = (q - p).norm();
        (d < clear_m).then_some(d)
    })
}

/// The nearest spot to `from_m` at least `clear_m` from every point of `taken_m` (where
/// the others come down; m, ENU) and, with a fence, at least its margin inside it:
/// looked for on rings [`SPOT_STEP_M`] apart out to [`SPOT_REACH_CLEARANCES`] clearances,
/// [`SPOT_STEP_M`] apart along each ring, from east anticlockwise. `None` when no spot
/// that near is clear.
pub fn landing_spot_m(
    clear_m: f64,
    from_m: Vector2<f64>,
    taken_m: &[Vector2<f64>],
    fence: Option<(&Fence, f64)>,
) -> Option<Vector2<f64>> {
    if !(clear_m.is_finite() && clear_m > 0.0 && from_m.iter().all(|x| x.is_finite())) {
        return None;
    }
    let reach_m = SPOT_REACH_CLEARANCES * clear_m;
    // Only what can be within the clearance of a spot in reach.
    let near: Vec<Vector2<f64>> = taken_m
        .iter()
        .copied()
        .filter(|q| (q - from_m).norm() < reach_m + clear_m)
        .collect();
    let clear = |c: Vector2<f64>| {
        near.iter().all(|q| (q - c).norm() >= clear_m)
            && fence.is_none_or(|(f, margin_m)| f.horizontal_margin_m(c) >= margin_m)
    };
    let rings = (reach_m / SPOT_STEP_M).ceil() as usize;
    (0..=rings).find_map(|ring| {
        let r = ring as f64 * SPOT_STEP_M;
        let count = if ring == 0 {
            1
        } else {
            ((std::f64::consts::TAU * r / SPOT_STEP_M).ceil() as usize).max(8)
        };
        (0..count)
            .map(|a| {
                let angle = std::f64::consts::TAU * a as f64 / count as f64;
                from_m + r * Vector2::new(angle.cos(), angle.sin())
            })
            .find(|&c| clear(c))
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::safety::FenceShape;

    fn p3(x: f64, y: f64, z: f64) -> Option<Vector3<f64>> {
        Some(Vector3::new(x, y, z))
    }

    #[test]
    fn only_the_upper_vehicle_of_a_close_pair_waits() {
        // 1 m apart horizontally, 12 m apart vertically: the upper one waits; a third
        // vehicle 3.5 m from both lands as it is.
        let positions = [p3(0.0, 0.0, 62.0), p3(1.0, 0.0, 50.0), p3(0.0, 3.5, 50.0)];
        assert_eq!(below_within(3.0, 0, &positions), Some((1, 1.0)));
        assert_eq!(below_within(3.0, 1, &positions), None);
        assert_eq!(below_within(3.0, 2, &positions), None);
        // A vehicle below but 3 m away or more does not hold it.
        let apart = [p3(0.0, 0.0, 62.0), p3(3.0, 0.0, 50.0)];
        assert_eq!(below_within(3.0, 0, &apart), None);
        // An unknown position holds nobody and is held by nobody.
        let unknown = [p3(0.0, 0.0, 62.0), None];
        assert_eq!(below_within(3.0, 0, &unknown), None);
        assert_eq!(below_within(3.0, 1, &unknown), None);
    }

    #[test]
    fn the_nearest_within_the_clearance_is_named() {
        let xy = |x: f64, y: f64| Some(Vector2::new(x, y));
        let positions = [xy(0.0, 0.0), xy(3.0, 0.0), xy(0.0, -2.0), None];
        assert_eq!(nearest_within(3.6, 0, &positions), Some((2, 2.0)));
        assert_eq!(nearest_within(1.9, 0, &positions), None);
        assert_eq!(nearest_within(3.6, 3, &positions), None);
    }

    #[test]
    fn a_spot_already_clear_is_where_the_vehicle_is() {
        let taken = [Vector2::new(5.0, 0.0)];
        let from = Vector2::new(0.0, 0.0);
        assert_eq!(landing_spot_m(3.6, from, &taken, None), Some(from));
    }

    #[test]
    fn the_spot_is_on_the_nearest_ring_with_a_clear_point() {
        // One vehicle 1 m east: a point on the ring of radius r is at most r + 1 from it,
        // so the 2.5 m ring has none 3.6 m away and the 3.0 m ring is the first. On it
        // (38 points, east first, anticlockwise) the first clear one has cos θ ≤ −0.4933
        // (|p − (1, 0)|² = 10 − 6 cos θ ≥ 3.6²): the 14th, at 13 × 360° / 38.
        let taken = [Vector2::new(1.0, 0.0)];
        let spot = landing_spot_m(3.6, Vector2::zeros(), &taken, None).unwrap();
        let angle = 13.0 * std::f64::consts::TAU / 38.0;
        assert!(
            (spot - 3.0 * Vector2::new(angle.cos(), angle.sin())).norm() < 1e-12,
            "{spot}"
        );
        assert!((spot - taken[0]).norm() >= 3.6);
        // Between two vehicles 2 m east and west: clear of both needs
        // r² + 4 − 4r|cos θ| ≥ 3.6². On the 3.0 m ring only within 0.19° of north or
        // south, where none of its points lies (9.47° apart); on the 3.5 m ring
        // (44 points) |cos θ| ≤ 0.235: the 11th, at 10 × 360° / 44 = 81.8°.
        let taken = [Vector2::new(2.0, 0.0), Vector2::new(-2.0, 0.0)];
        let spot = landing_spot_m(3.6, Vector2::zeros(), &taken, None).unwrap();
        let angle = 10.0 * std::f64::consts::TAU / 44.0;
        assert!(
            (spot - 3.5 * Vector2::new(angle.cos(), angle.sin())).norm() < 1e-12,
            "{spot}"
        );
        assert!(taken.iter().all(|q| (spot - q).norm() >= 3.6));
    }

    #[test]
    fn a_spot_stays_inside_the_fence_by_its_margin() {
        // A vehicle 1 m east, the fence's edge 2 m west of the start with a 1 m margin,
        // so a spot needs x ≥ −1. On the 3.0 m ring the clear points have
        // cos θ ≤ −0.4933, x ≤ −1.48: none inside. On the 3.5 m ring they need
        // −0.2857 ≤ cos θ ≤ 0.0414: the first is due north (11 × 360° / 44).
        let fence = Fence {
            shape: FenceShape::Polygon {
                vertices_m: vec![
                    Vector2::new(-2.0, -50.0),
                    Vector2::new(50.0, -50.0),
                    Vector2::new(50.0, 50.0),
                    Vector2::new(-2.0, 50.0),
                ],
            },
            min_altitude_m: 0.0,
            max_altitude_m: 100.0,
        };
        let taken = [Vector2::new(1.0, 0.0)];
        let spot = landing_spot_m(3.6, Vector2::zeros(), &taken, Some((&fence, 1.0))).unwrap();
        assert!((spot - Vector2::new(0.0, 3.5)).norm() < 1e-12, "{spot}");
        assert!(fence.horizontal_margin_m(spot) >= 1.0, "{spot}");
        // Without the fence the same vehicle's spot is on the 3.0 m ring, west of x = −1.
        let free = landing_spot_m(3.6, Vector2::zeros(), &taken, None).unwrap();
        assert!((free.norm() - 3.0).abs() < 1e-12 && free.x < -1.0, "{free}");
    }

    #[test]
    fn no_spot_in_reach_is_none() {
        // A ring of vehicles 3 m apart all around, out past the reach.
        let mut taken = Vec::new();
        for i in -10..=10 {
            for j in -10..=10 {
                taken.push(Vector2::new(3.0 * i as f64 + 0.5, 3.0 * j as f64));
            }
        }
        assert_eq!(landing_spot_m(3.6, Vector2::zeros(), &taken, None), None);
        assert_eq!(landing_spot_m(f64::NAN, Vector2::zeros(), &[], None), None);
        assert_eq!(
            landing_spot_m(3.6, Vector2::new(f64::NAN, 0.0), &[], None),
            None
        );
    }
}
