//! The achievable-velocity planner (paper, Section "Analysis of achievable velocities").
//!
//! In the paper's 1-based numbering, with `g = Σᵢ (v_f − v_{2i}(0))` over the even agents
//! and `h = Σᵢ (v_{2i−1}(0) − v_f)` over the odd ones, the swarm reaches `v_f` iff
//! `δ·g = h` with `δ = 1 + k` and `k` stable. When no feasible `δ` exists, one agent's
//! initial velocity is changed by `Δ`:
//!
//! - an odd agent changes `h` by `Δ`: `Δ = δg − h`, least `|Δ|` at `δ = g·h/|g|²`;
//! - an even agent changes `g` by `−Δ`: `Δ = g − h/δ`, least `|Δ|` at `1/δ = g·h/|h|²`;
//!
//! each clamped to the admissible `δ ∈ [1 + k_min + margin, 1 + k_max]` (and `δ ≠ 0` for
//! an even agent, where `k = −1` would give the even agents no weight). The change is the
//! same for every agent of a class, so within a class the agent whose new velocity is the
//! slowest is chosen, and between classes the smaller change wins (odd on a tie, as in the
//! paper). When `g` and `h` are already collinear with an admissible `δ`, no agent
//! changes. Pure: no I/O.

use nalgebra::Vector2;

use super::graph::{RingDigraph, check_finite};
use super::stability::k_lower_bound;
use super::velocity::predicted_final_velocity;
use crate::error::ConsensusError;

/// What the planner is asked.
#[derive(Debug, Clone, PartialEq)]
pub struct PlanRequest {
    /// Initial horizontal velocities, one per agent, 0-based order (m/s).
    pub velocities_mps: Vec<Vector2<f64>>,
    /// The desired final velocity (m/s).
    pub target_mps: Vector2<f64>,
    /// How far above the stability bound `k` must stay (`k ≥ k_min + margin`).
    pub k_margin: f64,
    /// The largest `k` the planner may choose.
    pub k_max: f64,
    /// If set, a re-targeted agent's new speed may not exceed this (m/s).
    pub max_speed_mps: Option<f64>,
}

/// Which half of a macro-vertex an agent is (paper numbering: odd agents listen to two
/// neighbours, even agents to one).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AgentClass {
    /// Paper's odd agents `2i−1` (0-based even indices).
    Odd,
    /// Paper's even agents `2i` (0-based odd indices).
    Even,
}

impl AgentClass {
    /// The paper's name: `odd` or `even`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Odd => "odd",
            Self::Even => "even",
        }
    }
}

/// A change of one agent's initial velocity.
#[derive(Debug, Clone, PartialEq)]
pub struct Retarget {
    /// The agent, 0-based.
    pub agent: usize,
    /// Its class.
    pub class: AgentClass,
    /// Its initial velocity before (m/s).
    pub old_velocity_mps: Vector2<f64>,
    /// The velocity it must have when consensus starts (m/s).
    pub new_velocity_mps: Vector2<f64>,
    /// `|new − old|` (m/s).
    pub change_mps: f64,
}

/// The planner's answer.
#[derive(Debug, Clone, PartialEq)]
pub struct Plan {
    /// `g` for the target, before any change.
    pub g: Vector2<f64>,
    /// `h` for the target, before any change.
    pub h: Vector2<f64>,
    /// The stability bound on `k`.
    pub k_min: f64,
    /// The outcome.
    pub outcome: PlanOutcome,
}

/// Whether and how the target can be reached.
#[derive(Debug, Clone, PartialEq)]
pub enum PlanOutcome {
    /// Reachable: fly gain `k`, after re-targeting one agent if `retarget` is set.
    Feasible {
        /// `δ = 1 + k`.
        delta: f64,
        /// The gain.
        k: f64,
        /// The agent to re-target, if the velocities as given do not suffice.
        retarget: Option<Retarget>,
        /// The final velocity predicted from the (modified) velocities and `k` (m/s).
        predicted_final_velocity_mps: Vector2<f64>,
    },
    /// Not reachable under the constraints.
    Infeasible {
        /// Why, in words.
        reason: String,
    },
}

impl Plan {
    /// Whether the target is reachable.
    pub fn is_feasible(&self) -> bool {
        matches!(self.outcome, PlanOutcome::Feasible { .. })
    }
}

/// `g = Σ (v_f − v_even)` and `h = Σ (v_odd − v_f)` in the paper's numbering.
pub fn g_and_h(velocities: &[Vector2<f64>], target: Vector2<f64>) -> (Vector2<f64>, Vector2<f64>) {
    let mut g = Vector2::zeros();
    let mut h = Vector2::zeros();
    for pair in velocities.chunks(2) {
        h += pair[0] - target;
        if let Some(even) = pair.get(1) {
            g += target - even;
        }
    }
    (g, h)
}

/// The initial velocity agent `agent` (0-based) must have so that the target is reached
/// with `δ = 1 + k` (the paper's manual step). `None` for an even agent with `δ = 0`.
pub fn retarget_velocity(
    velocities: &[Vector2<f64>],
    target: Vector2<f64>,
    agent: usize,
    delta: f64,
) -> Option<Vector2<f64>> {
    let (g, h) = g_and_h(velocities, target);
    let change = if agent.is_multiple_of(2) {
        g * delta - h
    } else if delta == 0.0 {
        return None;
    } else {
        g - h / delta
    };
    velocities.get(agent).map(|v| v + change)
}

/// Plans the gain (and, if needed, one agent's new initial velocity) for the target.
///
/// # Errors
/// Invalid input: an odd or zero agent count, non-finite numbers, a negative margin, or
/// `k_max` not finite. An unreachable target is an [`PlanOutcome::Infeasible`] answer.
pub fn plan(request: &PlanRequest) -> Result<Plan, ConsensusError> {
    validate(request)?;
    let n = request.velocities_mps.len();
    let k_min = k_lower_bound(n / 2)?;
    let (g, h) = g_and_h(&request.velocities_mps, request.target_mps);
    let delta_range = (1.0 + k_min + request.k_margin, 1.0 + request.k_max);
    if delta_range.0 > delta_range.1 {
        let reason = format!(
            "no admissible gain: k_min + margin = {:.6} exceeds k_max = {}",
            k_min + request.k_margin,
            request.k_max
        );
        return Ok(Plan {
            g,
            h,
            k_min,
            outcome: PlanOutcome::Infeasible { reason },
        });
    }
    let odd = best_odd_change(g, h, delta_range);
    let even = best_even_change(g, h, delta_range);
    let scale = 1.0
        + request.target_mps.norm()
        + request
            .velocities_mps
            .iter()
            .map(|v| v.norm())
            .fold(0.0, f64::max);
    let mut best: Option<(f64, Option<Retarget>)> = None;
    for (class, candidate) in [(AgentClass::Odd, odd), (AgentClass::Even, even)] {
        let Some((delta, change)) = candidate else {
            continue;
        };
        if change.norm() <= 1e-12 * scale {
            best = Some((delta, None));
            break;
        }
        let Some(retarget) = pick_agent(request, class, change) else {
            continue;
        };
        let better = best.as_ref().is_none_or(|(_, r)| {
            r.as_ref()
                .is_some_and(|r| retarget.change_mps < r.change_mps)
        });
        if better {
            best = Some((delta, Some(retarget)));
        }
    }
    let outcome = match best {
        None => PlanOutcome::Infeasible {
            reason: format!(
                "every re-targeted agent would need a speed above the limit of {} m/s",
                request.max_speed_mps.unwrap_or(f64::INFINITY)
            ),
        },
        Some((delta, retarget)) => {
            let mut velocities = request.velocities_mps.clone();
            if let Some(r) = &retarget {
                velocities[r.agent] = r.new_velocity_mps;
            }
            let ring = RingDigraph::new(n / 2, delta - 1.0)?;
            PlanOutcome::Feasible {
                delta,
                k: delta - 1.0,
                retarget,
                predicted_final_velocity_mps: predicted_final_velocity(&ring, &velocities)?,
            }
        }
    };
    Ok(Plan {
        g,
        h,
        k_min,
        outcome,
    })
}

fn validate(request: &PlanRequest) -> Result<(), ConsensusError> {
    let n = request.velocities_mps.len();
    if n == 0 {
        return Err(ConsensusError::NoMacroVertices);
    }
    if n % 2 == 1 {
        return Err(ConsensusError::OddAgentCount(n));
    }
    for v in &request.velocities_mps {
        check_finite("initial velocity component", v.x)?;
        check_finite("initial velocity component", v.y)?;
    }
    check_finite("target velocity component", request.target_mps.x)?;
    check_finite("target velocity component", request.target_mps.y)?;
    check_finite("k margin", request.k_margin)?;
    check_finite("k_max", request.k_max)?;
    if request.k_margin < 0.0 {
        return Err(ConsensusError::NotPositive {
            name: "k margin",
            value: request.k_margin,
        });
    }
    if let Some(limit) = request.max_speed_mps {
        check_finite("max speed", limit)?;
        if limit <= 0.0 {
            return Err(ConsensusError::NotPositive {
                name: "max speed",
                value: limit,
            });
        }
    }
    Ok(())
}

/// Least `|δg − h|` over `δ ∈ [lo, hi]`: returns `(δ, Δ)`.
fn best_odd_change(
    g: Vector2<f64>,
    h: Vector2<f64>,
    (lo, hi): (f64, f64),
) -> Option<(f64, Vector2<f64>)> {
    let g2 = g.norm_squared();
    // With g = 0 every δ gives the same change; take k = 0 (the plain ring) if admissible.
    let unconstrained = if g2 > 0.0 { g.dot(&h) / g2 } else { 1.0 };
    let delta = unconstrained.clamp(lo, hi);
    Some((delta, g * delta - h))
}

/// Least `|g − t·h|` over `t = 1/δ` with `δ ∈ [lo, hi] \ {0}`: returns `(δ, Δ)`.
fn best_even_change(
    g: Vector2<f64>,
    h: Vector2<f64>,
    (lo, hi): (f64, f64),
) -> Option<(f64, Vector2<f64>)> {
    let h2 = h.norm_squared();
    let unconstrained = if h2 > 0.0 { g.dot(&h) / h2 } else { 1.0 };
    // The admissible t form one or two closed intervals (δ = 0 is excluded).
    let mut intervals: [Option<(f64, f64)>; 2] = [None, None];
    if lo > 0.0 {
        intervals[0] = Some((1.0 / hi, 1.0 / lo));
    } else if hi < 0.0 {
        intervals[0] = Some((1.0 / lo, 1.0 / hi));
    } else {
        if lo < 0.0 {
            intervals[0] = Some((f64::NEG_INFINITY, 1.0 / lo));
        }
        if hi > 0.0 {
            intervals[1] = Some((1.0 / hi, f64::INFINITY));
        }
    }
    intervals
        .iter()
        .flatten()
        .map(|&(a, b)| {
            let t = unconstrained.clamp(a, b);
            (1.0 / t, g - h * t)
        })
        .min_by(|a, b| a.1.norm().total_cmp(&b.1.norm()))
}

/// The agent of `class` whose new velocity is the slowest and within the speed limit.
fn pick_agent(request: &PlanRequest, class: AgentClass, change: Vector2<f64>) -> Option<Retarget> {
    let first = match class {
        AgentClass::Odd => 0,
        AgentClass::Even => 1,
    };
    request
        .velocities_mps
        .iter()
        .enumerate()
        .skip(first)
        .step_by(2)
        .map(|(agent, old)| Retarget {
            agent,
            class,
            old_velocity_mps: *old,
            new_velocity_mps: old + change,
            change_mps: change.norm(),
        })
        .filter(|r| {
            request
                .max_speed_mps
                .is_none_or(|limit| r.new_velocity_mps.norm() <= limit)
        })
        .min_by(|a, b| {
            a.new_velocity_mps
                .norm()
                .total_cmp(&b.new_velocity_mps.norm())
                .then(a.agent.cmp(&b.agent))
        })
}
