//! `analyze`: the ring's stability, the bound on `k`, the recommended gains and the
//! bandwidth gate.

use std::fmt;

use serde::Serialize;

use super::bandwidth_text;
use crate::consensus::{
    BandwidthCheck, CouplingGains, RingDigraph, StabilityReport, analyze, check_bandwidth,
    fastest_mode_per_s, numeric_k_lower_bound, recommend_gains,
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
