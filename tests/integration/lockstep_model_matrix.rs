//! A wrong model never runs the swarm away: six emulated x500s (2.0 kg, hover 0.5, drag
//! 0.1/s) flown with config/px4-sih.toml's gains and formation, the coordinator's model
//! wrong one way at a time: drag 10× and 2× over and under, hover ±10 %, mass ±30 %.
//! Each is flown twice: hovering into the hexagon (no target), and with the planner
//! asked for (3, 2) m/s. The drag estimator learns the drag in flight and the feed-forward
//! never exceeds what the estimate supports, so every run ends on its prediction.
//!
//! Truth at the end of consensus (the emulator's velocities and positions):
//! - the w-weighted mean velocity within 1 % of the prediction (0.01 m/s when it is zero);
//! - the formation within 1 m;
//! - no vehicle faster than the planner's speed limit (`[target] max_speed_mps` = 6).
//!
//! Then the same runaway with the drag estimator off: the divergence guard stops it.

use nalgebra::Vector2;
use ringswarm::config::Config;
use ringswarm::control::ned_to_enu;
use ringswarm::driver::lockstep::Lockstep;
use ringswarm::swarm::VehicleIndex;
use ringswarm::swarm::{PlanDecision, StopReason, SwarmPhase};
use ringswarm_wire::time::SimTime;

/// px4-sih.toml on the emulator's x500 (each vehicle's `profile = "x500"`), with the model
/// numbers given and, with `target`, the planner asked for it.
fn config(mass_kg: f64, hover: f64, drag_per_s: f64, target: bool) -> Config {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/px4-sih.toml");
    let mut config = Config::from_toml(&std::fs::read_to_string(path).unwrap()).unwrap();
    for v in &mut config.vehicle {
        v.mass_kg = mass_kg;
        v.hover_throttle = hover;
        v.drag_per_s = drag_per_s;
    }
    if target {
        let text =
            "velocity_enu_mps = [3.0, 2.0]\nk_margin = 1.3\nk_max = 2.0\nmax_speed_mps = 6.0";
        config.target = Some(toml::from_str(text).unwrap());
    }
    config
}

#[derive(Debug)]
struct Outcome {
    predicted: Vector2<f64>,
    mean: Vector2<f64>,
    formation_m: f64,
    max_speed_mps: f64,
    stop: Option<StopReason>,
    drag: Vec<f64>,
    planned: Option<PlanDecision>,
}

/// Flies to the end of consensus (40 s after it starts) and reads the truth there.
fn fly(config: &Config) -> Outcome {
    let mut run = Lockstep::from_config(config).unwrap();
    let mut max_speed_mps: f64 = 0.0;
    let end = SimTime::from_millis(120_000);
    let mut at_end = None;
    while run.now() < end && at_end.is_none() {
        let next = run.now() + std::time::Duration::from_millis(20);
        run.run_until(next, |_| {});
        for v in run.vehicles() {
            max_speed_mps = max_speed_mps.max(v.status().vel_ned_mps.xy().norm());
        }
        if matches!(
            run.swarm().phase(),
            SwarmPhase::Landing(_) | SwarmPhase::Stopped(_)
        ) {
            at_end = Some(());
        }
    }
    let swarm = run.swarm();
    let mean = crate::common::weighted_mean_velocity_enu(run.vehicles(), &swarm.setup().ring);
    let shifted: Vec<Vector2<f64>> = run
        .vehicles()
        .iter()
        .zip(&swarm.setup().offsets_m)
        .map(|(v, d)| ned_to_enu(v.status().pos_world_ned_m).xy() - d)
        .collect();
    let centre = shifted.iter().sum::<Vector2<f64>>() / 6.0;
    Outcome {
        predicted: swarm.predicted_final_velocity().unwrap(),
        mean,
        formation_m: shifted
            .iter()
            .map(|p| (p - centre).norm())
            .fold(0.0, f64::max),
        max_speed_mps,
        stop: swarm.stop_reason(),
        drag: (0..6)
            .map(|i| swarm.drag_estimate(VehicleIndex(i)).unwrap().0)
            .collect(),
        planned: swarm.plan_decision().cloned(),
    }
}

fn check(name: &str, mass_kg: f64, hover: f64, drag_per_s: f64) {
    for target in [false, true] {
        let o = fly(&config(mass_kg, hover, drag_per_s, target));
        eprintln!("{name} target {target}: {o:?}");
        assert_eq!(o.stop, Some(StopReason::DurationOver), "{name}: {o:?}");
        let error = (o.mean - o.predicted).norm();
        let bound = if target {
            0.01 * o.predicted.norm()
        } else {
            0.01
        };
        assert!(
            error <= bound,
            "{name} target {target}: {error} m/s off, {o:?}"
        );
        assert!(o.formation_m < 1.0, "{name} target {target}: {o:?}");
        // Far below the x500's drag-limited top speed (g·tan 35° / 0.1 = 68.7 m/s; the
        // runaways reached 38 and 63 m/s): within 10 % of the planner's 6 m/s limit, the
        // formation's transient on top of the cruise (measured 5.6-6.1 m/s).
        assert!(o.max_speed_mps <= 6.6, "{name} target {target}: {o:?}");
        if target {
            // The target itself: stage 1 ends with every re-targeted agent within 0.05 m/s
            // of its planned velocity, whose weighted mean is the target, so the
            // prediction is within 0.05 m/s of it (1.4 % of 3.6 m/s).
            assert!(
                (o.predicted - Vector2::new(3.0, 2.0)).norm() <= 0.05,
                "{name}: {o:?}"
            );
            // The paper's one agent would need (3, 2)·9/2 = 16.2 m/s at k = 1 and more at
            // any admissible k ≤ 2: every agent is re-targeted.
            let Some(PlanDecision::Planned { retarget, .. }) = &o.planned else {
                panic!("{name}: {o:?}");
            };
            assert_eq!(retarget.len(), 6, "{name}: {o:?}");
        }
    }
}

#[test]
fn drag_ten_times_too_high_flies() {
    check("drag 10x over", 2.0, 0.5, 1.0);
}

#[test]
fn drag_twice_too_high_flies() {
    check("drag 2x over", 2.0, 0.5, 0.2);
}

#[test]
fn drag_half_flies() {
    check("drag 2x under", 2.0, 0.5, 0.05);
}

#[test]
fn drag_a_tenth_flies() {
    check("drag 10x under", 2.0, 0.5, 0.01);
}

#[test]
fn hover_ten_percent_off_flies() {
    check("hover +10 %", 2.0, 0.55, 0.1);
    check("hover -10 %", 2.0, 0.45, 0.1);
}

#[test]
fn mass_thirty_percent_off_flies() {
    // The law asks for a specific thrust: thrust_norm = |u + g|·hover/g, the mass cancels.
    check("mass +30 %", 2.6, 0.5, 0.1);
    check("mass -30 %", 1.4, 0.5, 0.1);
}

#[test]
fn the_learnt_drag_is_the_airframes() {
    // With the target the vehicles cruise at 3.6 m/s: the drag shows in every window.
    let o = fly(&config(2.0, 0.5, 1.0, true));
    for d in &o.drag {
        assert!((d - 0.1).abs() < 0.03, "{:?}", o.drag);
    }
}

#[test]
fn without_the_estimator_the_guard_stops_the_runaway_within_seconds() {
    let mut config = config(2.0, 0.5, 1.0, true);
    config.swarm.estimate_drag = false;
    config.swarm.disturbance_time_constant_s = 0.0;
    let mut run = Lockstep::from_config(&config).unwrap();
    run.run_until(SimTime::from_millis(120_000), |_| {});
    let swarm = run.swarm();
    let Some(StopReason::Guard(trip)) = swarm.stop_reason() else {
        panic!("{:?}", swarm.stop_reason());
    };
    assert_eq!(trip.cause(), "velocity", "{trip}");
    let started = swarm.consensus_started().unwrap();
    let stopped = swarm
        .events()
        .iter()
        .find(|e| e.text.starts_with("divergence guard"))
        .unwrap()
        .t;
    let after_s = stopped.saturating_since(started).as_secs_f64();
    assert!(after_s < 5.0, "stopped {after_s} s into consensus");
    // The end action after the duration: everyone landed, nobody ever sped off.
    assert!(matches!(swarm.phase(), SwarmPhase::Landing(_)));
    assert!(swarm.guard_trip().is_some());
}
