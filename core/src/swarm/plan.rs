//! Planner stage 0, run once when every vehicle flies with a target velocity: choose `k`
//! (and an agent to re-target) from the velocities now, and check the planned ring.

use nalgebra::Vector2;
use ringswarm_wire::time::SimTime;

use super::VehicleIndex;
use super::{MAX_SPEED_MPS, PlanDecision, Retargeted, Swarm, SwarmPhase, TargetVelocity};
use crate::consensus::{
    LeastChange, PlanOutcome, PlanRequest, RingDigraph, RingModes, analyze, fastest_mode_per_s,
    k_lower_bound, least_change_velocities,
};

impl Swarm {
    /// Planner stage 0: choose `k` (and an agent to re-target) from the velocities now.
    /// Runs once; allocates (the planner and the stability check), like the start of
    /// consensus.
    pub(super) fn plan_target(&mut self, now: SimTime) {
        if self.peers.is_some() {
            self.plan_in_shards(now);
            return;
        }
        let velocities: Vec<Vector2<f64>> = self
            .law
            .states
            .iter()
            .flatten()
            .map(|s| s.vel_enu_mps.xy())
            .collect();
        let limits = self
            .indices()
            .map(|i| self.vehicle_speed_limit_mps(i))
            .collect();
        self.plan_from(now, velocities, limits);
    }

    /// With shards: the plan at an instant every shard adopts, from every vehicle's
    /// velocity and top speed then. This shard agrees on the instant as on a consensus
    /// start, takes its own vehicles' velocities at it, and plans once every shard's are
    /// in: every shard plans from the same numbers, to the same plan. It then re-targets
    /// its own vehicles, and consensus starts at an instant agreed anew.
    fn plan_in_shards(&mut self, now: SimTime) {
        if self.peers.as_ref().is_some_and(|p| p.plan_own.is_none()) {
            if !self.start_due(now) {
                return;
            }
            let own: Vec<super::peers::OwnPlanInput> = self
                .indices()
                .filter(|i| !self.is_remote(*i))
                .map(|i| {
                    let v = self.law.states[i].map_or(Vector2::zeros(), |s| s.vel_enu_mps.xy());
                    (v, self.vehicle_speed_limit_mps(i))
                })
                .collect();
            let Some(p) = self.peers.as_mut() else {
                return;
            };
            let at = p.adopted_start().unwrap_or(now);
            p.plan_own = Some((at, own));
            self.log.push(
                now,
                false,
                format!(
                    "plan instant adopted at {:.3} s: waiting for every shard's velocities",
                    at.as_secs_f64()
                ),
            );
        }
        let Some(inputs) = self.peers.as_ref().and_then(|p| p.plan_inputs()) else {
            return;
        };
        self.plan_from(now, inputs.velocities_mps, inputs.limits_mps);
    }

    /// Planner stage 0 from every vehicle's velocity and top speed (ring order).
    fn plan_from(&mut self, now: SimTime, velocities: Vec<Vector2<f64>>, limits: Vec<Option<f64>>) {
        let Some(target) = self.setup.target else {
            return;
        };
        // Stage 1: the others keep these velocities, with feedback.
        for (slot, v) in self.slots.iter_mut().zip(&velocities) {
            slot.keep_velocity = Some(*v);
        }
        let decision = match self.planned_ring(&target, velocities, &limits) {
            Ok((ring, retarget)) => {
                let k = ring.k();
                self.law.w = self.indices().map(|i| ring.w(i.0)).collect();
                self.setup.ring = ring;
                PlanDecision::Planned { k, retarget }
            }
            Err(reason) => {
                self.log.push(
                    now,
                    true,
                    format!("target velocity not used ({reason}): flying the configured k"),
                );
                PlanDecision::Rejected(reason)
            }
        };
        if let PlanDecision::Planned { k, retarget } = &decision {
            let mut text = format!("plan: k = {k:.6}, ");
            if retarget.is_empty() {
                text.push_str("no re-target needed");
            }
            for (j, (agent, v)) in retarget.iter().enumerate() {
                let sep = if j == 0 { "" } else { ", " };
                let was = self.slots[*agent].keep_velocity.unwrap_or_default();
                text.push_str(&format!(
                    "{sep}vehicle {} re-targeted to ({:.3}, {:.3}) m/s (by {:.3} m/s)",
                    self.setup.links[*agent].system_id,
                    v.x,
                    v.y,
                    (v - was).norm()
                ));
            }
            self.log.push(now, false, text);
        }
        let retargeting = matches!(
            &decision,
            PlanDecision::Planned { retarget, .. } if !retarget.is_empty()
        );
        self.plan = Some(decision);
        if let Some(p) = self.peers.as_mut() {
            // Every shard re-targets its own vehicles (if any), then consensus starts at
            // an instant agreed anew among shards that have all planned.
            p.agreement.set_planned();
            p.reweigh(&self.law.w);
            self.new_round(now);
            self.phase = SwarmPhase::Retargeting(now);
            self.first_law.get_or_insert(now);
            return;
        }
        if retargeting {
            self.phase = SwarmPhase::Retargeting(now);
            self.first_law.get_or_insert(now);
        } else {
            self.start_consensus(now);
        }
    }

    /// The paper's plan (one agent re-targeted, or none) when it keeps every speed
    /// within its limit; otherwise the least change of every agent's velocity with the
    /// configured `k` (kept within the planner's range).
    fn planned_ring(
        &self,
        target: &TargetVelocity,
        velocities: Vec<Vector2<f64>>,
        per_vehicle: &[Option<f64>],
    ) -> Result<(RingDigraph, Vec<Retargeted>), String> {
        let limits = speed_limits_mps(target, per_vehicle);
        let max_speed_mps = limits.iter().copied().reduce(f64::min);
        let k_max = self.k_max_the_airframes_fly(target)?;
        let plan = crate::consensus::plan(&PlanRequest {
            velocities_mps: velocities.clone(),
            target_mps: target.velocity_mps,
            k_margin: target.k_margin,
            k_max,
            max_speed_mps,
        })
        .map_err(|e| e.to_string())?;
        let (k, retarget) = match plan.outcome {
            PlanOutcome::Feasible { k, retarget, .. } => (
                k,
                retarget
                    .map(|r| vec![(r.agent, r.new_velocity_mps)])
                    .unwrap_or_default(),
            ),
            PlanOutcome::Infeasible { reason } => {
                let k_lo = plan.k_min + target.k_margin;
                let k = self.setup.ring.k().clamp(k_lo.min(k_max), k_max);
                let ring = RingDigraph::new(self.setup.ring.macro_vertices(), k)
                    .map_err(|e| e.to_string())?;
                let w: Vec<f64> = (0..velocities.len()).map(|i| ring.w(i)).collect();
                let limits: Vec<f64> = if limits.is_empty() {
                    vec![MAX_SPEED_MPS; velocities.len()]
                } else {
                    limits
                };
                match least_change_velocities(&velocities, &w, target.velocity_mps, &limits)
                    .map_err(|e| e.to_string())?
                {
                    LeastChange::Reached { velocities_mps, .. } => (
                        k,
                        velocities_mps
                            .into_iter()
                            .enumerate()
                            .filter(|(i, v)| (v - velocities[*i]).norm() > 1e-9)
                            .collect(),
                    ),
                    LeastChange::Unreachable { reason: all, .. } => {
                        return Err(format!(
                            "{reason}; re-targeting every vehicle with k = {k:.6}: {all}"
                        ));
                    }
                }
            }
        };
        let ring =
            RingDigraph::new(self.setup.ring.macro_vertices(), k).map_err(|e| e.to_string())?;
        let report = analyze(&ring, Some(self.setup.gains)).map_err(|e| e.to_string())?;
        if !report.stable {
            return Err(format!(
                "the planned k = {k:.6} is unstable with alpha = {}, beta = {}",
                self.setup.gains.alpha, self.setup.gains.beta
            ));
        }
        Ok((ring, retarget))
    }

    /// `target.k_max`, lowered if needed so that the law's fastest mode stays within what
    /// the bandwidth gate allows (`setup.bandwidth`): the largest `k` that fits, by
    /// bisection (the fastest mode grows with `k`, through `βμ_max ≈ β(2 + k)`).
    fn k_max_the_airframes_fly(&self, target: &TargetVelocity) -> Result<f64, String> {
        let Some(allowed) = self.setup.bandwidth.map(|b| b.allowed_per_s) else {
            return Ok(target.k_max);
        };
        let m = self.setup.ring.macro_vertices();
        let modes = RingModes::new(m);
        let fastest = |k: f64| -> Result<f64, String> {
            RingDigraph::new(m, k).map_err(|e| e.to_string())?;
            let mu = modes.spectrum(k).nonzero_up_to_conjugation();
            Ok(fastest_mode_per_s(&mu, self.setup.gains))
        };
        if fastest(target.k_max)? <= allowed {
            return Ok(target.k_max);
        }
        let lo_k = k_lower_bound(m).map_err(|e| e.to_string())? + target.k_margin;
        if fastest(lo_k)? > allowed {
            return Err(format!(
                "no admissible k keeps the law's fastest mode within {allowed:.2} 1/s (the bandwidth gate)"
            ));
        }
        let (mut lo, mut hi) = (lo_k, target.k_max);
        for _ in 0..50 {
            let mid = 0.5 * (lo + hi);
            if fastest(mid)? <= allowed {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        Ok(lo)
    }

    /// Vehicle `i`'s top speed level against its drag (the estimate once it is flown, the
    /// configuration before), with a margin: [`SPEED_MARGIN`]` · a_h / drag`, where `a_h`
    /// is the horizontal acceleration the envelope allows at hover (`g·tan θ_max` when
    /// thrust allows). `None` without drag.
    fn vehicle_speed_limit_mps(&self, i: VehicleIndex) -> Option<f64> {
        let d = self.slots.get(i.0).map(|s| s.flown.drag_best_per_s())?;
        let model = self.law.flown_models.get(i.0)?;
        (d > 0.0).then(|| SPEED_MARGIN * self.setup.envelope.horizontal_limit_mps2(0.0, model) / d)
    }
}

/// Each vehicle's speed limit for the planner (m/s): `target.max_speed_mps` and its own
/// drag-limited top speed (`per_vehicle`, [`Swarm::vehicle_speed_limit_mps`]), the
/// smaller; empty when neither is known for any vehicle.
fn speed_limits_mps(target: &TargetVelocity, per_vehicle: &[Option<f64>]) -> Vec<f64> {
    let limits: Vec<Option<f64>> = per_vehicle
        .iter()
        .map(|own| match (target.max_speed_mps, *own) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        })
        .collect();
    if limits.iter().all(Option::is_none) {
        return Vec::new();
    }
    limits
        .into_iter()
        .map(|l| l.unwrap_or(MAX_SPEED_MPS))
        .collect()
}

/// Fraction of the drag-limited top speed the planner may ask for.
pub const SPEED_MARGIN: f64 = 0.8;
