//! `plan`: the paper's planner, re-targeting one agent's initial velocity (or every
//! agent's, least change) so that the swarm ends at a target velocity.

use std::fmt;

use nalgebra::Vector2;
use serde::Serialize;

use crate::consensus::{
    LeastChange, PlanOutcome, PlanRequest, RingDigraph, least_change_velocities, plan,
    predicted_final_velocity,
};
use crate::error::InputError;

/// The output of `plan` (agents numbered from 1, as in the paper).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PlanOutput {
    /// `N`.
    pub agents: usize,
    /// The target (m/s).
    pub target: [f64; 2],
    /// `g` before any change.
    pub g: [f64; 2],
    /// `h` before any change.
    pub h: [f64; 2],
    /// The stability bound on `k`.
    pub k_min: f64,
    /// The required distance above it.
    pub margin: f64,
    /// Whether the target is reachable.
    pub feasible: bool,
    /// The re-targeted agent (1-based), if any.
    pub agent: Option<usize>,
    /// Its class (`odd` / `even` in the paper's numbering).
    pub agent_class: Option<String>,
    /// Its initial velocity before (m/s).
    pub old_velocity: Option<[f64; 2]>,
    /// Its new initial velocity (m/s).
    pub new_velocity: Option<[f64; 2]>,
    /// `|new − old|` (m/s).
    pub velocity_change: Option<f64>,
    /// `δ = 1 + k`.
    pub delta: Option<f64>,
    /// The gain.
    pub k: Option<f64>,
    /// The final velocity predicted from the (modified) velocities and `k` (m/s).
    pub predicted_final_velocity: Option<[f64; 2]>,
    /// Why the target is not reachable (or, when every agent is re-targeted, why one agent
    /// could not do it).
    pub reason: Option<String>,
    /// Which plan: `one agent` (the paper's) or `every agent` (the least change of every
    /// velocity, when one agent cannot reach the target within the limits).
    pub method: Option<String>,
    /// With `every agent`: each agent that changes (1-based), old and new velocity (m/s).
    pub retargeted: Vec<Retarget>,
    /// With an unreachable target: the nearest final velocity the speed limit allows
    /// with every agent re-targeted (m/s).
    pub best_reachable_velocity: Option<[f64; 2]>,
}

/// The `k` of `plan`'s every-agent plan unless `--k` says otherwise.
pub const EVERY_AGENT_K: f64 = 1.0;

/// One agent of an every-agent plan.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Retarget {
    /// The agent (1-based).
    pub agent: usize,
    /// Its initial velocity before (m/s).
    pub old_velocity: [f64; 2],
    /// Its new initial velocity (m/s).
    pub new_velocity: [f64; 2],
    /// `|new − old|` (m/s).
    pub change: f64,
}

/// Runs `plan`: the paper's plan (one agent re-targeted); when it is infeasible, every
/// agent re-targeted by the least change of their velocities at `every_k` (default 1:
/// weights 1 and 2 per macro-vertex, all positive, so that the weighted mean of speeds
/// within the limit stays within it; kept within `[k_min + margin, k_max]`), each within
/// `max_speed_mps`.
///
/// # Errors
/// [`InputError`] for an odd agent count, non-finite numbers or a negative margin.
pub fn run_plan_everyone(
    request: &PlanRequest,
    every_k: Option<f64>,
) -> Result<PlanOutput, InputError> {
    let mut out = run_plan(request)?;
    if out.feasible {
        out.method = Some("one agent".to_owned());
        return Ok(out);
    }
    let k_lo = out.k_min + request.k_margin;
    if k_lo > request.k_max {
        return Ok(out);
    }
    if let Some(k) = every_k
        && !(k.is_finite() && k > 0.0)
    {
        return Err(InputError::OutOfRange {
            name: "--k",
            range: "(0, ∞)",
            value: k,
        });
    }
    let k = every_k.unwrap_or(EVERY_AGENT_K).clamp(k_lo, request.k_max);
    let n = request.velocities_mps.len();
    let ring = RingDigraph::for_agents(n, k)?;
    let w: Vec<f64> = (0..n).map(|i| ring.w(i)).collect();
    let limit = request.max_speed_mps.unwrap_or(crate::swarm::MAX_SPEED_MPS);
    let answer = least_change_velocities(
        &request.velocities_mps,
        &w,
        request.target_mps,
        &vec![limit; n],
    )?;
    let pair = |v: Vector2<f64>| [v.x, v.y];
    let one_agent = out.reason.take().unwrap_or_default();
    match answer {
        LeastChange::Reached { velocities_mps, .. } => {
            out.feasible = true;
            out.method = Some("every agent".to_owned());
            out.k = Some(k);
            out.delta = Some(1.0 + k);
            out.reason = Some(one_agent);
            out.predicted_final_velocity =
                Some(pair(predicted_final_velocity(&ring, &velocities_mps)?));
            out.retargeted = velocities_mps
                .iter()
                .zip(&request.velocities_mps)
                .enumerate()
                .filter(|(_, (new, old))| (*new - *old).norm() > 1e-9)
                .map(|(i, (new, old))| Retarget {
                    agent: i + 1,
                    old_velocity: pair(*old),
                    new_velocity: pair(*new),
                    change: (new - old).norm(),
                })
                .collect();
        }
        LeastChange::Unreachable { best_mps, reason } => {
            out.reason = Some(format!(
                "{one_agent}; re-targeting every agent with k = {k:.6}: {reason}"
            ));
            out.best_reachable_velocity = Some(pair(best_mps));
        }
    }
    Ok(out)
}

/// Runs `plan`.
///
/// # Errors
/// [`InputError`] for an odd agent count, non-finite numbers or a negative margin.
pub fn run_plan(request: &PlanRequest) -> Result<PlanOutput, InputError> {
    let answer = plan(request)?;
    let pair = |v: Vector2<f64>| [v.x, v.y];
    let mut out = PlanOutput {
        agents: request.velocities_mps.len(),
        target: pair(request.target_mps),
        g: pair(answer.g),
        h: pair(answer.h),
        k_min: answer.k_min,
        margin: request.k_margin,
        feasible: answer.is_feasible(),
        agent: None,
        agent_class: None,
        old_velocity: None,
        new_velocity: None,
        velocity_change: None,
        delta: None,
        k: None,
        predicted_final_velocity: None,
        reason: None,
        method: None,
        retargeted: Vec::new(),
        best_reachable_velocity: None,
    };
    match answer.outcome {
        PlanOutcome::Feasible {
            delta,
            k,
            retarget,
            predicted_final_velocity_mps,
        } => {
            out.delta = Some(delta);
            out.k = Some(k);
            out.predicted_final_velocity = Some(pair(predicted_final_velocity_mps));
            if let Some(r) = retarget {
                out.agent = Some(r.agent + 1);
                out.agent_class = Some(r.class.name().to_owned());
                out.old_velocity = Some(pair(r.old_velocity_mps));
                out.new_velocity = Some(pair(r.new_velocity_mps));
                out.velocity_change = Some(r.change_mps);
            }
        }
        PlanOutcome::Infeasible { reason } => out.reason = Some(reason),
    }
    Ok(out)
}

impl fmt::Display for PlanOutput {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let v = |p: [f64; 2]| format!("({:.4}, {:.4})", p[0], p[1]);
        writeln!(
            f,
            "{} agents, target final velocity {} m/s",
            self.agents,
            v(self.target)
        )?;
        writeln!(
            f,
            "g = {}, h = {}   (the target is reached iff delta*g = h, delta = 1 + k)",
            v(self.g),
            v(self.h)
        )?;
        writeln!(
            f,
            "admissible k: k >= k_min + margin = {:.6} + {}",
            self.k_min, self.margin
        )?;
        if !self.feasible {
            write!(
                f,
                "INFEASIBLE: {}",
                self.reason.as_deref().unwrap_or("no admissible gain")
            )?;
            if let Some(best) = self.best_reachable_velocity {
                write!(f, "\nnearest reachable final velocity: {} m/s", v(best))?;
            }
            return Ok(());
        }
        if self.method.as_deref() == Some("every agent") {
            writeln!(
                f,
                "one agent cannot do it ({}): every agent re-targeted by the least change",
                self.reason.as_deref().unwrap_or("")
            )?;
            for r in &self.retargeted {
                writeln!(
                    f,
                    "re-target agent {}: initial velocity {} -> {} m/s (change {:.4} m/s)",
                    r.agent,
                    v(r.old_velocity),
                    v(r.new_velocity),
                    r.change
                )?;
            }
        } else {
            self.one_agent_line(f, &v)?;
        }
        writeln!(
            f,
            "delta = {:.6}, k = {:.6}",
            self.delta.unwrap_or(f64::NAN),
            self.k.unwrap_or(f64::NAN)
        )?;
        let predicted = self.predicted_final_velocity.map(v).unwrap_or_default();
        write!(
            f,
            "predicted final velocity with these velocities and k: {predicted} m/s\nverdict: FEASIBLE"
        )
    }
}

impl PlanOutput {
    fn one_agent_line(
        &self,
        f: &mut fmt::Formatter<'_>,
        v: &dyn Fn([f64; 2]) -> String,
    ) -> fmt::Result {
        match (self.agent, self.old_velocity, self.new_velocity) {
            (Some(agent), Some(old), Some(new)) => writeln!(
                f,
                "re-target agent {agent} ({}): initial velocity {} -> {} m/s (change {:.4} m/s)",
                self.agent_class.as_deref().unwrap_or("?"),
                v(old),
                v(new),
                self.velocity_change.unwrap_or(f64::NAN)
            )?,
            _ => writeln!(
                f,
                "no agent needs a new velocity: g and h are collinear with an admissible delta"
            )?,
        }
        Ok(())
    }
}
