//! Gain design: `(α, β)` that meet Yu's bound for every gain in `[k̂, k]`.
//!
//! The paper designs `(α, β)` at a gain `k̂` closer to the stability bound than the gain
//! `k` actually flown, so that the design survives a change of `k`. Yu's bound is not
//! monotone in `k` (it grows without limit near the bound and again for large `k`), so
//! the design takes the largest bound over the whole interval `[k̂, k]`: a dense grid,
//! refined around its worst point, then multiplied by `1 + margin`. `α` is fixed at 1 and
//! `β = √((1 + margin)·bound)`. Pure: no I/O.

use super::graph::check_finite;
use super::spectrum::RingModes;
use super::stability::{CouplingGains, k_lower_bound, yu_bound};
use crate::error::ConsensusError;

/// Grid points over `[k̂, k]` before refinement.
const GRID_POINTS: usize = 65;

/// A recommended pair of gains and what it was designed for.
#[derive(Debug, Clone, PartialEq)]
pub struct GainDesign {
    /// The design gain `k̂` (the low end of the interval).
    pub design_k: f64,
    /// The gain flown (the high end of the interval).
    pub k: f64,
    /// The largest Yu bound found over `[k̂, k]`.
    pub worst_yu_bound: f64,
    /// Where in `[k̂, k]` it was found.
    pub worst_k: f64,
    /// The relative margin: `β²/α = (1 + margin)·worst_yu_bound`.
    pub margin: f64,
    /// The recommended gains (`α = 1`).
    pub gains: CouplingGains,
}

/// Recommends `(α, β)` valid for every gain in `[design_k, k]` with a relative margin.
///
/// # Errors
/// [`ConsensusError::BadDesignGain`] unless `k_min < design_k ≤ k`;
/// [`ConsensusError::NotPositive`] for a margin that is not positive; non-finite inputs.
pub fn recommend_gains(
    macro_vertices: usize,
    k: f64,
    design_k: f64,
    margin: f64,
) -> Result<GainDesign, ConsensusError> {
    check_finite("k", k)?;
    check_finite("design k", design_k)?;
    check_finite("margin", margin)?;
    if margin <= 0.0 {
        return Err(ConsensusError::NotPositive {
            name: "margin",
            value: margin,
        });
    }
    let k_min = k_lower_bound(macro_vertices)?;
    if !(design_k > k_min && design_k <= k) {
        return Err(ConsensusError::BadDesignGain { design_k, k, k_min });
    }
    let modes = RingModes::new(macro_vertices);
    let bound_at = |kk: f64| -> Result<f64, ConsensusError> {
        check_finite("k", kk)?;
        // Inside (k_min, ∞) the Laplacian is stable, so the bound exists; an infinite
        // value would only mean an eigenvalue on the imaginary axis.
        Ok(yu_bound(&modes.spectrum(kk).nonzero_up_to_conjugation()).unwrap_or(f64::INFINITY))
    };
    // A design at k alone (the usual case) needs one evaluation, not a grid.
    let points = if k > design_k { GRID_POINTS } else { 1 };
    let step = (k - design_k) / (GRID_POINTS - 1) as f64;
    let mut worst = (design_k, bound_at(design_k)?);
    for i in 1..points {
        let kk = design_k + step * i as f64;
        let b = bound_at(kk)?;
        if b > worst.1 {
            worst = (kk, b);
        }
    }
    // Golden-section refinement of the maximum in the grid cell around the worst point.
    let (mut lo, mut hi) = ((worst.0 - step).max(design_k), (worst.0 + step).min(k));
    let ratio = 0.5 * (5.0_f64.sqrt() - 1.0);
    for _ in 0..40 {
        if hi - lo <= 1e-12 {
            break;
        }
        let a = hi - ratio * (hi - lo);
        let b = lo + ratio * (hi - lo);
        let (fa, fb) = (bound_at(a)?, bound_at(b)?);
        if fa > worst.1 {
            worst = (a, fa);
        }
        if fb > worst.1 {
            worst = (b, fb);
        }
        if fa >= fb { hi = b } else { lo = a }
    }
    let beta = ((1.0 + margin) * worst.1).sqrt();
    Ok(GainDesign {
        design_k,
        k,
        worst_yu_bound: worst.1,
        worst_k: worst.0,
        margin,
        gains: CouplingGains::new(1.0, beta.max(f64::MIN_POSITIVE))?,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::consensus::RingDigraph;
    use crate::consensus::stability::{closed_loop_abscissa, eigenvalues, nonzero_eigenvalues};

    #[test]
    fn design_at_k_alone_meets_the_bound_with_the_margin() {
        let design = recommend_gains(4, -0.5, -0.5, 0.2).unwrap();
        // Yu's bound at m = 4, k = −0.5 is 5.389377 (numpy: max Im²/(Re|μ|²)).
        assert!((design.worst_yu_bound - 5.389_377_276_6).abs() < 1e-8);
        assert!((design.gains.ratio() - 1.2 * 5.389_377_276_6).abs() < 1e-8);
    }

    #[test]
    fn design_over_an_interval_is_stable_everywhere_in_it() {
        let (m, k_hat, k) = (4, -0.7, 3.0);
        let design = recommend_gains(m, k, k_hat, 0.1).unwrap();
        for i in 0..=200 {
            let kk = k_hat + (k - k_hat) * f64::from(i) / 200.0;
            let ring = RingDigraph::new(m, kk).unwrap();
            let nonzero = nonzero_eigenvalues(&eigenvalues(ring.laplacian()).unwrap());
            assert!(
                closed_loop_abscissa(&nonzero, design.gains) < 0.0,
                "k = {kk}"
            );
        }
    }

    #[test]
    fn design_gain_outside_the_interval_is_refused() {
        assert!(matches!(
            recommend_gains(4, 1.0, -1.5, 0.1),
            Err(ConsensusError::BadDesignGain { .. })
        ));
        assert!(matches!(
            recommend_gains(4, 1.0, 2.0, 0.1),
            Err(ConsensusError::BadDesignGain { .. })
        ));
        assert!(matches!(
            recommend_gains(4, 1.0, 0.5, 0.0),
            Err(ConsensusError::NotPositive { name: "margin", .. })
        ));
    }
}
