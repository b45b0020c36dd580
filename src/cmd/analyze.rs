//! `ringswarm analyze`: the stability bound, Yu's bound and the gains of a ring, printed
//! as text or JSON (computed by [`crate::report`]).

use crate::cli::AnalyzeArgs;
use crate::report::{AnalyzeRequest, emit, run_analyze};

/// Prints the analysis; `Ok(stable)`.
///
/// # Errors
/// A value the analysis refuses, or stdout closed.
pub fn run(args: &AnalyzeArgs) -> anyhow::Result<bool> {
    let output = run_analyze(&AnalyzeRequest {
        macro_vertices: args.macro_vertices,
        k: args.k,
        gains: args.alpha.zip(args.beta),
        design_k: args.design_k,
        gain_margin: args.gain_margin,
        airframe: args.attitude_bandwidth.map(|a| (a, args.control_rate)),
        list_eigenvalues: args.eigenvalues,
    })?;
    if args.json {
        emit(&serde_json::to_string_pretty(&output)?)?;
    } else {
        emit(&output.to_string())?;
    }
    Ok(output.stable)
}
