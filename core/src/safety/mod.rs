//! Keeping vehicles apart: a control-barrier-function safety filter between the law and
//! the saturation (docs/math.md, "Keeping vehicles apart").
//!
//! Each tick, the pairs close enough to matter (a sweep, [`neighbours`]) each give one
//! barrier row ([`barrier`]) on the two vehicles' horizontal commands. When the law's
//! commands break none of them they pass untouched; otherwise the filter solves
//!
//! ```text
//! minimise Σ wᵢ|uᵢ − ûᵢ|²  subject to  every barrier row,
//!                                      each |uᵢ| within its envelope's disc,
//!                                      Σ wᵢuᵢ = Σ wᵢûᵢ (in consensus)
//! ```
//!
//! with clarabel (the discs as second-order cones). It runs on the saturated commands, so
//! `û` is inside the discs. A pairwise row is `+a` on one vehicle and `−a` on the other,
//! so without the discs the optimum keeps `Σ wᵢuᵢ` by itself; the discs (one vehicle's
//! limit) can break that, and the explicit equality restores it. Each row has a slack
//! `σ ≥ 0` costing [`SLACK_COST`] times the largest weight: a pair that closes faster than
//! the envelopes can stop is braked as hard as they allow (`relaxed`), and the problem is
//! always feasible (`û` with large slacks meets every row), so the equality always
//! holds. When the solver fails anyway, it solves again without the equality
//! (`sum_kept = false`); when that fails too, or it does not converge in time, every
//! vehicle of the problem accelerates away from its neighbours at its share of the
//! authority the barrier assumed (the fallback, counted and logged). The commands
//! it writes are finite and inside the envelope: the saturation after it changes nothing.
//!
//! Pure and synchronous.

pub mod barrier;
pub mod fence;
pub mod jam;
pub mod neighbours;

use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettingsBuilder, DefaultSolver, IPSolver, SolverStatus, SupportedConeT,
};
use nalgebra::{Vector2, Vector3};

pub use barrier::{PairRow, Separation, Side, pair_row};
pub use fence::{Fence, FenceItem, FenceItemKind, FenceShape, fence_row, stop_point_m};
pub use neighbours::Sweep;

/// How far ahead a pair is looked at (s): pairs that cannot meet within this time at
/// the swarm's top speed are not considered.
pub const LOOKAHEAD_S: f64 = 3.0;

/// The cost of a row's slack (per m/s² and unit of weight, linear: an exact penalty): a
/// row that cannot be met inside the envelopes is met as nearly as they allow.
pub const SLACK_COST: f64 = 1e4;

/// The scaled distance (m) within which a pair is looked at: the separation, what two
/// vehicles at `top_speed_mps` (scaled, as [`Separation::scaled`]) close head-on in
/// `lookahead_s`, and a metre.
pub fn look_radius_m(separation: &Separation, top_speed_mps: f64, lookahead_s: f64) -> f64 {
    separation.horizontal_m + 2.0 * top_speed_mps * lookahead_s + 1.0
}

/// A barrier row counts as active when the command leaves less slack than this (m/s²).
pub const ACTIVE_SLACK_MPS2: f64 = 1e-6;
/// Rounds of the piecewise solve (rows an answer breaks join the pieces) before the
/// whole problem is solved at once.
pub const PIECE_ROUNDS: usize = 4;

/// One vehicle as the filter sees it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Agent {
    /// What is known of it (`None`: nothing usable; it takes no part).
    pub side: Option<Side>,
    /// Whether its horizontal command is the filter's to change (ours, in the air).
    pub controlled: bool,
    /// Its weight in the objective (the consensus weight `wᵢ`, or 1).
    pub weight: f64,
    /// The part of its command that does not accelerate it (m/s²): the drag fed forward
    /// less the disturbance taken off. Net acceleration = command − drift.
    pub drift_mps2: Vector2<f64>,
    /// The radius of its envelope for the horizontal command (m/s²).
    pub limit_mps2: f64,
    /// Its share of a pair's braking authority (m/s²).
    pub braking_mps2: f64,
}

/// What the filter did on one tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Outcome {
    /// No barrier row was broken by the law's commands: nothing changed.
    Untouched,
    /// The commands were changed; `sum_kept` when `Σ wᵢuᵢ` was held as an equality.
    Filtered {
        /// Whether the weighted sum was kept.
        sum_kept: bool,
        /// Whether a row could not be met inside the envelopes and was relaxed: the
        /// commands then come as close to it as the envelopes allow (most braking).
        relaxed: bool,
    },
    /// No solution in time: the vehicles of the problem brake.
    Fallback {
        /// Why (`infeasible`, `not converged`, `solver setup`).
        reason: &'static str,
    },
}

/// One tick's report.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Report {
    /// What was done.
    pub outcome: Outcome,
    /// Pairs with a barrier row.
    pub rows: usize,
    /// Rows the final commands meet with (almost) no slack.
    pub active: usize,
    /// The closest pair seen (indices and scaled distance, m).
    pub closest: Option<(usize, usize, f64)>,
}

/// The filter's settings for one tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Settings {
    /// The separation enforced.
    pub separation: Separation,
    /// How old what is known of the vehicles may be when the command acts (s).
    pub age_s: f64,
    /// Hold `Σ wᵢuᵢ` as an equality (consensus).
    pub keep_weighted_sum: bool,
    /// The solver's time limit (s).
    pub time_limit_s: f64,
}

#[derive(Debug, Clone, Copy)]
struct Row {
    i: usize,
    /// The other vehicle; `i` itself for a fence row (one vehicle only).
    j: usize,
    row: PairRow,
}

impl Row {
    fn single(&self) -> bool {
        self.i == self.j
    }

    /// `aᵀ(netᵢ − netⱼ)` for the commands (`netⱼ` left out of a fence row).
    fn lhs(&self, agents: &[Agent], commands: &[Vector2<f64>]) -> f64 {
        let other = if self.single() {
            Vector2::zeros()
        } else {
            net(agents, commands, self.j)
        };
        self.row.a.dot(&(net(agents, commands, self.i) - other))
    }
}

/// Agent `k`'s net acceleration under its command (zero for one the filter does not
/// command: its acceleration is not known, and taken as none).
fn net(agents: &[Agent], commands: &[Vector2<f64>], k: usize) -> Vector2<f64> {
    if agents[k].controlled {
        commands[k] - agents[k].drift_mps2
    } else {
        Vector2::zeros()
    }
}

/// The filter, with its buffers.
#[derive(Debug, Clone, Default)]
pub struct SafetyFilter {
    sweep: Sweep,
    positions: Vec<Option<Vector3<f64>>>,
    rows: Vec<Row>,
    var_of: Vec<Option<usize>>,
    vars: Vec<usize>,
    /// The rows of the last call the filtered commands meet with less than
    /// `ACTIVE_SLACK_MPS2` to spare, as `(i, j)` (`i == j`: the fence).
    active: Vec<(usize, usize)>,
    /// Solve every problem at once, never piece by piece (for comparing the two).
    #[cfg(test)]
    pub(crate) whole_only: bool,
}

impl SafetyFilter {
    /// Filters the horizontal commands `commands` (m/s², ENU; one per agent) in place.
    /// Agents and commands have the same length (a shorter slice is filtered as far as
    /// both go).
    ///
    /// With a fence (and its margin, m), every vehicle the filter commands whose margin
    /// is within the look-ahead also gets a row against the fence's horizontal boundary.
    pub fn filter(
        &mut self,
        settings: &Settings,
        agents: &[Agent],
        commands: &mut [Vector2<f64>],
        fence: Option<(&Fence, f64)>,
    ) -> Report {
        let n = agents.len().min(commands.len());
        let sep = settings.separation;
        self.positions.clear();
        self.positions
            .extend(agents[..n].iter().map(|a| a.side.map(|s| s.pos_m)));
        let top_speed = agents[..n]
            .iter()
            .filter_map(|a| a.side.map(|s| sep.scaled(s.vel_mps).norm()))
            .filter(|v| v.is_finite())
            .fold(0.0, f64::max);
        let radius = look_radius_m(&sep, top_speed, LOOKAHEAD_S);
        let pairs = self
            .sweep
            .pairs_within(&self.positions, sep.vertical_scale(), radius);
        self.rows.clear();
        self.active.clear();
        let mut closest: Option<(usize, usize, f64)> = None;
        let mut broken = false;
        for &(i, j) in pairs {
            let (a, b) = (&agents[i], &agents[j]);
            let (Some(si), Some(sj)) = (a.side, b.side) else {
                continue;
            };
            let d = sep.distance_m(si.pos_m, sj.pos_m);
            if closest.is_none_or(|c| d < c.2) {
                closest = Some((i, j, d));
            }
            if !(a.controlled || b.controlled) {
                continue;
            }
            let authority = braking(a) + braking(b);
            let Some(row) = pair_row(&sep, &si, &sj, authority, settings.age_s) else {
                continue;
            };
            // A row no command inside the envelopes can reach never binds.
            let reach = limit(a) + limit(b);
            if !row.b.is_finite() || row.b <= -reach - 1.0 {
                continue;
            }
            let row = Row { i, j, row };
            broken |= row.lhs(agents, commands) < row.row.b;
            self.rows.push(row);
        }
        if let Some((fence, margin_m)) = fence {
            for (i, a) in agents[..n].iter().enumerate() {
                let Some(side) = a.side.filter(|_| a.controlled) else {
                    continue;
                };
                if fence.horizontal_margin_m(side.pos_m.xy()) > radius + margin_m {
                    continue;
                }
                let Some(row) = fence::fence_row(
                    fence,
                    margin_m,
                    &side,
                    braking(a),
                    settings.age_s,
                    sep.gamma,
                ) else {
                    continue;
                };
                if !row.b.is_finite() || row.b <= -limit(a) - 1.0 {
                    continue;
                }
                let row = Row { i, j: i, row };
                broken |= row.lhs(agents, commands) < row.row.b;
                self.rows.push(row);
            }
        }
        if !broken {
            return Report {
                outcome: Outcome::Untouched,
                rows: self.rows.len(),
                active: 0,
                closest,
            };
        }
        if let Some(relaxed) = self.solve_in_pieces(settings, agents, &mut commands[..n]) {
            let outcome = Outcome::Filtered {
                sum_kept: settings.keep_weighted_sum,
                relaxed,
            };
            return self.report(agents, commands, outcome, closest);
        }
        self.index_variables(agents, n, settings.keep_weighted_sum);
        let all: Vec<usize> = (0..self.rows.len()).collect();
        let (vars, var_of) = (
            std::mem::take(&mut self.vars),
            std::mem::take(&mut self.var_of),
        );
        let solved = self.solve(settings, agents, commands, &all, &vars, &var_of, true);
        let outcome = match solved {
            Ok(relaxed) => Outcome::Filtered {
                sum_kept: settings.keep_weighted_sum,
                relaxed,
            },
            Err(_) if settings.keep_weighted_sum => {
                match self.solve(settings, agents, commands, &all, &vars, &var_of, false) {
                    Ok(relaxed) => Outcome::Filtered {
                        sum_kept: false,
                        relaxed,
                    },
                    Err(reason) => {
                        self.brake(agents, commands, &vars);
                        Outcome::Fallback { reason }
                    }
                }
            }
            Err(reason) => {
                self.brake(agents, commands, &vars);
                Outcome::Fallback { reason }
            }
        };
        (self.vars, self.var_of) = (vars, var_of);
        self.report(agents, commands, outcome, closest)
    }

    /// The report of a filtered tick, with the rows left active.
    fn report(
        &mut self,
        agents: &[Agent],
        commands: &[Vector2<f64>],
        outcome: Outcome,
        closest: Option<(usize, usize, f64)>,
    ) -> Report {
        self.active.extend(
            self.rows
                .iter()
                .filter(|r| r.lhs(agents, commands) - r.row.b < ACTIVE_SLACK_MPS2)
                .map(|r| (r.i, r.j)),
        );
        let active = self.active.len();
        Report {
            outcome,
            rows: self.rows.len(),
            active,
            closest,
        }
    }

    /// The rows the last call's commands meet with (almost) nothing to spare, as the
    /// agents' indices `(i, j)`; `i == j` for a vehicle's row against the fence.
    pub fn active_rows(&self) -> &[(usize, usize)] {
        &self.active
    }

    /// The pairs of the last call closer than `distance_m` (scaled), with their distance:
    /// every pair with a vehicle the filter commands that was near enough for a row.
    pub fn close_pairs(&self, distance_m: f64) -> impl Iterator<Item = (usize, usize, f64)> + '_ {
        self.rows
            .iter()
            .filter(move |r| !r.single() && r.row.distance_m < distance_m)
            .map(|r| (r.i, r.j, r.row.distance_m))
    }

    /// The controlled agents of the rows, each given a variable index.
    ///
    /// A one-vehicle row (the fence) changes `Σ wᵢuᵢ`, which only other vehicles can give
    /// back: when the sum is kept, every vehicle the filter commands is then a variable.
    fn index_variables(&mut self, agents: &[Agent], n: usize, keep_sum: bool) {
        self.var_of.clear();
        self.var_of.resize(n, None);
        self.vars.clear();
        // A row with one commanded vehicle (the fence, or a neighbour the filter does not
        // command) changes Σ wᵢuᵢ, which only the others can give back.
        let everyone = keep_sum && self.rows.iter().any(|r| !two_sided(agents, r));
        let rows = self.rows.iter().flat_map(|r| [r.i, r.j]);
        let all = (0..n).filter(|_| everyone);
        for k in rows.chain(all) {
            if agents[k].controlled && self.var_of[k].is_none() {
                self.var_of[k] = Some(self.vars.len());
                self.vars.push(k);
            }
        }
    }

    /// One QP over the variables; writes the commands when solved and says whether a
    /// row had to be relaxed (its slack used).
    #[allow(clippy::too_many_arguments)]
    fn solve(
        &self,
        settings: &Settings,
        agents: &[Agent],
        commands: &mut [Vector2<f64>],
        rows: &[usize],
        vars: &[usize],
        var_of: &[Option<usize>],
        with_sum: bool,
    ) -> Result<bool, &'static str> {
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
        let time_limit = if settings.time_limit_s.is_finite() && settings.time_limit_s > 0.0 {
            settings.time_limit_s
        } else {
            f64::INFINITY
        };
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
    fn solve_in_pieces(
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
                    &rows,
                    &vars,
                    &var_of,
                    keeps_own_sum,
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

    /// The fallback, the manoeuvre the barrier counts on: every vehicle of the problem
    /// accelerates at its share of the authority away from the vehicles of its rows (the
    /// sum of their directions), or, where those cancel, brakes along its velocity; inside
    /// its disc.
    fn brake(&self, agents: &[Agent], commands: &mut [Vector2<f64>], vars: &[usize]) {
        for &k in vars {
            let a = &agents[k];
            let away: Vector2<f64> = self
                .rows
                .iter()
                .map(|r| {
                    if r.i == k {
                        r.row.a
                    } else if r.j == k && !r.single() {
                        -r.row.a
                    } else {
                        Vector2::zeros()
                    }
                })
                .sum();
            let v = a.side.map_or(Vector2::zeros(), |s| s.vel_mps.xy());
            let speed = v.norm();
            let net = if away.norm() > 1e-6 {
                away / away.norm() * braking(a)
            } else if speed > 1e-6 {
                // Stop in no less than 0.5 s: no overshoot of zero speed in one tick.
                -v / speed * braking(a).min(speed / 0.5)
            } else {
                Vector2::zeros()
            };
            let mut command = net + a.drift_mps2;
            let cap = limit(a);
            if command.norm() > cap {
                command *= cap / command.norm();
            }
            commands[k] = if command.iter().all(|x| x.is_finite()) {
                command
            } else {
                Vector2::zeros()
            };
        }
    }
}

/// A row with both vehicles commanded (not the fence's, not against one the filter does
/// not command).
fn two_sided(agents: &[Agent], r: &Row) -> bool {
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

fn braking(a: &Agent) -> f64 {
    if a.controlled && a.braking_mps2.is_finite() {
        a.braking_mps2.max(0.0)
    } else {
        0.0
    }
}

fn limit(a: &Agent) -> f64 {
    if a.controlled && a.limit_mps2.is_finite() {
        a.limit_mps2.max(0.0)
    } else {
        0.0
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

#[cfg(test)]
mod tests;
