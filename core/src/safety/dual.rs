//! The filter's QP solved by coordinate ascent on its dual (Hildreth's method with the
//! discs and the sum as blocks), warm-started from the last tick's multipliers.
//!
//! The problem of one piece, over its variables `u` (one per commanded vehicle):
//!
//! ```text
//! minimise Σ wᵢ|uᵢ − ûᵢ|² + ρ Σ σᵣ   subject to  aᵣᵀ(uᵢ − uⱼ) + σᵣ ≥ cᵣ,  σᵣ ≥ 0,
//!                                               |uᵢ| ≤ Lᵢ,  (Σ wᵢuᵢ = Σ wᵢûᵢ)
//! ```
//!
//! Each constraint has a multiplier; `u` is the minimiser of the Lagrangian,
//! `uᵢ = ûᵢ + (Σᵣ λᵣ sᵣᵢ aᵣ − μᵢ + wᵢν)/(2wᵢ)`, kept up to date as each block in turn is
//! set to its best value with the others fixed:
//! - a row's `λᵣ ∈ [0, ρ]` (the slack's linear penalty boxes it), in closed form, over
//!   relaxed by [`OVER_RELAXATION`] (a lattice of rows converges in far fewer sweeps);
//! - a disc's `μᵢ`: `uᵢ` projected onto the disc;
//! - the sum's `ν`: every `uᵢ` moved by the same amount.
//!
//! The dual is concave and each block step increases it, so the sweeps converge to the
//! optimum (the primal is strictly convex in `u`). A sweep costs one visit of every row
//! and every variable: linear in the piece. It stops when every row, disc and sum meets
//! its optimality conditions within [`TOLERANCE_MPS2`], or when told to stop.
//!
//! Pure: no allocation after the first calls, no clock (the caller's `stop` decides).

use nalgebra::Vector2;

/// How far the closing of every condition is asked for (m/s²).
pub const TOLERANCE_MPS2: f64 = 1e-9;

/// The over-relaxation of the row steps (1: plain coordinate ascent; below 2 converges).
pub const OVER_RELAXATION: f64 = 1.5;

/// One row `aᵀ(Σ sₖ u_vₖ) ≥ c` over one or two variables.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DualRow {
    /// The variables and their signs (`+1` for `i`, `−1` for `j`); one side when `two`
    /// is false.
    pub sides: [(usize, f64); 2],
    /// Whether the second side is used.
    pub two: bool,
    /// `a` (unit or shorter).
    pub a: Vector2<f64>,
    /// `c` (m/s²): the bound on the commands.
    pub c: f64,
}

/// One piece: its variables and rows.
#[derive(Debug, Clone, Default)]
pub struct DualPiece {
    /// Each variable's weight `wᵢ` (> 0).
    pub weight: Vec<f64>,
    /// Each variable's disc `Lᵢ` (m/s²).
    pub limit: Vec<f64>,
    /// The commands as given, `ûᵢ` (inside their discs).
    pub given: Vec<Vector2<f64>>,
    /// The rows.
    pub rows: Vec<DualRow>,
    /// Whether `Σ wᵢuᵢ = Σ wᵢûᵢ` is held.
    pub keep_sum: bool,
    /// The bound of every row's multiplier (the slack's cost).
    pub rho: f64,
}

/// How the ascent ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DualEnd {
    /// Every condition met within the tolerance, after this many sweeps.
    Converged {
        /// Sweeps made.
        sweeps: usize,
    },
    /// Stopped (its `stop` said so, or `max_sweeps` were made) before that.
    Stopped {
        /// Sweeps made.
        sweeps: usize,
    },
}

/// The ascent's state: the multipliers and the commands they give.
#[derive(Debug, Clone, Default)]
pub struct DualState {
    /// Each row's `λ` (set before [`ascend`] to warm-start it; `0` for none).
    pub lambda: Vec<f64>,
    /// Each disc's `μ`.
    mu: Vec<Vector2<f64>>,
    /// The commands.
    pub u: Vec<Vector2<f64>>,
}

impl DualPiece {
    fn half_inverse_weight(&self, v: usize) -> f64 {
        0.5 / self.weight[v]
    }

    /// `aᵀ(Σ sₖ uₖ)` of row `r` at `u`.
    fn lhs(&self, r: &DualRow, u: &[Vector2<f64>]) -> f64 {
        let first = r.sides[0].1 * r.a.dot(&u[r.sides[0].0]);
        if r.two {
            first + r.sides[1].1 * r.a.dot(&u[r.sides[1].0])
        } else {
            first
        }
    }

    /// Moves the commands by row `r`'s multiplier changing by `delta`.
    fn apply(&self, r: &DualRow, delta: f64, u: &mut [Vector2<f64>]) {
        let count = if r.two { 2 } else { 1 };
        for &(v, sign) in &r.sides[..count] {
            u[v] += r.a * (sign * delta * self.half_inverse_weight(v));
        }
    }

    /// The largest breach of an optimality condition at `state` (m/s²).
    fn residual(&self, state: &DualState) -> f64 {
        let mut worst: f64 = 0.0;
        for (r, &lambda) in self.rows.iter().zip(&state.lambda) {
            let gap = r.c - self.lhs(r, &state.u);
            if lambda < self.rho {
                worst = worst.max(gap);
            }
            if lambda > 0.0 {
                worst = worst.max(-gap);
            }
        }
        for ((u, mu), &limit) in state.u.iter().zip(&state.mu).zip(&self.limit) {
            let norm = u.norm();
            worst = worst.max(norm - limit);
            if mu.norm_squared() > 0.0 {
                worst = worst.max(limit - norm);
            }
        }
        worst
    }
}

/// Sweeps the dual's blocks until the optimality conditions hold, `max_sweeps` were
/// made, or `stop()` (asked after every sweep) says so. `state.lambda` holds one value
/// per row on entry (the warm start, each clamped into `[0, ρ]`); on return `state.u`
/// holds the commands.
pub fn ascend(
    piece: &DualPiece,
    state: &mut DualState,
    max_sweeps: usize,
    mut stop: impl FnMut() -> bool,
) -> DualEnd {
    let n = piece.given.len();
    state.lambda.resize(piece.rows.len(), 0.0);
    state.mu.clear();
    state.mu.resize(n, Vector2::zeros());
    state.u.clear();
    state.u.extend_from_slice(&piece.given);
    for (r, lambda) in piece.rows.iter().zip(state.lambda.iter_mut()) {
        *lambda = if lambda.is_finite() {
            lambda.clamp(0.0, piece.rho)
        } else {
            0.0
        };
        piece.apply(r, *lambda, &mut state.u);
    }
    let total_weight: f64 = piece.weight.iter().sum();
    let target: Vector2<f64> = piece
        .weight
        .iter()
        .zip(&piece.given)
        .map(|(w, u)| *w * u)
        .sum();
    for sweep in 1..=max_sweeps {
        for (r, lambda) in piece.rows.iter().zip(state.lambda.iter_mut()) {
            let count = if r.two { 2 } else { 1 };
            let curvature: f64 = r.sides[..count]
                .iter()
                .map(|&(v, _)| piece.half_inverse_weight(v))
                .sum::<f64>()
                * r.a.norm_squared();
            if curvature <= 0.0 {
                continue;
            }
            let gap = r.c - piece.lhs(r, &state.u);
            let next = (*lambda + OVER_RELAXATION * gap / curvature).clamp(0.0, piece.rho);
            let delta = next - *lambda;
            if delta != 0.0 {
                piece.apply(r, delta, &mut state.u);
                *lambda = next;
            }
        }
        for v in 0..n {
            let (limit, two_w) = (piece.limit[v], 2.0 * piece.weight[v]);
            let free = state.u[v] + state.mu[v] / two_w;
            let norm = free.norm();
            let projected = if norm > limit {
                free * (limit / norm)
            } else {
                free
            };
            state.mu[v] = (free - projected) * two_w;
            state.u[v] = projected;
        }
        if piece.keep_sum && total_weight > 0.0 {
            let got: Vector2<f64> = piece.weight.iter().zip(&state.u).map(|(w, u)| *w * u).sum();
            let shift = (target - got) / total_weight;
            state.u.iter_mut().for_each(|u| *u += shift);
        }
        if piece.residual(state) <= TOLERANCE_MPS2 {
            return DualEnd::Converged { sweeps: sweep };
        }
        if stop() {
            return DualEnd::Stopped { sweeps: sweep };
        }
    }
    DualEnd::Stopped { sweeps: max_sweeps }
}
