//! Which vehicles are close enough to need a barrier: a sweep along east over the
//! vehicles sorted by position, O(N log N + pairs found) instead of all N² pairs.
//!
//! Each vehicle reaches out by its own distance (the filter's [`super::reach`]): a pair
//! is found when it is closer than the sum of its two reaches (and a cap). The same
//! sweep finds the closest pair of all, whatever the reaches.

use nalgebra::Vector3;

/// The sweep's buffers, kept between ticks so that a tick allocates only when the swarm
/// grows or more pairs than ever are close.
#[derive(Debug, Clone, Default)]
pub struct Sweep {
    order: Vec<usize>,
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
    /// below both `reach_m(i) + reach_m(j)` and `cap_m`, and the closest pair of all.
    /// Non-finite positions take no part; a reach that is not a number reaches nothing.
    pub fn sweep(
        &mut self,
        positions: &[Option<Vector3<f64>>],
        vertical_scale: f64,
        reach_m: impl Fn(usize) -> f64,
        cap_m: f64,
    ) -> Found<'_> {
        self.order.clear();
        self.pairs.clear();
        self.order.extend(
            positions
                .iter()
                .enumerate()
                .filter(|(_, p)| p.is_some_and(|p| p.iter().all(|x| x.is_finite())))
                .map(|(i, _)| i),
        );
        let x = |i: usize| positions[i].map_or(0.0, |p| p.x);
        self.order.sort_by(|&a, &b| x(a).total_cmp(&x(b)));
        let reach = |i: usize| {
            let r = reach_m(i);
            if r.is_nan() { 0.0 } else { r.max(0.0) }
        };
        let widest = self.order.iter().map(|&i| reach(i)).fold(0.0, f64::max);
        let mut closest: Option<(usize, usize, f64)> = None;
        let mut best2 = f64::INFINITY;
        for (k, &a) in self.order.iter().enumerate() {
            let Some(pa) = positions[a] else { continue };
            let reach_a = reach(a);
            let scan = (reach_a + widest).min(cap_m);
            for &b in &self.order[k + 1..] {
                let Some(pb) = positions[b] else { continue };
                let gap = pb.x - pa.x;
                if gap >= scan && gap * gap >= best2 {
                    break;
                }
                let d = pa - pb;
                let d2 = d.x * d.x + d.y * d.y + (d.z * vertical_scale).powi(2);
                if d2 < best2 {
                    best2 = d2;
                    closest = Some((a.min(b), a.max(b), d2));
                }
                let limit = (reach_a + reach(b)).min(cap_m);
                if d2 < limit * limit {
                    self.pairs.push((a.min(b), a.max(b)));
                }
            }
        }
        self.pairs.sort_unstable();
        Found {
            pairs: &self.pairs,
            closest: closest.map(|(i, j, d2)| (i, j, d2.sqrt())),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_sweep_finds_exactly_the_pairs_all_pairs_would() {
        // A deterministic scatter of 300 positions, some unknown, against the brute force.
        let mut x: u64 = 99;
        let mut next = || {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (x >> 11) as f64 / (1u64 << 53) as f64
        };
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
        let mut x: u64 = 7;
        let mut next = || {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (x >> 11) as f64 / (1u64 << 53) as f64
        };
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
