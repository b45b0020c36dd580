//! Which vehicles are close enough to need a barrier: the vehicles binned on a grid and
//! each held against its neighbouring cells, O(N log N + pairs looked at) instead of all
//! N² pairs.
//!
//! Each vehicle reaches out by its own distance (the filter's [`super::reach`]): a pair
//! is found when it is closer than the sum of its two reaches (and a cap). The same
//! sweep finds the closest pair of all, whatever the reaches.

use nalgebra::{Vector2, Vector3};

/// The most grid cells along east or north; a swarm spread wider than this many of its
/// widest pair distances is swept along east instead.
const MAX_CELLS_PER_AXIS: f64 = 1e9;

/// The sweep's buffers, kept between ticks so that a tick allocates only when the swarm
/// grows or more pairs than ever are close.
#[derive(Debug, Clone, Default)]
pub struct Sweep {
    order: Vec<usize>,
    /// Each known vehicle's cell (north, east) and index, sorted.
    cells: Vec<(i64, i64, usize)>,
    pairs: Vec<(usize, usize)>,
}

/// What one sweep found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Found<'a> {
    /// Every pair `(i, j)`, `i < j`, closer than its reach, sorted.
    pub pairs: &'a [(usize, usize)],
    /// The closest pair of all, with its scaled distance (m); `None` with fewer than two
    /// known positions.
    pub closest: Option<(usize, usize, f64)>,
}

impl Sweep {
    /// Every pair `(i, j)`, `i < j`, of the given positions (`None`: not known) whose
    /// scaled distance (vertical axis multiplied by `vertical_scale`) is below
    /// `radius_m`. Non-finite positions take no part.
    pub fn pairs_within(
        &mut self,
        positions: &[Option<Vector3<f64>>],
        vertical_scale: f64,
        radius_m: f64,
    ) -> &[(usize, usize)] {
        self.sweep(positions, vertical_scale, |_| 0.5 * radius_m, radius_m)
            .pairs
    }

    /// Every pair `(i, j)`, `i < j`, of the given positions whose scaled distance is
    /// below both `reach_m(i) + reach_m(j)` and `cap_m`, and the closest pair of all
    /// (of equally close pairs, the first in `(i, j)` order).
    /// Non-finite positions take no part; a reach that is not a number reaches nothing.
    ///
    /// The vehicles are binned on a square grid of the widest pair distance (`2 ×` the
    /// widest reach, at most the cap): a pair found lies in the same or adjacent cells,
    /// so each vehicle is held against its own cell and four of its eight neighbours.
    /// When no pair lies closer than a cell, the closest is looked for by the sweep along
    /// east, which stops as soon as the gap in east alone is wider than the best found.
    pub fn sweep(
        &mut self,
        positions: &[Option<Vector3<f64>>],
        vertical_scale: f64,
        reach_m: impl Fn(usize) -> f64,
        cap_m: f64,
    ) -> Found<'_> {
        self.sweep_pairs(positions, vertical_scale, reach_m, cap_m, |_, _| {
            f64::INFINITY
        })
    }

    /// As [`Sweep::sweep`], keeping a pair `(i, j)` found only when it is also closer
    /// than `pair_limit_m(i, j)` (asked only of pairs within their reaches: a bound of the
    /// pair's own, tighter than the sum of two reaches).
    pub fn sweep_pairs(
        &mut self,
        positions: &[Option<Vector3<f64>>],
        vertical_scale: f64,
        reach_m: impl Fn(usize) -> f64,
        cap_m: f64,
        pair_limit_m: impl Fn(usize, usize) -> f64,
    ) -> Found<'_> {
        self.pairs.clear();
        let known = |p: &Option<Vector3<f64>>| p.filter(|p| p.iter().all(|x| x.is_finite()));
        let reach = |i: usize| {
            let r = reach_m(i);
            if r.is_nan() { 0.0 } else { r.max(0.0) }
        };
        let (mut widest, mut low, mut high) = (
            0.0f64,
            Vector2::repeat(f64::INFINITY),
            Vector2::repeat(f64::NEG_INFINITY),
        );
        for (i, p) in positions.iter().enumerate() {
            if let Some(p) = known(p) {
                widest = widest.max(reach(i));
                low = low.inf(&p.xy());
                high = high.sup(&p.xy());
            }
        }
        let cell_m = (2.0 * widest).min(cap_m);
        let span = (high - low).max() / cell_m;
        let mut best = Closest::default();
        let distance2 = |a: Vector3<f64>, b: Vector3<f64>| {
            let d = a - b;
            d.x * d.x + d.y * d.y + (d.z * vertical_scale).powi(2)
        };
        if cell_m > 0.0 && span.is_finite() && span < MAX_CELLS_PER_AXIS {
            self.cells.clear();
            self.cells
                .extend(positions.iter().enumerate().filter_map(|(i, p)| {
                    let p = known(p)?;
                    let cell = ((p.xy() - low) / cell_m).map(|c| c.floor() as i64);
                    Some((cell.y, cell.x, i))
                }));
            self.cells.sort_unstable();
            let cells = &self.cells;
            for (t, &(cy, cx, a)) in cells.iter().enumerate() {
                let Some(pa) = positions[a] else { continue };
                let reach_a = reach(a);
                // Its own cell and the next along east (the rest of its row, in order),
                // then the three cells north of it.
                let row = cells[t + 1..]
                    .iter()
                    .take_while(|c| c.0 == cy && c.1 <= cx + 1);
                let from = cells.partition_point(|c| (c.0, c.1) < (cy + 1, cx - 1));
                let to = cells.partition_point(|c| (c.0, c.1) <= (cy + 1, cx + 1));
                for &(_, _, b) in row.chain(&cells[from..to]) {
                    let Some(pb) = positions[b] else { continue };
                    let d2 = distance2(pa, pb);
                    let (i, j) = (a.min(b), a.max(b));
                    best.offer(i, j, d2);
                    let limit = (reach_a + reach(b)).min(cap_m);
                    if d2 < limit * limit && d2 < pair_limit_m(i, j).powi(2) {
                        self.pairs.push((i, j));
                    }
                }
            }
            if best.d2 >= cell_m * cell_m {
                // A closer pair may lie further apart than a cell in east or north.
                self.order.clear();
                self.order.extend(self.cells.iter().map(|c| c.2));
                closest_along_east(&mut self.order, positions, &mut best, distance2);
            }
        } else {
            // No grid (nothing reaches, or the cells would be too many): along east.
            self.order.clear();
            self.order.extend(
                positions
                    .iter()
                    .enumerate()
                    .filter(|(_, p)| known(p).is_some())
                    .map(|(i, _)| i),
            );
            let x = |i: usize| positions[i].map_or(0.0, |p| p.x);
            self.order.sort_by(|&a, &b| x(a).total_cmp(&x(b)));
            for (k, &a) in self.order.iter().enumerate() {
                let Some(pa) = positions[a] else { continue };
                let reach_a = reach(a);
                let scan = (reach_a + widest).min(cap_m);
                for &b in &self.order[k + 1..] {
                    let Some(pb) = positions[b] else { continue };
                    let gap = pb.x - pa.x;
                    if gap >= scan && gap * gap > best.d2 {
                        break;
                    }
                    let d2 = distance2(pa, pb);
                    let (i, j) = (a.min(b), a.max(b));
                    best.offer(i, j, d2);
                    let limit = (reach_a + reach(b)).min(cap_m);
                    if d2 < limit * limit && d2 < pair_limit_m(i, j).powi(2) {
                        self.pairs.push((i, j));
                    }
                }
            }
        }
        self.pairs.sort_unstable();
        Found {
            pairs: &self.pairs,
            closest: best.pair.map(|(i, j)| (i, j, best.d2.sqrt())),
        }
    }
}

/// The closest pair of all among the vehicles `order` by the sweep along east, starting
/// from `best` (`order` is sorted here).
pub(super) fn closest_along_east(
    order: &mut [usize],
    positions: &[Option<Vector3<f64>>],
    best: &mut Closest,
    distance2: impl Fn(Vector3<f64>, Vector3<f64>) -> f64,
) {
    let x = |i: usize| positions[i].map_or(0.0, |p| p.x);
    order.sort_by(|&a, &b| x(a).total_cmp(&x(b)));
    for (k, &a) in order.iter().enumerate() {
        let Some(pa) = positions[a] else { continue };
        for &b in &order[k + 1..] {
            let Some(pb) = positions[b] else { continue };
            let gap = pb.x - pa.x;
            if gap * gap > best.d2 {
                break;
            }
            best.offer(a.min(b), a.max(b), distance2(pa, pb));
        }
    }
}

/// The closest pair so far and its squared distance.
#[derive(Debug, Clone, Copy)]
pub(super) struct Closest {
    pub(super) pair: Option<(usize, usize)>,
    pub(super) d2: f64,
}

impl Default for Closest {
    fn default() -> Self {
        Self {
            pair: None,
            d2: f64::INFINITY,
        }
    }
}

impl Closest {
    /// Keeps `(i, j)` when it is closer, or as close and first in order.
    pub(super) fn offer(&mut self, i: usize, j: usize, d2: f64) {
        let first = self.pair.is_none_or(|p| (i, j) < p);
        if d2 < self.d2 || (d2 == self.d2 && first) {
            self.pair = Some((i, j));
            self.d2 = d2;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_sweep_finds_exactly_the_pairs_all_pairs_would() {
        // A deterministic scatter of 300 positions, some unknown, against the brute force.
        let mut next = super::super::tests::uniform(99);
        let positions: Vec<Option<Vector3<f64>>> = (0..300)
            .map(|k| {
                let p = Vector3::new(200.0 * next(), 200.0 * next(), 30.0 * next());
                (k % 17 != 0).then_some(p)
            })
            .collect();
        let mut sweep = Sweep::default();
        let found = sweep.pairs_within(&positions, 1.0 / 3.0, 12.0).to_vec();
        let mut brute = Vec::new();
        for i in 0..positions.len() {
            for j in i + 1..positions.len() {
                if let (Some(a), Some(b)) = (positions[i], positions[j]) {
                    let d = a - b;
                    if (d.x * d.x + d.y * d.y + (d.z / 3.0).powi(2)).sqrt() < 12.0 {
                        brute.push((i, j));
                    }
                }
            }
        }
        assert!(!brute.is_empty());
        assert_eq!(found, brute);
    }

    #[test]
    fn each_vehicle_reaches_its_own_distance_and_the_closest_pair_is_exact() {
        // 400 positions with reaches from 0 to 9 m and a 12 m cap, against all pairs.
        let mut next = super::super::tests::uniform(7);
        let positions: Vec<Option<Vector3<f64>>> = (0..400)
            .map(|k| {
                let p = Vector3::new(300.0 * next(), 300.0 * next(), 30.0 * next());
                (k % 13 != 0).then_some(p)
            })
            .collect();
        let reach: Vec<f64> = (0..400)
            .map(|k| 9.0 * ((k * 37) % 100) as f64 / 100.0)
            .collect();
        let scale = 1.0 / 3.0;
        let dist = |a: Vector3<f64>, b: Vector3<f64>| {
            let d = a - b;
            (d.x * d.x + d.y * d.y + (d.z * scale).powi(2)).sqrt()
        };
        let mut brute = Vec::new();
        let mut nearest = (0, 0, f64::INFINITY);
        for i in 0..positions.len() {
            for j in i + 1..positions.len() {
                if let (Some(a), Some(b)) = (positions[i], positions[j]) {
                    let d = dist(a, b);
                    if d < (reach[i] + reach[j]).min(12.0) {
                        brute.push((i, j));
                    }
                    if d < nearest.2 {
                        nearest = (i, j, d);
                    }
                }
            }
        }
        let mut sweep = Sweep::default();
        let found = sweep.sweep(&positions, scale, |k| reach[k], 12.0);
        assert!(brute.len() > 50, "{}", brute.len());
        assert_eq!(found.pairs, brute.as_slice());
        let (i, j, d) = found.closest.expect("two known");
        assert_eq!((i, j), (nearest.0, nearest.1));
        assert!((d - nearest.2).abs() < 1e-12);
        // Reaching nothing, the closest pair is still found.
        let none = sweep.sweep(&positions, scale, |_| 0.0, 12.0);
        assert!(none.pairs.is_empty());
        assert_eq!(
            none.closest.map(|c| (c.0, c.1)),
            Some((nearest.0, nearest.1))
        );
        // A pair's own limit keeps only the pairs within it too.
        let own = |i: usize, j: usize| ((i + 3 * j) % 11) as f64;
        let kept: Vec<(usize, usize)> = brute
            .iter()
            .copied()
            .filter(|&(i, j)| {
                let (Some(a), Some(b)) = (positions[i], positions[j]) else {
                    return false;
                };
                dist(a, b) < own(i, j)
            })
            .collect();
        assert!(!kept.is_empty() && kept.len() < brute.len());
        let found = sweep.sweep_pairs(&positions, scale, |k| reach[k], 12.0, own);
        assert_eq!(found.pairs, kept.as_slice());
        // Reaching a centimetre, no pair is within a cell: the closest is found along east.
        let tiny = sweep.sweep(&positions, scale, |_| 0.01, 12.0);
        assert!(tiny.pairs.is_empty());
        assert_eq!(
            tiny.closest.map(|c| (c.0, c.1)),
            Some((nearest.0, nearest.1))
        );
    }

    #[test]
    fn a_packed_lattice_gives_the_pairs_of_all_pairs_and_its_first_closest_pair() {
        // 12 × 12 vehicles 4 m apart, shuffled in index, each reaching 2.5–4.5 m, 9 m cap.
        let positions: Vec<Option<Vector3<f64>>> = (0..144)
            .map(|k| {
                let cell = (k * 89) % 144;
                Some(Vector3::new(
                    4.0 * (cell % 12) as f64,
                    4.0 * (cell / 12) as f64,
                    50.0,
                ))
            })
            .collect();
        let reach = |k: usize| 2.5 + (k % 5) as f64 * 0.5;
        let mut brute = Vec::new();
        for i in 0..144 {
            for j in i + 1..144 {
                let (Some(a), Some(b)) = (positions[i], positions[j]) else {
                    continue;
                };
                if (a - b).norm() < (reach(i) + reach(j)).min(9.0) {
                    brute.push((i, j));
                }
            }
        }
        let mut sweep = Sweep::default();
        let found = sweep.sweep(&positions, 1.0 / 3.0, reach, 9.0);
        assert_eq!(found.pairs, brute.as_slice());
        // Every pair 4 m apart ties: the first in (i, j) order is kept, 0 and the
        // vehicle beside it (cells 0 and 1, 12: vehicles 1 and 131 by 89k mod 144).
        let first_tie = (0..144)
            .filter(|&j| (positions[j].map(|p| p.xy().norm())) == Some(4.0))
            .min();
        assert_eq!(
            found.closest,
            Some((0, first_tie.expect("a neighbour"), 4.0))
        );
    }

    #[test]
    fn non_finite_positions_take_no_part() {
        let positions = [
            Some(Vector3::new(0.0, 0.0, 0.0)),
            Some(Vector3::new(f64::NAN, 0.0, 0.0)),
            Some(Vector3::new(1.0, 0.0, 0.0)),
        ];
        let mut sweep = Sweep::default();
        assert_eq!(sweep.pairs_within(&positions, 1.0, 5.0), &[(0, 2)]);
    }
}
