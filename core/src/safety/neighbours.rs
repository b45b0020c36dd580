//! Which vehicles are close enough to need a barrier: a sweep along east over the
//! vehicles sorted by position, O(N log N + pairs found) instead of all N² pairs.

use nalgebra::Vector3;

/// The sweep's buffers, kept between ticks so that a tick allocates only when the swarm
/// grows or more pairs than ever are close.
#[derive(Debug, Clone, Default)]
pub struct Sweep {
    order: Vec<usize>,
    pairs: Vec<(usize, usize)>,
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
        let r2 = radius_m * radius_m;
        for (k, &a) in self.order.iter().enumerate() {
            let Some(pa) = positions[a] else { continue };
            for &b in &self.order[k + 1..] {
                let Some(pb) = positions[b] else { continue };
                if pb.x - pa.x >= radius_m {
                    break;
                }
                let d = pa - pb;
                let d2 = d.x * d.x + d.y * d.y + (d.z * vertical_scale).powi(2);
                if d2 < r2 {
                    self.pairs.push((a.min(b), a.max(b)));
                }
            }
        }
        self.pairs.sort_unstable();
        &self.pairs
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
