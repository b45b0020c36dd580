//! What `analyze` and `plan` compute and print: one serialisable output per command,
//! shown as text (`Display`) or as one JSON object.

use std::io::Write;

use crate::consensus::BandwidthCheck;

mod analyze;
mod plan;

pub use analyze::{
    AnalyzeOutput, AnalyzeRequest, LISTED_AGENTS, MAX_ANALYZE_MACRO_VERTICES, Recommendation,
    run_analyze,
};
pub use plan::{PlanOutput, Retarget, run_plan, run_plan_everyone};

/// Writes `text` and a newline to stdout. A closed pipe (`ringswarm analyze … | head`) is
/// not an error: the reader has what it wanted.
///
/// # Errors
/// Any other write error.
pub fn emit(text: &str) -> std::io::Result<()> {
    let mut out = std::io::stdout().lock();
    match writeln!(out, "{text}").and_then(|()| out.flush()) {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        other => other,
    }
}

/// The bandwidth gate in words, for gains flown at time scale `time_scale`.
pub fn bandwidth_text(b: &BandwidthCheck, time_scale: f64) -> String {
    let limit = match b.limited_by {
        "attitude" => format!(
            "{:.1} × attitude bandwidth {} rad/s",
            crate::consensus::ATTITUDE_RATIO,
            b.attitude_bandwidth_rps
        ),
        "hop between shards" => format!(
            "{} / hop between shards {} ms",
            crate::consensus::HOP_PRODUCT,
            b.hop_s * 1e3
        ),
        _ => format!(
            "{} × control rate {} Hz",
            crate::consensus::SAMPLING_PRODUCT,
            b.control_rate_hz
        ),
    };
    let fits = time_scale * b.scale_that_fits;
    if b.fits {
        format!(
            "bandwidth: the law's fastest mode {:.2} 1/s fits the airframe ({:.2} 1/s = {limit}); time scales up to {:.2} fit",
            b.fastest_mode_per_s, b.allowed_per_s, fits
        )
    } else {
        format!(
            "bandwidth: the law's fastest mode {:.2} 1/s is too fast for the airframe ({:.2} 1/s = {limit}): fly gains.time_scale = {:.2} or less (now {time_scale})",
            b.fastest_mode_per_s, b.allowed_per_s, fits
        )
    }
}
