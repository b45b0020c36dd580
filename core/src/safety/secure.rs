//! The stopping check: every vehicle whose command, held for the tick and followed by
//! braking, would bring it within the separation of a neighbour's plan brakes instead
//! ([`super::stopping`]), until no pair of the rows conflicts. Braking is always such an
//! answer, so this needs no optimum and costs one check per row and per row of a vehicle
//! that turned to braking. It secures the answer so far when the filter's time runs out
//! and, with the stopping rows ([`super::stop_rows`]), every tick's answer.

use std::time::Instant;

use nalgebra::Vector2;

use super::stopping::{First, Motion, Plan, Timing, closest_between};
use super::{Agent, Row, SafetyFilter, Separation, Settings, braking, command_for, limit};

/// What securing an answer did.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(super) struct Secured {
    /// Vehicles turned to braking.
    pub(super) braked: usize,
    /// Pairs that conflict even with both braking (the separation was already lost to
    /// what braking can do).
    pub(super) unresolved: usize,
    /// The check ran out of time and every vehicle brakes.
    pub(super) out_of_time: bool,
}

impl SafetyFilter {
    /// Makes `commands` safe by the stopping check over the pairs of this call's rows.
    ///
    /// With the stopping rows every tick is checked and the last check passed every pair,
    /// so two vehicles that both brake from now fly the tails of plans already passed:
    /// such a pair needs no check, and when `deadline` comes before the check is done,
    /// every vehicle brakes (`out_of_time`).
    pub(super) fn secure(
        &mut self,
        settings: &Settings,
        agents: &[Agent],
        commands: &mut [Vector2<f64>],
        deadline: Option<Instant>,
    ) -> Secured {
        let n = agents.len().min(commands.len());
        let sep = settings.separation;
        let timing = settings.timing();
        let hold_s = timing.hold_s;
        // With the stopping rows every vehicle brakes to rest after the common stop time;
        // otherwise each at its own braking share.
        let stops = self.stop.map(|s| Stops {
            command_s: s.stop_s,
            brake_s: self.last_stop_s.unwrap_or(s.stop_s),
        });
        // The plans in the frame that moves at the velocity braked to (the stopping rows
        // plan to rest, and so does their check): a pair's distance at each instant is
        // the same in any such frame, and braking to rest in it is braking to that
        // velocity.
        let frame_mps = Some(settings.brake_to_mps)
            .filter(|v| stops.is_none() && v.iter().all(|x| x.is_finite()))
            .unwrap_or_default();
        self.committed.resize(n, None);
        self.plans.clear();
        self.motions.clear();
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
                // The commands on their way, each for its period (as the stopping rows
                // count them); before any call, this one held for the delay.
                let before = match self.stop {
                    Some(_) => self.before.get(k).copied().unwrap_or_default(),
                    None if self.on_way.known(k) => self.on_way.halves(k, timing, a.lag_s),
                    None => [net; 2],
                };
                let mut plan = Plan {
                    pos_m: pos,
                    vel_mps: vel.xy() - frame_mps,
                    vz_mps: vel.z,
                    before_mps2: if a.controlled { before } else { [net; 2] },
                    first: First::Command(net),
                    braking_mps2: braking(a),
                };
                plan.braking_mps2 = braking_of(&plan, a, timing, stops, None);
                ok.then_some(plan)
            });
            let motion = plan.map(|p| Motion::of(&p, timing));
            self.paths
                .push(motion.map_or(f64::INFINITY, |m| m.path_m()));
            self.plans.push(plan);
            self.motions.push(motion);
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
        let mut out = Secured::default();
        let mut clock = Clock {
            deadline,
            checks: 0,
        };
        self.queue.clear();
        for r in 0..self.rows.len() {
            let Row { i, j, .. } = self.rows[r];
            if i == j {
                continue;
            }
            if clock.out(&mut out) {
                break;
            }
            if !self.conflict(&sep, agents, timing, i, j) {
                continue;
            }
            for k in [i, j] {
                if self.turn_to_braking(agents, timing, stops, k) {
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
                let braking_too = self.plans[m].is_some_and(|p| p.first == First::Brake);
                if stops.is_some() && braking_too && agents[m].controlled {
                    // Both fly the tails of plans the last check passed.
                    continue;
                }
                if clock.out(&mut out) {
                    break;
                }
                if !self.conflict(&sep, agents, timing, k, m) {
                    continue;
                }
                if self.turn_to_braking(agents, timing, stops, m) {
                    self.queue.push(m);
                } else if self.done[m] || !agents[m].controlled {
                    out.unresolved += 1;
                }
            }
            if out.out_of_time {
                break;
            }
        }
        if out.out_of_time {
            // No time to finish: every vehicle brakes, the tail of what the last check
            // passed.
            self.queue.clear();
            out.braked = 0;
            for k in 0..n {
                self.turn_to_braking(agents, timing, stops, k);
                out.braked += usize::from(self.plans[k].is_some_and(|p| p.first == First::Brake));
            }
        }
        for k in 0..n {
            let Some(p) = self.plans[k].filter(|p| p.first == First::Brake) else {
                self.committed[k] = None;
                continue;
            };
            self.committed[k] = Some(p.braking_mps2);
            let a = &agents[k];
            // Braking along the velocity as the plan does (from when the command acts),
            // no further than to rest within the hold (both in the plans' frame).
            let v = p.vel_mps + (p.before_mps2[0] + p.before_mps2[1]) * (0.5 * timing.delay_s);
            let speed = v.norm();
            let net = if speed > 0.0 {
                -v / speed * p.braking_mps2.min(speed / hold_s.max(1e-3))
            } else {
                Vector2::zeros()
            };
            if let Some(command) = command_for(a, net) {
                commands[k] = command;
            }
        }
        out
    }

    /// Whether the plans of `i` and `j` conflict; a pair further apart than both can go
    /// does not.
    fn conflict(
        &self,
        sep: &Separation,
        agents: &[Agent],
        timing: Timing,
        i: usize,
        j: usize,
    ) -> bool {
        let (Some(mut a), Some(mut b), Some(mut ma), Some(mut mb)) = (
            self.plans[i],
            self.plans[j],
            self.motions[i],
            self.motions[j],
        ) else {
            return false;
        };
        let (mut path_a, mut path_b) = (self.paths[i], self.paths[j]);
        // A pair whose positions may close faster than their velocities say (their unseen
        // speeds, [`crate::control::UnseenMotion`]): that speed is taken as the velocity
        // towards the other of the vehicle that brakes harder, which it then brakes away,
        // as the barrier's row counts it.
        let unseen = agents[i].unseen() + agents[j].unseen();
        if unseen > 0.0 && a.braking_mps2.max(b.braking_mps2) > 0.0 {
            if a.braking_mps2 >= b.braking_mps2 {
                a = closing(&a, &b, unseen);
                ma = Motion::of(&a, timing);
                path_a = ma.path_m();
            } else {
                b = closing(&b, &a, unseen);
                mb = Motion::of(&b, timing);
                path_b = mb.path_m();
            }
        }
        let keep = keep_m(sep, (&agents[i], &agents[j]), timing, self.stop.is_some());
        if (a.pos_m - b.pos_m).norm() - path_a - path_b >= keep {
            return false;
        }
        // Rounding of a pair at rest exactly the distance apart is no conflict.
        closest_between((&a, &ma), (&b, &mb)) < keep - 1e-9
    }

    /// Turns vehicle `k` (ours, with a plan, not yet braking) to braking; whether it did.
    fn turn_to_braking(
        &mut self,
        agents: &[Agent],
        timing: Timing,
        stops: Option<Stops>,
        k: usize,
    ) -> bool {
        let a = &agents[k];
        let Some(p) = self.plans[k]
            .as_mut()
            .filter(|p| a.controlled && p.first != First::Brake)
        else {
            return false;
        };
        p.first = First::Brake;
        p.braking_mps2 = braking_of(p, a, timing, stops, self.committed[k]);
        let motion = Motion::of(p, timing);
        self.paths[k] = motion.path_m();
        self.motions[k] = Some(motion);
        true
    }
}

/// `plan` with `speed_mps` more velocity towards `other` (horizontal, scaled frame).
fn closing(plan: &Plan, other: &Plan, speed_mps: f64) -> Plan {
    let towards = (other.pos_m - plan.pos_m).xy();
    let distance = towards.norm();
    let mut out = *plan;
    if distance > 0.0 {
        out.vel_mps += towards * (speed_mps / distance);
    }
    out
}

/// The check's deadline, looked at every few checks.
struct Clock {
    deadline: Option<Instant>,
    checks: usize,
}

impl Clock {
    /// Whether the deadline has passed (noted in `out`).
    fn out(&mut self, out: &mut Secured) -> bool {
        self.checks += 1;
        // The first check looks too, then every 32nd.
        if !out.out_of_time
            && (self.checks - 1).is_multiple_of(32)
            && self.deadline.is_some_and(|d| Instant::now() >= d)
        {
            out.out_of_time = true;
        }
        out.out_of_time
    }
}

/// A check's stop times with the stopping rows (s).
#[derive(Debug, Clone, Copy)]
struct Stops {
    /// After a new command: this tick's common stop time.
    command_s: f64,
    /// Braking from when the command on its way ends: the last check's, under which
    /// braking then is the tail of the plan that check passed.
    brake_s: f64,
}

/// A plan's braking (m/s²), never more than its share: a vehicle already braking keeps
/// its rate (`committed`); with the stopping rows, the rate that brings it to rest after
/// the common stop time from its velocity when it starts braking; otherwise its share.
fn braking_of(
    plan: &Plan,
    a: &Agent,
    timing: Timing,
    stops: Option<Stops>,
    committed: Option<f64>,
) -> f64 {
    let share = braking(a);
    let Some(stops) = stops.filter(|_| share > 0.0) else {
        return share;
    };
    let mut v = plan.vel_mps + (plan.before_mps2[0] + plan.before_mps2[1]) * (0.5 * timing.delay_s);
    let stop_s = match plan.first {
        First::Command(net) => {
            v += net * timing.hold_s;
            stops.command_s
        }
        First::Brake => match committed {
            Some(rate) => return rate.min(share),
            None => stops.brake_s,
        },
    };
    if stop_s > 0.0 {
        (v.norm() / stop_s).min(share)
    } else {
        share
    }
}

/// The distance a pair must keep in the check (m, scaled). With the stopping rows, the
/// separation: what each vehicle does in the delay is in its plan (the command on its
/// way). Otherwise, the separation and what the two can move apart from what is known in
/// the delay, as the barrier's age-grown separation.
pub(super) fn keep_m(
    sep: &Separation,
    (a, b): (&Agent, &Agent),
    timing: Timing,
    stopping: bool,
) -> f64 {
    let separation_m = sep.horizontal_m + a.spread() + b.spread();
    if stopping {
        return separation_m;
    }
    let delay_s = timing.delay_s;
    separation_m + 0.5 * (limit(a) + limit(b)) * delay_s * delay_s
}
