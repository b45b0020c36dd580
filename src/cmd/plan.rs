//! `ringswarm plan`: whether the ring can reach a target velocity, with which `k` and
//! which agent re-targeted, printed as text or JSON (computed by [`crate::report`]).

use crate::cli::PlanArgs;
use crate::consensus::PlanRequest;
use crate::report::{emit, run_plan_everyone};

/// Prints the plan; `Ok(feasible)`.
///
/// # Errors
/// A value the planner refuses, or stdout closed.
pub fn run(args: &PlanArgs) -> anyhow::Result<bool> {
    let output = run_plan_everyone(
        &PlanRequest {
            velocities_mps: args.initial_velocities.0.clone(),
            target_mps: args.target,
            k_margin: args.margin,
            k_max: args.k_max,
            max_speed_mps: args.max_speed,
        },
        args.k,
    )?;
    if args.json {
        emit(&serde_json::to_string_pretty(&output)?)?;
    } else {
        emit(&output.to_string())?;
    }
    Ok(output.feasible)
}
