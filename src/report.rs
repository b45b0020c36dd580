//! What `analyze` and `plan` compute and print: one serialisable output per command,
//! shown as text (`Display`) or as one JSON object.

use std::fmt;
use std::io::Write;

use nalgebra::Vector2;
use serde::Serialize;

use crate::consensus::{
    BandwidthCheck, CouplingGains, LeastChange, PlanOutcome, PlanRequest, RingDigraph,
    StabilityReport, analyze, check_bandwidth, fastest_mode_per_s, least_change_velocities,
    numeric_k_lower_bound, plan, predicted_final_velocity, recommend_gains,
};
use crate::error::InputError;

/// The largest ring `analyze` accepts: everything is `O(m)` (the Fourier blocks), about
/// 0.3 s per million macro-vertices; this keeps memory under a gigabyte.
pub const MAX_ANALYZE_MACRO_VERTICES: usize = 10_000_000;

/// Up to this many agents `analyze` lists the eigenvalues and `w` without being asked.
pub const LISTED_AGENTS: usize = 64;

/// Tolerance of the numeric cross-check of the bound on `k`.
const NUMERIC_BOUND_TOLERANCE: f64 = 1e-9;

/// What `analyze` is asked.
#[derive(Debug, Clone, PartialEq)]
pub struct AnalyzeRequest {
    /// `m`.
    pub macro_vertices: usize,
    /// `k`.
    pub k: f64,
    /// `(α, β)`, if given.
    pub gains: Option<(f64, f64)>,
    /// `k̂` for the recommended gains (default `k`).
    pub design_k: Option<f64>,
    /// Relative margin of the recommended gains.
    pub gain_margin: f64,
    /// Attitude bandwidth (rad/s) and control rate (Hz) for the bandwidth gate.
    pub airframe: Option<(f64, f64)>,
    /// List every eigenvalue and `w` even above [`LISTED_AGENTS`].
    pub list_eigenvalues: bool,
}

/// Recommended gains in the output.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Recommendation {
    /// `α`.
    pub alpha: f64,
    /// `β`.
    pub beta: f64,
    /// `k̂`: the gains hold for every `k` in `[k̂, k]`.
    pub design_k: f64,
    /// The largest Yu bound over `[k̂, k]`.
    pub worst_yu_bound: f64,
    /// `β²/α ÷ worst_yu_bound − 1`.
    pub margin: f64,
}

/// The output of `analyze`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AnalyzeOutput {
    /// `m`.
    pub macro_vertices: usize,
    /// `N = 2m`.
    pub agents: usize,
    /// `k`.
    pub k: f64,
    /// The bound of Theorem 1 (true bound for `m = 1`).
    pub k_min: f64,
    /// The same bound found by bisection on numeric eigenvalues.
    pub k_min_numeric: f64,
    /// `k − k_min`.
    pub k_margin: f64,
    /// Eigenvalues of `L` as `[re, im]`, sorted by real part (`null` when not listed:
    /// above [`LISTED_AGENTS`] without `--eigenvalues`).
    pub laplacian_eigenvalues: Option<Vec<[f64; 2]>>,
    /// The smallest real part over the non-zero eigenvalues (how fast the slowest mode
    /// of `L` decays; negative when `L` is unstable).
    pub smallest_nonzero_real_part: f64,
    /// The largest modulus over the eigenvalues.
    pub largest_modulus: f64,
    /// The left null vector `w = (1, 1+k, 1, 1+k, …)` (`null` when not listed).
    pub w: Option<Vec<f64>>,
    /// Yu's bound on `β²/α` (`null` when `L` is unstable).
    pub yu_bound: Option<f64>,
    /// `α`, when given.
    pub alpha: Option<f64>,
    /// `β`, when given.
    pub beta: Option<f64>,
    /// `β²/α`, when given.
    pub gain_ratio: Option<f64>,
    /// Whether `(α, β)` meet Yu's bound, when given.
    pub meets_yu_bound: Option<bool>,
    /// Largest real part of the closed-loop eigenvalues except the double zero (1/s).
    pub closed_loop_abscissa: Option<f64>,
    /// Recommended gains when none were given and `k` is stable.
    pub recommended: Option<Recommendation>,
    /// The bandwidth gate, with gains and an airframe.
    pub bandwidth: Option<BandwidthCheck>,
    /// The verdict.
    pub stable: bool,
}

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

/// Runs `analyze`.
///
/// # Errors
/// [`InputError`] for `m = 0`, a ring too large, non-finite or non-positive gains, or a
/// design gain outside `(k_min, k]`.
pub fn run_analyze(request: &AnalyzeRequest) -> Result<AnalyzeOutput, InputError> {
    if request.macro_vertices > MAX_ANALYZE_MACRO_VERTICES {
        return Err(InputError::TooLarge {
            given: request.macro_vertices,
            max: MAX_ANALYZE_MACRO_VERTICES,
        });
    }
    let ring = RingDigraph::new(request.macro_vertices, request.k)?;
    let gains = request
        .gains
        .map(|(alpha, beta)| CouplingGains::new(alpha, beta))
        .transpose()?;
    let report: StabilityReport = analyze(&ring, gains)?;
    let recommended = match (gains, report.yu_bound) {
        (None, Some(_)) => {
            let design = recommend_gains(
                request.macro_vertices,
                request.k,
                request.design_k.unwrap_or(request.k),
                request.gain_margin,
            )?;
            Some(Recommendation {
                alpha: design.gains.alpha,
                beta: design.gains.beta,
                design_k: design.design_k,
                worst_yu_bound: design.worst_yu_bound,
                margin: design.margin,
            })
        }
        _ => None,
    };
    let bandwidth = match (gains, request.airframe) {
        (Some(gains), Some((attitude, rate))) => {
            for (name, range, value, ok) in [
                (
                    "--attitude-bandwidth",
                    "(0, 1000] rad/s",
                    attitude,
                    attitude > 0.0 && attitude <= 1000.0,
                ),
                (
                    "--control-rate",
                    "[1, 1000] Hz",
                    rate,
                    (1.0..=1000.0).contains(&rate),
                ),
            ] {
                if !(value.is_finite() && ok) {
                    return Err(InputError::OutOfRange { name, range, value });
                }
            }
            let mu = report.spectrum.nonzero_up_to_conjugation();
            Some(check_bandwidth(
                fastest_mode_per_s(&mu, gains),
                attitude,
                rate,
            ))
        }
        _ => None,
    };
    let check = report.gain_check.as_ref();
    let listed = request.list_eigenvalues || ring.agents() <= LISTED_AGENTS;
    let nonzero = report.spectrum.nonzero_up_to_conjugation();
    Ok(AnalyzeOutput {
        macro_vertices: report.macro_vertices,
        agents: ring.agents(),
        k: report.k,
        k_min: report.k_min,
        k_min_numeric: numeric_k_lower_bound(request.macro_vertices, NUMERIC_BOUND_TOLERANCE)?,
        k_margin: report.k_margin,
        laplacian_eigenvalues: listed.then(|| {
            report
                .spectrum
                .eigenvalues()
                .iter()
                .map(|z| [z.re, z.im])
                .collect()
        }),
        smallest_nonzero_real_part: nonzero.iter().map(|z| z.re).fold(f64::INFINITY, f64::min),
        largest_modulus: nonzero.iter().map(|z| z.norm()).fold(0.0, f64::max),
        w: listed.then(|| (0..ring.agents()).map(|i| ring.w(i)).collect()),
        yu_bound: report.yu_bound,
        alpha: gains.map(|g| g.alpha),
        beta: gains.map(|g| g.beta),
        gain_ratio: check.map(|c| c.ratio),
        meets_yu_bound: check.map(|c| c.yu_margin.is_some_and(|m| m > 0.0)),
        closed_loop_abscissa: check.map(|c| c.closed_loop_abscissa),
        recommended,
        bandwidth,
        stable: report.stable,
    })
}

impl fmt::Display for AnalyzeOutput {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "ring digraph: m = {} macro-vertices, N = {} agents, k = {}",
            self.macro_vertices, self.agents, self.k
        )?;
        writeln!(
            f,
            "bound on k (Theorem 1): k > {:.6}   (numeric eigenvalue check: {:.6})",
            self.k_min, self.k_min_numeric
        )?;
        let side = if self.k_margin > 0.0 {
            "above"
        } else {
            "NOT above"
        };
        writeln!(
            f,
            "  k is {side} the bound: margin k - k_min = {:+.6}",
            self.k_margin
        )?;
        match (&self.laplacian_eigenvalues, &self.w) {
            (Some(eigenvalues), Some(w)) => {
                writeln!(f, "eigenvalues of L:")?;
                for [re, im] in eigenvalues {
                    writeln!(f, "  {re:+.6} {im:+.6}i")?;
                }
                let w: Vec<String> = w.iter().map(|x| format!("{x}")).collect();
                writeln!(f, "left null vector w = ({})", w.join(", "))?;
            }
            _ => {
                writeln!(
                    f,
                    "eigenvalues of L: {} from {} Fourier blocks (list them with --eigenvalues)",
                    self.agents, self.macro_vertices
                )?;
                writeln!(
                    f,
                    "left null vector w = (1, {}, 1, {}, ...)",
                    1.0 + self.k,
                    1.0 + self.k
                )?;
            }
        }
        writeln!(
            f,
            "  smallest non-zero real part {:+.6e}, largest modulus {:.6}",
            self.smallest_nonzero_real_part, self.largest_modulus
        )?;
        match self.yu_bound {
            Some(bound) => writeln!(f, "Yu's bound: beta^2/alpha > {bound:.6}")?,
            None => writeln!(
                f,
                "Yu's bound: none (a non-zero eigenvalue of L is not in the right half-plane)"
            )?,
        }
        if let (Some(alpha), Some(beta), Some(ratio)) = (self.alpha, self.beta, self.gain_ratio) {
            let meets = if self.meets_yu_bound == Some(true) {
                "meets"
            } else {
                "does NOT meet"
            };
            writeln!(
                f,
                "gains: alpha = {alpha}, beta = {beta}, beta^2/alpha = {ratio:.6} ({meets} the bound)"
            )?;
        }
        if let Some(abscissa) = self.closed_loop_abscissa {
            writeln!(
                f,
                "closed-loop spectral abscissa (without the double zero): {abscissa:+.6} 1/s"
            )?;
        }
        if let Some(r) = &self.recommended {
            writeln!(
                f,
                "recommended gains: alpha = {:.6}, beta = {:.6} (beta^2/alpha = {:.0}% above the worst bound {:.6} over k in [{}, {}])",
                r.alpha,
                r.beta,
                100.0 * r.margin,
                r.worst_yu_bound,
                r.design_k,
                self.k
            )?;
        }
        if let Some(b) = &self.bandwidth {
            writeln!(f, "{}", bandwidth_text(b, 1.0))?;
        }
        write!(
            f,
            "verdict: {}",
            if self.stable { "STABLE" } else { "UNSTABLE" }
        )
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
