//! Planner stage 0, run once when every vehicle flies with a target velocity: choose `k`
//! (and an agent to re-target) from the velocities now, and check the planned ring.

use nalgebra::Vector2;
use ringswarm_sitl::time::SimTime;

use super::{PlanDecision, Retargeted, Swarm, SwarmPhase, TargetVelocity};
use crate::consensus::{PlanOutcome, PlanRequest, RingDigraph, analyze};

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
        let decision = match self.planned_ring(&target, velocities) {
            Ok((ring, retarget)) => {
                let k = ring.k();
                self.w = (0..self.links.len()).map(|i| ring.w(i)).collect();
                self.setup.ring = ring;
                PlanDecision::Planned { k, retarget }
            }
            Err(reason) => {
                tracing::warn!(%reason, "target velocity not used; flying the configured k");
                PlanDecision::Rejected(reason)
            }
        };
        tracing::info!(?decision, "plan");
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
        let plan = crate::consensus::plan(&PlanRequest {
            velocities_mps: velocities,
            target_mps: target.velocity_mps,
            k_margin: target.k_margin,
            k_max: target.k_max,
            max_speed_mps: target.max_speed_mps,
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
}
