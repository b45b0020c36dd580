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
mod dual;
mod exact;
pub mod fence;
pub mod flow;
pub mod jam;
pub mod landing;
pub mod layers;
pub mod lost;
pub mod neighbours;
mod on_way;
mod pieces;
pub mod reach;
mod secure;
pub mod stop_rows;
pub mod stopping;

use std::time::{Duration, Instant};

use nalgebra::{Vector2, Vector3};

use pieces::two_sided;

pub use barrier::{PairRow, Separation, Side, pair_row, pair_row_spread};
pub use fence::{Fence, FenceItem, FenceItemKind, FenceShape, fence_row, stop_point_m};
pub use neighbours::{Found, Sweep};
pub use reach::ReachBound;
pub use stop_rows::StopRows;

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

/// The least share of the time limit left to the stopping check after the solve.
pub const SECURE_SHARE: f64 = 0.25;
/// The most share of the time limit left to the stopping check after the solve.
pub const MAX_SECURE_SHARE: f64 = 0.6;
/// The check is given its last duration times this.
pub const CHECK_ROOM: f64 = 1.5;
/// The share of the time limit by which the check ends: past it every vehicle brakes.
pub const CHECK_END_SHARE: f64 = 0.9;

/// What a stopping row keeps beyond the stopping check's distance (m): the bend of the
/// pair's path while the commands act, and rounding.
pub const STOP_ROW_MARGIN_M: f64 = 0.005;

/// A barrier row counts as active when the command leaves less slack than this (m/s²).
pub const ACTIVE_SLACK_MPS2: f64 = 1e-6;
/// Rounds of the piecewise solve (rows an answer breaks join the pieces) before the
/// whole problem is solved at once.
pub const PIECE_ROUNDS: usize = 4;
/// The most sweeps of the dual ascent on one piece ([`dual`]) without a time limit
/// (lockstep): a piece it does not finish is solved by clarabel, so that a lockstep
/// flight flies the optimum and does not depend on the machine. With a time limit the
/// ascent goes on until the limit.
pub const MAX_SWEEPS: usize = 300;
/// The most sweeps with a time limit (a bound that the limit always reaches first).
pub const MAX_SWEEPS_TIMED: usize = 1_000_000;
/// With a time limit, the largest piece (variables) solved by clarabel when the dual
/// ascent did not finish it and time is left.
pub const EXACT_MAX_VARS: usize = 32;

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
    /// The time constant of the lag through which its acceleration follows its commands
    /// (s; 0: after a pure delay), its attitude response's. Counted inside the age as a
    /// delay; its state already shows part of the commands it is still following
    /// ([`on_way`]).
    pub lag_s: f64,
    /// How far it may be from its side's position (m, scaled; 0 for a measured state):
    /// a vehicle whose state stopped arriving is a chain of points along the path it may
    /// take until its own Hold has stopped it ([`lost`]), each standing for the stretch
    /// of that path within this of it. Every pair with it keeps this much more than the
    /// separation. An agent with a spread stands for where a vehicle may be, not for a
    /// state: it is left out of the closest pair, the close pairs and the active rows.
    pub spread_m: f64,
    /// How fast its reported position may move beyond what its reported velocity says
    /// (m/s, ≥ 0; [`crate::control::UnseenMotion`]): every pair with it is taken to
    /// close this much faster than its velocities show, in its closing rate and in how
    /// far it closes during the age.
    pub unseen_mps: f64,
}

impl Agent {
    /// A point of where a vehicle may be ([`Self::spread_m`]): at rest, not commanded,
    /// `spread_m` around `pos_m` (m, ENU).
    pub fn bound(pos_m: Vector3<f64>, spread_m: f64) -> Self {
        Self {
            side: Some(Side {
                pos_m,
                vel_mps: Vector3::zeros(),
                accel_z_mps2: 0.0,
            }),
            controlled: false,
            weight: 1.0,
            drift_mps2: Vector2::zeros(),
            limit_mps2: 0.0,
            braking_mps2: 0.0,
            lag_s: 0.0,
            spread_m,
            unseen_mps: 0.0,
        }
    }

    /// Whether it is a measured state (no spread): counted in the closest pair, the close
    /// pairs and the active rows.
    pub fn measured(&self) -> bool {
        self.spread() <= 0.0
    }

    /// Its unseen speed (m/s; one that is not a positive number counts as none).
    pub(crate) fn unseen(&self) -> f64 {
        positive_or_zero(self.unseen_mps)
    }

    /// Its spread, as a distance to keep (m; a spread that is not a positive number
    /// counts as none).
    fn spread(&self) -> f64 {
        positive_or_zero(self.spread_m)
    }
}

/// `x` when it is a positive number, else 0.
fn positive_or_zero(x: f64) -> f64 {
    if x.is_finite() { x.max(0.0) } else { 0.0 }
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
    /// The time limit ended a piece's solve before its answer: the ascent's answer so
    /// far, secured by the stopping check ([`stopping`]): every vehicle whose command
    /// and then braking would come within the separation of a neighbour's plan brakes
    /// instead. The braked vehicles no longer keep `Σ wᵢuᵢ`.
    Unfinished {
        /// The most a row of the ascent's answer was missed by (m/s²).
        missed_mps2: f64,
        /// Vehicles turned to braking by the check.
        braked: usize,
        /// Pairs that conflict even braking (already closer than braking can keep).
        unresolved: usize,
    },
}

/// Which row keeps each pair apart.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Rows {
    /// The barrier row ([`barrier`]): each pair counts on braking its relative motion at
    /// the two vehicles' summed braking shares.
    #[default]
    Barrier,
    /// The stopping row ([`stop_rows`]): every vehicle must be able to stop together, at
    /// the pace of the slowest, and stay apart; every tick's answer is checked against
    /// that stop ([`stopping`]) and a vehicle that fails the check brakes instead.
    Stopping,
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
    /// The closest pair of all (indices and scaled distance, m).
    pub closest: Option<(usize, usize, f64)>,
    /// Sweeps of the dual ascent, over every piece.
    pub sweeps: usize,
    /// The most vehicles in one piece solved together (0: none needed a solver).
    pub largest_piece: usize,
    /// How long the call took (wall clock).
    pub elapsed: Duration,
    /// Vehicles the stopping check turned to braking (with [`Rows::Stopping`] on every
    /// tick, otherwise on an unfinished one).
    pub braked: usize,
    /// Pairs that conflict even with both braking.
    pub unresolved: usize,
    /// The check ran out of time and every vehicle braked.
    pub check_out_of_time: bool,
}

/// The filter's settings for one tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Settings {
    /// The separation enforced.
    pub separation: Separation,
    /// How old what is known of the vehicles may be when the command acts (s).
    pub age_s: f64,
    /// How long a command holds before the next can act (s): the control period, at
    /// most `age_s`.
    pub period_s: f64,
    /// Hold `Σ wᵢuᵢ` as an equality (consensus).
    pub keep_weighted_sum: bool,
    /// How long the call may take (s, wall clock; infinite: no limit, only
    /// [`MAX_SWEEPS`]). Past it, no piece starts a solver and one being solved stops with
    /// its answer so far ([`Outcome::Unfinished`]).
    pub time_limit_s: f64,
    /// Which row keeps each pair apart.
    pub rows: Rows,
    /// The velocity the stopping check brakes a vehicle to, with the barrier rows (m/s,
    /// ENU; zero: to rest): the swarm's common velocity while it drifts. Braked to rest,
    /// a vehicle of a block drifting at 1 m/s is run into by the neighbours behind it
    /// that keep flying (a vehicle not flown on our commands, another shard's on a tick
    /// its own filter finished). Braked to the common velocity it keeps its place among
    /// them, and a pair that both brake is as far apart as braking to rest in the frame
    /// moving at that velocity keeps it. Not finite: zero.
    pub brake_to_mps: Vector2<f64>,
}

impl Settings {
    /// When a new command acts (after the age less a period) and how long it holds (a
    /// period, at most the age).
    pub fn timing(&self) -> stopping::Timing {
        let hold_s = self.period_s.clamp(0.0, self.age_s.max(0.0));
        stopping::Timing {
            delay_s: self.age_s.max(0.0) - hold_s,
            hold_s,
        }
    }
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
    sweep: flow::FlowSweep,
    positions: Vec<Option<Vector3<f64>>>,
    /// Whether each agent of the last call is a measured state ([`Agent::measured`]).
    measured: Vec<bool>,
    velocities: Vec<Option<Vector3<f64>>>,
    rows: Vec<Row>,
    var_of: Vec<Option<usize>>,
    vars: Vec<usize>,
    /// The rows of the last call the filtered commands meet with less than
    /// `ACTIVE_SLACK_MPS2` to spare, as `(i, j)` (`i == j`: the fence).
    active: Vec<(usize, usize)>,
    /// Each row's multiplier (parallel to `rows`), warm-started from the last call.
    lambda: Vec<f64>,
    /// The last call's non-zero multipliers by pair `(i, j)`, sorted: the warm start.
    warm: Vec<((usize, usize), f64)>,
    piece: dual::DualPiece,
    dual: dual::DualState,
    /// Each agent's direction away from its rows (the fallback's buffer).
    away: Vec<Vector2<f64>>,
    /// The stopping check's buffers ([`secure`]): each vehicle's plan, its neighbours
    /// (`neighbours[neighbour_start[k]..neighbour_start[k + 1]]`), and the vehicles
    /// turned to braking still to be checked against theirs.
    plans: Vec<Option<stopping::Plan>>,
    motions: Vec<Option<stopping::Motion>>,
    paths: Vec<f64>,
    /// Each vehicle's net commands of the last calls: the commands on their way when the
    /// next is checked.
    on_way: on_way::OnWay,
    /// This call's accelerations on their way, over each half of the delay (m/s²).
    before: Vec<[Vector2<f64>; 2]>,
    neighbour_start: Vec<usize>,
    neighbours: Vec<usize>,
    fill: Vec<usize>,
    queue: Vec<usize>,
    done: Vec<bool>,
    /// This call's synchronised stop (`None`: barrier rows, or no stop).
    stop: Option<StopRows>,
    /// The last stopping check's common stop time (s; `None`: no check last call).
    last_stop_s: Option<f64>,
    /// How long the last stopping check took (s, wall clock).
    last_check_s: f64,
    /// Each vehicle's braking (m/s²) when the last check turned it to braking: braking on
    /// continues at that rate, the tail of the plan that check passed.
    committed: Vec<Option<f64>>,
    /// When this call must be done (`None`: no wall-clock limit).
    deadline: Option<Instant>,
    tally: Tally,
    /// Solve every problem at once, never piece by piece (for comparing the two).
    #[cfg(test)]
    pub(crate) whole_only: bool,
    /// Solve every piece with clarabel, never by dual ascent (for comparing the two).
    #[cfg(test)]
    pub(crate) exact_only: bool,
}

/// One QP of the filter: its rows and variables (indices into the rows and the agents),
/// each agent's variable, and whether `Σ wᵢuᵢ` is held.
#[derive(Debug, Clone, Copy)]
struct Piece<'a> {
    rows: &'a [usize],
    vars: &'a [usize],
    var_of: &'a [Option<usize>],
    with_sum: bool,
}

/// One call's count of the solver's work.
#[derive(Debug, Clone, Copy, Default)]
struct Tally {
    sweeps: usize,
    largest_piece: usize,
    unfinished: bool,
    missed_mps2: f64,
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
        let started = Instant::now();
        // The solve stops early enough to leave the stopping check its share: what the
        // last check took with room to spare, within bounds. The check itself ends by
        // the limit's last few per cent.
        let limit_s = settings.time_limit_s;
        let timed = limit_s.is_finite() && limit_s >= 0.0;
        let reserve_s = (CHECK_ROOM * self.last_check_s)
            .clamp(SECURE_SHARE * limit_s, MAX_SECURE_SHARE * limit_s);
        self.deadline = timed.then(|| started + Duration::from_secs_f64(limit_s - reserve_s));
        let check_deadline =
            timed.then(|| started + Duration::from_secs_f64(CHECK_END_SHARE * limit_s));
        self.tally = Tally::default();
        let mut report = self.filter_rows(settings, agents, commands, fence);
        self.warm.clear();
        self.warm.extend(
            self.rows
                .iter()
                .zip(&self.lambda)
                .filter(|(_, l)| **l > 0.0)
                .map(|(r, l)| ((r.i, r.j), *l)),
        );
        self.warm.sort_unstable_by_key(|w| w.0);
        let unfinished =
            self.tally.unfinished && matches!(report.outcome, Outcome::Filtered { .. });
        let every_tick = self.stop.is_some() && !self.rows.is_empty();
        let checked = unfinished || every_tick;
        if !checked {
            self.committed.clear();
        }
        if checked {
            let check_started = Instant::now();
            let secured = self.secure(settings, agents, commands, check_deadline);
            self.last_check_s = check_started.elapsed().as_secs_f64();
            report.braked = secured.braked;
            report.unresolved = secured.unresolved;
            report.check_out_of_time = secured.out_of_time;
            if unfinished {
                report.outcome = Outcome::Unfinished {
                    missed_mps2: self.tally.missed_mps2,
                    braked: secured.braked,
                    unresolved: secured.unresolved,
                };
            }
        }
        self.last_stop_s = self.stop.filter(|_| checked).map(|s| s.stop_s);
        self.on_way.record(
            agents
                .iter()
                .zip(commands.iter())
                .map(|(a, u)| a.controlled.then(|| u - a.drift_mps2)),
        );
        report.sweeps = self.tally.sweeps;
        report.largest_piece = self.tally.largest_piece;
        report.elapsed = started.elapsed();
        report
    }

    /// The call's work: the rows, and the answer when one is broken.
    fn filter_rows(
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
        self.measured.clear();
        self.measured
            .extend(agents[..n].iter().map(Agent::measured));
        let top_speed = agents[..n]
            .iter()
            .filter_map(|a| a.side.map(|s| sep.scaled(s.vel_mps).norm()))
            .filter(|v| v.is_finite())
            .fold(0.0, f64::max);
        // Two spreads at most between any pair.
        let widest_spread = agents[..n].iter().map(Agent::spread).fold(0.0, f64::max);
        let radius = look_radius_m(&sep, top_speed, LOOKAHEAD_S) + 2.0 * widest_spread;
        // With the stopping rows, what each vehicle's commands on their way still do.
        let timing = settings.timing();
        self.before.clear();
        if settings.rows == Rows::Stopping {
            self.before
                .extend((0..n).map(|k| self.on_way.halves(k, timing, agents[k].lag_s)));
        }
        self.stop = match settings.rows {
            Rows::Barrier => None,
            Rows::Stopping => StopRows::new(
                &agents[..n],
                &self.before,
                (self.last_stop_s, &self.committed),
                timing,
            ),
        };
        // A pair is looked at as far as a row of it can bind at its own relative speed,
        // never beyond the look-ahead radius: what the radius finds that can bind is found.
        let bound = ReachBound::new(&sep, settings.age_s, &agents[..n]);
        let stop = self.stop;
        let pair_limit = |v: f64| match (stop, bound) {
            (Some(stop), _) => stop.distance_m(sep.horizontal_m + STOP_ROW_MARGIN_M, v),
            (None, Some(b)) => b.distance_m(v),
            (None, None) => f64::INFINITY,
        };
        self.velocities.clear();
        self.velocities
            .extend(agents[..n].iter().map(|a| a.side.map(|s| s.vel_mps)));
        let mut sweep = std::mem::take(&mut self.sweep);
        let found = sweep.sweep(
            &self.positions,
            &self.velocities,
            sep.vertical_scale(),
            pair_limit,
            radius,
            2.0 * pair_limit(0.0),
        );
        let mut closest = found.closest;
        self.rows.clear();
        self.lambda.clear();
        self.active.clear();
        let mut broken = false;
        for &(i, j) in found.pairs {
            let (a, b) = (&agents[i], &agents[j]);
            let (Some(si), Some(sj)) = (a.side, b.side) else {
                continue;
            };
            if !(a.controlled || b.controlled) {
                continue;
            }
            let row = if let Some(stop) = stop {
                // The check's distance and a little more: an answer that meets the row
                // passes the check.
                let keep = secure::keep_m(&sep, (a, b), stop.timing, true) + STOP_ROW_MARGIN_M;
                stop.row(&sep, (a, self.before[i]), (b, self.before[j]), keep)
            } else {
                pair_row_spread(
                    &sep,
                    &si,
                    &sj,
                    braking(a) + braking(b),
                    settings.age_s,
                    a.spread() + b.spread(),
                    a.unseen() + b.unseen(),
                )
            };
            let Some(row) = row else {
                continue;
            };
            // A row no command inside the envelopes can reach never binds; with the
            // stopping rows its pair is still checked (braking may bring it closer).
            let reach = limit(a) + limit(b);
            if !row.b.is_finite() || (row.b <= -reach - 1.0 && stop.is_none()) {
                continue;
            }
            let row = Row { i, j, row };
            broken |= row.lhs(agents, commands) < row.row.b;
            self.push_row(row);
        }
        if self.measured.contains(&false) {
            // The closest pair of the measured states alone.
            for (p, measured) in self.positions.iter_mut().zip(&self.measured) {
                if !measured {
                    *p = None;
                }
            }
            closest = sweep
                .sweep(
                    &self.positions,
                    &[],
                    sep.vertical_scale(),
                    |_| 0.0,
                    0.0,
                    radius,
                )
                .closest;
        }
        self.sweep = sweep;
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
                self.push_row(row);
            }
        }
        if !broken {
            return Report {
                outcome: Outcome::Untouched,
                rows: self.rows.len(),
                active: 0,
                closest,
                sweeps: 0,
                largest_piece: 0,
                elapsed: Duration::ZERO,
                braked: 0,
                unresolved: 0,
                check_out_of_time: false,
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
        let whole = |with_sum| Piece {
            rows: &all,
            vars: &vars,
            var_of: &var_of,
            with_sum,
        };
        let solved = self.solve(settings, agents, commands, whole(true));
        let outcome = match solved {
            Ok(relaxed) => Outcome::Filtered {
                sum_kept: settings.keep_weighted_sum,
                relaxed,
            },
            Err(_) if settings.keep_weighted_sum => {
                match self.solve(settings, agents, commands, whole(false)) {
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
                .filter(|r| self.measured[r.i] && self.measured[r.j])
                .filter(|r| r.lhs(agents, commands) - r.row.b < ACTIVE_SLACK_MPS2)
                .map(|r| (r.i, r.j)),
        );
        let active = self.active.len();
        Report {
            outcome,
            rows: self.rows.len(),
            active,
            closest,
            sweeps: 0,
            largest_piece: 0,
            elapsed: Duration::ZERO,
            braked: 0,
            unresolved: 0,
            check_out_of_time: false,
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
            .filter(move |r| !r.single() && self.measured[r.i] && self.measured[r.j])
            .filter(move |r| r.row.distance_m < distance_m)
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

    /// A row, with its multiplier from the last call (0 when it had none).
    fn push_row(&mut self, row: Row) {
        let key = (row.i, row.j);
        let warm = self
            .warm
            .binary_search_by_key(&key, |w| w.0)
            .map_or(0.0, |k| self.warm[k].1);
        self.rows.push(row);
        self.lambda.push(warm);
    }

    /// The wall-clock time left of the call (s; infinite without a limit).
    fn time_left_s(&self) -> f64 {
        self.deadline.map_or(f64::INFINITY, |d| {
            d.saturating_duration_since(Instant::now()).as_secs_f64()
        })
    }

    /// One piece's QP over its variables: writes the commands and says whether a row had
    /// to be relaxed (its slack used). The dual ascent first ([`dual`]); when it does not
    /// finish, clarabel without a time limit, or for a small piece with time left;
    /// otherwise the ascent's answer so far ([`Outcome::Unfinished`]).
    fn solve(
        &mut self,
        settings: &Settings,
        agents: &[Agent],
        commands: &mut [Vector2<f64>],
        piece: Piece<'_>,
    ) -> Result<bool, &'static str> {
        let Piece { rows, vars, .. } = piece;
        self.tally.largest_piece = self.tally.largest_piece.max(vars.len());
        #[cfg(test)]
        if self.exact_only {
            return self.solve_exact(settings, agents, commands, piece);
        }
        if let Some(relaxed) = self.solve_dual(settings, agents, commands, piece) {
            return Ok(relaxed);
        }
        let time_left = self.time_left_s();
        if self.deadline.is_none() || (vars.len() <= EXACT_MAX_VARS && time_left > 0.0) {
            return self.solve_exact(settings, agents, commands, piece);
        }
        self.tally.unfinished = true;
        self.write_ascent(agents, commands, vars);
        let missed = rows
            .iter()
            .map(|&r| &self.rows[r])
            .map(|r| r.row.b.min(reach_of(agents, r) + 1.0) - r.lhs(agents, commands))
            .fold(0.0f64, f64::max);
        self.tally.missed_mps2 = self.tally.missed_mps2.max(missed);
        Ok(false)
    }

    /// The ascent's commands written for the piece's variables, each inside its disc (the
    /// ascent leaves them at most its tolerance outside).
    fn write_ascent(&self, agents: &[Agent], commands: &mut [Vector2<f64>], vars: &[usize]) {
        for (&u, &k) in self.dual.u.iter().zip(vars) {
            let cap = limit(&agents[k]);
            commands[k] = if u.norm() > cap {
                u * (cap / u.norm())
            } else {
                u
            };
        }
    }

    /// The piece's QP by dual ascent, warm-started from the rows' multipliers; `None`
    /// (commands untouched) when it stopped before converging.
    fn solve_dual(
        &mut self,
        settings: &Settings,
        agents: &[Agent],
        commands: &mut [Vector2<f64>],
        piece: Piece<'_>,
    ) -> Option<bool> {
        let Piece {
            rows,
            vars,
            var_of,
            with_sum,
        } = piece;
        let weight = |k: usize| agents[k].weight.max(1e-9);
        let piece = &mut self.piece;
        piece.weight.clear();
        piece.limit.clear();
        piece.given.clear();
        for &k in vars {
            piece.weight.push(weight(k));
            piece.limit.push(limit(&agents[k]));
            piece.given.push(commands[k]);
        }
        piece.rows.clear();
        for r in rows.iter().map(|&k| &self.rows[k]) {
            // a·(netᵢ − netⱼ) ≥ b with net = u − drift for a commanded vehicle (a
            // variable) and 0 otherwise; a bound beyond the two discs clipped as in
            // `solve_exact`.
            let mut c = r.row.b.min(reach_of(agents, r) + 1.0);
            let mut sides = [(0, 0.0); 2];
            let mut count = 0;
            let ends: &[(usize, f64)] = if r.single() {
                &[(r.i, 1.0)]
            } else {
                &[(r.i, 1.0), (r.j, -1.0)]
            };
            for &(k, sign) in ends {
                if let Some(v) = var_of[k] {
                    sides[count] = (v, sign);
                    count += 1;
                    c += sign * r.row.a.dot(&agents[k].drift_mps2);
                }
            }
            if count > 0 {
                piece.rows.push(dual::DualRow {
                    sides,
                    two: count == 2,
                    a: r.row.a,
                    c,
                });
            }
        }
        piece.keep_sum = with_sum && settings.keep_weighted_sum;
        piece.rho = SLACK_COST * vars.iter().map(|&k| weight(k)).fold(1.0, f64::max);
        self.dual.lambda.clear();
        self.dual.lambda.extend(
            rows.iter()
                .filter(|&&k| piece_has_side(&self.rows[k], var_of))
                .map(|&k| self.lambda[k]),
        );
        let deadline = self.deadline;
        let max_sweeps = if deadline.is_some() {
            MAX_SWEEPS_TIMED
        } else {
            MAX_SWEEPS
        };
        let end = dual::ascend(&self.piece, &mut self.dual, max_sweeps, || {
            deadline.is_some_and(|d| Instant::now() >= d)
        });
        let used = rows
            .iter()
            .filter(|&&k| piece_has_side(&self.rows[k], var_of));
        for (&k, &l) in used.zip(&self.dual.lambda) {
            self.lambda[k] = l;
        }
        let sweeps = match end {
            dual::DualEnd::Converged { sweeps } | dual::DualEnd::Stopped { sweeps } => sweeps,
        };
        self.tally.sweeps += sweeps;
        if !matches!(end, dual::DualEnd::Converged { .. }) {
            return None;
        }
        self.write_ascent(agents, commands, vars);
        // A row is relaxed when the commands miss it by more than the ascent's tolerance
        // allows for.
        let largest = self.piece.rows.iter().fold(0.0f64, |m, r| m.max(r.c.abs()));
        let tolerance = 1e-6 * (1.0 + largest);
        Some(
            rows.iter()
                .map(|&k| &self.rows[k])
                .any(|r| r.lhs(agents, commands) < r.row.b - tolerance),
        )
    }

    /// The fallback, the manoeuvre the barrier counts on: every vehicle of the problem
    /// accelerates at its share of the authority away from the vehicles of its rows (the
    /// sum of their directions), or, where those cancel, brakes along its velocity; inside
    /// its disc.
    fn brake(&mut self, agents: &[Agent], commands: &mut [Vector2<f64>], vars: &[usize]) {
        self.away.clear();
        self.away.resize(agents.len(), Vector2::zeros());
        for r in &self.rows {
            self.away[r.i] += r.row.a;
            if !r.single() {
                self.away[r.j] -= r.row.a;
            }
        }
        for &k in vars {
            let a = &agents[k];
            let away = self.away[k];
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
            commands[k] = command_for(a, net).unwrap_or_else(Vector2::zeros);
        }
    }
}

/// The command that gives `a` the net acceleration `net` (m/s²): the drift added back,
/// inside its disc; `None` when it is not a number.
fn command_for(a: &Agent, net: Vector2<f64>) -> Option<Vector2<f64>> {
    let mut command = net + a.drift_mps2;
    let cap = limit(a);
    if command.norm() > cap {
        command *= cap / command.norm();
    }
    command.iter().all(|x| x.is_finite()).then_some(command)
}

/// What the discs of a row's vehicles can give it at most (m/s²).
fn reach_of(agents: &[Agent], r: &Row) -> f64 {
    if r.single() {
        limit(&agents[r.i])
    } else {
        limit(&agents[r.i]) + limit(&agents[r.j])
    }
}

/// Whether a row has a variable of the piece on some side.
fn piece_has_side(r: &Row, var_of: &[Option<usize>]) -> bool {
    var_of[r.i].is_some() || (!r.single() && var_of[r.j].is_some())
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

#[cfg(test)]
mod tests;
