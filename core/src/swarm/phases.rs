//! Moving between the swarm's phases (drawn in the module above): the handshake and its
//! timeout, the planner's stages, consensus, holding on a loss, the end of the flight.

use std::time::Duration;

use nalgebra::Vector2;
use ringswarm_wire::time::SimTime;

use super::VehicleIndex;
use super::status::NotFlying;
use super::{EndAction, LossPolicy, PlanDecision, StopReason, Swarm, SwarmFailure, SwarmPhase};
use crate::consensus::{formation_error_m, predicted_final_velocity};
use crate::vehicle::Phase;

/// How close to the commanded altitude (m) and how slow vertically (m/s) every vehicle must
/// be before the planner plans.
pub const PLAN_ALTITUDE_M: f64 = 1.0;
/// The same, vertical speed.
pub const PLAN_CLIMB_MPS: f64 = 0.5;
/// The planner plans anyway after this long with every vehicle flying.
pub const PLAN_ALTITUDE_WAIT: Duration = Duration::from_secs(30);

/// Stage 1 ends once the w-weighted mean velocity is within `target.tolerance_mps` times
/// the re-targeted agents' share of the weights of the target (the prediction one agent
/// within the tolerance would give), and every re-targeted agent within this much of its
/// planned velocity (m/s).
pub const RETARGET_AGENT_TOLERANCE_MPS: f64 = 0.5;

/// How long a landing waits for vehicles that are lost (silent for the link timeout):
/// one heard again in that time is told to land; after it, if every other vehicle is
/// down, failed or taken over, the flight ends without them, named, and they are left to
/// their own failsafes (PX4's data-link-loss action, ArduPilot's GCS failsafe).
pub const LOST_LANDING_WAIT: Duration = Duration::from_secs(30);

impl Swarm {
    /// Every vehicle within [`PLAN_ALTITUDE_M`] of the commanded altitude and slower than
    /// [`PLAN_CLIMB_MPS`] vertically.
    fn level_at_altitude(&self) -> bool {
        // Over the vehicles known here (every one in one process).
        let known = self.indices().filter(|i| self.is_known(*i));
        known.map(|i| self.law.states[i]).all(|s| {
            s.is_some_and(|s| {
                (s.pos_enu_m.z - self.setup.altitude_m).abs() < PLAN_ALTITUDE_M
                    && s.vel_enu_mps.z.abs() < PLAN_CLIMB_MPS
            })
        })
    }

    /// Moves between phases; runs at the start of every control tick.
    pub(super) fn transition(&mut self, now: SimTime) {
        let (all_flying, any_lost) = self.fleet_status(now);
        if !all_flying {
            // This shard no longer vouches for a start: the others wait for it.
            self.withdraw_start();
        }
        if self.phase == SwarmPhase::Handshake && !all_flying && self.handshake_over(now) {
            return;
        }
        let over = |start: Option<SimTime>| {
            start
                .zip(self.setup.duration)
                .is_some_and(|(t0, d)| now >= t0 + d)
        };
        match self.phase {
            SwarmPhase::Handshake
                if all_flying && self.setup.target.is_some() && self.plan.is_none() =>
            {
                self.plan_when_level(now);
            }
            SwarmPhase::Retargeting(since) if !any_lost => self.retarget_stage(now, since),
            SwarmPhase::Handshake | SwarmPhase::Holding(_) if all_flying => {
                if over(self.first_consensus.or(self.first_law)) {
                    self.end(now);
                    return;
                }
                if self.start_due(now) {
                    self.start_consensus(now);
                }
            }
            SwarmPhase::Consensus(_) | SwarmPhase::Retargeting(_) if any_lost => {
                self.on_vehicle_lost(now);
            }
            SwarmPhase::Consensus(_) if over(self.first_consensus) => self.end(now),
            SwarmPhase::Holding(_) | SwarmPhase::Stopped(_)
                if over(self.first_consensus.or(self.first_law)) =>
            {
                self.end(now)
            }
            SwarmPhase::Landing(since)
                if self.left_lost.is_none() && now >= since + LOST_LANDING_WAIT =>
            {
                self.leave_the_lost(now, since);
            }
            _ => {}
        }
    }

    /// Whether every vehicle flies on a fresh state, and whether one is lost, over the
    /// vehicles known here (all of them in one process); with shards, the others through
    /// their shard's report (shard.rs).
    fn fleet_status(&self, now: SimTime) -> (bool, bool) {
        let known = |i: &VehicleIndex| self.is_known(*i);
        let all_flying = self
            .indices()
            .filter(known)
            .all(|i| self.vehicle_phase(i) == Phase::Flying && self.law.states[i].is_some())
            && self.others_flying(now);
        // A vehicle taken out of OFFBOARD (pilot, its failsafe) counts as lost: it never
        // comes back on its own, so the swarm holds (or lands) until told otherwise. So
        // does one that flies on a position too old to use, or that was handed to its own
        // Hold.
        let any_lost = self.indices().filter(known).any(|i| {
            let phase = self.vehicle_phase(i);
            matches!(phase, Phase::Lost | Phase::Overridden | Phase::VehicleHold)
                || (phase == Phase::Flying && self.law.states[i].is_none())
        }) || self.others_lost(now).is_some();
        (all_flying, any_lost)
    }

    /// With a target velocity and every vehicle flying: plans once the swarm flies level
    /// at its altitude, or after [`PLAN_ALTITUDE_WAIT`] anyway.
    fn plan_when_level(&mut self, now: SimTime) {
        // Plan from the velocities of a swarm that flies level at its altitude: a
        // plan made on the ground is spoilt by the climb that follows.
        let since = *self.all_flying_since.get_or_insert(now);
        let wait = self.setup.target.is_some_and(|t| t.wait_for_altitude);
        if !wait || self.level_at_altitude() {
            self.plan_target(now);
        } else if now.saturating_since(since) >= PLAN_ALTITUDE_WAIT {
            self.log.push(
                now,
                true,
                format!(
                    "not level at {} m after {} s: planning anyway",
                    self.setup.altitude_m,
                    PLAN_ALTITUDE_WAIT.as_secs()
                ),
            );
            self.plan_target(now);
        }
    }

    /// Planner stage 1: consensus starts once the re-targeted agents (this shard's) have
    /// their planned velocities and the weighted mean is near the target, or at the
    /// stage's timeout (said once).
    fn retarget_stage(&mut self, now: SimTime, since: SimTime) {
        let Some(PlanDecision::Planned { retarget, .. }) = &self.plan else {
            return;
        };
        let tolerance = self.setup.target.map_or(0.05, |t| t.tolerance_mps);
        let target = self.setup.target.map(|t| t.velocity_mps);
        let off = |&(agent, v): &(usize, Vector2<f64>)| {
            self.law.states[agent].map_or(f64::INFINITY, |s| (s.vel_enu_mps.xy() - v).norm())
        };
        // With shards, each judges its own re-targeted vehicles, and consensus
        // starts once every shard is ready (start_when_agreed).
        let worst = retarget
            .iter()
            .filter(|(agent, _)| !self.is_remote(VehicleIndex(*agent)))
            .map(|r| (off(r), *r))
            .max_by(|a, b| a.0.total_cmp(&b.0));
        // The prediction is the w-weighted mean at the start of consensus: that
        // mean is what has to reach the target. An agent still off its planned
        // velocity only starts the formation from a little further away.
        // Held to the re-targeted agents' share of the weights, the bound on the
        // prediction is what one agent within `tolerance` would give.
        let total: f64 = self.law.w.iter().sum();
        let share: f64 = retarget.iter().map(|(a, _)| self.law.w[*a]).sum::<f64>() / total;
        let mean = self.weighted_mean_velocity();
        let mean_off = match (mean, target) {
            (Some(m), Some(t)) => (m - t).norm(),
            _ => 0.0,
        };
        let timeout = self
            .setup
            .target
            .map_or(Duration::from_secs(30), |t| t.timeout);
        match worst {
            None => self.start_when_agreed(now),
            Some((error, _))
                if mean_off < tolerance * share && error < RETARGET_AGENT_TOLERANCE_MPS =>
            {
                self.start_when_agreed(now)
            }
            Some(_) if now.saturating_since(since) >= timeout && self.start_proposed() => {
                // Timed out before, and said so: waiting for the other shards.
                self.start_when_agreed(now)
            }
            Some((_, (agent, v))) if now.saturating_since(since) >= timeout => {
                let at = self.law.states[agent].map_or(Vector2::zeros(), |s| s.vel_enu_mps.xy());
                let m = mean.unwrap_or_default();
                self.log.push_vehicle(
                    now,
                    &self.setup.links[agent],
                    true,
                    format!(
                        "re-target stage timed out after {:.1} s with the weighted mean velocity at ({:.2}, {:.2}) m/s and this vehicle at ({:.2}, {:.2}) m/s, planned ({:.2}, {:.2}) m/s: consensus from the velocities now",
                        timeout.as_secs_f64(),
                        m.x,
                        m.y,
                        at.x,
                        at.y,
                        v.x,
                        v.y
                    ),
                );
                self.start_when_agreed(now);
            }
            Some(_) => {}
        }
    }

    /// A vehicle lost in consensus or the re-target stage: the loss policy (the others
    /// brake and hold, or every vehicle lands).
    fn on_vehicle_lost(&mut self, now: SimTime) {
        match self.setup.loss_policy {
            LossPolicy::Hold => {
                let why = self.loss_cause(now);
                self.log.push(
                    now,
                    true,
                    format!("a vehicle is lost{why}: the others brake and hold"),
                );
                self.forget_hold_points();
                self.phase = SwarmPhase::Holding(now);
                self.new_round(now);
            }
            LossPolicy::Land => {
                let why = self.loss_cause(now);
                self.log.push(
                    now,
                    true,
                    format!("a vehicle is lost{why}: landing (on_link_loss = land)"),
                );
                self.land_because(now, StopReason::LinkLoss);
            }
        }
    }

    /// With shards, which shard the loss was seen in (`""` in one process).
    fn loss_cause(&self, now: SimTime) -> String {
        self.others_lost(now)
            .map_or(String::new(), |why| format!(" ({why})"))
    }

    /// Gives up on the handshake when the timeout is over or a vehicle's handshake failed:
    /// names the vehicles not flying and lands the others. Whether it gave up.
    fn handshake_over(&mut self, now: SimTime) -> bool {
        let failed = self
            .indices()
            .filter(|i| self.is_known(*i))
            .any(|i| self.vehicle_phase(i) == Phase::Failed);
        let timed_out = now >= SimTime::ZERO + self.setup.handshake_timeout;
        if !(failed || timed_out) {
            return false;
        }
        let not_flying: Vec<NotFlying> = self
            .indices()
            .filter_map(|i| {
                let cfg = &self.setup.links[i];
                if !self.is_known(i) {
                    // Another shard's, not watched here: its shard's report speaks for it.
                    return (!self.others_flying(now)).then(|| NotFlying {
                        system_id: cfg.system_id,
                        network: cfg.network.clone(),
                        phase: "its shard not all flying".to_owned(),
                    });
                }
                let phase = self.vehicle_phase(i);
                let state = self.law.states[i];
                if phase == Phase::Flying && state.is_some() {
                    return None;
                }
                let name = if phase == Phase::Flying {
                    "no usable position".to_owned()
                } else {
                    // What its handshake still waits for, when it knows.
                    let waiting = self.link(i).and_then(|l| l.waiting_for());
                    match waiting {
                        Some(what) => format!("{}: {what}", phase.name()),
                        None => phase.name().to_owned(),
                    }
                };
                Some(NotFlying {
                    system_id: cfg.system_id,
                    network: cfg.network.clone(),
                    phase: name,
                })
            })
            .collect();
        let failure = SwarmFailure::Handshake {
            not_flying,
            after: now.saturating_since(SimTime::ZERO),
        };
        self.log.push(now, true, failure.to_string());
        self.failure = Some(failure);
        self.land_because(now, StopReason::Handshake);
        true
    }

    pub(super) fn start_consensus(&mut self, now: SimTime) {
        // With shards, the instant every shard adopted (at most a tick before `now`): the
        // flight's end is counted from it, the same in every shard.
        let start = self.shard_start(now);
        let t0 = start.unwrap_or(now);
        self.phase = SwarmPhase::Consensus(t0);
        self.mean_velocity_integral = Vector2::zeros();
        if let Some(guard) = self.guard.as_mut() {
            guard.reset();
        }
        self.first_consensus.get_or_insert(t0);
        self.first_law.get_or_insert(t0);
        self.assign_places(now, t0);
        if start.is_some() {
            // From every shard's sum at the start, once all are in (shard.rs).
            self.predicted_final_velocity = None;
            let swarm_us = self.swarm_clock_us(t0).unwrap_or_default();
            self.log.push(
                now,
                false,
                format!(
                    "consensus started at the adopted {:.3} s (swarm clock {swarm_us} µs)",
                    t0.as_secs_f64()
                ),
            );
            self.shard_prediction(now);
            return;
        }
        let v0: Vec<Vector2<f64>> = self
            .law
            .states
            .iter()
            .flatten()
            .map(|s| s.vel_enu_mps.xy())
            .collect(); // once per (re)start
        self.predicted_final_velocity = predicted_final_velocity(&self.setup.ring, &v0).ok();
        let text = match self.predicted_final_velocity {
            Some(v) => format!(
                "consensus started: predicted final velocity ({:.3}, {:.3}) m/s",
                v.x, v.y
            ),
            None => "consensus started".to_owned(),
        };
        self.log.push(now, false, text);
    }

    /// The divergence guard, once per consensus tick (after the states are taken): when
    /// it trips, the swarm applies its loss policy (hold: brake and hover, never resuming;
    /// land) and logs the cause.
    pub(super) fn watch_divergence(&mut self, now: SimTime) {
        let (SwarmPhase::Consensus(_), Some(predicted)) =
            (self.phase, self.predicted_final_velocity)
        else {
            return;
        };
        if self.guard.is_none() {
            return;
        }
        let Some(mean) = self.weighted_mean_velocity() else {
            return;
        };
        let breaking_jams = self.safety.jams.watch.any();
        let Some(guard) = self.guard.as_mut() else {
            return;
        };
        if breaking_jams {
            guard.restart_formation();
        }
        // Over the vehicles known here (every one in one process).
        let peers = self.peers.as_deref();
        let known = |i: usize| peers.is_none_or(|p| p.plan.is_local(i) || p.plan.is_watched(i));
        let formation = formation_error_m(
            self.law
                .horizontal
                .iter()
                .enumerate()
                .filter(|(i, _)| known(*i))
                .map(|(_, h)| h.pos_m - h.offset_m),
        );
        let spread = self
            .law
            .horizontal
            .iter()
            .enumerate()
            .filter(|(i, _)| known(*i))
            .map(|(_, h)| (h.vel_mps - mean).norm())
            .fold(0.0, f64::max);
        let Some(trip) = guard.observe(now, mean, predicted, (formation, spread)) else {
            return;
        };
        let land = self.setup.loss_policy == LossPolicy::Land;
        let text = if land {
            format!("{trip}: landing")
        } else {
            format!("{trip}: the swarm brakes and holds")
        };
        self.stop_law(now, StopReason::Guard(trip), land, text);
    }

    /// A landing ordered at `since` that only lost vehicles hold up: they are named and
    /// left to their own failsafes, and the flight ends.
    fn leave_the_lost(&mut self, now: SimTime, since: SimTime) {
        let mut lost = Vec::new();
        for (i, link) in self.slots.iter().enumerate() {
            let Some(link) = link.link() else { continue };
            match link.phase() {
                Phase::Done | Phase::Failed | Phase::Overridden => {}
                Phase::Lost => {
                    let cfg = &self.setup.links[i];
                    lost.push(match &cfg.network {
                        Some(net) => format!("vehicle {} on {net}", cfg.system_id),
                        None => format!("vehicle {}", cfg.system_id),
                    });
                }
                // One still landing, or heard again: the landing goes on.
                _ => return,
            }
        }
        if lost.is_empty() {
            return;
        }
        self.log.push(
            now,
            true,
            format!(
                "landing ended without {}: lost and not heard again in the {:.0} s since the landing was ordered; left to their own failsafes",
                lost.join(", "),
                now.saturating_since(since).as_secs_f64()
            ),
        );
        self.left_lost = Some(lost);
    }

    fn end(&mut self, now: SimTime) {
        self.stop.get_or_insert(StopReason::DurationOver);
        match self.setup.end_action {
            EndAction::Land => self.land_because(now, StopReason::DurationOver),
            EndAction::Hold => {
                self.log
                    .push(now, false, "duration over: holding".to_owned());
                self.forget_hold_points();
                self.phase = SwarmPhase::Ended(now);
            }
        }
    }
}
