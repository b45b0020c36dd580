//! The broken rows solved piece by piece: the rows that bind fall apart into groups that
//! share no vehicle, each solved alone (a lone row in closed form), and the weighted sum
//! given back by the free vehicles where a piece cannot keep its own.

use nalgebra::Vector2;

use super::{Agent, PIECE_ROUNDS, Piece, Row, SafetyFilter, Settings, limit};

impl SafetyFilter {
    /// The broken rows solved piece by piece: the rows that bind fall apart into groups
    /// that share no vehicle, and each group is its own QP (a lone row: closed form,
    /// unless that leaves a disc). A group of rows with two commanded vehicles each keeps
    /// its own `Σ wᵢuᵢ`. A group with a one-vehicle row (the fence, a neighbour the filter
    /// does not command) cannot; when the sum is kept, what the groups changed of it is
    /// given back by every commanded vehicle in no binding row, all by the same amount
    /// (the least weighted change that does it). Rows an answer breaks join and the
    /// pieces are solved again (at most [`PIECE_ROUNDS`]). `None` when the whole problem
    /// must be solved at once: no convergence, a piece the solver could not solve, or a
    /// sum no free vehicle can give back inside its disc. On `None` the commands are as
    /// given.
    pub(super) fn solve_in_pieces(
        &mut self,
        settings: &Settings,
        agents: &[Agent],
        commands: &mut [Vector2<f64>],
    ) -> Option<bool> {
        let n = commands.len();
        #[cfg(test)]
        if self.whole_only {
            return None;
        }
        let weight = |k: usize| agents[k].weight.max(1e-9);
        let given: Vec<Vector2<f64>> = commands.to_vec();
        let mut work: Vec<bool> = self
            .rows
            .iter()
            .map(|r| r.lhs(agents, commands) < r.row.b)
            .collect();
        let mut var_of = vec![None; n];
        let mut in_rows = vec![false; n];
        for _ in 0..PIECE_ROUNDS {
            commands.copy_from_slice(&given);
            let mut parent: Vec<usize> = (0..n).collect();
            in_rows.iter_mut().for_each(|x| *x = false);
            for (r, _) in self.rows.iter().zip(&work).filter(|(_, w)| **w) {
                let (a, b) = (root(&mut parent, r.i), root(&mut parent, r.j));
                parent[a] = b;
                in_rows[r.i] = true;
                in_rows[r.j] = true;
            }
            let mut pieces: Vec<(usize, usize)> = (0..self.rows.len())
                .filter(|&k| work[k])
                .map(|k| (root(&mut parent, self.rows[k].i), k))
                .collect();
            pieces.sort_unstable();
            let mut relaxed = false;
            for piece in pieces.chunk_by(|a, b| a.0 == b.0) {
                let rows: Vec<usize> = piece.iter().map(|p| p.1).collect();
                if rows.len() == 1 && self.closed_form(agents, commands, rows[0]) {
                    continue;
                }
                let keeps_own_sum = rows.iter().all(|&k| two_sided(agents, &self.rows[k]));
                let mut vars: Vec<usize> = rows
                    .iter()
                    .flat_map(|&k| [self.rows[k].i, self.rows[k].j])
                    .filter(|&k| agents[k].controlled)
                    .collect();
                vars.sort_unstable();
                vars.dedup();
                for (v, &k) in vars.iter().enumerate() {
                    var_of[k] = Some(v);
                }
                let solved = self.solve(
                    settings,
                    agents,
                    commands,
                    Piece {
                        rows: &rows,
                        vars: &vars,
                        var_of: &var_of,
                        with_sum: keeps_own_sum,
                    },
                );
                for &k in &vars {
                    var_of[k] = None;
                }
                match solved {
                    Ok(r) => relaxed |= r,
                    Err(_) => {
                        commands.copy_from_slice(&given);
                        return None;
                    }
                }
            }
            if self.tally.unfinished {
                // Out of time: the answer so far goes out, as it is (the stopping check
                // secures it); solving the whole problem again would only overrun.
                return Some(relaxed);
            }
            if settings.keep_weighted_sum {
                let changed: Vector2<f64> = (0..n)
                    .filter(|&k| agents[k].controlled)
                    .map(|k| weight(k) * (commands[k] - given[k]))
                    .sum();
                if changed.norm() > 1e-12 {
                    let free: Vec<usize> = (0..n)
                        .filter(|&k| agents[k].controlled && !in_rows[k])
                        .collect();
                    let free_weight: f64 = free.iter().map(|&k| weight(k)).sum();
                    if free.is_empty() || free_weight <= 0.0 {
                        commands.copy_from_slice(&given);
                        return None;
                    }
                    let shift = -changed / free_weight;
                    for &k in &free {
                        commands[k] += shift;
                        if commands[k].norm() > limit(&agents[k]) {
                            commands.copy_from_slice(&given);
                            return None;
                        }
                    }
                }
            }
            let mut joined = false;
            for (k, r) in self.rows.iter().enumerate() {
                if !work[k] && r.lhs(agents, commands) < r.row.b - 1e-9 {
                    work[k] = true;
                    joined = true;
                }
            }
            if !joined {
                return Some(relaxed);
            }
        }
        commands.copy_from_slice(&given);
        None
    }

    /// One broken row solved exactly: the least weighted change that meets it, `Δuᵢ =
    /// λa/wᵢ` and `Δuⱼ = −λa/wⱼ` for two commanded vehicles (`Σ wΔu = 0` by
    /// construction), `Δuᵢ = λa` for one. `false` (nothing changed) when that would take
    /// a command out of its disc.
    fn closed_form(&self, agents: &[Agent], commands: &mut [Vector2<f64>], k: usize) -> bool {
        let r = &self.rows[k];
        let weight = |k: usize| agents[k].weight.max(1e-9);
        let a = r.row.a;
        let deficit = r.row.b - r.lhs(agents, commands);
        let norm2 = a.norm_squared();
        if !(deficit.is_finite() && norm2 > 1e-12) {
            return false;
        }
        // Which commanded vehicles move, and by which sign of `a`.
        let i_moves = agents[r.i].controlled;
        let j_moves = !r.single() && agents[r.j].controlled;
        let inverse_weights =
            f64::from(u8::from(i_moves)) / weight(r.i) + f64::from(u8::from(j_moves)) / weight(r.j);
        if inverse_weights <= 0.0 {
            return false;
        }
        let lambda = deficit / (norm2 * inverse_weights);
        let ui = commands[r.i] + a * (lambda / weight(r.i));
        let uj = commands[r.j] - a * (lambda / weight(r.j));
        let inside = |u: &Vector2<f64>, k: usize| u.norm() <= limit(&agents[k]) + 1e-12;
        if (i_moves && !inside(&ui, r.i)) || (j_moves && !inside(&uj, r.j)) {
            return false;
        }
        if i_moves {
            commands[r.i] = ui;
        }
        if j_moves {
            commands[r.j] = uj;
        }
        true
    }
}

/// A row with both vehicles commanded (not the fence's, not against one the filter does
/// not command).
pub(super) fn two_sided(agents: &[Agent], r: &Row) -> bool {
    !r.single() && agents[r.i].controlled && agents[r.j].controlled
}

/// The root of `k` in a union-find forest (halving the path).
fn root(parent: &mut [usize], mut k: usize) -> usize {
    while parent[k] != k {
        parent[k] = parent[parent[k]];
        k = parent[k];
    }
    k
}
