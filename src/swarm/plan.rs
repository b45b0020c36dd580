//! Planner stage 0, run once when every vehicle flies with a target velocity: choose `k`
//! (and an agent to re-target) from the velocities now, and check the planned ring.

use nalgebra::Vector2;
use ringswarm_wire::time::SimTime;

use super::{PlanDecision, Retargeted, Swarm, SwarmPhase, TargetVelocity};
use crate::consensus::{
    PlanOutcome, PlanRequest, RingDigraph, RingModes, analyze, fastest_mode_per_s, k_lower_bound,
};

impl Swarm {
    /// Planner stage 0: choose `k` (and an agent to re-target) from the velocities now.
    /// Runs once; allocates (the planner and the stability check), like the start of
    /// consensus.
    pub(super) fn plan_target(&mut self, now: SimTime) {
        let Some(target) = self.setup.target else {
            return;
        };
        let velocities: Vec<Vector2<f64>> = self
            .states
            .iter()
            .flatten()
            .map(|s| s.vel_enu_mps.xy())
            .collect();
        // Stage 1: the others keep these velocities, with feedback.
        for (keep, v) in self.keep_velocity.iter_mut().zip(&velocities) {
            *keep = Some(*v);
        }
        let decision = match self.planned_ring(&target, velocities) {
            Ok((ring, retarget)) => {
                let k = ring.k();
                self.w = (0..self.links.len()).map(|i| ring.w(i)).collect();
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
            let text = match retarget {
                Some((agent, v)) => format!(
                    "plan: k = {k:.6}, vehicle {} re-targeted to ({:.3}, {:.3}) m/s",
                    self.setup.links[*agent].system_id, v.x, v.y
                ),
                None => format!("plan: k = {k:.6}, no re-target needed"),
            };
            self.log.push(now, false, text);
        }
        let retargeting = matches!(
            decision,
            PlanDecision::Planned {
                retarget: Some(_),
                ..
            }
        );
        self.plan = Some(decision);
        if retargeting {
            self.phase = SwarmPhase::Retargeting(now);
        } else {
            self.start_consensus(now);
        }
    }

    fn planned_ring(
        &self,
        target: &TargetVelocity,
        velocities: Vec<Vector2<f64>>,
    ) -> Result<(RingDigraph, Option<Retargeted>), String> {
        let airframe = self.airframe_speed_limit_mps();
        let max_speed_mps = match (target.max_speed_mps, airframe) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        };
        let k_max = self.k_max_the_airframes_fly(target)?;
        let plan = crate::consensus::plan(&PlanRequest {
            velocities_mps: velocities,
            target_mps: target.velocity_mps,
            k_margin: target.k_margin,
            k_max,
            max_speed_mps,
        })
        .map_err(|e| e.to_string())?;
        let (k, retarget) = match plan.outcome {
            PlanOutcome::Feasible { k, retarget, .. } => (k, retarget),
            PlanOutcome::Infeasible { reason } => return Err(reason),
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
        Ok((ring, retarget.map(|r| (r.agent, r.new_velocity_mps))))
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

    /// The fastest any vehicle can fly level against its drag, with a margin:
    /// [`SPEED_MARGIN`]` · a_h / drag`, where `a_h` is the horizontal acceleration the
    /// envelope allows at hover (`g·tan θ_max` when thrust allows). `None` without drag.
    pub(super) fn airframe_speed_limit_mps(&self) -> Option<f64> {
        self.setup
            .drag_per_s
            .iter()
            .zip(&self.flown_models)
            .filter(|(d, _)| **d > 0.0)
            .map(|(d, m)| SPEED_MARGIN * self.setup.envelope.horizontal_limit_mps2(0.0, m) / d)
            .reduce(f64::min)
    }
}

/// Fraction of the drag-limited top speed the planner may ask for.
pub const SPEED_MARGIN: f64 = 0.8;
