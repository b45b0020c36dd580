use super::secure::Secured;
use super::*;

/// The separation the filter's tests fly: 3 m by 9 m, γ = 1.
pub(super) fn sep() -> Separation {
    Separation {
        horizontal_m: 3.0,
        vertical_m: 9.0,
        gamma: 1.0,
    }
}

fn settings(keep: bool) -> Settings {
    Settings {
        separation: sep(),
        age_s: 0.04,
        period_s: 0.02,
        keep_weighted_sum: keep,
        time_limit_s: f64::INFINITY,
        rows: Rows::Barrier,
        brake_to_mps: Vector2::zeros(),
    }
}

fn agent(p: [f64; 3], v: [f64; 3], weight: f64) -> Agent {
    Agent {
        side: Some(Side {
            pos_m: Vector3::from(p),
            vel_mps: Vector3::from(v),
            accel_z_mps2: 0.0,
        }),
        controlled: true,
        weight,
        drift_mps2: Vector2::zeros(),
        limit_mps2: 6.0,
        braking_mps2: 2.0,
        lag_s: 0.0,
        spread_m: 0.0,
        unseen_mps: 0.0,
    }
}

/// Every barrier row of the agents, recomputed from scratch, and whether the commands
/// meet it.
fn rows_hold(s: &Settings, agents: &[Agent], commands: &[Vector2<f64>], tolerance: f64) -> bool {
    let net = |k: usize| {
        if agents[k].controlled {
            commands[k] - agents[k].drift_mps2
        } else {
            Vector2::zeros()
        }
    };
    for i in 0..agents.len() {
        for j in i + 1..agents.len() {
            let (a, b) = (&agents[i], &agents[j]);
            if !(a.controlled || b.controlled) {
                continue;
            }
            let authority = braking(a) + braking(b);
            let (Some(si), Some(sj)) = (a.side, b.side) else {
                continue;
            };
            let Some(row) = pair_row(&s.separation, &si, &sj, authority, s.age_s) else {
                continue;
            };
            if row.b <= -(limit(a) + limit(b)) - 1.0 {
                continue;
            }
            if row.a.dot(&(net(i) - net(j))) < row.b - tolerance {
                return false;
            }
        }
    }
    true
}

#[test]
fn two_vehicles_head_on_are_slowed_and_the_weighted_sum_is_kept() {
    // 6 m apart, closing at 4 m/s, each commanded on towards the other.
    let agents = [
        agent([0.0, 0.0, 10.0], [2.0, 0.0, 0.0], 1.0),
        agent([6.0, 0.2, 10.0], [-2.0, 0.0, 0.0], 3.0),
    ];
    let before = [Vector2::new(1.0, 0.0), Vector2::new(-1.0, 0.0)];
    let mut commands = before;
    let mut filter = SafetyFilter::default();
    let report = filter.filter(&settings(true), &agents, &mut commands, None);
    assert_eq!(
        report.outcome,
        Outcome::Filtered {
            sum_kept: true,
            relaxed: false
        }
    );
    assert_eq!(report.rows, 1);
    assert_eq!(report.active, 1);
    assert!(rows_hold(&settings(true), &agents, &commands, 1e-9));
    // Optimality with one row: wᵢΔuᵢ = −wⱼΔuⱼ, both along the row's a.
    let (d0, d1) = (commands[0] - before[0], commands[1] - before[1]);
    assert!((d0 * 1.0 + d1 * 3.0).norm() < 1e-9, "{d0} {d1}");
    assert!(d0.x < 0.0 && d1.x > 0.0, "pushed apart: {d0} {d1}");
    let closest = report.closest.expect("a pair");
    assert_eq!((closest.0, closest.1), (0, 1));
    assert!((closest.2 - (36.0f64 + 0.04).sqrt()).abs() < 1e-12);
}

#[test]
fn vehicles_far_apart_are_untouched() {
    let agents = [
        agent([0.0, 0.0, 10.0], [1.0, 0.0, 0.0], 1.0),
        agent([100.0, 0.0, 10.0], [1.0, 0.0, 0.0], 1.0),
    ];
    let mut commands = [Vector2::new(1.0, 2.0), Vector2::new(-3.0, 0.5)];
    let before = commands;
    let report = SafetyFilter::default().filter(&settings(true), &agents, &mut commands, None);
    assert_eq!(report.outcome, Outcome::Untouched);
    assert_eq!(commands, before);
}

#[test]
fn a_pair_too_fast_to_stop_brakes_as_hard_as_the_envelopes_allow() {
    // 10 m apart, closing at 20 m/s, with 0.5 m/s² of authority: h ≈ −17.5 m/s asks for
    // thousands of m/s², which no command within the envelopes gives. The row is relaxed:
    // each vehicle pushes away from the other with all of its disc (0.5 m/s²).
    let mut agents = [
        agent([0.0, 0.0, 10.0], [10.0, 0.0, 0.0], 1.0),
        agent([10.0, 0.0, 10.0], [-10.0, 0.0, 0.0], 1.0),
    ];
    for a in &mut agents {
        a.limit_mps2 = 0.5;
        a.braking_mps2 = 0.25;
    }
    let mut commands = [Vector2::new(0.3, 0.0), Vector2::new(-0.3, 0.0)];
    let mut filter = SafetyFilter::default();
    let report = filter.filter(&settings(true), &agents, &mut commands, None);
    assert_eq!(
        report.outcome,
        Outcome::Filtered {
            sum_kept: true,
            relaxed: true
        },
        "{report:?}"
    );
    assert!(
        (commands[0] - Vector2::new(-0.5, 0.0)).norm() < 1e-6,
        "{commands:?}"
    );
    assert!(
        (commands[1] - Vector2::new(0.5, 0.0)).norm() < 1e-6,
        "{commands:?}"
    );
    // The fallback (for a solver that fails): each accelerates away from the other at its
    // share, inside its envelope.
    filter.brake(&agents, &mut commands, &[0, 1]);
    assert!(
        (commands[0] - Vector2::new(-0.25, 0.0)).norm() < 1e-12,
        "{commands:?}"
    );
    assert!(
        (commands[1] - Vector2::new(0.25, 0.0)).norm() < 1e-12,
        "{commands:?}"
    );
}

/// Uniform numbers in [0, 1) from a 64-bit linear congruential generator (Knuth's MMIX
/// constants): the same swarms on every run.
pub(super) fn uniform(seed: u64) -> impl FnMut() -> f64 {
    let mut x = seed;
    move || {
        x = x
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (x >> 11) as f64 / (1u64 << 53) as f64
    }
}

#[test]
fn random_swarms_meet_every_row_keep_the_sum_and_stay_finite() {
    let mut next = uniform(2024);
    let (mut filtered, mut kept, mut fallbacks, mut relaxed_cases) = (0, 0, 0, 0);
    let mut filter = SafetyFilter::default();
    for case in 0..300 {
        let n = 2 + case % 11;
        let mut agents: Vec<Agent> = (0..n)
            .map(|_| {
                let mut a = agent(
                    [25.0 * next(), 25.0 * next(), 10.0 + 4.0 * next()],
                    [8.0 * next() - 4.0, 8.0 * next() - 4.0, 0.0],
                    1.0 + 3.0 * next(),
                );
                a.drift_mps2 = Vector2::new(next() - 0.5, next() - 0.5);
                a.limit_mps2 = 4.0 + 4.0 * next();
                a.braking_mps2 = 0.25 * a.limit_mps2;
                a
            })
            .collect();
        if case % 7 == 0 {
            agents[0].controlled = false;
        }
        let before: Vec<Vector2<f64>> = (0..n)
            .map(|_| Vector2::new(6.0 * next() - 3.0, 6.0 * next() - 3.0))
            .collect();
        let mut commands = before.clone();
        let keep = case % 3 != 0;
        let s = settings(keep);
        let report = filter.filter(&s, &agents, &mut commands, None);
        assert!(commands.iter().all(|c| c.iter().all(|v| v.is_finite())));
        match report.outcome {
            Outcome::Untouched => assert_eq!(commands, before),
            Outcome::Filtered { sum_kept, relaxed } => {
                filtered += 1;
                assert_eq!(
                    !relaxed,
                    rows_hold(&s, &agents, &commands, 1e-5),
                    "case {case}"
                );
                relaxed_cases += usize::from(relaxed);
                for (k, c) in commands.iter().enumerate() {
                    if agents[k].controlled {
                        // Inside its disc to the solver's tolerance (1e-8): the exact
                        // polish of the sum moves a command by that much.
                        assert!(
                            c.norm() <= agents[k].limit_mps2 + 1e-8,
                            "case {case}: {} > {}",
                            c.norm(),
                            agents[k].limit_mps2
                        );
                    } else {
                        assert_eq!(*c, before[k]);
                    }
                }
                if sum_kept {
                    kept += 1;
                    let delta: Vector2<f64> = (0..n)
                        .map(|k| agents[k].weight * (commands[k] - before[k]))
                        .sum();
                    assert!(delta.norm() < 1e-9, "case {case}: {delta}");
                }
            }
            Outcome::Fallback { .. } | Outcome::Unfinished { .. } => fallbacks += 1,
        }
    }
    eprintln!(
        "filtered {filtered} (relaxed {relaxed_cases}), sum kept {kept}, fallbacks {fallbacks}"
    );
    assert!(filtered > 100 && kept > 50, "{filtered} {kept}");
    // Slack makes every problem feasible: the solver never fails.
    assert_eq!(fallbacks, 0);
}

#[test]
fn pieces_give_what_the_whole_problem_gives_when_no_disc_binds() {
    // Random swarms of commanded vehicles with wide envelopes: the piecewise solve (one
    // QP per group of rows sharing no vehicle, closed form for a lone row) and one QP
    // over everything meet the same optimum, which with no disc binding is unique.
    let mut next = uniform(77);
    let (mut compared, mut max_diff) = (0, 0.0f64);
    for case in 0..200 {
        let n = 2 + case % 13;
        let agents: Vec<Agent> = (0..n)
            .map(|_| {
                let mut a = agent(
                    [40.0 * next(), 40.0 * next(), 10.0],
                    [6.0 * next() - 3.0, 6.0 * next() - 3.0, 0.0],
                    1.0 + 3.0 * next(),
                );
                a.limit_mps2 = 1e3;
                a.braking_mps2 = 3.0;
                a
            })
            .collect();
        let before: Vec<Vector2<f64>> = (0..n)
            .map(|_| Vector2::new(4.0 * next() - 2.0, 4.0 * next() - 2.0))
            .collect();
        let s = settings(case % 2 == 0);
        let mut pieces = before.clone();
        let by_pieces = SafetyFilter::default().filter(&s, &agents, &mut pieces, None);
        let mut whole = before.clone();
        let mut one = SafetyFilter {
            whole_only: true,
            ..SafetyFilter::default()
        };
        let by_whole = one.filter(&s, &agents, &mut whole, None);
        assert_eq!(by_pieces.outcome, by_whole.outcome, "case {case}");
        if let Outcome::Filtered { relaxed: false, .. } = by_whole.outcome {
            compared += 1;
            for k in 0..n {
                max_diff = max_diff.max((pieces[k] - whole[k]).norm());
            }
        }
    }
    eprintln!("{compared} problems compared, largest difference {max_diff:.2e} m/s²");
    assert!(compared > 60, "{compared}");
    // The interior-point solution is accurate to about 1e-5 m/s² (measured 3.1e-5 at
    // most here); a lone row's closed form is exact.
    assert!(max_diff < 1e-4, "{max_diff}");
}

#[test]
fn a_neighbour_the_filter_does_not_command_is_avoided_in_consensus() {
    // Vehicle 0 is in its own Hold (not commanded) at the origin; vehicle 1 flies at it
    // at 3 m/s from 6 m; vehicle 2 is far away. Keeping Σ wᵢuᵢ, vehicle 1 must still turn
    // away (vehicle 2 gives the sum back), not be held to its command with the row
    // relaxed.
    let mut agents = [
        agent([0.0, 0.0, 10.0], [0.0, 0.0, 0.0], 1.0),
        agent([6.0, 0.0, 10.0], [-3.0, 0.0, 0.0], 2.0),
        agent([200.0, 0.0, 10.0], [0.0, 0.0, 0.0], 1.0),
    ];
    agents[0].controlled = false;
    let before = [Vector2::zeros(), Vector2::new(-1.0, 0.0), Vector2::zeros()];
    let mut commands = before;
    let s = settings(true);
    let report = SafetyFilter::default().filter(&s, &agents, &mut commands, None);
    assert_eq!(
        report.outcome,
        Outcome::Filtered {
            sum_kept: true,
            relaxed: false
        },
        "{report:?}"
    );
    assert!(rows_hold(&s, &agents, &commands, 1e-6));
    assert!(commands[1].x > 0.0, "{commands:?}");
    let delta: Vector2<f64> = (1..3)
        .map(|k| agents[k].weight * (commands[k] - before[k]))
        .sum();
    assert!(delta.norm() < 1e-9, "{delta}");
}

#[test]
fn a_vehicle_heading_out_of_the_fence_is_turned_in_and_the_sum_is_kept() {
    // A circle of radius 100 m, margin 5 m. Vehicle 0 is 12 m inside, flying outward at
    // 6 m/s (braking 2 m/s² needs 9 m): its command pushing outward breaks its fence row.
    // Vehicle 1, far inside, takes up the weighted sum.
    let fence = Fence {
        shape: FenceShape::Circle {
            centre_m: Vector2::zeros(),
            radius_m: 100.0,
        },
        min_altitude_m: 0.0,
        max_altitude_m: 100.0,
    };
    let agents = [
        agent([88.0, 0.0, 10.0], [6.0, 0.0, 0.0], 1.0),
        agent([0.0, 0.0, 10.0], [0.0, 0.0, 0.0], 2.0),
    ];
    let before = [Vector2::new(1.0, 0.0), Vector2::new(0.0, 0.0)];
    let mut commands = before;
    let s = settings(true);
    let report = SafetyFilter::default().filter(&s, &agents, &mut commands, Some((&fence, 5.0)));
    assert_eq!(
        report.outcome,
        Outcome::Filtered {
            sum_kept: true,
            relaxed: false
        },
        "{report:?}"
    );
    let row = fence_row(&fence, 5.0, &agents[0].side.unwrap(), 2.0, s.age_s, 1.0).unwrap();
    assert!(
        row.a.dot(&commands[0]) >= row.b - 1e-9,
        "{commands:?} {row:?}"
    );
    assert!(commands[0].x < before[0].x, "turned in: {commands:?}");
    let delta: Vector2<f64> = (0..2)
        .map(|k| agents[k].weight * (commands[k] - before[k]))
        .sum();
    assert!(delta.norm() < 1e-9, "{delta}");
}

#[test]
fn the_dual_ascent_meets_the_interior_point_optimum_with_discs_and_the_sum() {
    // Random packed swarms with narrow envelopes (discs bind) and weights, solved whole
    // by dual ascent and by clarabel: the same commands where clarabel solved without
    // relaxing a row (the optimum is unique: the objective is strictly convex in u).
    let mut next = uniform(2024);
    let (mut compared, mut discs, mut max_diff) = (0, 0, 0.0f64);
    let mut worst_gap = f64::NEG_INFINITY;
    for case in 0..300 {
        let n = 3 + case % 10;
        let agents: Vec<Agent> = (0..n)
            .map(|_| {
                let mut a = agent(
                    [14.0 * next(), 14.0 * next(), 10.0],
                    [4.0 * next() - 2.0, 4.0 * next() - 2.0, 0.0],
                    1.0 + 3.0 * next(),
                );
                a.limit_mps2 = 2.0 + 2.0 * next();
                a.braking_mps2 = 0.5 * a.limit_mps2;
                a
            })
            .collect();
        let before: Vec<Vector2<f64>> = (0..n)
            .map(|k| {
                let u = Vector2::new(4.0 * next() - 2.0, 4.0 * next() - 2.0);
                u * (agents[k].limit_mps2 / u.norm()).min(1.0)
            })
            .collect();
        let s = settings(case % 3 != 0);
        let solve = |exact_only: bool| {
            let mut filter = SafetyFilter {
                whole_only: true,
                exact_only,
                ..SafetyFilter::default()
            };
            let mut commands = before.clone();
            let report = filter.filter(&s, &agents, &mut commands, None);
            (report, commands)
        };
        let (dual, by_dual) = solve(false);
        let (exact, by_exact) = solve(true);
        let Outcome::Filtered { relaxed: false, .. } = exact.outcome else {
            continue;
        };
        assert_eq!(dual.outcome, exact.outcome, "case {case}");
        assert!(rows_hold(&s, &agents, &by_dual, 1e-6), "case {case}");
        compared += 1;
        discs += usize::from((0..n).any(|k| by_exact[k].norm() > agents[k].limit_mps2 - 1e-6));
        for k in 0..n {
            max_diff = max_diff.max((by_dual[k] - by_exact[k]).norm());
        }
        // Both feasible: the ascent's answer costs no more than the interior point's.
        let cost = |u: &[Vector2<f64>]| -> f64 {
            (0..n)
                .map(|k| agents[k].weight * (u[k] - before[k]).norm_squared())
                .sum()
        };
        let (c_dual, c_exact) = (cost(&by_dual), cost(&by_exact));
        worst_gap = worst_gap.max(c_dual - c_exact);
        assert!(
            c_dual <= c_exact + 1e-6 * (1.0 + c_exact),
            "case {case}: {c_dual} > {c_exact}"
        );
        if s.keep_weighted_sum {
            let delta: Vector2<f64> = (0..n)
                .map(|k| agents[k].weight * (by_dual[k] - before[k]))
                .sum();
            assert!(delta.norm() < 1e-8, "case {case}: {delta}");
        }
    }
    eprintln!(
        "{compared} compared ({discs} with a disc binding), largest difference {max_diff:.2e} m/s², cost of the ascent less the interior point's at most {worst_gap:.2e}"
    );
    assert!(compared > 100 && discs > 10, "{compared} {discs}");
    // The interior point stops at its tolerance (about 1e-4 m/s² here with the discs'
    // cones binding); the ascent at 1e-9.
    assert!(max_diff < 5e-4, "{max_diff}");
}

#[test]
fn a_warm_start_from_the_last_tick_takes_fewer_sweeps() {
    // A 6 × 6 block 3.3 m apart, contracting, every vehicle pulled inward: solved twice
    // from the same state, the second call starts from the first one's multipliers and
    // converges in one sweep to the same commands.
    let mut agents = Vec::new();
    let mut before = Vec::new();
    for k in 0..36 {
        let p = Vector2::new(3.3 * (k % 6) as f64 - 8.25, 3.3 * (k / 6) as f64 - 8.25);
        let v = -p * (0.5 / 3.3);
        agents.push(agent([p.x, p.y, 10.0], [v.x, v.y, 0.0], 1.0));
        before.push(-p * (2.0 / p.norm()));
    }
    let s = settings(true);
    let mut filter = SafetyFilter::default();
    let mut cold = before.clone();
    let first = filter.filter(&s, &agents, &mut cold, None);
    let mut warm = before.clone();
    let second = filter.filter(&s, &agents, &mut warm, None);
    assert!(
        matches!(first.outcome, Outcome::Filtered { relaxed: false, .. }),
        "{first:?}"
    );
    assert_eq!(first.outcome, second.outcome);
    assert!(first.sweeps > 10, "{first:?}");
    assert!(second.sweeps <= 2, "{second:?} after {first:?}");
    for k in 0..36 {
        assert!((cold[k] - warm[k]).norm() < 1e-6, "{k}");
    }
}

#[test]
fn out_of_time_the_vehicles_whose_command_then_braking_would_meet_brake_instead() {
    // Two vehicles closing at 2 m/s each, the law pushing them together at 2 m/s²; a
    // third 100 m away flying on.
    let s = Settings {
        time_limit_s: 0.0,
        ..settings(true)
    };
    let agents = [
        agent([0.0, 0.0, 50.0], [2.0, 0.0, 0.0], 1.0),
        agent([8.0, 0.0, 50.0], [-2.0, 0.0, 0.0], 1.0),
        agent([100.0, 0.0, 50.0], [1.0, 0.0, 0.0], 1.0),
    ];
    let mut commands = [
        Vector2::new(2.0, 0.0),
        Vector2::new(-2.0, 0.0),
        Vector2::new(0.5, 0.0),
    ];
    let mut filter = SafetyFilter::default();
    let report = filter.filter(&s, &agents, &mut commands, None);
    // 8 m apart the law's commands break no barrier row: untouched.
    assert_eq!(report.outcome, Outcome::Untouched);
    assert_eq!(commands[0], Vector2::new(2.0, 0.0));
    // 4.4 m apart: rows break. Were there no time to solve, each command, held for the
    // age (0.04 s) and then braking at 2 m/s², closes 0.0816 + 2.08²/4 = 1.16 m, so
    // 4.4 − 2.33 < 3 m: both brake instead, along their velocities at 2 m/s².
    let mut agents = agents;
    agents[1].side = Some(Side {
        pos_m: Vector3::new(4.4, 0.0, 50.0),
        vel_mps: Vector3::new(-2.0, 0.0, 0.0),
        accel_z_mps2: 0.0,
    });
    let mut commands = [
        Vector2::new(2.0, 0.0),
        Vector2::new(-2.0, 0.0),
        Vector2::new(0.5, 0.0),
    ];
    let mut filter = SafetyFilter::default();
    let law = commands;
    let report = filter.filter(&s, &agents, &mut commands, None);
    assert!(report.rows > 0);
    // The check on the law's own commands, over the rows of that call.
    let mut commands = law;
    let Secured {
        braked, unresolved, ..
    } = filter.secure(&s, &agents, &mut commands, None);
    assert_eq!(braked, 2);
    // The command already on its way still flies for the delay (0.02 s): 0.0404 m, then
    // 2.04²/4 = 1.04 m braking, each: 2.24 m apart at rest, inside 3 m, so counted.
    assert_eq!(unresolved, 1);
    assert!(
        (commands[0] - Vector2::new(-2.0, 0.0)).norm() < 1e-12,
        "{:?}",
        commands[0]
    );
    assert!(
        (commands[1] - Vector2::new(2.0, 0.0)).norm() < 1e-12,
        "{:?}",
        commands[1]
    );
    assert_eq!(commands[2], Vector2::new(0.5, 0.0));
}

/// The check counts a pair's unseen speed as closing velocity of its harder-braking
/// vehicle, braked away as the barrier's row counts it.
#[test]
fn the_check_counts_a_pair_s_unseen_speed_as_closing() {
    // Two vehicles at rest 3.3 m apart; a first call with no command gives the rows and
    // puts nothing on its way. Then the first is pushed towards the second at 0.5 m/s².
    // Age 0.04 s of which a period (0.02 s) is the hold: keep 3 + ½(6 + 6)·0.02² =
    // 3.0024 m. With δ of unseen speed on the first (the two brake alike: the first takes
    // it), it moves at δ for the delay (0.02 δ m), then for the hold at 0.5 m/s²
    // (0.02 δ + ½·0.5·0.02² m, to δ + 0.01 m/s), then brakes at 2 m/s² ((δ + 0.01)²/4 m):
    // with x = δ + 0.01 the pair conflicts when x² + 0.16x − 1.1916 > 0, i.e.
    // δ > 1.00453 m/s.
    let s = settings(false);
    let check = |unseen_mps: f64| {
        let mut agents = [
            agent([0.0, 0.0, 50.0], [0.0, 0.0, 0.0], 1.0),
            agent([3.3, 0.0, 50.0], [0.0, 0.0, 0.0], 1.0),
        ];
        let mut filter = SafetyFilter::default();
        filter.filter(&s, &agents, &mut [Vector2::zeros(); 2], None);
        agents[0].unseen_mps = unseen_mps;
        let mut commands = [Vector2::new(0.5, 0.0), Vector2::zeros()];
        let secured = filter.secure(&s, &agents, &mut commands, None);
        (secured.braked, commands[0])
    };
    assert_eq!(check(0.0), (0, Vector2::new(0.5, 0.0)));
    assert_eq!(check(0.995), (0, Vector2::new(0.5, 0.0)));
    // Over the bound both brake: the first stops pushing (its reported velocity is nil,
    // so there is nothing to brake).
    assert_eq!(check(1.015), (2, Vector2::zeros()));
}

/// A `side` × `side` block 4 m apart about the origin, each vehicle flown by a PD law to
/// its start mirrored through the centre, every command acting a tick after its state
/// (exact double integrators, 10 ms ticks, age 0.02 s); the filter with `s` except that
/// ticks `[out_from, ticks)` have no time at all. The closest pair at any tick (m), the
/// vehicles the check braked and the pairs it left unresolved.
fn packed_swap(side: usize, s: Settings, ticks: usize, out_from: usize) -> (f64, usize, usize) {
    let dt = 0.01;
    let half = 2.0 * (side - 1) as f64;
    let mut pos: Vec<Vector2<f64>> = (0..side * side)
        .map(|i| {
            Vector2::new(
                4.0 * (i % side) as f64 - half,
                4.0 * (i / side) as f64 - half,
            )
        })
        .collect();
    let places: Vec<Vector2<f64>> = pos.iter().map(|p| -p).collect();
    let n = pos.len();
    let mut vel = vec![Vector2::zeros(); n];
    let mut flying = vec![Vector2::zeros(); n];
    let mut filter = SafetyFilter::default();
    let (mut closest, mut braked, mut unresolved) = (f64::INFINITY, 0, 0);
    for tick in 0..ticks {
        let agents: Vec<Agent> = (0..n)
            .map(|k| Agent {
                braking_mps2: 3.0,
                lag_s: 0.0,
                spread_m: 0.0,
                unseen_mps: 0.0,
                ..agent([pos[k].x, pos[k].y, 50.0], [vel[k].x, vel[k].y, 0.0], 1.0)
            })
            .collect();
        let mut commands: Vec<Vector2<f64>> = (0..n)
            .map(|k| {
                let u = (places[k] - pos[k]) * 0.05 - vel[k] * 0.5;
                u * (6.0 / u.norm().max(6.0))
            })
            .collect();
        let tick_settings = Settings {
            time_limit_s: if tick >= out_from {
                0.0
            } else {
                s.time_limit_s
            },
            ..s
        };
        let report = filter.filter(&tick_settings, &agents, &mut commands, None);
        braked += report.braked;
        unresolved += report.unresolved;
        for i in 0..n {
            for j in i + 1..n {
                closest = closest.min((pos[i] - pos[j]).norm());
            }
        }
        for k in 0..n {
            pos[k] += vel[k] * dt + flying[k] * (0.5 * dt * dt);
            vel[k] += flying[k] * dt;
        }
        flying = commands;
    }
    (closest, braked, unresolved)
}

#[test]
fn with_the_stopping_rows_a_packed_swap_keeps_apart_and_braking_from_any_tick_is_safe() {
    let s = Settings {
        age_s: 0.02,
        period_s: 0.01,
        rows: Rows::Stopping,
        ..settings(true)
    };
    // Solved every tick: the answers meet the stopping rows, which leave 5 mm to the
    // check: it never brakes, and the block stays 3 m apart.
    let (closest, braked, unresolved) = packed_swap(4, s, 800, usize::MAX);
    assert!(closest >= 3.0, "{closest}");
    assert_eq!((braked, unresolved), (0, 0));
    // From tick 300 (the block compressed and moving) no time at all: every vehicle
    // brakes along the plans the last check passed, and nobody comes within 3 m.
    let (closest, braked, unresolved) = packed_swap(4, s, 800, 300);
    assert!(closest >= 3.0 - 1e-9, "{closest}");
    assert!(braked >= 16 * 400, "{braked}");
    assert_eq!(unresolved, 0);
}

/// The check in a frame that moves: a drifting line, the middle vehicle ours and its two
/// neighbours flown by somebody else at the drift (1 m/s east), 3.5 m apart; our
/// vehicle's command keeps the drift. Braked to rest, it is run into by the one behind:
/// the check brakes it and still counts the pair. Braked to the drift, nothing conflicts
/// and the command stays.
#[test]
fn braking_to_the_common_velocity_keeps_a_vehicle_s_place_in_a_drifting_line() {
    let drift = Vector2::new(1.0, 0.0);
    let mut agents = [
        agent([0.0, 0.0, 50.0], [1.0, 0.0, 0.0], 1.0),
        agent([3.5, 0.0, 50.0], [1.0, 0.0, 0.0], 1.0),
        agent([7.0, 0.0, 50.0], [1.0, 0.0, 0.0], 1.0),
    ];
    agents[0].controlled = false;
    agents[2].controlled = false;
    let check = |brake_to_mps: Vector2<f64>| {
        let s = Settings {
            time_limit_s: 0.0,
            brake_to_mps,
            ..settings(false)
        };
        let mut filter = SafetyFilter::default();
        let mut commands = [Vector2::zeros(); 3];
        filter.filter(&s, &agents, &mut commands, None);
        let mut commands = [Vector2::zeros(); 3];
        let secured = filter.secure(&s, &agents, &mut commands, None);
        (secured, commands)
    };
    let (at_rest, commands) = check(Vector2::zeros());
    assert_eq!((at_rest.braked, at_rest.unresolved), (1, 1));
    // Braking along its velocity at 2 m/s², the most that stops it within the hold:
    // 1 m/s over the 0.02 s hold would be 50 m/s², so the braking share.
    assert!(
        (commands[1] - Vector2::new(-2.0, 0.0)).norm() < 1e-12,
        "{commands:?}"
    );
    let (moving, commands) = check(drift);
    assert_eq!((moving.braked, moving.unresolved), (0, 0));
    assert_eq!(commands[1], Vector2::zeros());
    // A velocity that is not a number is rest.
    let (nan, _) = check(Vector2::new(f64::NAN, 0.0));
    assert_eq!((nan.braked, nan.unresolved), (1, 1));
}

/// The same conflict seen from a frame moving at `c`: every velocity plus `c` and the
/// check braking to `c` brakes the same vehicles, counts the same pairs and gives the same
/// commands as the check braking to rest (accelerations do not change with the frame).
#[test]
fn the_check_braking_to_a_velocity_is_the_check_at_rest_in_the_frame_moving_with_it() {
    let base = [
        agent([0.0, 0.0, 50.0], [2.0, 0.0, 0.0], 1.0),
        agent([4.4, 0.0, 50.0], [-2.0, 0.0, 0.0], 1.0),
        agent([100.0, 0.0, 50.0], [1.0, 0.0, 0.0], 1.0),
    ];
    let law = [
        Vector2::new(2.0, 0.0),
        Vector2::new(-2.0, 0.0),
        Vector2::new(0.5, 0.0),
    ];
    let run = |c: Vector2<f64>| {
        let s = Settings {
            time_limit_s: 0.0,
            brake_to_mps: c,
            ..settings(true)
        };
        let mut agents = base;
        for a in &mut agents {
            if let Some(side) = a.side.as_mut() {
                side.vel_mps += Vector3::new(c.x, c.y, 0.0);
            }
        }
        let mut filter = SafetyFilter::default();
        let mut commands = law;
        filter.filter(&s, &agents, &mut commands, None);
        let mut commands = law;
        let secured = filter.secure(&s, &agents, &mut commands, None);
        (secured.braked, secured.unresolved, commands)
    };
    let (braked, unresolved, at_rest) = run(Vector2::zeros());
    assert_eq!((braked, unresolved), (2, 1));
    for c in [Vector2::new(1.0, 0.0), Vector2::new(-3.0, 2.5)] {
        let (b, u, moving) = run(c);
        assert_eq!((b, u), (braked, unresolved), "{c}");
        for k in 0..3 {
            assert!(
                (moving[k] - at_rest[k]).norm() < 1e-9,
                "{c} {k}: {moving:?} {at_rest:?}"
            );
        }
    }
}

#[test]
fn a_vehicle_closing_on_a_lost_ones_stopping_path_brakes_for_where_it_may_stop() {
    use super::lost::LostVehicle;
    // Ours at x = 0 flying east at 1 m/s; the lost one last seen at x = 8 flying west at
    // 2 m/s, coasting 1.05 s at most, then braking at 1 m/s² or harder: its path runs
    // 2·(1.05 + 2/2) = 4.1 m west, to x = 3.9, with the Hold's 0.25 m either side.
    let path = LostVehicle {
        pos_m: Vector3::new(8.0, 0.0, 10.0),
        vel_mps: Vector2::new(-2.0, 0.0),
        coast_s: 1.05,
        speed_margin_mps: 0.0,
        braking_mps2: 1.0,
    }
    .path()
    .expect("bounded");
    let mut agents = vec![agent([0.0, 0.0, 10.0], [1.0, 0.0, 0.0], 1.0)];
    agents.extend(path.points().map(|(p, spread)| Agent::bound(p, spread)));
    // 9 gaps of 4.1/9 m: each point's spread is 0.25 m and half a gap.
    assert_eq!(agents.len(), 11);
    let spread: f64 = 0.25 + 0.5 * 4.1 / 9.0;
    let mut commands = vec![Vector2::zeros(); agents.len()];
    let s = settings(false);
    let report = SafetyFilter::default().filter(&s, &agents, &mut commands, None);
    // The nearest point, at x = 3.9: D = 3.9, d = 3 + spread + |Δv|τ + Aτ²/2 with
    // |Δv| = 1, τ = 0.04 s and A = 2 (ours alone brakes); closing at s = −1:
    // aᵀu ≥ −γh³ − A·s/√(2A(D − d)), a = (−1, 0).
    let d: f64 = 3.0 + spread + 0.04 + 0.5 * 2.0 * 0.04 * 0.04;
    let root = (2.0 * 2.0 * (3.9 - d)).sqrt();
    let h = -1.0 + root;
    let b = -h * h * h + 2.0 / root;
    assert!(b > 1.5, "it must brake: {b}");
    assert!(
        (commands[0].x + b).abs() < 1e-6,
        "{} vs {}",
        commands[0].x,
        -b
    );
    assert!(commands[0].y.abs() < 1e-9);
    assert!(matches!(report.outcome, Outcome::Filtered { .. }));
    // The points stand for where it may be, not for a state: no closest pair, no close
    // pair, no active row named.
    assert_eq!(report.closest, None);
    let filter_close = {
        let mut f = SafetyFilter::default();
        let mut c = vec![Vector2::zeros(); agents.len()];
        f.filter(&s, &agents, &mut c, None);
        (f.close_pairs(100.0).count(), f.active_rows().len())
    };
    assert_eq!(filter_close, (0, 0));
    // Seen as a state that keeps its velocity, it would not have been braked for.
    let mut as_state = vec![
        agents[0],
        Agent {
            controlled: false,
            ..agent([8.0, 0.0, 10.0], [-2.0, 0.0, 0.0], 1.0)
        },
    ];
    let mut free = vec![Vector2::zeros(); 2];
    SafetyFilter::default().filter(&s, &as_state, &mut free, None);
    assert_eq!(free[0], Vector2::zeros());
    // Beside a measured neighbour the closest pair is the measured one.
    as_state[1].side = Some(Side {
        pos_m: Vector3::new(0.0, 30.0, 10.0),
        vel_mps: Vector3::zeros(),
        accel_z_mps2: 0.0,
    });
    agents.push(as_state[1]);
    let mut c = vec![Vector2::zeros(); agents.len()];
    let report = SafetyFilter::default().filter(&s, &agents, &mut c, None);
    let (i, j, distance) = report.closest.expect("two measured");
    assert_eq!((i, j), (0, agents.len() - 1));
    assert!((distance - 30.0).abs() < 1e-12);
}
