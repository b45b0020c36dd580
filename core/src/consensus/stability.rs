//! Stability of the double-integrator consensus over the ring digraph.
//!
//! - **Theorem 1 (corrected for `m = 1`).** The non-zero eigenvalues of `L` have positive
//!   real part iff `k > −2 + √2·cos(π/m)` for `m ≥ 2`, and iff `k > −2` for `m = 1`
//!   (the printed formula would give `−2 − √2` there, but `L = [[1+k, −1−k], [−1, 1]]`
//!   has eigenvalues `0` and `2+k`).
//! - **Yu's bound.** With every non-zero `μ` in the open right half-plane, consensus
//!   holds iff `β²/α > max Im(μ)² / (Re(μ)·|μ|²)`.
//! - **Closed loop.** The `2N × 2N` matrix `[[0, I], [−αL, −βL]]` has, for each
//!   eigenvalue `μ` of `L`, the two eigenvalues `s` with `s² + βμ·s + αμ = 0`; `μ = 0`
//!   gives the double zero of the drifting consensus. Its spectral abscissa here means
//!   the largest real part over all the other eigenvalues.
//!
//! The spectrum comes from the ring's Fourier blocks in `O(m)` ([`RingSpectrum`]); every
//! formula is cross-checked in tests against dense eigenvalues (faer) of the `2m × 2m`
//! Laplacian. Pure: no I/O, no logging.

use nalgebra::{Complex, DMatrix};

use super::graph::{RingDigraph, check_finite};
use super::spectrum::{RingModes, RingSpectrum};
use crate::error::ConsensusError;

/// The coupling strengths of the law `u = −αL(p−d) − βLv`, both strictly positive.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CouplingGains {
    /// Position coupling `α` (1/s²).
    pub alpha: f64,
    /// Velocity coupling `β` (1/s).
    pub beta: f64,
}

impl CouplingGains {
    /// Validates `α > 0` and `β > 0`, both finite.
    ///
    /// # Errors
    /// [`ConsensusError::NonFinite`] or [`ConsensusError::NotPositive`], naming the gain.
    pub fn new(alpha: f64, beta: f64) -> Result<Self, ConsensusError> {
        for (name, value) in [("alpha", alpha), ("beta", beta)] {
            check_finite(name, value)?;
            if value <= 0.0 {
                return Err(ConsensusError::NotPositive { name, value });
            }
        }
        Ok(Self { alpha, beta })
    }

    /// `β²/α`, the quantity Yu's bound constrains (1, dimensionless).
    pub fn ratio(&self) -> f64 {
        self.beta * self.beta / self.alpha
    }
}

/// The lower bound on `k` (Theorem 1, with the true value `−2` for `m = 1`).
///
/// # Errors
/// [`ConsensusError::NoMacroVertices`] for `m = 0`.
pub fn k_lower_bound(macro_vertices: usize) -> Result<f64, ConsensusError> {
    match macro_vertices {
        0 => Err(ConsensusError::NoMacroVertices),
        1 => Ok(-2.0),
        m => Ok(-2.0 + std::f64::consts::SQRT_2 * (std::f64::consts::PI / m as f64).cos()),
    }
}

/// All eigenvalues of a real square matrix, sorted by real then imaginary part.
///
/// Computed with faer's Hessenberg QR. nalgebra's real Schur iteration stalls on a few
/// percent of these ring Laplacians (for example `m = 3`, `1.1 < k < 1.6`), so it is not
/// used here.
///
/// # Errors
/// [`ConsensusError::EigenvaluesDidNotConverge`] if the iteration fails.
pub fn eigenvalues(matrix: DMatrix<f64>) -> Result<Vec<Complex<f64>>, ConsensusError> {
    let size = matrix.nrows();
    let dense = faer::Mat::<f64>::from_fn(size, size, |i, j| matrix[(i, j)]);
    let mut eigs: Vec<Complex<f64>> = dense
        .eigenvalues()
        .map_err(|_| ConsensusError::EigenvaluesDidNotConverge { size })?;
    eigs.sort_by(|a, b| a.re.total_cmp(&b.re).then(a.im.total_cmp(&b.im)));
    Ok(eigs)
}

/// The eigenvalues of `L` without the one at zero (the one of smallest modulus; the
/// ring always has a spanning tree, so zero is an eigenvalue).
pub fn nonzero_eigenvalues(laplacian_eigs: &[Complex<f64>]) -> Vec<Complex<f64>> {
    let zero_at = laplacian_eigs
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.norm().total_cmp(&b.1.norm()))
        .map(|(i, _)| i);
    laplacian_eigs
        .iter()
        .enumerate()
        .filter(|(i, _)| Some(*i) != zero_at)
        .map(|(_, mu)| *mu)
        .collect()
}

/// Yu's bound `max Im(μ)²/(Re(μ)|μ|²)` over the non-zero eigenvalues; `None` when some
/// non-zero eigenvalue is not in the open right half-plane (no `α, β` can help then).
pub fn yu_bound(nonzero_eigs: &[Complex<f64>]) -> Option<f64> {
    let mut bound = 0.0_f64;
    for mu in nonzero_eigs {
        if mu.re <= 0.0 {
            return None;
        }
        bound = bound.max(mu.im * mu.im / (mu.re * mu.norm_sqr()));
    }
    Some(bound)
}

/// The closed-loop eigenvalues belonging to the non-zero eigenvalues of `L`: both roots
/// of `s² + βμ·s + αμ = 0` for each `μ`.
pub fn closed_loop_eigenvalues(
    nonzero_eigs: &[Complex<f64>],
    gains: CouplingGains,
) -> Vec<Complex<f64>> {
    nonzero_eigs
        .iter()
        .flat_map(|&mu| {
            let b = mu * gains.beta;
            let c = mu * gains.alpha;
            let root = (b * b - c * 4.0).sqrt();
            [(-b + root) * 0.5, (-b - root) * 0.5]
        })
        .collect()
}

/// The largest real part of the closed-loop eigenvalues other than the double zero.
pub fn closed_loop_abscissa(nonzero_eigs: &[Complex<f64>], gains: CouplingGains) -> f64 {
    closed_loop_eigenvalues(nonzero_eigs, gains)
        .iter()
        .map(|s| s.re)
        .fold(f64::NEG_INFINITY, f64::max)
}

/// The `2N × 2N` closed-loop matrix `[[0, I], [−αL, −βL]]` (state `[p; v]`, one axis).
pub fn closed_loop_matrix(laplacian: &DMatrix<f64>, gains: CouplingGains) -> DMatrix<f64> {
    let n = laplacian.nrows();
    let mut a = DMatrix::zeros(2 * n, 2 * n);
    a.view_mut((0, n), (n, n)).fill_with_identity();
    a.view_mut((n, 0), (n, n))
        .copy_from(&(laplacian * -gains.alpha));
    a.view_mut((n, n), (n, n))
        .copy_from(&(laplacian * -gains.beta));
    a
}

/// Whether every non-zero eigenvalue of `L(m, k)`, computed from the Fourier blocks, has a
/// positive real part.
///
/// # Errors
/// As [`RingDigraph::new`].
pub fn laplacian_is_stable_numerically(
    macro_vertices: usize,
    k: f64,
) -> Result<bool, ConsensusError> {
    RingDigraph::new(macro_vertices, k)?;
    Ok(RingModes::new(macro_vertices).is_stable(k))
}

/// The stability threshold on `k` found by bisection on the eigenvalues of the Fourier
/// blocks (independent of Theorem 1's closed form), to within `tolerance`: `O(m)` per step.
///
/// # Errors
/// [`ConsensusError::NoMacroVertices`] for `m = 0`; [`ConsensusError::NotPositive`] for a
/// tolerance that is not positive.
pub fn numeric_k_lower_bound(macro_vertices: usize, tolerance: f64) -> Result<f64, ConsensusError> {
    if tolerance.is_nan() || tolerance <= 0.0 {
        return Err(ConsensusError::NotPositive {
            name: "tolerance",
            value: tolerance,
        });
    }
    RingDigraph::new(macro_vertices, 0.0)?;
    let modes = RingModes::new(macro_vertices);
    // k = 0 is the plain directed cycle (stable for every m); below k = −2 the eigenvalue
    // 2+k of the first Fourier block is negative (unstable for every m).
    let (mut unstable, mut stable) = (-2.5_f64, 0.0_f64);
    while stable - unstable > tolerance {
        let mid = 0.5 * (stable + unstable);
        if modes.is_stable(mid) {
            stable = mid;
        } else {
            unstable = mid;
        }
    }
    Ok(0.5 * (stable + unstable))
}

/// How a pair `(α, β)` fares against Yu's bound and the closed loop.
#[derive(Debug, Clone, PartialEq)]
pub struct GainCheck {
    /// The gains checked.
    pub gains: CouplingGains,
    /// `β²/α`.
    pub ratio: f64,
    /// `β²/α ÷ bound − 1` (positive when the bound is met); `None` when `L` is unstable.
    pub yu_margin: Option<f64>,
    /// Largest real part of the closed-loop eigenvalues except the double zero (1/s).
    pub closed_loop_abscissa: f64,
}

/// Everything `analyze` reports about a ring and, optionally, a pair of gains.
#[derive(Debug, Clone, PartialEq)]
pub struct StabilityReport {
    /// `m`.
    pub macro_vertices: usize,
    /// `k`.
    pub k: f64,
    /// The bound of Theorem 1 (true bound for `m = 1`).
    pub k_min: f64,
    /// `k − k_min`: positive when `L` is stable.
    pub k_margin: f64,
    /// The eigenvalues of `L`, from its Fourier blocks.
    pub spectrum: RingSpectrum,
    /// Yu's bound on `β²/α`; `None` when `L` is unstable.
    pub yu_bound: Option<f64>,
    /// The gain check, when gains were given.
    pub gain_check: Option<GainCheck>,
    /// `L` stable, and when gains were given, the closed loop too.
    pub stable: bool,
}

/// Analyses the ring `(m, k)` and, when given, the gains `(α, β)`.
///
/// An unstable `k` is an answer (with a negative margin), not an error.
///
/// # Errors
/// Only for invalid inputs ([`RingDigraph::new`]).
pub fn analyze(
    ring: &RingDigraph,
    gains: Option<CouplingGains>,
) -> Result<StabilityReport, ConsensusError> {
    let k_min = k_lower_bound(ring.macro_vertices())?;
    let spectrum = RingSpectrum::of(ring);
    let nonzero = spectrum.nonzero_up_to_conjugation();
    let yu = yu_bound(&nonzero);
    let laplacian_stable = yu.is_some();
    let gain_check = gains.map(|gains| {
        let ratio = gains.ratio();
        GainCheck {
            gains,
            ratio,
            yu_margin: yu.map(|bound| ratio / bound - 1.0),
            closed_loop_abscissa: closed_loop_abscissa(&nonzero, gains),
        }
    });
    let stable = laplacian_stable
        && gain_check
            .as_ref()
            .is_none_or(|check| check.closed_loop_abscissa < 0.0);
    Ok(StabilityReport {
        macro_vertices: ring.macro_vertices(),
        k: ring.k(),
        k_min,
        k_margin: ring.k() - k_min,
        spectrum,
        yu_bound: yu,
        gain_check,
        stable,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn single_macro_vertex_bound_is_minus_two() {
        assert_eq!(k_lower_bound(1).unwrap(), -2.0);
        let numeric = numeric_k_lower_bound(1, 1e-9).unwrap();
        assert!((numeric + 2.0).abs() < 1e-6, "numeric bound {numeric}");
    }

    #[test]
    fn two_macro_vertices_bound_is_minus_two() {
        // cos(π/2) = 0: the formula and the m = 1 special case agree.
        assert!((k_lower_bound(2).unwrap() + 2.0).abs() < 1e-15);
    }

    #[test]
    fn closed_loop_matrix_eigenvalues_match_the_quadratic_roots() {
        let ring = RingDigraph::new(3, -0.5).unwrap();
        let gains = CouplingGains::new(1.3, 2.2).unwrap();
        let l = ring.laplacian();
        let numeric = eigenvalues(closed_loop_matrix(&l, gains)).unwrap();
        let analytic =
            closed_loop_eigenvalues(&nonzero_eigenvalues(&eigenvalues(l).unwrap()), gains);
        // Every analytic root has a numeric partner; the two left over are the double zero.
        for s in &analytic {
            let nearest = numeric
                .iter()
                .map(|z| (z - s).norm())
                .fold(f64::INFINITY, f64::min);
            assert!(
                nearest < 1e-8,
                "root {s} has no numeric partner ({nearest})"
            );
        }
        let near_zero = numeric.iter().filter(|z| z.norm() < 1e-6).count();
        assert_eq!(near_zero, 2);
    }

    #[test]
    fn bad_gains_are_refused_with_their_name() {
        assert_eq!(
            CouplingGains::new(0.0, 1.0),
            Err(ConsensusError::NotPositive {
                name: "alpha",
                value: 0.0
            })
        );
        assert_eq!(
            CouplingGains::new(1.0, -2.0),
            Err(ConsensusError::NotPositive {
                name: "beta",
                value: -2.0
            })
        );
        assert!(matches!(
            CouplingGains::new(f64::INFINITY, 1.0),
            Err(ConsensusError::NonFinite { name: "alpha", .. })
        ));
    }

    #[test]
    fn unstable_k_is_an_answer_not_an_error() {
        let ring = RingDigraph::new(4, -1.2).unwrap();
        let report = analyze(&ring, None).unwrap();
        assert!(!report.stable);
        assert!(report.yu_bound.is_none());
        assert!((report.k_margin + 0.2).abs() < 1e-12);
    }
}
