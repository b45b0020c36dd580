//! Which pairs can bind, found by position and velocity together.
//!
//! A pair's barrier row can bind only within a distance that grows with the pair's own
//! relative speed ([`super::ReachBound::distance_m`]). A search by position alone must
//! look as far as the fastest pair could bind; in a packed block flying a swap, where
//! every vehicle moves fast about the mean but alike its neighbours, that is hundreds of
//! candidates a vehicle for a handful of rows.
//!
//! Here the vehicles are binned on a square grid, and each occupied cell keeps the box of
//! its vehicles' positions and of their velocities. Two cells are looked into only when
//! their boxes' nearest points are within the limit at the fastest relative speed their
//! velocity boxes allow; the vehicles of two neighbouring cells always are, so that the
//! closest pair of all is found as by the position sweep. The pairs kept are exactly
//! those closer than both the cap and the limit at their own relative speed.

use nalgebra::{Vector2, Vector3};

use super::neighbours::{Closest, Found, closest_along_east};

/// One occupied cell: its vehicles (a run of the sorted cells) and their boxes.
#[derive(Debug, Clone, Copy)]
struct Group {
    /// The cell (north, east).
    cell: (i64, i64),
    /// Its vehicles: `cells[start..end]`.
    start: usize,
    end: usize,
    /// The box of its scaled positions (m).
    low: Vector3<f64>,
    high: Vector3<f64>,
    /// The box of its scaled velocities (m/s; infinite when one is not known).
    vlow: Vector3<f64>,
    vhigh: Vector3<f64>,
}

impl Group {
    /// The fastest relative speed of a vehicle of this cell and one of `other` (m/s).
    fn fastest_mps(&self, other: &Group) -> f64 {
        let up = self.vhigh - other.vlow;
        let down = other.vhigh - self.vlow;
        up.sup(&down).map(|x| x.max(0.0)).norm()
    }

    /// The nearest two points of the two position boxes (m, scaled).
    fn nearest_m(&self, other: &Group) -> f64 {
        let gap = (self.low - other.high).sup(&(other.low - self.high));
        gap.map(|x| x.max(0.0)).norm()
    }
}

/// Up to this many vehicles every pair is looked at, without the grid.
const ALL_PAIRS_UP_TO: usize = 16;

/// The sweep's buffers, kept between ticks.
#[derive(Debug, Clone, Default)]
pub struct FlowSweep {
    /// Each known vehicle's cell (north, east) and index, sorted.
    cells: Vec<(i64, i64, usize)>,
    groups: Vec<Group>,
    /// Scaled positions and velocities (`None`: position not known or not finite).
    scaled: Vec<Option<(Vector3<f64>, Vector3<f64>)>>,
    /// The scaled positions alone, for the closest pair along east.
    points: Vec<Option<Vector3<f64>>>,
    order: Vec<usize>,
    pairs: Vec<(usize, usize)>,
}

impl FlowSweep {
    /// Every pair `(i, j)`, `i < j`, whose scaled distance (vertical axis multiplied by
    /// `vertical_scale`) is below both `cap_m` and `limit_m(v)` at the pair's scaled
    /// relative speed `v` (infinite when a velocity is not known), sorted; and the closest
    /// pair of all. `limit_m` must not decrease with speed. Positions that are not known
    /// or not finite take no part; cells are `cell_m` wide (at least a centimetre).
    pub fn sweep(
        &mut self,
        positions: &[Option<Vector3<f64>>],
        velocities: &[Option<Vector3<f64>>],
        vertical_scale: f64,
        limit_m: impl Fn(f64) -> f64,
        cap_m: f64,
        cell_m: f64,
    ) -> Found<'_> {
        let limit = |v: f64| {
            if v.is_finite() {
                limit_m(v.max(0.0)).min(cap_m)
            } else {
                cap_m
            }
        };
        let scale = Vector3::new(1.0, 1.0, vertical_scale);
        self.scaled.clear();
        self.scaled
            .extend(positions.iter().enumerate().map(|(k, p)| {
                let p = p.filter(|p| p.iter().all(|x| x.is_finite()))?;
                let v = velocities
                    .get(k)
                    .copied()
                    .flatten()
                    .filter(|v| v.iter().all(|x| x.is_finite()))
                    .map_or(Vector3::repeat(f64::NAN), |v| v.component_mul(&scale));
                Some((p.component_mul(&scale), v))
            }));
        if self.scaled.len() <= ALL_PAIRS_UP_TO {
            return self.all_pairs(limit);
        }
        let cell_m = if cell_m.is_finite() {
            cell_m.max(0.01)
        } else {
            cap_m.max(0.01)
        };
        let mut low = Vector2::repeat(f64::INFINITY);
        for (p, _) in self.scaled.iter().flatten() {
            low = low.inf(&p.xy());
        }
        self.cells.clear();
        self.cells
            .extend(self.scaled.iter().enumerate().filter_map(|(i, s)| {
                let (p, _) = (*s)?;
                let cell = ((p.xy() - low) / cell_m).map(|c| c.floor() as i64);
                Some((cell.y, cell.x, i))
            }));
        self.cells.sort_unstable();
        self.group();
        let (mut vlow, mut vhigh) = (
            Vector3::repeat(f64::INFINITY),
            -Vector3::repeat(f64::INFINITY),
        );
        for g in &self.groups {
            vlow = vlow.inf(&g.vlow);
            vhigh = vhigh.sup(&g.vhigh);
        }
        let everyone = Group {
            cell: (0, 0),
            start: 0,
            end: 0,
            low: Vector3::zeros(),
            high: Vector3::zeros(),
            vlow,
            vhigh,
        };
        self.pairs.clear();
        let mut best = Closest::default();
        let (groups, cells, scaled) = (&self.groups, &self.cells, &self.scaled);
        let north_most = groups.last().map_or(0, |g| g.cell.0);
        for (ga, a) in groups.iter().enumerate() {
            // No pair of this cell binds beyond the limit at its fastest relative speed
            // to anyone; its neighbours are looked into whatever that limit.
            let reach = limit(a.fastest_mps(&everyone));
            let span = ((reach / cell_m).ceil().max(1.0)).min(i64::MAX as f64 / 4.0) as i64;
            let (cy, cx) = a.cell;
            for y in cy..=cy.saturating_add(span).min(north_most) {
                // The cells after this one: the rest of its row, then whole rows north.
                let from_x = if y == cy { cx } else { cx.saturating_sub(span) };
                let from = groups[ga..].partition_point(|g| g.cell < (y, from_x)) + ga;
                let to =
                    groups[ga..].partition_point(|g| g.cell <= (y, cx.saturating_add(span))) + ga;
                for b in &groups[from..to] {
                    let near = (b.cell.0 - cy).abs() <= 1 && (b.cell.1 - cx).abs() <= 1;
                    let bound = limit(a.fastest_mps(b));
                    if !near && a.nearest_m(b) >= bound {
                        continue;
                    }
                    let same = b.cell == a.cell;
                    for (s, &(_, _, i)) in cells[a.start..a.end].iter().enumerate() {
                        let Some((pi, vi)) = scaled[i] else { continue };
                        let others = if same {
                            &cells[a.start + s + 1..a.end]
                        } else {
                            &cells[b.start..b.end]
                        };
                        for &(_, _, j) in others {
                            let Some((pj, vj)) = scaled[j] else { continue };
                            let d2 = (pi - pj).norm_squared();
                            let (i, j) = (i.min(j), i.max(j));
                            best.offer(i, j, d2);
                            if d2 < bound * bound && d2 < limit((vi - vj).norm()).powi(2) {
                                self.pairs.push((i, j));
                            }
                        }
                    }
                }
            }
        }
        if best.d2 >= cell_m * cell_m {
            // A closer pair may lie further apart than a cell in east or north.
            self.order.clear();
            self.order.extend(self.cells.iter().map(|c| c.2));
            self.points.clear();
            self.points
                .extend(self.scaled.iter().map(|s| s.map(|s| s.0)));
            closest_along_east(&mut self.order, &self.points, &mut best, |a, b| {
                (a - b).norm_squared()
            });
        }
        self.pairs.sort_unstable();
        Found {
            pairs: &self.pairs,
            closest: best.pair.map(|(i, j)| (i, j, best.d2.sqrt())),
        }
    }

    /// Every pair of the scaled vehicles looked at: for a few vehicles, cheaper than the
    /// grid and the same answer.
    fn all_pairs(&mut self, limit: impl Fn(f64) -> f64) -> Found<'_> {
        self.pairs.clear();
        let mut best = Closest::default();
        for (i, a) in self.scaled.iter().enumerate() {
            let Some((pi, vi)) = a else { continue };
            for (j, b) in self.scaled.iter().enumerate().skip(i + 1) {
                let Some((pj, vj)) = b else { continue };
                let d2 = (pi - pj).norm_squared();
                best.offer(i, j, d2);
                if d2 < limit((vi - vj).norm()).powi(2) {
                    self.pairs.push((i, j));
                }
            }
        }
        Found {
            pairs: &self.pairs,
            closest: best.pair.map(|(i, j)| (i, j, best.d2.sqrt())),
        }
    }

    /// The occupied cells of the sorted `cells`, each with its boxes.
    fn group(&mut self) {
        self.groups.clear();
        for (k, &(cy, cx, i)) in self.cells.iter().enumerate() {
            let Some((p, v)) = self.scaled[i] else {
                continue;
            };
            let v_known = v.iter().all(|x| x.is_finite());
            let (vl, vh) = if v_known {
                (v, v)
            } else {
                (
                    Vector3::repeat(f64::NEG_INFINITY),
                    Vector3::repeat(f64::INFINITY),
                )
            };
            match self.groups.last_mut() {
                Some(g) if g.cell == (cy, cx) => {
                    g.end = k + 1;
                    g.low = g.low.inf(&p);
                    g.high = g.high.sup(&p);
                    g.vlow = g.vlow.inf(&vl);
                    g.vhigh = g.vhigh.sup(&vh);
                }
                _ => self.groups.push(Group {
                    cell: (cy, cx),
                    start: k,
                    end: k + 1,
                    low: p,
                    high: p,
                    vlow: vl,
                    vhigh: vh,
                }),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Pairs, and the closest pair with its distance.
    type Pairs = (Vec<(usize, usize)>, Option<(usize, usize, f64)>);

    /// Every pair and the closest, by brute force.
    fn brute(
        positions: &[Option<Vector3<f64>>],
        velocities: &[Option<Vector3<f64>>],
        scale: f64,
        limit: impl Fn(f64) -> f64,
        cap: f64,
    ) -> Pairs {
        let s = Vector3::new(1.0, 1.0, scale);
        let mut pairs = Vec::new();
        let mut nearest: Option<(usize, usize, f64)> = None;
        for i in 0..positions.len() {
            for j in i + 1..positions.len() {
                let (Some(a), Some(b)) = (positions[i], positions[j]) else {
                    continue;
                };
                let d = (a - b).component_mul(&s).norm();
                let v = match (velocities[i], velocities[j]) {
                    (Some(x), Some(y)) => (x - y).component_mul(&s).norm(),
                    _ => f64::INFINITY,
                };
                let l = if v.is_finite() {
                    limit(v)
                } else {
                    f64::INFINITY
                };
                if d < cap && d < l {
                    pairs.push((i, j));
                }
                if nearest.is_none_or(|n| d < n.2) {
                    nearest = Some((i, j, d));
                }
            }
        }
        (pairs, nearest)
    }

    #[test]
    fn a_swap_of_a_packed_block_gives_the_pairs_of_all_pairs() {
        // 20 × 20 vehicles 4 m apart flying towards the centre at 0.1/s times their
        // distance, some velocities unknown, a few vehicles 200 m out and one far above.
        let mut next = super::super::tests::uniform(5);
        let mut positions = Vec::new();
        let mut velocities = Vec::new();
        for k in 0..400 {
            let p = Vector3::new(
                4.0 * (k % 20) as f64 - 38.0 + 0.3 * next(),
                4.0 * (k / 20) as f64 - 38.0 + 0.3 * next(),
                50.0 + next(),
            );
            positions.push(Some(p));
            velocities.push((k % 37 != 5).then(|| Vector3::new(-0.1 * p.x, -0.1 * p.y, 0.0)));
        }
        positions.push(Some(Vector3::new(200.0, 0.0, 50.0)));
        velocities.push(Some(Vector3::new(-6.0, 0.0, 0.0)));
        positions.push(Some(Vector3::new(1.0, 1.0, 90.0)));
        velocities.push(Some(Vector3::zeros()));
        positions.push(None);
        velocities.push(Some(Vector3::zeros()));
        let limit = |v: f64| 4.2 + (v + 2.7).powi(2) / 6.0;
        let (pairs, nearest) = brute(&positions, &velocities, 1.0 / 3.0, limit, 40.0);
        let mut sweep = FlowSweep::default();
        let found = sweep.sweep(&positions, &velocities, 1.0 / 3.0, limit, 40.0, 8.4);
        assert!(pairs.len() > 1000, "{}", pairs.len());
        assert_eq!(found.pairs, pairs.as_slice());
        let (i, j, d) = found.closest.expect("known");
        let n = nearest.expect("known");
        assert_eq!((i, j), (n.0, n.1));
        assert!((d - n.2).abs() < 1e-12);
    }

    #[test]
    fn a_scatter_with_any_cell_size_gives_the_pairs_of_all_pairs_and_the_closest() {
        let mut next = super::super::tests::uniform(11);
        let positions: Vec<Option<Vector3<f64>>> = (0..300)
            .map(|k| {
                let p = Vector3::new(300.0 * next(), 300.0 * next(), 30.0 * next());
                (k % 13 != 0).then_some(p)
            })
            .collect();
        let velocities: Vec<Option<Vector3<f64>>> = (0..300)
            .map(|_| Some(Vector3::new(8.0 * next() - 4.0, 8.0 * next() - 4.0, next())))
            .collect();
        let limit = |v: f64| 3.0 + 1.5 * v;
        let (pairs, nearest) = brute(&positions, &velocities, 0.5, limit, 25.0);
        assert!(pairs.len() > 50, "{}", pairs.len());
        let mut sweep = FlowSweep::default();
        for cell in [0.5, 3.0, 8.0, 30.0, f64::INFINITY] {
            let found = sweep.sweep(&positions, &velocities, 0.5, limit, 25.0, cell);
            assert_eq!(found.pairs, pairs.as_slice(), "cell {cell}");
            let n = nearest.expect("known");
            assert_eq!(found.closest.map(|c| (c.0, c.1)), Some((n.0, n.1)));
        }
        // Limits of nothing: no pair, and still the closest of all.
        let found = sweep.sweep(&positions, &velocities, 0.5, |_| 0.0, 25.0, 1.0);
        assert!(found.pairs.is_empty());
        let n = nearest.expect("known");
        assert_eq!(found.closest.map(|c| (c.0, c.1)), Some((n.0, n.1)));
    }

    #[test]
    fn a_few_vehicles_looked_at_pair_by_pair_give_the_pairs_of_all_pairs() {
        // Sixteen and fewer take the pair-by-pair path: the same pairs and closest pair as
        // brute force, with a vehicle unknown, one velocity unknown and one not finite.
        let mut next = super::super::tests::uniform(7);
        for n in [2, 6, ALL_PAIRS_UP_TO] {
            let mut positions: Vec<Option<Vector3<f64>>> = (0..n)
                .map(|_| Some(Vector3::new(30.0 * next(), 30.0 * next(), 5.0 * next())))
                .collect();
            let mut velocities: Vec<Option<Vector3<f64>>> = (0..n)
                .map(|_| Some(Vector3::new(6.0 * next() - 3.0, 6.0 * next() - 3.0, next())))
                .collect();
            if n > 2 {
                positions[1] = None;
                velocities[2] = None;
                velocities[n - 1] = Some(Vector3::new(f64::NAN, 0.0, 0.0));
            }
            let limit = |v: f64| 4.0 + 2.0 * v;
            let (pairs, nearest) = brute(&positions, &velocities, 0.5, limit, 12.0);
            let mut sweep = FlowSweep::default();
            let found = sweep.sweep(&positions, &velocities, 0.5, limit, 12.0, 3.0);
            assert_eq!(found.pairs, pairs.as_slice(), "{n} vehicles");
            if n == ALL_PAIRS_UP_TO {
                // Some pairs kept and some left out: both sides of the limit are checked.
                assert!(
                    !pairs.is_empty() && pairs.len() < n * (n - 1) / 2,
                    "{pairs:?}"
                );
            }
            let (i, j, d) = found.closest.expect("known");
            let m = nearest.expect("known");
            assert_eq!((i, j), (m.0, m.1), "{n} vehicles");
            assert!((d - m.2).abs() < 1e-12);
        }
    }
}
