//! The filter's QP solved exactly by clarabel, for a piece the dual ascent
//! ([`super::dual`]) did not finish and that is small enough to solve in the time left.

use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettingsBuilder, DefaultSolver, IPSolver, SolverStatus, SupportedConeT,
};
use nalgebra::Vector2;

use super::{Agent, Piece, SLACK_COST, SafetyFilter, Settings, limit};

impl SafetyFilter {
    /// One QP over the variables solved by clarabel (interior point, the discs as
    /// second-order cones) within what is left of the time limit; writes the commands when solved and says whether a
    /// row had to be relaxed (its slack used).
    pub(super) fn solve_exact(
        &self,
        settings: &Settings,
        agents: &[Agent],
        commands: &mut [Vector2<f64>],
        piece: Piece<'_>,
    ) -> Result<bool, &'static str> {
        let Piece {
            rows,
            vars,
            var_of,
            with_sum,
        } = piece;
        let n_u = 2 * vars.len();
        let n_rows = rows.len();
        let nv = n_u + n_rows;
        let weight = |k: usize| agents[k].weight.max(1e-9);
        let max_weight = vars.iter().map(|&k| weight(k)).fold(1.0, f64::max);
        // Objective ½xᵀPx + qᵀx: P = 2W and q = −2Wû on the commands, and ρσ on each row's
        // slack, linear: an exact penalty, so a row that can be met is met exactly
        // (ρ = 10⁴·max w is far above any multiplier a row of these sizes needs).
        let mut p_diag = Vec::with_capacity(nv);
        let mut q = Vec::with_capacity(nv);
        for &k in vars {
            for component in commands[k].iter() {
                p_diag.push(2.0 * weight(k));
                q.push(-2.0 * weight(k) * component);
            }
        }
        for _ in 0..n_rows {
            p_diag.push(0.0);
            q.push(SLACK_COST * max_weight);
        }
        // Constraint rows as (row, column, value) and b, zero cone first.
        let mut entries: Vec<(usize, usize, f64)> = Vec::new();
        let mut b = Vec::new();
        let mut zero_rows = 0;
        if with_sum && settings.keep_weighted_sum {
            for axis in [0, 1] {
                let mut total = 0.0;
                for (v, &k) in vars.iter().enumerate() {
                    entries.push((b.len(), 2 * v + axis, weight(k)));
                    total += weight(k) * commands[k][axis];
                }
                b.push(total);
                zero_rows += 1;
            }
        }
        for (r_index, r) in rows.iter().map(|&k| &self.rows[k]).enumerate() {
            // a·(netᵢ − netⱼ) + σ ≥ b  ⇔  −a·xᵢ + a·xⱼ − σ + s = −b − a·cᵢ + a·cⱼ, s ≥ 0.
            // A bound beyond what the two envelopes can give asks for the same thing as
            // one just beyond it (all of both discs): clipped, the problem stays scaled.
            let reach = if r.single() {
                limit(&agents[r.i])
            } else {
                limit(&agents[r.i]) + limit(&agents[r.j])
            };
            let mut rhs = -r.row.b.min(reach + 1.0);
            let sides: &[(usize, f64)] = if r.single() {
                &[(r.i, -1.0)]
            } else {
                &[(r.i, -1.0), (r.j, 1.0)]
            };
            for &(k, sign) in sides {
                if let Some(v) = var_of[k] {
                    for axis in 0..2 {
                        entries.push((b.len(), 2 * v + axis, sign * r.row.a[axis]));
                    }
                    rhs += sign * r.row.a.dot(&agents[k].drift_mps2);
                }
            }
            entries.push((b.len(), n_u + r_index, -1.0));
            b.push(rhs);
        }
        for r_index in 0..n_rows {
            // σ ≥ 0.
            entries.push((b.len(), n_u + r_index, -1.0));
            b.push(0.0);
        }
        let nonnegative = b.len() - zero_rows;
        // Each command inside its disc: s = (L, x, y) in the second-order cone.
        for (v, &k) in vars.iter().enumerate() {
            b.push(limit(&agents[k]));
            entries.push((b.len(), 2 * v, -1.0));
            b.push(0.0);
            entries.push((b.len(), 2 * v + 1, -1.0));
            b.push(0.0);
        }
        let m = b.len();
        let a = csc(m, nv, &mut entries);
        let p = csc(
            nv,
            nv,
            &mut p_diag
                .iter()
                .enumerate()
                .map(|(c, &x)| (c, c, x))
                .collect::<Vec<_>>(),
        );
        let mut cones = Vec::with_capacity(2 + vars.len());
        if zero_rows > 0 {
            cones.push(SupportedConeT::ZeroConeT(zero_rows));
        }
        if nonnegative > 0 {
            cones.push(SupportedConeT::NonnegativeConeT(nonnegative));
        }
        cones.extend(vars.iter().map(|_| SupportedConeT::SecondOrderConeT(3)));
        let time_limit = self.time_left_s();
        let solver_settings = DefaultSettingsBuilder::default()
            .verbose(false)
            .max_iter(100)
            .time_limit(time_limit)
            .build()
            .map_err(|_| "solver setup")?;
        let mut solver = DefaultSolver::new(&p, &q, &a, &b, &cones, solver_settings)
            .map_err(|_| "solver setup")?;
        solver.solve();
        match solver.solution.status {
            SolverStatus::Solved | SolverStatus::AlmostSolved => {}
            SolverStatus::PrimalInfeasible | SolverStatus::AlmostPrimalInfeasible => {
                return Err("infeasible");
            }
            _ => return Err("not converged"),
        }
        let x = &solver.solution.x;
        if x.len() != nv || x.iter().any(|v| !v.is_finite()) {
            return Err("not converged");
        }
        for (v, &k) in vars.iter().enumerate() {
            commands[k] = Vector2::new(x[2 * v], x[2 * v + 1]);
        }
        if with_sum && settings.keep_weighted_sum {
            // The solver meets the equality to its tolerance (1e-8); the least weighted
            // change that meets it exactly is uₖ −= δ/Σw (δ the sum's error per axis).
            let total_w: f64 = vars.iter().map(|&k| weight(k)).sum();
            for axis in 0..2 {
                let got: f64 = vars.iter().map(|&k| weight(k) * commands[k][axis]).sum();
                let delta = (got - b[axis]) / total_w;
                for &k in vars {
                    commands[k][axis] -= delta;
                }
            }
        }
        // A row is relaxed when the commands miss it by more than the solver's tolerance.
        let tolerance = 1e-6 * (1.0 + b.iter().fold(0.0f64, |acc, v| acc.max(v.abs())));
        // (Every commanded vehicle of a row is a variable, so `lhs` reads the solution.)
        Ok(rows
            .iter()
            .map(|&k| &self.rows[k])
            .any(|r| r.lhs(agents, commands) < r.row.b - tolerance))
    }
}

/// A compressed-column matrix from (row, column, value) entries (sorted here).
fn csc(m: usize, n: usize, entries: &mut [(usize, usize, f64)]) -> CscMatrix<f64> {
    entries.sort_by_key(|e| (e.1, e.0));
    let mut colptr = vec![0usize; n + 1];
    let mut rowval = Vec::with_capacity(entries.len());
    let mut nzval = Vec::with_capacity(entries.len());
    for &(r, c, v) in entries.iter() {
        colptr[c + 1] += 1;
        rowval.push(r);
        nzval.push(v);
    }
    for c in 0..n {
        colptr[c + 1] += colptr[c];
    }
    CscMatrix::new(m, n, colptr, rowval, nzval)
}
