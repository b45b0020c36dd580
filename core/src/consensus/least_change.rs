//! Re-targeting every agent at once: the least change of the agents' velocities that
//! makes the consensus value the target, each agent within its speed limit.
//!
//! The paper re-targets one agent because it takes the others' velocities as given. A
//! coordinator that commands every vehicle can move them all, and then asks far less of
//! each. With the left null vector `w` of the ring (`W = Σwᵢ`), consensus reaches
//! `Σwᵢvᵢ / W`, so the problem is
//!
//! ```text
//!   minimise Σ ‖v'ᵢ − vᵢ‖²   subject to   Σ wᵢ v'ᵢ = W·v_t,   ‖v'ᵢ‖ ≤ sᵢ.
//! ```
//!
//! Its Lagrangian gives, for a multiplier `λ ∈ R²`, `v'ᵢ(λ) = P_sᵢ(vᵢ + wᵢλ)` (`P_s`: the
//! projection onto the disc of radius `s`), and `λ` solves `F(λ) = Σwᵢv'ᵢ(λ) − W·v_t = 0`.
//! `−F` is the gradient of the concave dual function, so a Newton step with backtracking
//! on the dual converges; without a binding limit it is one step, the closed form
//! `v'ᵢ = vᵢ + wᵢ·(W·v_t − Σwⱼvⱼ) / Σwⱼ²`.
//!
//! The reachable consensus values are the disc of radius `Σ|wᵢ|sᵢ / |W|`: a target
//! outside it is refused, with the nearest reachable value. Pure: no I/O.

use nalgebra::{Matrix2, Vector2};

use crate::error::ConsensusError;

/// A target beyond this fraction of the reachable radius is refused: at the edge every
/// agent flies at its limit and the multiplier grows without bound.
pub const REACH_MARGIN: f64 = 1.0 - 1e-6;
const MAX_ITERATIONS: usize = 200;

/// The least change, or why there is none.
#[derive(Debug, Clone, PartialEq)]
pub enum LeastChange {
    /// Every agent's new velocity (m/s), in agent order.
    Reached {
        /// The new velocities.
        velocities_mps: Vec<Vector2<f64>>,
        /// `Σ‖v'ᵢ − vᵢ‖²` ((m/s)²).
        cost: f64,
    },
    /// The target is out of reach with these limits.
    Unreachable {
        /// The nearest consensus value the limits allow (m/s).
        best_mps: Vector2<f64>,
        /// Why, in words.
        reason: String,
    },
}

/// The least change of `velocities_mps` (m/s) that makes the `weights`-weighted mean the
/// `target_mps`, each new velocity within its `max_speed_mps`.
///
/// # Errors
/// No agents, lengths that differ, a non-finite number, a speed limit that is not
/// positive, or weights that sum to zero.
pub fn least_change_velocities(
    velocities_mps: &[Vector2<f64>],
    weights: &[f64],
    target_mps: Vector2<f64>,
    max_speed_mps: &[f64],
) -> Result<LeastChange, ConsensusError> {
    let n = velocities_mps.len();
    if n == 0 {
        return Err(ConsensusError::NoMacroVertices);
    }
    for (what, got) in [
        ("weights", weights.len()),
        ("speed limits", max_speed_mps.len()),
    ] {
        if got != n {
            return Err(ConsensusError::WrongLength {
                what,
                expected: n,
                got,
            });
        }
    }
    let values = velocities_mps
        .iter()
        .flat_map(|v| [("velocity", v.x), ("velocity", v.y)])
        .chain(weights.iter().map(|w| ("weight", *w)))
        .chain([("target", target_mps.x), ("target", target_mps.y)])
        .chain(max_speed_mps.iter().map(|s| ("speed limit", *s)));
    for (name, value) in values {
        if !value.is_finite() {
            return Err(ConsensusError::NonFinite { name, value });
        }
    }
    if let Some(s) = max_speed_mps.iter().find(|s| **s <= 0.0) {
        return Err(ConsensusError::NotPositive {
            name: "speed limit",
            value: *s,
        });
    }
    let total: f64 = weights.iter().sum();
    let squares: f64 = weights.iter().map(|w| w * w).sum();
    if total.abs() < 1e-12 || squares < 1e-24 {
        return Err(ConsensusError::ZeroWeightSum);
    }
    let radius = weights
        .iter()
        .zip(max_speed_mps)
        .map(|(w, s)| w.abs() * s)
        .sum::<f64>()
        / total.abs();
    let speed = target_mps.norm();
    if speed > REACH_MARGIN * radius {
        let best = if speed > 0.0 {
            target_mps * (REACH_MARGIN * radius / speed)
        } else {
            target_mps
        };
        return Ok(LeastChange::Unreachable {
            best_mps: best,
            reason: format!(
                "({:.3}, {:.3}) m/s is beyond what the speed limits allow ({radius:.3} m/s in any direction): the nearest reachable is ({:.3}, {:.3}) m/s",
                target_mps.x, target_mps.y, best.x, best.y
            ),
        });
    }
    let b = target_mps * total;
    let solve = Dual {
        v: velocities_mps,
        w: weights,
        s: max_speed_mps,
        b,
    };
    // The closed form of the unlimited problem is the first guess.
    let weighted: Vector2<f64> = velocities_mps
        .iter()
        .zip(weights)
        .map(|(v, w)| v * *w)
        .sum();
    let mut lambda = (b - weighted) / squares;
    let tolerance = 1e-12 * (1.0 + b.norm() + radius * total.abs());
    for _ in 0..MAX_ITERATIONS {
        let residual = solve.residual(lambda);
        if residual.norm() <= tolerance {
            break;
        }
        lambda = solve.step(lambda, residual, squares);
    }
    let velocities: Vec<Vector2<f64>> = (0..n).map(|i| solve.velocity(i, lambda)).collect();
    let cost = velocities
        .iter()
        .zip(velocities_mps)
        .map(|(a, b)| (a - b).norm_squared())
        .sum();
    Ok(LeastChange::Reached {
        velocities_mps: velocities,
        cost,
    })
}

/// The dual problem of one request.
struct Dual<'a> {
    v: &'a [Vector2<f64>],
    w: &'a [f64],
    s: &'a [f64],
    b: Vector2<f64>,
}

impl Dual<'_> {
    fn velocity(&self, i: usize, lambda: Vector2<f64>) -> Vector2<f64> {
        project(self.v[i] + lambda * self.w[i], self.s[i])
    }

    /// `F(λ) = Σwᵢv'ᵢ(λ) − b`.
    fn residual(&self, lambda: Vector2<f64>) -> Vector2<f64> {
        (0..self.v.len())
            .map(|i| self.velocity(i, lambda) * self.w[i])
            .sum::<Vector2<f64>>()
            - self.b
    }

    /// The dual function, concave in `λ`.
    fn value(&self, lambda: Vector2<f64>) -> f64 {
        (0..self.v.len())
            .map(|i| {
                let u = self.velocity(i, lambda);
                0.5 * (u - self.v[i]).norm_squared() - self.w[i] * lambda.dot(&u)
            })
            .sum::<f64>()
            + lambda.dot(&self.b)
    }

    /// `J = Σwᵢ² DPᵢ`, the Jacobian of `F`.
    fn jacobian(&self, lambda: Vector2<f64>) -> Matrix2<f64> {
        (0..self.v.len())
            .map(|i| {
                let x = self.v[i] + lambda * self.w[i];
                let r = x.norm();
                let dp = if r <= self.s[i] {
                    Matrix2::identity()
                } else {
                    let u = x / r;
                    (Matrix2::identity() - u * u.transpose()) * (self.s[i] / r)
                };
                dp * (self.w[i] * self.w[i])
            })
            .sum()
    }

    /// A Newton step on the dual with backtracking; a gradient step (1/L with
    /// `L = Σwᵢ²`) when the Newton direction does not climb.
    fn step(&self, lambda: Vector2<f64>, residual: Vector2<f64>, squares: f64) -> Vector2<f64> {
        let g0 = self.value(lambda);
        let j = self.jacobian(lambda) + Matrix2::identity() * (1e-12 * squares);
        if let Some(inv) = j.try_inverse() {
            let direction = -(inv * residual);
            let mut t = 1.0;
            for _ in 0..40 {
                let candidate = lambda + direction * t;
                if self.value(candidate) > g0 - 1e-15 * g0.abs()
                    && self.residual(candidate).norm() < residual.norm()
                {
                    return candidate;
                }
                t *= 0.5;
            }
        }
        lambda - residual / squares
    }
}

/// The projection of `x` onto the disc of radius `s`.
fn project(x: Vector2<f64>, s: f64) -> Vector2<f64> {
    let r = x.norm();
    if r <= s { x } else { x * (s / r) }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ring_w(m: usize, k: f64) -> Vec<f64> {
        (0..2 * m)
            .map(|i| if i % 2 == 0 { 1.0 } else { 1.0 + k })
            .collect()
    }

    fn reached(r: LeastChange) -> Vec<Vector2<f64>> {
        match r {
            LeastChange::Reached { velocities_mps, .. } => velocities_mps,
            LeastChange::Unreachable { reason, .. } => panic!("{reason}"),
        }
    }

    #[test]
    fn without_a_binding_limit_it_is_the_weighted_least_norm_closed_form() {
        // Six agents, k = 1: w = (1, 2, 1, 2, 1, 2), W = 9, Σw² = 15.
        let w = ring_w(3, 1.0);
        let v: Vec<Vector2<f64>> = (0..6)
            .map(|i| Vector2::new(0.3 * i as f64 - 0.5, 0.1 * (i as f64).powi(2) - 1.0))
            .collect();
        let target = Vector2::new(3.0, 2.0);
        let got = reached(least_change_velocities(&v, &w, target, &[100.0; 6]).unwrap());
        let weighted: Vector2<f64> = v.iter().zip(&w).map(|(v, w)| v * *w).sum();
        let c = (target * 9.0 - weighted) / 15.0;
        for i in 0..6 {
            let expected = v[i] + c * w[i];
            assert!(
                (got[i] - expected).norm() < 1e-12,
                "{i}: {} vs {expected}",
                got[i]
            );
        }
    }

    #[test]
    fn from_rest_a_three_two_target_asks_three_point_six_of_each_with_equal_weights() {
        // k = 0: every weight 1, so each agent goes to the target itself: |(3, 2)| = 3.606.
        let w = ring_w(3, 0.0);
        let got = reached(
            least_change_velocities(
                &[Vector2::zeros(); 6],
                &w,
                Vector2::new(3.0, 2.0),
                &[5.49; 6],
            )
            .unwrap(),
        );
        for v in &got {
            assert!((v - Vector2::new(3.0, 2.0)).norm() < 1e-12);
        }
        assert!((got[0].norm() - 13f64.sqrt()).abs() < 1e-12);
    }

    #[test]
    fn a_binding_limit_caps_the_heavy_agents_and_the_light_ones_make_up_the_rest() {
        // From rest, k = 2: w = (1, 3, 1, 3), W = 8, Σw² = 20, target 4 m/s east. Unlimited,
        // c = 32/20 = 1.6: the heavy agents would fly 4.8 m/s. With a 4.5 m/s limit they
        // fly 4.5, and the light ones x from 2·1·x + 2·3·4.5 = 32: x = 2.5. The KKT
        // conditions hold with λ = 2.5 (light: vᵢ + 1·λ inside the disc; heavy: 3·λ = 7.5
        // beyond 4.5, projected).
        let w = ring_w(2, 2.0);
        let got = reached(
            least_change_velocities(
                &[Vector2::zeros(); 4],
                &w,
                Vector2::new(4.0, 0.0),
                &[4.5; 4],
            )
            .unwrap(),
        );
        let expected = [2.5, 4.5, 2.5, 4.5];
        for (v, e) in got.iter().zip(expected) {
            assert!((v - Vector2::new(e, 0.0)).norm() < 1e-9, "{got:?}");
        }
    }

    #[test]
    fn binding_limits_in_two_dimensions_keep_the_constraint_and_optimality() {
        let w = ring_w(4, 0.5);
        let v: Vec<Vector2<f64>> = (0..8)
            .map(|i| Vector2::new((i as f64).sin() * 3.0, (i as f64 * 0.7).cos() * 2.0))
            .collect();
        let limits = [3.0, 4.0, 3.5, 3.0, 4.0, 3.5, 3.0, 4.0];
        let target = Vector2::new(2.5, -1.5);
        let got = reached(least_change_velocities(&v, &w, target, &limits).unwrap());
        let total: f64 = w.iter().sum();
        let mean: Vector2<f64> = got
            .iter()
            .zip(&w)
            .map(|(v, w)| v * *w)
            .sum::<Vector2<f64>>()
            / total;
        assert!((mean - target).norm() < 1e-10, "{mean}");
        let mut binding = 0;
        for i in 0..8 {
            assert!(got[i].norm() <= limits[i] + 1e-12);
            binding += usize::from(got[i].norm() > limits[i] - 1e-9);
        }
        assert!(binding > 0, "no limit binds: not the case this test is for");
        // Optimality: no feasible perturbation that keeps the mean lowers the cost. Moving
        // δ from agent i to agent j (δ/wᵢ and −δ/wⱼ) keeps Σwv; try small ones.
        let cost = |u: &[Vector2<f64>]| -> f64 {
            u.iter().zip(&v).map(|(a, b)| (a - b).norm_squared()).sum()
        };
        let base = cost(&got);
        for i in 0..8 {
            for j in 0..8 {
                if i == j {
                    continue;
                }
                for d in [
                    Vector2::new(1e-4, 0.0),
                    Vector2::new(0.0, 1e-4),
                    Vector2::new(-1e-4, 3e-5),
                ] {
                    let mut u = got.clone();
                    u[i] += d / w[i];
                    u[j] -= d / w[j];
                    if u[i].norm() <= limits[i] && u[j].norm() <= limits[j] {
                        assert!(cost(&u) >= base - 1e-12, "{i} {j} {d}");
                    }
                }
            }
        }
    }

    #[test]
    fn an_unreachable_target_names_the_nearest_reachable() {
        // w = (1, 2, 1, 2), W = 6, limits 3: reachable radius (2·3 + 2·6)/6 = 3 m/s.
        let w = ring_w(2, 1.0);
        let r = least_change_velocities(
            &[Vector2::zeros(); 4],
            &w,
            Vector2::new(0.0, 5.0),
            &[3.0; 4],
        )
        .unwrap();
        let LeastChange::Unreachable { best_mps, reason } = r else {
            panic!("{r:?}")
        };
        assert!(
            (best_mps - Vector2::new(0.0, 3.0)).norm() < 1e-5,
            "{best_mps}"
        );
        assert!(reason.contains("3.000 m/s in any direction"), "{reason}");
    }

    #[test]
    fn bad_input_is_refused_by_name() {
        let w = ring_w(1, 1.0);
        let v = [Vector2::zeros(); 2];
        let e = least_change_velocities(&v, &w, Vector2::zeros(), &[1.0]).unwrap_err();
        assert!(e.to_string().starts_with("speed limits"), "{e}");
        let e = least_change_velocities(&v, &w, Vector2::zeros(), &[1.0, 0.0]).unwrap_err();
        assert!(
            e.to_string().starts_with("speed limit must be greater"),
            "{e}"
        );
        let e =
            least_change_velocities(&v, &w, Vector2::new(f64::NAN, 0.0), &[1.0; 2]).unwrap_err();
        assert!(e.to_string().starts_with("target must be a finite"), "{e}");
        let e = least_change_velocities(&v, &[1.0, -1.0], Vector2::zeros(), &[1.0; 2]).unwrap_err();
        assert!(e.to_string().contains("sum to zero"), "{e}");
    }
}
