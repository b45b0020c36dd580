//! The spectrum of the ring's Laplacian in `O(m)`, from its block-circulant structure.
//!
//! Order the agents by macro-vertex, `x_j = (x_{2j}, x_{2j+1})`. Block row `j` of `L`
//! is `A₀·x_j + A₁·x_{j−1}` with `A₀ = [[1+k, −k], [−1, 1]]` and `A₁ = [[0, −1], [0, 0]]`
//! (for `m = 1` both fall in one block, `A₀ + A₁`), so `L` is block-circulant. On
//! `x_j = v·e^{2πiℓj/m}` it acts as `B_ℓ = A₀ + ω_ℓ·A₁` with `ω_ℓ = e^{−2πiℓ/m}`, whose
//! characteristic polynomial is `μ² − (2+k)·μ + (1 − ω_ℓ)`: the `m` Fourier blocks give
//! all `2m` eigenvalues. Block `m − ℓ` is the complex conjugate of block `ℓ`, so blocks
//! `0..=⌊m/2⌋` hold everything the stability questions ask: whether every non-zero
//! eigenvalue is in the right half-plane, Yu's bound, the closed loop's abscissa and its
//! fastest mode are all unchanged by conjugation.
//!
//! Numerics: `1 − ω_ℓ = 2·sin²(θ/2) + i·sin θ` (no cancellation at small `θ = 2πℓ/m`;
//! exactly 2 at `ℓ = m/2`, whose block is real and whose complex roots are exact conjugates),
//! and the roots are `q` and `(1 − ω_ℓ)/q` with `q` the root of larger modulus, so the
//! small eigenvalues of a large ring (`|μ| ~ 2π/m`) keep their relative accuracy. Block 0
//! is exactly `{0, 2+k}`.
//!
//! The dense path ([`super::eigenvalues`] on [`RingDigraph::laplacian`]) stays as the
//! cross-check in tests. Pure: no I/O, no logging.

use nalgebra::Complex;

use super::graph::RingDigraph;

/// `1 − ω_ℓ` for the Fourier blocks `ℓ = 0..=⌊m/2⌋` of a ring with `m` macro-vertices:
/// what the spectrum needs that does not depend on `k`, computed once for many `k`.
#[derive(Debug, Clone, PartialEq)]
pub struct RingModes {
    macro_vertices: usize,
    one_minus_omega: Vec<Complex<f64>>,
}

impl RingModes {
    /// The modes of a ring with `macro_vertices = m ≥ 1` (`m = 0` gives no block).
    pub fn new(macro_vertices: usize) -> Self {
        let m = macro_vertices as f64;
        let one_minus_omega = (0..=macro_vertices / 2)
            .map(|l| {
                if 2 * l == macro_vertices {
                    // ω = −1 exactly: a real block, whose complex roots are then exact
                    // conjugates.
                    return Complex::new(2.0, 0.0);
                }
                let half_theta = std::f64::consts::PI * l as f64 / m;
                let (s, c) = half_theta.sin_cos();
                Complex::new(2.0 * s * s, 2.0 * s * c)
            })
            .collect();
        Self {
            macro_vertices,
            one_minus_omega,
        }
    }

    /// The spectrum of `L(m, k)`.
    pub fn spectrum(&self, k: f64) -> RingSpectrum {
        RingSpectrum {
            macro_vertices: self.macro_vertices,
            blocks: self
                .one_minus_omega
                .iter()
                .map(|&d| block_roots(2.0 + k, d))
                .collect(),
        }
    }

    /// Whether every non-zero eigenvalue of `L(m, k)` has a positive real part, without
    /// storing the spectrum.
    pub fn is_stable(&self, k: f64) -> bool {
        self.one_minus_omega
            .iter()
            .all(|&d| nonzero_roots_stable(block_roots(2.0 + k, d), d))
    }
}

/// The two roots of `μ² − c·μ + d = 0` (`d = 1 − ω_ℓ`); for `d = 0` exactly `[0, c]`.
fn block_roots(c: f64, d: Complex<f64>) -> [Complex<f64>; 2] {
    if d == Complex::new(0.0, 0.0) {
        return [Complex::new(0.0, 0.0), Complex::new(c, 0.0)];
    }
    if d.im == 0.0 && c * c < 4.0 * d.re {
        // A real block with complex roots: an exact conjugate pair.
        let half = Complex::new(0.5 * c, 0.5 * (4.0 * d.re - c * c).sqrt());
        return [half, half.conj()];
    }
    let root = principal_sqrt(Complex::new(c * c, 0.0) - d * 4.0);
    // The sum with the larger modulus: c is real, so compare c·Re(root) with 0.
    let q = if c * root.re >= 0.0 {
        (root + c) * 0.5
    } else {
        (-root + c) * 0.5
    };
    // q·(d/q) = d and q + d/q = c; q ≠ 0 because their product d is not zero.
    [q, d / q]
}

/// The principal square root, algebraically: `t = √((|z| + |Re z|)/2)`, then `(t, Im z/2t)`
/// or `(|Im z|/2t, ±t)`. Four times faster than the polar form (`atan2`, `sin_cos`),
/// which dominated the whole analysis.
fn principal_sqrt(z: Complex<f64>) -> Complex<f64> {
    if z.re == 0.0 && z.im == 0.0 {
        return z;
    }
    let t = (0.5 * (z.re.hypot(z.im) + z.re.abs())).sqrt();
    if z.re >= 0.0 {
        Complex::new(t, z.im / (2.0 * t))
    } else {
        Complex::new(z.im.abs() / (2.0 * t), t.copysign(z.im))
    }
}

/// Both roots of a block in the open right half-plane, except block 0's exact zero.
fn nonzero_roots_stable(roots: [Complex<f64>; 2], d: Complex<f64>) -> bool {
    if d == Complex::new(0.0, 0.0) {
        roots[1].re > 0.0
    } else {
        roots.iter().all(|mu| mu.re > 0.0)
    }
}

/// The eigenvalues of `L(m, k)` as the roots of its Fourier blocks `0..=⌊m/2⌋`.
#[derive(Debug, Clone, PartialEq)]
pub struct RingSpectrum {
    macro_vertices: usize,
    /// Block `ℓ`'s two roots; block 0 is `[0, 2+k]`.
    blocks: Vec<[Complex<f64>; 2]>,
}

impl RingSpectrum {
    /// The spectrum of `ring` (for several `k` on one ring, build [`RingModes`] once).
    pub fn of(ring: &RingDigraph) -> Self {
        RingModes::new(ring.macro_vertices()).spectrum(ring.k())
    }

    /// All `2m` eigenvalues, sorted by real then imaginary part (as
    /// [`super::eigenvalues`] sorts the dense ones).
    pub fn eigenvalues(&self) -> Vec<Complex<f64>> {
        let m = self.macro_vertices;
        let mut all = Vec::with_capacity(2 * m);
        all.extend(self.blocks.iter().flatten().copied());
        // Blocks ⌊m/2⌋+1..m are the conjugates of blocks 1..=⌈m/2⌉−1.
        let mirrored = m.saturating_sub(1) / 2;
        all.extend(
            self.blocks
                .iter()
                .skip(1)
                .take(mirrored)
                .flatten()
                .map(Complex::conj),
        );
        all.sort_by(|a, b| a.re.total_cmp(&b.re).then(a.im.total_cmp(&b.im)));
        all
    }

    /// The non-zero eigenvalues up to conjugation: both roots of blocks `1..=⌊m/2⌋` and
    /// `2+k`. Enough for [`super::yu_bound`], [`super::closed_loop_abscissa`] and
    /// [`super::fastest_mode_per_s`], which conjugation does not change, at half the
    /// cost of the full list. (`2+k` is listed even when it is zero, at `k = −2`, so that
    /// such a ring reads as unstable.)
    pub fn nonzero_up_to_conjugation(&self) -> Vec<Complex<f64>> {
        let mut out = Vec::with_capacity(2 * self.blocks.len());
        if let Some(first) = self.blocks.first() {
            out.push(first[1]);
        }
        out.extend(self.blocks.iter().skip(1).flatten().copied());
        out
    }

    /// Whether every non-zero eigenvalue has a positive real part.
    pub fn is_stable(&self) -> bool {
        self.nonzero_up_to_conjugation()
            .iter()
            .all(|mu| mu.re > 0.0)
    }

    /// The number of eigenvalues, `2m`.
    pub fn len(&self) -> usize {
        2 * self.macro_vertices
    }

    /// Whether the ring has no agent (never, for a valid ring).
    pub fn is_empty(&self) -> bool {
        self.macro_vertices == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::consensus::stability::{eigenvalues, nonzero_eigenvalues};

    /// The smallest distance from `mu` to a dense eigenvalue not used yet, which it takes.
    fn take_nearest(dense: &mut Vec<Complex<f64>>, mu: Complex<f64>) -> f64 {
        let (at, distance) = dense
            .iter()
            .enumerate()
            .map(|(i, z)| (i, (z - mu).norm()))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .expect("as many dense eigenvalues as block ones");
        dense.swap_remove(at);
        distance
    }

    #[test]
    fn small_rings_match_the_dense_spectrum_one_to_one() {
        for (m, k) in [
            (1, 0.5),
            (2, -1.5),
            (3, 5.0),
            (4, -0.5),
            (5, 1.0),
            (6, -1.9),
        ] {
            let ring = RingDigraph::new(m, k).unwrap();
            let ours = RingSpectrum::of(&ring).eigenvalues();
            let mut dense = eigenvalues(ring.laplacian()).unwrap();
            assert_eq!(ours.len(), 2 * m);
            for mu in ours {
                let d = take_nearest(&mut dense, mu);
                assert!(d < 1e-9, "m = {m}, k = {k}: {mu} off by {d}");
            }
        }
    }

    #[test]
    fn block_zero_is_exactly_zero_and_two_plus_k() {
        let spectrum = RingSpectrum::of(&RingDigraph::new(7, 0.3).unwrap());
        assert_eq!(
            spectrum.blocks[0],
            [Complex::new(0.0, 0.0), Complex::new(2.3, 0.0)]
        );
        let all = spectrum.eigenvalues();
        assert_eq!(all.iter().filter(|z| z.norm() == 0.0).count(), 1);
        // The same non-zero set as the dense path's, up to conjugation.
        let dense = nonzero_eigenvalues(
            &eigenvalues(RingDigraph::new(7, 0.3).unwrap().laplacian()).unwrap(),
        );
        assert_eq!(dense.len(), 13);
        assert_eq!(spectrum.nonzero_up_to_conjugation().len(), 7);
    }

    #[test]
    fn the_algebraic_square_root_is_the_principal_one() {
        for (re, im) in [
            (4.0, 0.0),
            (-4.0, 0.0),
            (-4.0, -0.0),
            (3.0, 4.0),
            (-3.0, 4.0),
            (-3.0, -4.0),
            (1e-300, -1e-300),
            (-7.5, 1e-12),
        ] {
            let z = Complex::new(re, im);
            let ours = principal_sqrt(z);
            let polar = z.sqrt();
            assert!(
                (ours - polar).norm() <= 1e-15 * polar.norm(),
                "{z}: {ours} vs {polar}"
            );
            assert!(ours.re >= 0.0, "{z}: {ours}");
        }
        assert_eq!(
            principal_sqrt(Complex::new(0.0, 0.0)),
            Complex::new(0.0, 0.0)
        );
    }

    #[test]
    fn k_of_minus_two_is_unstable_for_every_m() {
        for m in 1..6 {
            let modes = RingModes::new(m);
            assert!(!modes.is_stable(-2.0), "m = {m}");
            assert!(!modes.spectrum(-2.0).is_stable(), "m = {m}");
        }
    }
}
