//! The paper's worked examples and simulations, recomputed.
//!
//! Every expected value here was derived independently of this crate, with numpy
//! (`tests/python/derive_expected.py` prints them all) or by hand where the arithmetic is
//! short; none is copied from the paper, whose printed numbers contain slips. Where the
//! paper's figure differs, the comment says so.

use nalgebra::Vector2;
use ringswarm::consensus::{
    CouplingGains, PlanOutcome, PlanRequest, RingDigraph, analyze, g_and_h, k_lower_bound, plan,
    predicted_final_velocity, retarget_velocity,
};

fn v(list: &[(f64, f64)]) -> Vec<Vector2<f64>> {
    list.iter().map(|&(x, y)| Vector2::new(x, y)).collect()
}

fn assert_close(got: f64, expected: f64, tol: f64, what: &str) {
    assert!(
        (got - expected).abs() <= tol,
        "{what}: got {got}, expected {expected} (±{tol})"
    );
}

const EXAMPLE_VELOCITIES: [(f64, f64); 6] = [
    (1.0, 2.0),
    (-1.0, 3.0),
    (-2.0, 4.0),
    (1.0, 5.0),
    (2.0, 3.0),
    (2.0, 2.0),
];
const SIM_VELOCITIES: [(f64, f64); 6] = [
    (9.0, 4.0),
    (15.0, 8.0),
    (18.0, -2.0),
    (13.0, 1.0),
    (-8.0, -7.0),
    (14.0, 18.0),
];

#[test]
fn example_1_four_macro_vertices() {
    // Theorem 1: −2 + √2·cos(π/4) = −2 + 1 = −1.
    assert_close(k_lower_bound(4).unwrap(), -1.0, 1e-15, "k_min");

    // k = −0.5: eigenvalues of L (numpy.linalg.eigvals): 0, 0.178154 ± 0.874361i,
    // 0.75 ± 1.198958i, 1.321846 ± 0.874361i, 1.5.
    let ring = RingDigraph::new(4, -0.5).unwrap();
    let report = analyze(&ring, Some(CouplingGains::new(1.0, 6.0).unwrap())).unwrap();
    let expected = [
        (0.0, 0.0),
        (0.178154, -0.874361),
        (0.178154, 0.874361),
        (0.75, -1.198958),
        (0.75, 1.198958),
        (1.321846, -0.874361),
        (1.321846, 0.874361),
        (1.5, 0.0),
    ];
    let eigenvalues = report.spectrum.eigenvalues();
    assert_eq!(eigenvalues.len(), expected.len());
    for (got, (re, im)) in eigenvalues.iter().zip(expected) {
        assert_close(got.re, re, 1e-6, "Re μ");
        assert_close(got.im, im, 1e-6, "Im μ");
    }
    // Yu's bound (numpy): 5.389377276613346; the paper prints 5.39.
    assert_close(
        report.yu_bound.unwrap(),
        5.389_377_276_613_346,
        1e-9,
        "Yu bound at k = −0.5",
    );
    // Closed loop with α = 1, β = 6 (numpy, 16×16 eigenvalues without the double zero).
    let check = report.gain_check.unwrap();
    assert_close(
        check.closed_loop_abscissa,
        -0.167_392_671_721_78,
        1e-9,
        "abscissa",
    );
    assert!(report.stable);

    // k = 1: the bound drops to 2.129326042744725 (numpy); α = 1, β = 3 is stable.
    let report = analyze(
        &RingDigraph::new(4, 1.0).unwrap(),
        Some(CouplingGains::new(1.0, 3.0).unwrap()),
    )
    .unwrap();
    assert_close(
        report.yu_bound.unwrap(),
        2.129_326_042_744_725,
        1e-9,
        "Yu bound at k = 1",
    );
    assert!(report.stable);

    // k = −0.8 with α = 1, β = 3: L is stable, but β²/α = 9 < 12.920154767385764 (numpy)
    // and the closed loop has an eigenvalue at real part +0.0970857575 (numpy).
    let report = analyze(
        &RingDigraph::new(4, -0.8).unwrap(),
        Some(CouplingGains::new(1.0, 3.0).unwrap()),
    )
    .unwrap();
    assert!(report.k_margin > 0.0);
    assert_close(
        report.yu_bound.unwrap(),
        12.920_154_767_385_764,
        1e-9,
        "Yu bound at k = −0.8",
    );
    assert_close(
        report.gain_check.unwrap().closed_loop_abscissa,
        0.097_085_757_510_16,
        1e-9,
        "abscissa",
    );
    assert!(!report.stable);
}

#[test]
fn achievable_velocity_example() {
    let velocities = v(&EXAMPLE_VELOCITIES);
    let target = Vector2::new(5.0, -4.0);
    // g = 3·(5, −4) − ((−1, 3) + (1, 5) + (2, 2)) = (13, −22)   [paper: (13, −23)]
    // h = ((1, 2) + (−2, 4) + (2, 3)) − 3·(5, −4) = (−14, 21)   [paper: (−14, 20)]
    let (g, h) = g_and_h(&velocities, target);
    assert_eq!(g, Vector2::new(13.0, -22.0));
    assert_eq!(h, Vector2::new(-14.0, 21.0));

    // The paper's manual choices, recomputed: agent 1 with δ = 1.5 needs
    // v1 = (1, 2) + 1.5·(13, −22) − (−14, 21) = (34.5, −52)   [paper: (34.5, −52.5)];
    // agent 3 with δ = 0.5 needs v3 = (−2, 4) + 0.5·(13, −22) − (−14, 21) = (18.5, −28)
    // [paper: (18.5, −27.5)]. Both then reach (5, −4) exactly.
    for (agent, delta, expected) in [
        (0, 1.5, Vector2::new(34.5, -52.0)),
        (2, 0.5, Vector2::new(18.5, -28.0)),
    ] {
        let new = retarget_velocity(&velocities, target, agent, delta).unwrap();
        assert!((new - expected).norm() < 1e-12, "agent {agent}: {new:?}");
        let mut modified = velocities.clone();
        modified[agent] = new;
        let ring = RingDigraph::new(3, delta - 1.0).unwrap();
        let vf = predicted_final_velocity(&ring, &modified).unwrap();
        assert!((vf - target).norm() < 1e-12);
    }

    // The planner's own choice (least change, k ≥ k_min + 0.1, k ≤ 10). A brute-force
    // numpy search over δ on a grid of 2·10⁶ points and over all six agents finds the
    // least change 20.318716 m/s at δ = 1 + k_min + 0.1 = −0.192893, for any odd agent;
    // the slowest result is agent 3: (9.492388, −12.756349) m/s.
    let answer = plan(&PlanRequest {
        velocities_mps: velocities,
        target_mps: target,
        k_margin: 0.1,
        k_max: 10.0,
        max_speed_mps: None,
    })
    .unwrap();
    let PlanOutcome::Feasible {
        delta,
        retarget: Some(r),
        predicted_final_velocity_mps,
        ..
    } = answer.outcome
    else {
        panic!("expected a re-targeting plan, got {:?}", answer.outcome);
    };
    assert_eq!(r.agent, 2);
    assert_close(delta, -0.192_893_218_813_452_3, 1e-9, "δ");
    assert_close(r.change_mps, 20.318_716_090_383_41, 1e-6, "change");
    assert!((r.new_velocity_mps - Vector2::new(9.492_388_16, -12.756_349_19)).norm() < 1e-6);
    assert!((predicted_final_velocity_mps - target).norm() < 1e-9);
}

#[test]
fn second_simulation_plan() {
    let velocities = v(&SIM_VELOCITIES);
    let target = Vector2::new(20.0, 30.0);
    // g = 3·(20, 30) − ((15, 8) + (13, 1) + (14, 18)) = (18, 63)   [paper: (18, 62)]
    // h = ((9, 4) + (18, −2) + (−8, −7)) − 3·(20, 30) = (−41, −95)   [paper: (−41, −97)]
    let (g, h) = g_and_h(&velocities, target);
    assert_eq!(g, Vector2::new(18.0, 63.0));
    assert_eq!(h, Vector2::new(-41.0, -95.0));

    // The paper's choice: agent 1 with δ = 0.5 (k = −0.5) needs
    // v1 = (9, 4) + 0.5·(18, 63) − (−41, −95) = (59, 130.5)   [paper: (59, 132.5)].
    let new = retarget_velocity(&velocities, target, 0, 0.5).unwrap();
    assert!((new - Vector2::new(59.0, 130.5)).norm() < 1e-12);
    let mut modified = velocities.clone();
    modified[0] = new;
    let vf = predicted_final_velocity(&RingDigraph::new(3, -0.5).unwrap(), &modified).unwrap();
    assert!((vf - target).norm() < 1e-12);

    // The planner's least change (numpy brute force as above): an even agent, δ = 11
    // (k = k_max = 10), change 74.858820 m/s; the slowest result is agent 4,
    // (34.727273, 72.636364) m/s = (13, 1) + (18, 63) − (−41, −95)/11.
    let answer = plan(&PlanRequest {
        velocities_mps: velocities,
        target_mps: target,
        k_margin: 0.1,
        k_max: 10.0,
        max_speed_mps: None,
    })
    .unwrap();
    let PlanOutcome::Feasible {
        k,
        retarget: Some(r),
        ..
    } = answer.outcome
    else {
        panic!("expected a re-targeting plan");
    };
    assert_eq!(r.agent, 3);
    assert_close(k, 10.0, 1e-12, "k");
    let expected = Vector2::new(13.0 + 18.0 + 41.0 / 11.0, 1.0 + 63.0 + 95.0 / 11.0);
    assert!((r.new_velocity_mps - expected).norm() < 1e-9);
    assert_close(r.change_mps, 74.858_820_289_973_92, 1e-6, "change");
}

#[test]
fn first_simulation_gains_are_stable_and_predict_the_final_velocity() {
    // m = 3, k = 5: bound −2 + √2·cos(π/3) = −1.292893; Yu's bound 1.221423 (numpy)
    // against β²/α = 25.
    let ring = RingDigraph::new(3, 5.0).unwrap();
    let report = analyze(&ring, Some(CouplingGains::new(1.0, 5.0).unwrap())).unwrap();
    assert_close(report.k_min, -2.0 + 2f64.sqrt() * 0.5, 1e-15, "k_min");
    assert_close(
        report.yu_bound.unwrap(),
        1.221_422_976_340_136,
        1e-9,
        "Yu bound",
    );
    assert!(report.stable);
    // w = (1, 6, 1, 6, 1, 6): v_f = (271, 157)/21.
    let vf = predicted_final_velocity(&ring, &v(&SIM_VELOCITIES)).unwrap();
    assert!((vf - Vector2::new(271.0 / 21.0, 157.0 / 21.0)).norm() < 1e-12);
}
