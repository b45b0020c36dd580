//! Properties of the consensus maths over many rings and random gains (seeded, so every
//! run checks the same cases).

use nalgebra::{Complex, DMatrix, DVector, SVector, Vector2, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use ringswarm::consensus::{
    CouplingGains, HorizontalState, RingDigraph, RingSpectrum, closed_loop_abscissa,
    closed_loop_matrix, eigenvalues, k_lower_bound, laplacian_is_stable_numerically,
    nonzero_eigenvalues, numeric_k_lower_bound, predicted_final_velocity, recommend_gains,
    ring_accelerations, yu_bound,
};
use ringswarm::control::{Envelope, SaturationMode, VehicleModel, saturate};

fn rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

#[test]
fn theorem_1_bound_matches_the_numeric_threshold_for_m_up_to_64() {
    for m in 1..=64 {
        let k_min = k_lower_bound(m).unwrap();
        assert!(
            laplacian_is_stable_numerically(m, k_min + 1e-6).unwrap(),
            "m = {m}: unstable just above the bound {k_min}"
        );
        assert!(
            !laplacian_is_stable_numerically(m, k_min - 1e-6).unwrap(),
            "m = {m}: stable just below the bound {k_min}"
        );
    }
    // A full bisection, independent of the formula, for a few sizes.
    for m in [1, 2, 3, 5, 8, 13] {
        let numeric = numeric_k_lower_bound(m, 1e-9).unwrap();
        let formula = k_lower_bound(m).unwrap();
        assert!(
            (numeric - formula).abs() < 1e-6,
            "m = {m}: {numeric} vs {formula}"
        );
    }
}

/// The eigenvalues of `L` from the paper's block diagonalisation: `μ = 0`, `μ = 2 + k`
/// from the first block, and for ℓ = 2..m the roots of `μ² − (2+k)μ + (1 − ω_ℓ) = 0`
/// with `ω_ℓ = exp(−2πi(ℓ−1)/m)` (the negated roots of the paper's eq. Eq.d2charpoly).
fn block_eigenvalues(m: usize, k: f64) -> Vec<Complex<f64>> {
    let mut out = vec![Complex::new(0.0, 0.0), Complex::new(2.0 + k, 0.0)];
    for l in 2..=m {
        let theta = 2.0 * std::f64::consts::PI * (l - 1) as f64 / m as f64;
        let omega = Complex::new(theta.cos(), -theta.sin());
        let b = Complex::new(2.0 + k, 0.0);
        let c = Complex::new(1.0, 0.0) - omega;
        let root = (b * b - c * 4.0).sqrt();
        out.push((b + root) * 0.5);
        out.push((b - root) * 0.5);
    }
    out
}

#[test]
fn numeric_spectrum_equals_the_block_circulant_spectrum_and_w_is_a_left_null_vector() {
    let mut r = rng(1);
    for m in 1..=64 {
        let k = r.random_range(-2.5..6.0);
        let ring = RingDigraph::new(m, k).unwrap();
        let l = ring.laplacian();
        let w = ring.left_null_vector();
        assert!((w.transpose() * &l).amax() < 1e-12, "w·L ≠ 0 for m = {m}");
        let numeric = eigenvalues(l).unwrap();
        for mu in block_eigenvalues(m, k) {
            let nearest = numeric
                .iter()
                .map(|z| (z - mu).norm())
                .fold(f64::INFINITY, f64::min);
            assert!(
                nearest < 1e-7,
                "m = {m}, k = {k}: block eigenvalue {mu} missing ({nearest})"
            );
        }
    }
}

#[test]
fn fourier_block_spectrum_equals_the_dense_one_for_m_up_to_64() {
    let mut r = rng(3);
    for m in 1..=64 {
        for _ in 0..3 {
            let k = r.random_range(-2.5..6.0);
            let ring = RingDigraph::new(m, k).unwrap();
            let blocks = RingSpectrum::of(&ring);
            let ours = blocks.eigenvalues();
            let mut dense = eigenvalues(ring.laplacian()).unwrap();
            assert_eq!(ours.len(), dense.len());
            // One to one: each block eigenvalue takes the nearest dense one left.
            for mu in &ours {
                let (at, distance) = dense
                    .iter()
                    .enumerate()
                    .map(|(i, z)| (i, (z - mu).norm()))
                    .min_by(|a, b| a.1.total_cmp(&b.1))
                    .unwrap();
                assert!(distance < 1e-9, "m = {m}, k = {k}: {mu} off by {distance}");
                dense.swap_remove(at);
            }
            // The quantities built on them, from half the spectrum and from the whole.
            let dense_nonzero = nonzero_eigenvalues(&eigenvalues(ring.laplacian()).unwrap());
            let half = blocks.nonzero_up_to_conjugation();
            assert_eq!(
                blocks.is_stable(),
                yu_bound(&dense_nonzero).is_some(),
                "m = {m}, k = {k}"
            );
            if let (Some(a), Some(b)) = (yu_bound(&half), yu_bound(&dense_nonzero)) {
                assert!((a - b).abs() <= 1e-9 * b.max(1.0), "Yu's bound {a} vs {b}");
            }
            let gains =
                CouplingGains::new(r.random_range(0.1..3.0), r.random_range(0.1..6.0)).unwrap();
            let (a, b) = (
                closed_loop_abscissa(&half, gains),
                closed_loop_abscissa(&dense_nonzero, gains),
            );
            assert!((a - b).abs() < 1e-9, "abscissa {a} vs {b}");
        }
    }
}

/// For a large ring the slowest Fourier block (`θ = 2π/m`) sets Yu's bound. Expanding its
/// small root `μ = d/c + d²/c³ + O(d³)` with `d = 1 − e^{−iθ} = iθ + θ²/2 + O(θ³)` and
/// `c = 2 + k`: `Im μ = θ/c + O(θ³)`, `Re μ = θ²(c² − 2)/(2c³) + O(θ⁴)`, so
/// `Im²/(Re·|μ|²) = 2c³/((c² − 2)θ²)·(1 + O(θ²))` (checked with 50-digit arithmetic:
/// the relative remainder is 5.3·10⁻¹⁰ at m = 10⁵, k = 1).
#[test]
fn a_ring_of_a_hundred_thousand_keeps_its_trace_yu_asymptote_and_bound() {
    let (m, k) = (100_000, 1.0);
    let ring = RingDigraph::new(m, k).unwrap();
    let spectrum = RingSpectrum::of(&ring);
    let all = spectrum.eigenvalues();
    assert_eq!(all.len(), 2 * m);
    // trace(L) = Σ L_ii = m(1 + k) + m.
    let trace: Complex<f64> = all.iter().sum();
    let expected_trace = m as f64 * (2.0 + k);
    assert!(
        (trace.re - expected_trace).abs() < 1e-9 * expected_trace,
        "{trace}"
    );
    assert!(trace.im.abs() < 1e-6, "{trace}");
    let c: f64 = 2.0 + k;
    let theta = 2.0 * std::f64::consts::PI / m as f64;
    let asymptote = 2.0 * c.powi(3) / ((c * c - 2.0) * theta * theta);
    let bound = yu_bound(&spectrum.nonzero_up_to_conjugation()).unwrap();
    assert!(
        (bound / asymptote - 1.0).abs() < 2e-9,
        "{bound} vs {asymptote}"
    );
    // The bisection on the blocks finds Theorem 1's bound for a large ring too.
    let numeric = numeric_k_lower_bound(m, 1e-10).unwrap();
    let formula = k_lower_bound(m).unwrap();
    assert!((numeric - formula).abs() < 1e-9, "{numeric} vs {formula}");
}

#[test]
fn yu_bound_decides_closed_loop_stability_and_matches_the_full_matrix() {
    let mut r = rng(2);
    let mut checked = 0;
    while checked < 300 {
        let m = r.random_range(1..=12);
        let k_min = k_lower_bound(m).unwrap();
        let k = r.random_range(k_min + 0.01..k_min + 8.0);
        let gains = CouplingGains::new(r.random_range(0.1..3.0), r.random_range(0.1..6.0)).unwrap();
        let ring = RingDigraph::new(m, k).unwrap();
        let l = ring.laplacian();
        let nonzero = nonzero_eigenvalues(&eigenvalues(l.clone()).unwrap());
        let bound = yu_bound(&nonzero).expect("stable L above the bound");
        let abscissa = closed_loop_abscissa(&nonzero, gains);
        if (gains.ratio() / bound - 1.0).abs() < 1e-6 || abscissa.abs() < 1e-9 {
            continue; // on the boundary itself the verdict is a rounding question
        }
        assert_eq!(
            gains.ratio() > bound,
            abscissa < 0.0,
            "m = {m}, k = {k}, {gains:?}"
        );
        if checked % 10 == 0 {
            // The 2N×2N matrix, eigenvalues computed numerically, double zero removed.
            let mut full = eigenvalues(closed_loop_matrix(&l, gains)).unwrap();
            full.sort_by(|a, b| a.norm().total_cmp(&b.norm()));
            let numeric = full[2..]
                .iter()
                .map(|s| s.re)
                .fold(f64::NEG_INFINITY, f64::max);
            assert!(
                (numeric - abscissa).abs() < 1e-6,
                "abscissa {abscissa} vs numeric {numeric}"
            );
        }
        checked += 1;
    }
}

/// Integrates `ṗ = v, v̇ = −αLp − βLv` (per axis) with classical RK4.
fn simulate<const D: usize>(
    l: &DMatrix<f64>,
    gains: CouplingGains,
    p0: &[SVector<f64, D>],
    v0: &[SVector<f64, D>],
    seconds: f64,
) -> Vec<SVector<f64, D>> {
    let n = p0.len();
    let dt = 0.01;
    let steps = (seconds / dt).ceil() as usize;
    let mut out = vec![SVector::<f64, D>::zeros(); n];
    for axis in 0..D {
        let mut p = DVector::from_fn(n, |i, _| p0[i][axis]);
        let mut v = DVector::from_fn(n, |i, _| v0[i][axis]);
        let accel =
            |p: &DVector<f64>, v: &DVector<f64>| -(l * p) * gains.alpha - (l * v) * gains.beta;
        for _ in 0..steps {
            let (k1p, k1v) = (v.clone(), accel(&p, &v));
            let (p2, v2) = (&p + &k1p * (dt / 2.0), &v + &k1v * (dt / 2.0));
            let (k2p, k2v) = (v2.clone(), accel(&p2, &v2));
            let (p3, v3) = (&p + &k2p * (dt / 2.0), &v + &k2v * (dt / 2.0));
            let (k3p, k3v) = (v3.clone(), accel(&p3, &v3));
            let (p4, v4) = (&p + &k3p * dt, &v + &k3v * dt);
            let (k4p, k4v) = (v4.clone(), accel(&p4, &v4));
            p += (k1p + &k2p * 2.0 + &k3p * 2.0 + k4p) * (dt / 6.0);
            v += (k1v + &k2v * 2.0 + &k3v * 2.0 + k4v) * (dt / 6.0);
        }
        for i in 0..n {
            out[i][axis] = v[i];
        }
    }
    out
}

#[test]
fn predicted_final_velocity_equals_the_end_of_a_long_simulation() {
    let mut r = rng(3);
    let mut checked = 0;
    while checked < 12 {
        let m = r.random_range(1..=6);
        let k_min = k_lower_bound(m).unwrap();
        let k = r.random_range(k_min + 0.3..6.0);
        let gains = recommend_gains(m, k, k, 1.0).unwrap().gains;
        let ring = RingDigraph::new(m, k).unwrap();
        let nonzero = nonzero_eigenvalues(&eigenvalues(ring.laplacian()).unwrap());
        let decay = -closed_loop_abscissa(&nonzero, gains);
        if decay < 0.05 {
            continue; // too slow to settle in a test's budget
        }
        let n = ring.agents();
        let p0: Vec<Vector3<f64>> = (0..n)
            .map(|_| Vector3::from_fn(|_, _| r.random_range(-50.0..50.0)))
            .collect();
        let v0: Vec<Vector3<f64>> = (0..n)
            .map(|_| Vector3::from_fn(|_, _| r.random_range(-20.0..20.0)))
            .collect();
        let predicted = predicted_final_velocity(&ring, &v0).unwrap();
        // Modal error decays as e^(−decay·t); 40/decay seconds leaves e^(−40) ≈ 4e−18
        // times a modal factor.
        let end = simulate(&ring.laplacian(), gains, &p0, &v0, 40.0 / decay);
        for v in &end {
            assert!(
                (v - predicted).amax() < 1e-6,
                "m = {m}, k = {k}: {v:?} vs {predicted:?}"
            );
        }
        checked += 1;
    }
}

/// Random ring, gains and states, and the nominal law's commands for them.
struct Case {
    ring: RingDigraph,
    commands: Vec<Vector3<f64>>,
    models: Vec<VehicleModel>,
}

fn random_case(r: &mut ChaCha8Rng) -> Case {
    let m = r.random_range(1..=16);
    let k_min = k_lower_bound(m).unwrap();
    let k = r.random_range(k_min + 0.05..6.0); // includes k < −1: negative weights in w
    let ring = RingDigraph::new(m, k).unwrap();
    let gains = CouplingGains::new(r.random_range(0.2..2.0), r.random_range(0.5..6.0)).unwrap();
    let n = ring.agents();
    let states: Vec<HorizontalState> = (0..n)
        .map(|_| HorizontalState {
            pos_m: Vector2::new(r.random_range(-60.0..60.0), r.random_range(-60.0..60.0)),
            vel_mps: Vector2::new(r.random_range(-20.0..20.0), r.random_range(-20.0..20.0)),
            offset_m: Vector2::new(r.random_range(-20.0..20.0), r.random_range(-20.0..20.0)),
        })
        .collect();
    let mut horizontal = vec![Vector2::zeros(); n];
    ring_accelerations(&ring, gains, &states, &mut horizontal);
    let commands = horizontal
        .iter()
        .map(|u| Vector3::new(u.x, u.y, r.random_range(-3.0..3.0)))
        .collect();
    let models = (0..n)
        .map(|_| {
            VehicleModel::from_hover_throttle(r.random_range(0.5..3.0), r.random_range(0.3..0.7))
                .unwrap()
        })
        .collect();
    Case {
        ring,
        commands,
        models,
    }
}

fn weighted_sum(w: &DVector<f64>, u: &[Vector3<f64>]) -> Vector2<f64> {
    u.iter()
        .zip(w.iter())
        .fold(Vector2::zeros(), |acc, (u, wi)| acc + u.xy() * *wi)
}

#[test]
fn conserve_keeps_the_weighted_sum_and_the_envelope() {
    let mut r = rng(4);
    let envelope = Envelope::new(30f64.to_radians(), 0.1, 0.95).unwrap();
    let mut saturated_cases = 0;
    for _ in 0..400 {
        let case = random_case(&mut r);
        let w = case.ring.left_null_vector();
        let scale: f64 = case
            .commands
            .iter()
            .zip(w.iter())
            .map(|(u, wi)| u.xy().norm() * wi.abs())
            .sum::<f64>()
            + 1.0;
        assert!(
            weighted_sum(&w, &case.commands).amax() < 1e-9 * scale,
            "the law itself keeps Σwu = 0"
        );
        let mut u = case.commands.clone();
        let summary = saturate(
            SaturationMode::Conserve,
            &envelope,
            &case.models,
            w.as_slice(),
            &mut u,
        )
        .unwrap();
        saturated_cases += usize::from(summary.horizontal_limited > 0);
        assert!(
            weighted_sum(&w, &u).amax() < 1e-9 * scale,
            "Σwũ = {:?}",
            weighted_sum(&w, &u)
        );
        for (ui, model) in u.iter().zip(&case.models) {
            let a_max = envelope.horizontal_limit_mps2(ui.z, model);
            assert!(
                ui.xy().norm() <= a_max * (1.0 + 1e-12),
                "|ũ| = {} > {a_max}",
                ui.xy().norm()
            );
        }
    }
    assert!(
        saturated_cases > 200,
        "the cases must exercise saturation ({saturated_cases})"
    );
}

#[test]
fn clip_keeps_the_envelope_but_not_the_weighted_sum() {
    let mut r = rng(5);
    let envelope = Envelope::new(30f64.to_radians(), 0.1, 0.95).unwrap();
    let mut sum_broken = 0;
    let mut saturated_cases = 0;
    for _ in 0..400 {
        let case = random_case(&mut r);
        let w = case.ring.left_null_vector();
        let mut u = case.commands.clone();
        let summary = saturate(
            SaturationMode::Clip,
            &envelope,
            &case.models,
            w.as_slice(),
            &mut u,
        )
        .unwrap();
        for (ui, model) in u.iter().zip(&case.models) {
            let a_max = envelope.horizontal_limit_mps2(ui.z, model);
            assert!(ui.xy().norm() <= a_max * (1.0 + 1e-12));
        }
        if summary.horizontal_limited > 0 {
            saturated_cases += 1;
            sum_broken += usize::from(weighted_sum(&w, &u).amax() > 1e-3);
        }
    }
    assert!(saturated_cases > 200);
    // Clipping vehicles one by one almost never keeps Σwũ = 0.
    assert!(
        sum_broken * 10 >= saturated_cases * 9,
        "{sum_broken} of {saturated_cases}"
    );
}
