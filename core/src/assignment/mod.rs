//! Place assignment: which vehicle flies to which place of a formation whose places are
//! interchangeable.
//!
//! The assignment of minimum total squared distance between the vehicles and their places
//! (Turpin, Michael & Kumar's CAPT) makes straight, synchronized paths free of collisions
//! when starts and places are far enough apart; it is the linear assignment problem on
//! the costs `|pᵢ − c − d_j|²`, solved by Bertsekas' auction with ε-scaling
//! ([`auction`]), exact on the costs rounded to 2⁻²⁴ of the largest. The centre `c` does not
//! change the answer: `Σ|pᵢ − c − d_σ(i)|² = Σ|pᵢ − c|² + Σ|d_j|² − 2Σ pᵢ·d_σ(i) +
//! 2c·Σd_j`, and only the third term depends on σ. The costs are taken about both
//! centroids so that they stay small.
//!
//! Places move only the position consensus: the velocity consensus, and so the final
//! velocity `w·v₀/Σw`, does not read them.
//!
//! Pure and synchronous.

use nalgebra::Vector2;

mod auction;

/// Why no assignment was made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AssignError {
    /// Not as many places as vehicles.
    #[error("{vehicles} vehicles for {places} places")]
    Count {
        /// Vehicles.
        vehicles: usize,
        /// Places.
        places: usize,
    },
    /// A position or place is not a finite number.
    #[error("{what} {index} is not finite")]
    NotFinite {
        /// `"position"` or `"place"`.
        what: &'static str,
        /// Its index.
        index: usize,
    },
    /// The solver refused the costs.
    #[error("the assignment solver failed: {0}")]
    Solver(&'static str),
}

/// An assignment: `place_of[i]` is the place vehicle `i` takes, each place taken once.
#[derive(Debug, Clone, PartialEq)]
pub struct Assignment {
    /// The place of each vehicle.
    pub place_of: Vec<usize>,
    /// `Σ|pᵢ − c − d_σ(i)|²` (m²) about the centroids, assigned.
    pub cost_m2: f64,
    /// The same sum with every vehicle at its own index's place (`σ(i) = i`).
    pub identity_cost_m2: f64,
}

impl Assignment {
    /// Vehicles not at their own index's place.
    pub fn moved(&self) -> usize {
        self.place_of
            .iter()
            .enumerate()
            .filter(|(i, p)| i != *p)
            .count()
    }

    /// The event that reports it: `places assigned: 15 of 16 vehicles away from their
    /// configured place; total squared distance 402.6 m² (configured 3154.6 m²)`.
    pub fn event_text(&self) -> String {
        format!(
            "places assigned: {} of {} vehicles away from their configured place; total \
             squared distance {:.1} m² (configured {:.1} m²)",
            self.moved(),
            self.place_of.len(),
            self.cost_m2,
            self.identity_cost_m2
        )
    }
}

/// The assignment of `places_m` (formation offsets, m) to the vehicles at `positions_m`
/// (m, the same horizontal frame) of minimum total squared distance.
///
/// # Errors
/// [`AssignError`] for unequal counts, a non-finite number, or a solver failure.
pub fn assign_places(
    positions_m: &[Vector2<f64>],
    places_m: &[Vector2<f64>],
) -> Result<Assignment, AssignError> {
    let n = positions_m.len();
    if places_m.len() != n {
        return Err(AssignError::Count {
            vehicles: n,
            places: places_m.len(),
        });
    }
    let finite = |v: &Vector2<f64>| v.iter().all(|x| x.is_finite());
    for (what, list) in [("position", positions_m), ("place", places_m)] {
        if let Some(index) = list.iter().position(|v| !finite(v)) {
            return Err(AssignError::NotFinite { what, index });
        }
    }
    if n == 0 {
        return Ok(Assignment {
            place_of: Vec::new(),
            cost_m2: 0.0,
            identity_cost_m2: 0.0,
        });
    }
    let centroid = |list: &[Vector2<f64>]| list.iter().sum::<Vector2<f64>>() / n as f64;
    let (cp, cd) = (centroid(positions_m), centroid(places_m));
    let cost = |i: usize, j: usize| ((positions_m[i] - cp) - (places_m[j] - cd)).norm_squared();
    let costs: Vec<f64> = (0..n * n).map(|k| cost(k / n, k % n)).collect();
    let place_of = auction::minimum_cost(n, &costs).map_err(AssignError::Solver)?;
    let cost_m2 = place_of.iter().enumerate().map(|(i, &j)| cost(i, j)).sum();
    let identity_cost_m2 = (0..n).map(|i| cost(i, i)).sum();
    Ok(Assignment {
        place_of,
        cost_m2,
        identity_cost_m2,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn v(x: f64, y: f64) -> Vector2<f64> {
        Vector2::new(x, y)
    }

    fn is_permutation(place_of: &[usize]) -> bool {
        let mut seen = vec![false; place_of.len()];
        place_of
            .iter()
            .all(|&j| j < seen.len() && !std::mem::replace(&mut seen[j], true))
    }

    /// Every permutation of `0..n` (Heap's algorithm).
    fn permutations(n: usize) -> Vec<Vec<usize>> {
        fn heap(k: usize, a: &mut Vec<usize>, out: &mut Vec<Vec<usize>>) {
            if k <= 1 {
                out.push(a.clone());
                return;
            }
            for i in 0..k {
                heap(k - 1, a, out);
                let swap = if k.is_multiple_of(2) { i } else { 0 };
                a.swap(swap, k - 1);
            }
        }
        let mut out = Vec::new();
        heap(n, &mut (0..n).collect(), &mut out);
        out
    }

    #[test]
    fn two_vehicles_take_the_nearer_places_wherever_the_formation_is() {
        // Places in the opposite order to the vehicles, and 100 m away: the translation
        // changes nothing.
        let positions = [v(0.0, 0.0), v(10.0, 0.0)];
        let places = [v(110.0, 50.0), v(100.0, 50.0)];
        let a = assign_places(&positions, &places).unwrap();
        assert_eq!(a.place_of, vec![1, 0]);
        assert!(a.cost_m2.abs() < 1e-12);
        // In order, each vehicle is 10 m from its place about the centroids: 2 · 10².
        assert!((a.identity_cost_m2 - 200.0).abs() < 1e-9);
        assert_eq!(a.moved(), 2);
    }

    #[test]
    fn the_assignment_is_the_cheapest_of_all_permutations() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for _ in 0..20 {
            let n = 6;
            let mut draw = || v(rng.random_range(-20.0..20.0), rng.random_range(-20.0..20.0));
            let positions: Vec<_> = (0..n).map(|_| draw()).collect();
            let places: Vec<_> = (0..n).map(|_| draw()).collect();
            let a = assign_places(&positions, &places).unwrap();
            assert!(is_permutation(&a.place_of));
            let (cp, cd) = (
                positions.iter().sum::<Vector2<f64>>() / n as f64,
                places.iter().sum::<Vector2<f64>>() / n as f64,
            );
            let best = permutations(n)
                .iter()
                .map(|p| {
                    p.iter()
                        .enumerate()
                        .map(|(i, &j)| ((positions[i] - cp) - (places[j] - cd)).norm_squared())
                        .sum::<f64>()
                })
                .fold(f64::INFINITY, f64::min);
            // Optimal for the costs rounded to 1/RESOLUTION of the largest: within n such
            // units of the optimum, never below it.
            let largest = (0..n)
                .flat_map(|i| (0..n).map(move |j| (i, j)))
                .map(|(i, j)| ((positions[i] - cp) - (places[j] - cd)).norm_squared())
                .fold(0.0, f64::max);
            let tolerance = n as f64 * largest / auction::RESOLUTION;
            assert!(a.cost_m2 <= best + tolerance, "{} vs {best}", a.cost_m2);
            assert!(a.cost_m2 >= best - 1e-9, "{} vs {best}", a.cost_m2);
        }
    }

    /// A 4 × 4 block 4 m apart to a circle of the same spacing (chord 4 m, radius
    /// 2 / sin(π/16)), places in vehicle order: straight synchronized paths, assigned,
    /// keep every pair at least 4 / √2 m apart (CAPT: starts and places ≥ 2√2·R apart
    /// keep discs of radius R apart), where vehicle order brings some within 1 m.
    #[test]
    fn block_to_circle_assigned_keeps_straight_paths_apart() {
        let n = 16;
        let positions: Vec<_> = (0..n)
            .map(|i| v(4.0 * (i % 4) as f64, 4.0 * (i / 4) as f64))
            .collect();
        let radius = 2.0 / (std::f64::consts::PI / 16.0).sin();
        let places: Vec<_> = (0..n)
            .map(|l| {
                let angle = 2.0 * std::f64::consts::PI * l as f64 / n as f64;
                v(angle.cos(), angle.sin()) * radius
            })
            .collect();
        let closest_along = |place_of: &[usize]| {
            let (cp, cd) = (
                positions.iter().sum::<Vector2<f64>>() / n as f64,
                places.iter().sum::<Vector2<f64>>() / n as f64,
            );
            let at = |i: usize, s: f64| {
                let goal = places[place_of[i]] - cd + cp;
                positions[i] + (goal - positions[i]) * s
            };
            let mut closest = f64::INFINITY;
            for step in 0..=1000 {
                let s = f64::from(step) / 1000.0;
                for i in 0..n {
                    for j in i + 1..n {
                        closest = closest.min((at(i, s) - at(j, s)).norm());
                    }
                }
            }
            closest
        };
        let a = assign_places(&positions, &places).unwrap();
        assert!(closest_along(&a.place_of) >= 4.0 / 2f64.sqrt() - 1e-9);
        let in_order: Vec<usize> = (0..n).collect();
        assert!(closest_along(&in_order) < 1.0);
        assert!(a.cost_m2 < a.identity_cost_m2);
    }

    /// A thousand vehicles: solved, and no two vehicles gain by swapping places (what
    /// every optimal assignment satisfies).
    #[test]
    fn a_thousand_vehicles_are_assigned_with_no_improving_swap() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let n = 1024;
        let positions: Vec<_> = (0..n)
            .map(|i| v(4.0 * (i % 32) as f64, 4.0 * (i / 32) as f64))
            .collect();
        let places: Vec<_> = (0..n)
            .map(|_| {
                v(
                    rng.random_range(-100.0..100.0),
                    rng.random_range(-100.0..100.0),
                )
            })
            .collect();
        let a = assign_places(&positions, &places).unwrap();
        assert!(is_permutation(&a.place_of));
        let (cp, cd) = (
            positions.iter().sum::<Vector2<f64>>() / n as f64,
            places.iter().sum::<Vector2<f64>>() / n as f64,
        );
        let c = |i: usize, j: usize| ((positions[i] - cp) - (places[j] - cd)).norm_squared();
        let p = &a.place_of;
        let largest = (0..n)
            .flat_map(|i| (0..n).map(move |j| (i, j)))
            .map(|(i, j)| c(i, j))
            .fold(0.0, f64::max);
        let unit = largest / auction::RESOLUTION;
        for i in 0..n {
            for j in i + 1..n {
                let now = c(i, p[i]) + c(j, p[j]);
                let swapped = c(i, p[j]) + c(j, p[i]);
                // Exact on the costs rounded to 1/RESOLUTION of the largest.
                assert!(
                    now <= swapped + 4.0 * unit,
                    "vehicles {i} and {j} gain by swapping"
                );
            }
        }
    }

    #[test]
    fn bad_input_is_named() {
        assert_eq!(
            assign_places(&[v(0.0, 0.0)], &[]),
            Err(AssignError::Count {
                vehicles: 1,
                places: 0
            })
        );
        assert_eq!(
            assign_places(&[v(0.0, f64::NAN)], &[v(0.0, 0.0)]),
            Err(AssignError::NotFinite {
                what: "position",
                index: 0
            })
        );
        assert_eq!(
            assign_places(&[v(0.0, 0.0)], &[v(f64::INFINITY, 0.0)]).map_err(|e| e.to_string()),
            Err("place 0 is not finite".to_owned())
        );
    }
}
