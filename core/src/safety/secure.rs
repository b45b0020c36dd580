//! The safe answer when the filter's time runs out: every vehicle whose command, held for
//! the tick and followed by braking, would bring it within the separation of a
//! neighbour's plan brakes instead ([`super::stopping`]), until no pair of the rows
//! conflicts. Braking is always such an answer, so this needs no optimum and costs one
//! check per row and per row of a vehicle that turned to braking.

use nalgebra::Vector2;

use super::stopping::{First, Plan, Timing, closest_m, path_m};
use super::{Agent, SafetyFilter, Settings, braking, command_for, limit};

/// What securing an answer did.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(super) struct Secured {
    /// Vehicles turned to braking.
    pub(super) braked: usize,
    /// Pairs that conflict even with both braking (the separation was already lost to
    /// what braking can do).
    pub(super) unresolved: usize,
}

impl SafetyFilter {
    /// Makes `commands` safe by the stopping check over the pairs of this call's rows.
    pub(super) fn secure(
        &mut self,
        settings: &Settings,
        agents: &[Agent],
        commands: &mut [Vector2<f64>],
    ) -> Secured {
        let n = agents.len().min(commands.len());
        let sep = settings.separation;
        let hold_s = settings.period_s.clamp(0.0, settings.age_s.max(0.0));
        let timing = Timing {
            delay_s: settings.age_s.max(0.0) - hold_s,
            hold_s,
        };
        self.plans.clear();
        self.paths.clear();
        for (k, (a, u)) in agents[..n].iter().zip(&commands[..n]).enumerate() {
            let plan = a.side.and_then(|side| {
                let pos = sep.scaled(side.pos_m);
                let vel = sep.scaled(side.vel_mps);
                let ok = pos.iter().chain(vel.iter()).all(|x| x.is_finite());
                let net = if a.controlled {
                    u - a.drift_mps2
                } else {
                    Vector2::zeros()
                };
                // The command on its way: the last call's, when it had one.
                let before = self.last_net.get(k).copied().flatten().unwrap_or(net);
                ok.then_some(Plan {
                    pos_m: pos,
                    vel_mps: vel.xy(),
                    vz_mps: vel.z,
                    before_mps2: if a.controlled { before } else { net },
                    first: First::Command(net),
                    braking_mps2: braking(a),
                })
            });
            self.paths
                .push(plan.map_or(f64::INFINITY, |p| path_m(&p, timing)));
            self.plans.push(plan);
        }
        // Each vehicle's pairs, as a list of neighbours by vehicle.
        self.neighbour_start.clear();
        self.neighbour_start.resize(n + 1, 0);
        for r in self.rows.iter().filter(|r| !r.single()) {
            self.neighbour_start[r.i + 1] += 1;
            self.neighbour_start[r.j + 1] += 1;
        }
        for k in 0..n {
            self.neighbour_start[k + 1] += self.neighbour_start[k];
        }
        self.neighbours.clear();
        self.neighbours.resize(self.neighbour_start[n], 0);
        self.fill.clear();
        self.fill.extend_from_slice(&self.neighbour_start[..n]);
        for r in self.rows.iter().filter(|r| !r.single()) {
            self.neighbours[self.fill[r.i]] = r.j;
            self.fill[r.i] += 1;
            self.neighbours[self.fill[r.j]] = r.i;
            self.fill[r.j] += 1;
        }
        // The distance a pair must keep: the separation and what the two can move apart
        // from what is known in the age of it.
        let delay_s = timing.delay_s;
        let keep = |i: usize, j: usize| {
            sep.horizontal_m + 0.5 * (limit(&agents[i]) + limit(&agents[j])) * delay_s * delay_s
        };
        // Whether a pair's plans conflict; a pair further apart than both can go does not.
        let conflict = |plans: &[Option<Plan>], paths: &[f64], i: usize, j: usize| {
            let (Some(a), Some(b)) = (plans[i], plans[j]) else {
                return false;
            };
            let keep = keep(i, j);
            if (a.pos_m - b.pos_m).norm() - paths[i] - paths[j] >= keep {
                return false;
            }
            closest_m(&a, &b, timing) < keep
        };
        let mut out = Secured::default();
        self.queue.clear();
        for r in self.rows.iter().filter(|r| !r.single()) {
            if !conflict(&self.plans, &self.paths, r.i, r.j) {
                continue;
            }
            for k in [r.i, r.j] {
                if agents[k].controlled
                    && let Some(p) = self.plans[k].as_mut()
                    && p.first != First::Brake
                {
                    p.first = First::Brake;
                    self.paths[k] = path_m(p, timing);
                    self.queue.push(k);
                }
            }
        }
        // A vehicle turned to braking changes its pairs' checks: its neighbours are
        // checked again against it.
        // A pair that still conflicts once both brake (or one is not ours) is counted
        // when the later of its braking vehicles is checked.
        self.done.clear();
        self.done.resize(n, false);
        while let Some(k) = self.queue.pop() {
            out.braked += 1;
            self.done[k] = true;
            for s in self.neighbour_start[k]..self.neighbour_start[k + 1] {
                let m = self.neighbours[s];
                if !conflict(&self.plans, &self.paths, k, m) {
                    continue;
                }
                if agents[m].controlled
                    && let Some(p) = self.plans[m].as_mut()
                    && p.first != First::Brake
                {
                    p.first = First::Brake;
                    self.paths[m] = path_m(p, timing);
                    self.queue.push(m);
                } else if self.done[m] || !agents[m].controlled {
                    out.unresolved += 1;
                }
            }
        }
        for k in 0..n {
            let Some(p) = self.plans[k].filter(|p| p.first == First::Brake) else {
                continue;
            };
            let a = &agents[k];
            let speed = p.vel_mps.norm();
            // Braking along the velocity, no further than to rest within the hold.
            let net = if speed > 0.0 {
                -p.vel_mps / speed * braking(a).min(speed / hold_s.max(1e-3))
            } else {
                Vector2::zeros()
            };
            if let Some(command) = command_for(a, net) {
                commands[k] = command;
            }
        }
        out
    }
}
