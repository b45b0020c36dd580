//! Passing a jam on another layer: a jammed vehicle leaves the formation's altitude for a
//! layer far enough above (or below) it that the downwash ellipsoid no longer binds, flies
//! over the vehicles that held it, and comes back once nobody is in its way.
//!
//! Which jammed vehicle leaves follows the semicircular rule of flight levels: the one
//! whose way to its place points into the northern half (east included, west not). Of
//! two vehicles head-on, exactly one leaves; vehicles going the same way stay together.
//! A jammed vehicle held only by vehicles parked at their places leaves whatever its way
//! (nobody else will move). A jammed vehicle on the layer whose way points south comes
//! back as soon as nobody is under it: it is the one that stays.
//!
//! A layered vehicle that is no longer jammed comes back once no vehicle is within
//! [`LayerRule::clear_m`] of it horizontally and either it is at its place or, after
//! [`LayerRule::dwell_s`] on the layer, no vehicle at the formation's altitude is within
//! `clear_m` of its straight way there. Without the dwell a vehicle comes back the moment
//! the vehicles it passes have stepped aside, and meets them again.
//!
//! Only altitude changes: the horizontal commands, their weighted sum `Σ wᵢuᵢ` and so
//! the velocity the law predicts are untouched, and the filter still keeps every pair
//! apart in three dimensions while vehicles climb and descend.
//!
//! Pure and synchronous.

use nalgebra::Vector2;
use ringswarm_wire::time::SimTime;

use super::fence::segment_distance_m;

/// A vehicle comes back from the jam layer (and comes down to land, `super::landing`) only
/// with nobody within this many horizontal separations of it ([`LayerRule::clear_m`]).
pub const LAYER_CLEAR_SHARE: f64 = 1.2;

/// Where the layer is and when a vehicle may leave it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LayerRule {
    /// The layer's distance from the formation's altitude (m).
    pub height_m: f64,
    /// `true`: the layer is above the formation; `false`: below (a fence band with no
    /// room above).
    pub above: bool,
    /// A vehicle comes back only with no other vehicle this close horizontally, and its
    /// way to its place this clear (m).
    pub clear_m: f64,
    /// The least time a vehicle stays on the layer unless it reaches its place.
    pub dwell_s: f64,
}

impl LayerRule {
    /// The layer's altitude offset from the formation's (m, up).
    pub fn offset_up_m(&self) -> f64 {
        if self.above {
            self.height_m
        } else {
            -self.height_m
        }
    }
}

/// What changed on a tick.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct LayerChange {
    /// Vehicles that leave for the layer.
    pub left: Vec<usize>,
    /// Vehicles that come back to the formation's altitude.
    pub back: Vec<usize>,
}

/// How far ahead a vehicle about to come back from the layer looks for one closing on
/// it (s): about the time its descent takes to bring it within the vertical separation of
/// the vehicles below. On PX4 SIH one came back 4.2 m from another that closed on it at
/// 2 m/s, and the two met during the descent.
pub const COME_BACK_LOOKAHEAD_S: f64 = 3.0;

/// Horizontal positions (m, ENU) and velocities (m/s, ENU; a vehicle without one, or
/// beyond the slice, is taken at rest).
pub type Motions<'a> = (&'a [Option<Vector2<f64>>], &'a [Option<Vector2<f64>>]);

/// Whether no other vehicle is, or within [`COME_BACK_LOOKAHEAD_S`] at the velocities they
/// have will be, within `clear_m` of vehicle `k` horizontally (false when its position is
/// unknown).
fn nobody_near(clear_m: f64, (positions_m, velocities_mps): Motions, k: usize) -> bool {
    let velocity = |j: usize| velocities_mps.get(j).copied().flatten().unwrap_or_default();
    positions_m.get(k).copied().flatten().is_some_and(|p| {
        let v = velocity(k);
        positions_m.iter().enumerate().all(|(j, q)| {
            j == k
                || q.is_none_or(|q| {
                    closest_approach_m(q - p, velocity(j) - v, COME_BACK_LOOKAHEAD_S) >= clear_m
                })
        })
    })
}

/// The least of `|d + v·t|` over `t` in `[0, horizon_s]` (m).
fn closest_approach_m(d: Vector2<f64>, v: Vector2<f64>, horizon_s: f64) -> f64 {
    let speed2 = v.norm_squared();
    let t = if speed2 > 0.0 {
        (-d.dot(&v) / speed2).clamp(0.0, horizon_s)
    } else {
        0.0
    };
    (d + v * t).norm()
}

/// When consensus is over: which of the layered vehicles `ks` may come back now, those
/// with nobody within the rule's clearance horizontally (the others wait, so that a block
/// holding below is not come down upon).
pub fn clear_to_come_back(
    rule: &LayerRule,
    ks: impl Iterator<Item = usize>,
    motions: Motions,
) -> Vec<usize> {
    ks.filter(|&k| nobody_near(rule.clear_m, motions, k))
        .collect()
}

/// Whether the way to a place points into the northern half (east included, west not):
/// of two opposite ways, exactly one does.
pub fn northern(way: Vector2<f64>) -> bool {
    way.y > 0.0 || (way.y == 0.0 && way.x > 0.0)
}

/// Takes a tick at `now`: which vehicles are jammed (`crate::safety::jam`), the
/// filter's active pair rows, each vehicle's offset from its place (m, ENU: where it is
/// less where it should be; `None`: unknown) and horizontal position (m, ENU), and since
/// when each vehicle has been on the layer (`layered`, `None`: at the formation's
/// altitude; updated). `parked_m`: a vehicle not jammed and this close to its place
/// counts as parked; it is also how close to its place a vehicle may come back before
/// the dwell.
#[allow(clippy::too_many_arguments)]
pub fn update_layers(
    rule: &LayerRule,
    now: SimTime,
    parked_m: f64,
    jammed: impl Fn(usize) -> bool,
    active: &[(usize, usize)],
    offset_m: &[Option<Vector2<f64>>],
    motions: Motions,
    layered: &mut [Option<SimTime>],
) -> LayerChange {
    let positions_m = motions.0;
    let n = layered.len().min(offset_m.len()).min(positions_m.len());
    let nobody_near = |k: usize| nobody_near(rule.clear_m, motions, k);
    let way_clear = |layered: &[Option<SimTime>], k: usize, offset: Vector2<f64>| {
        positions_m[k].is_some_and(|p| {
            positions_m.iter().enumerate().all(|(j, q)| {
                j == k
                    || layered.get(j).is_some_and(Option::is_some)
                    || q.is_none_or(|q| segment_distance_m(q, p, p - offset) >= rule.clear_m)
            })
        })
    };
    let parked = |k: usize| !jammed(k) && offset_m[k].is_some_and(|o| o.norm() <= parked_m);
    let mut change = LayerChange::default();
    for k in 0..n {
        let Some(offset) = offset_m[k] else { continue };
        let at_place = offset.norm() <= parked_m;
        // On the layer, and there long enough (or at its place) to come back.
        let up = layered[k].is_some();
        let may_come_back = layered[k].is_some_and(|since| {
            at_place || now.saturating_since(since).as_secs_f64() >= rule.dwell_s
        });
        if !jammed(k) {
            if may_come_back && (at_place || way_clear(layered, k, offset)) && nobody_near(k) {
                change.back.push(k);
            }
            continue;
        }
        if northern(-offset) {
            if !up {
                change.left.push(k);
            }
            continue;
        }
        if up {
            if may_come_back && nobody_near(k) {
                change.back.push(k);
            }
            continue;
        }
        let mut partners = active
            .iter()
            .filter(|&&(i, j)| i != j && (i == k || j == k))
            .map(|&(i, j)| if i == k { j } else { i })
            .peekable();
        if partners.peek().is_some() && partners.all(|o| o < n && parked(o)) {
            change.left.push(k);
        }
    }
    for &k in &change.left {
        layered[k] = Some(now);
    }
    for &k in &change.back {
        layered[k] = None;
    }
    change
}

#[cfg(test)]
mod tests {
    use super::*;
    use ringswarm_wire::time::SimTime;

    const RULE: LayerRule = LayerRule {
        height_m: 12.0,
        above: true,
        clear_m: 3.6,
        dwell_s: 20.0,
    };

    fn at(s: f64) -> SimTime {
        SimTime::from_secs_f64(s)
    }

    const UP: Option<SimTime> = Some(SimTime::ZERO);

    /// Jammed: the listed vehicles.
    fn jammed_of(jammed: &[usize]) -> impl Fn(usize) -> bool + '_ {
        move |k| jammed.contains(&k)
    }

    /// One tick of the rule with the tests' layer, vehicles parked within 1 m.
    fn step(
        now: SimTime,
        jammed: impl Fn(usize) -> bool,
        active: &[(usize, usize)],
        offsets: &[Option<Vector2<f64>>],
        positions: &[Option<Vector2<f64>>],
        layered: &mut [Option<SimTime>],
    ) -> LayerChange {
        update_layers(
            &RULE,
            now,
            1.0,
            jammed,
            active,
            offsets,
            (positions, &[]),
            layered,
        )
    }

    fn v(x: f64, y: f64) -> Option<Vector2<f64>> {
        Some(Vector2::new(x, y))
    }

    #[test]
    fn of_two_opposite_ways_exactly_one_is_northern() {
        for deg in (0..360).step_by(15) {
            let a = f64::from(deg).to_radians();
            let way = Vector2::new(a.cos(), a.sin());
            let (way, back) = if deg % 90 == 0 {
                // Exact axes: no rounding in the components.
                let axis = [(1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0)][deg as usize / 90];
                (Vector2::new(axis.0, axis.1), -Vector2::new(axis.0, axis.1))
            } else {
                (way, -way)
            };
            assert_ne!(northern(way), northern(back), "{deg}°");
        }
        assert!(northern(Vector2::new(1.0, 0.0)));
        assert!(!northern(Vector2::new(-1.0, 0.0)));
        assert!(northern(Vector2::new(-1.0, 0.01)));
    }

    #[test]
    fn of_a_head_on_pair_the_northbound_vehicle_leaves_and_comes_back_past_it() {
        // Vehicle 0 at (0, -2) bound north to (0, 8); vehicle 1 at (0, 2) bound south to
        // (0, -8): offsets are where they are less where they should be.
        let watch = jammed_of(&[0, 1]);
        let positions = [v(0.0, -2.0), v(0.0, 2.0)];
        let offsets = [v(0.0, -10.0), v(0.0, 10.0)];
        let mut layered = [None; 2];
        let now = at(0.0);
        let change = step(now, &watch, &[(0, 1)], &offsets, &positions, &mut layered);
        assert_eq!(change.left, vec![0]);
        assert!(change.back.is_empty());
        assert_eq!(layered, [UP, None]);
        // Still jammed, right over the other: it stays up.
        let now = at(1.0);
        let change = step(
            now,
            &watch,
            &[],
            &offsets,
            &[v(0.0, 1.0), v(0.0, 2.0)],
            &mut layered,
        );
        assert_eq!(change, LayerChange::default());
        // Released, 3 m past the other and 6 m short of its place: 3 m from the other is
        // inside clear_m, it stays up.
        let free = jammed_of(&[]);
        let now = at(25.0);
        let change = step(
            now,
            &free,
            &[],
            &[v(0.0, -6.0), v(0.0, 10.0)],
            &[v(0.0, 5.0), v(0.0, 2.0)],
            &mut layered,
        );
        assert!(change.back.is_empty());
        // 4 m past it, 5 m short of its place, the way there clear: it comes back once it
        // has been up for the dwell (20 s), not before.
        let past = |now, layered: &mut [Option<SimTime>]| {
            step(
                now,
                &free,
                &[],
                &[v(0.0, -5.0), v(0.0, 10.0)],
                &[v(0.0, 6.0), v(0.0, 2.0)],
                layered,
            )
        };
        assert!(past(at(19.9), &mut [UP, None]).back.is_empty());
        assert_eq!(past(at(20.0), &mut layered).back, vec![0]);
        assert_eq!(layered, [None, None]);
    }

    #[test]
    fn a_layered_vehicle_stays_up_while_one_below_is_on_its_way() {
        // Released, 4 m from the vehicle below, but that vehicle sits on its way.
        let free = jammed_of(&[]);
        let mut layered = [UP, None];
        let now = at(30.0);
        let change = step(
            now,
            &free,
            &[],
            &[v(0.0, -10.0), v(0.0, 0.0)],
            &[v(0.0, -2.0), v(0.0, 2.0)],
            &mut layered,
        );
        assert!(change.back.is_empty());
        // At its place (within 1 m) with nobody near, neither the way nor the dwell
        // matters.
        let now = at(1.0);
        let change = step(
            now,
            &free,
            &[],
            &[v(0.0, -0.5), v(0.0, 0.0)],
            &[v(0.0, -2.0), v(0.0, 2.0)],
            &mut layered,
        );
        assert_eq!(change.back, vec![0]);
    }

    #[test]
    fn a_southbound_vehicle_leaves_only_when_held_by_parked_vehicles() {
        // Vehicle 0 bound south, held by vehicle 1 parked at its place: it leaves.
        let watch = jammed_of(&[0]);
        let mut layered = [None; 2];
        let now = at(0.0);
        let change = step(
            now,
            &watch,
            &[(0, 1)],
            &[v(0.0, 10.0), v(0.0, 0.2)],
            &[v(0.0, 2.0), v(0.0, -1.5)],
            &mut layered,
        );
        assert_eq!(change.left, vec![0]);
        // Held by a vehicle that is jammed too (both south, side by side): it stays.
        let watch = jammed_of(&[0, 1]);
        let mut layered = [None; 2];
        let change = step(
            now,
            &watch,
            &[(0, 1)],
            &[v(0.0, 10.0), v(0.0, 10.0)],
            &[v(-1.6, 2.0), v(1.6, 2.0)],
            &mut layered,
        );
        assert_eq!(change, LayerChange::default());
        // A jammed southbound vehicle on the layer for the dwell comes back once nobody is
        // near.
        let watch = jammed_of(&[0, 1]);
        let mut layered = [UP, None];
        let now = at(20.0);
        let change = step(
            now,
            &watch,
            &[(0, 1)],
            &[v(0.0, 10.0), v(0.0, 10.0)],
            &[v(0.0, 2.0), v(5.0, 2.0)],
            &mut layered,
        );
        assert_eq!(change.back, vec![0]);
    }

    #[test]
    fn when_consensus_is_over_only_a_vehicle_with_nobody_near_comes_back() {
        // Vehicles 0 and 2 on the layer; 1 at the formation's altitude 3 m from 0 (inside
        // the 3.6 m clearance), 2 alone (4 m from 1, 5 m from 0); 3 not known.
        let positions = [v(0.0, 0.0), v(3.0, 0.0), v(3.0, 4.0), None];
        assert_eq!(
            clear_to_come_back(&RULE, [0, 2, 3].into_iter(), (&positions, &[])),
            vec![2]
        );
        // Exactly the clearance away counts as clear.
        let positions = [v(0.0, 0.0), v(3.6, 0.0)];
        assert_eq!(
            clear_to_come_back(&RULE, [0].into_iter(), (&positions, &[])),
            vec![0]
        );
    }

    #[test]
    fn a_vehicle_does_not_come_back_while_another_closes_on_it() {
        // PX4 SIH's line swap: vehicle 1 on the layer, vehicle 0 4.2 m west of it and
        // closing at 2 m/s. At rest it would be clear; closing, it is within the
        // clearance (3.6 m) in 0.3 s.
        let positions = [v(0.0, 0.0), v(4.2, 0.0)];
        let at_rest = clear_to_come_back(&RULE, [1].into_iter(), (&positions, &[]));
        assert_eq!(at_rest, vec![1]);
        let closing = [v(0.0, 0.0), v(-2.0, 0.0)];
        let back = clear_to_come_back(&RULE, [1].into_iter(), (&positions, &closing));
        assert!(back.is_empty());
        // Passing by: 4 m abeam at the closest, in 1 s (inside the look-ahead): clear.
        let positions = [v(-2.0, 4.0), v(0.0, 0.0)];
        let passing = [v(2.0, 0.0), None];
        let back = clear_to_come_back(&RULE, [1].into_iter(), (&positions, &passing));
        assert_eq!(back, vec![1]);
        // Closing from 12 m at 2 m/s: 6 m after the look-ahead's 3 s, clear; at 3 m/s,
        // 3 m: not.
        let positions = [v(12.0, 0.0), v(0.0, 0.0)];
        for (speed, clear) in [(2.0, true), (3.0, false)] {
            let closing = [v(-speed, 0.0), None];
            let back = clear_to_come_back(&RULE, [1].into_iter(), (&positions, &closing));
            assert_eq!(back.is_empty(), !clear, "{speed} m/s");
        }
        assert_eq!(
            closest_approach_m(Vector2::new(12.0, 0.0), Vector2::new(-3.0, 0.0), 3.0),
            3.0
        );
    }

    #[test]
    fn the_layer_is_above_or_below() {
        assert_eq!(RULE.offset_up_m(), 12.0);
        let below = LayerRule {
            above: false,
            ..RULE
        };
        assert_eq!(below.offset_up_m(), -12.0);
    }
}
