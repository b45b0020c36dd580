//! The coordinator's configuration files: the shipped scenarios load, bad files are refused
//! with every problem named.

use std::path::Path;

use ringswarm::config::Config;

fn load(name: &str) -> Config {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("config")
        .join(name);
    Config::from_toml(&std::fs::read_to_string(&path).unwrap()).unwrap()
}

#[test]
fn shipped_scenarios_validate() {
    for name in ["paper-sim1.toml", "paper-sim2.toml", "hexagon-x500.toml"] {
        let setup = load(name)
            .validate()
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(setup.ring.agents(), 6, "{name}");
        assert_eq!(setup.offsets_m.len(), 6);
        // Hexagon of radius 20: vertex 2 at 60°.
        assert!(
            (setup.offsets_m[1] - nalgebra::Vector2::new(10.0, 20.0 * 3f64.sqrt() / 2.0)).norm()
                < 1e-12
        );
    }
    // paper-sim2 starts like paper-sim1 and asks the planner for (20, 30).
    let sim2 = load("paper-sim2.toml").validate().unwrap();
    assert_eq!(
        sim2.target.map(|t| t.velocity_mps),
        Some(nalgebra::Vector2::new(20.0, 30.0))
    );
    assert_eq!(
        load("paper-sim2.toml").vehicle[0].start_velocity_enu_mps,
        [9.0, 4.0, 0.0]
    );
}

#[test]
fn a_bad_target_is_refused_with_every_problem() {
    let text = with(
        "[formation]",
        "[target]\nvelocity_enu_mps = [20.0, nan]\nk_margin = -1.0\ntolerance_mps = 0.0\n\n[formation]",
    );
    let err = Config::from_toml(&text).unwrap().validate().unwrap_err();
    for needle in [
        "target.velocity_enu_mps must be finite",
        "target.k_margin must be finite and at least 0, got -1",
        "target.tolerance_mps must be positive, got 0",
    ] {
        assert!(err.contains(needle), "{needle} not in:\n{err}");
    }
    let text = with(
        "[formation]",
        "[target]\nvelocity = [20.0, 30.0]\n\n[formation]",
    );
    let err = Config::from_toml(&text).unwrap_err();
    assert!(err.contains("unknown field `velocity`"), "{err}");
}

fn with(replace: &str, by: &str) -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/paper-sim1.toml");
    let text = std::fs::read_to_string(path).unwrap();
    assert!(text.contains(replace), "{replace}");
    text.replacen(replace, by, 1)
}

#[test]
fn unstable_gains_are_refused_with_the_numbers() {
    let cfg = Config::from_toml(&with("beta = 5.0", "beta = 0.5")).unwrap();
    let setup = with("k = 5.0", "k = -1.5");
    let err = cfg.validate().unwrap_err();
    assert!(
        err.contains("gains are unstable") && err.contains("Yu's bound 1.221423"),
        "{err}"
    );
    let err = Config::from_toml(&setup).unwrap().validate().unwrap_err();
    assert!(
        err.contains("bound k > -1.292893") && err.contains("margin -0.207107"),
        "{err}"
    );
}

#[test]
fn a_time_scale_scales_alpha_by_c_squared_and_beta_by_c_and_is_checked() {
    let setup = Config::from_toml(&with("k_vz = 4.0", "k_vz = 4.0\ntime_scale = 0.5"))
        .unwrap()
        .validate()
        .unwrap();
    assert_eq!((setup.gains.alpha, setup.gains.beta), (0.25, 2.5));
    let err = Config::from_toml(&with("k_vz = 4.0", "k_vz = 4.0\ntime_scale = 0.0"))
        .unwrap()
        .validate()
        .unwrap_err();
    assert!(
        err.contains("gains.time_scale must be in (0, 10], got 0"),
        "{err}"
    );
}

#[test]
fn unknown_keys_are_refused() {
    let err = Config::from_toml(&with(
        "kind = \"polygon\"",
        "kind = \"polygon\"\nradius = 3.0",
    ))
    .unwrap_err();
    assert!(err.contains("unknown field `radius`"), "{err}");
}

#[test]
fn odd_vehicle_count_nan_and_duplicates_are_all_reported_at_once() {
    let mut text = with("alpha = 1.0", "alpha = nan");
    text = text.replacen("system_id = 2", "system_id = 1", 1);
    let cut = text.rfind("[[vehicle]]").unwrap();
    text.truncate(cut); // five vehicles
    let err = Config::from_toml(&text).unwrap().validate().unwrap_err();
    let lines: Vec<&str> = err.lines().collect();
    assert!(
        err.contains("even number of agents (N = 2m); 5 given"),
        "{err}"
    );
    assert!(err.contains("alpha must be a finite number"), "{err}");
    assert!(err.contains("system_id 1 is used twice"), "{err}");
    assert!(lines.len() >= 3, "{err}");
}

#[test]
fn lockstep_faults_are_checked_and_converted() {
    let text = with(
        "ground_below_m = 100.0",
        "ground_below_m = 100.0\nlatency_ms = 10.0\njitter_ms = 20.0\nloss_pct = 20.0\nseed = 7\n\
         [[emulator.silence]]\nvehicle = 3\nfrom_s = 20.0\nuntil_s = 23.0",
    );
    let faults = Config::from_toml(&text).unwrap().lockstep_faults().unwrap();
    assert_eq!(
        faults.conditions.latency,
        std::time::Duration::from_millis(10)
    );
    assert_eq!(
        faults.conditions.jitter,
        std::time::Duration::from_millis(20)
    );
    assert!((faults.conditions.loss - 0.2).abs() < 1e-12);
    assert_eq!(faults.conditions.seed, 7);
    use ringswarm_sitl::time::SimTime;
    assert_eq!(
        faults.silences,
        vec![(
            2,
            SimTime::from_millis(20_000),
            SimTime::from_millis(23_000)
        )]
    );
    let bad = with(
        "ground_below_m = 100.0",
        "ground_below_m = 100.0\nloss_pct = 150.0\n\
         [[emulator.silence]]\nvehicle = 9\nfrom_s = 5.0\nuntil_s = 4.0",
    );
    let err = Config::from_toml(&bad)
        .unwrap()
        .lockstep_faults()
        .unwrap_err();
    for needle in [
        "emulator.loss_pct must be in [0, 100], got 150",
        "emulator.silence[0].vehicle must be 1..=6, got 9",
        "emulator.silence[0] needs 0 <= from_s < until_s, got 5 .. 4",
    ] {
        assert!(err.contains(needle), "{needle} not in:\n{err}");
    }
}

#[test]
fn the_coordinator_ids_default_to_253_190_and_may_not_be_a_vehicle_s() {
    let setup = load("paper-sim1.toml").validate().unwrap();
    assert!(setup.links.iter().all(|l| l.own_ids == (253, 190)));
    let text = with(
        "[swarm]",
        "[swarm]\ngcs_system_id = 2\ngcs_component_id = 191",
    );
    let err = Config::from_toml(&text).unwrap().validate().unwrap_err();
    assert!(
        err.contains("vehicle[1].system_id 2 is the coordinator's own swarm.gcs_system_id"),
        "{err}"
    );
    let text = with("[swarm]", "[swarm]\ngcs_system_id = 0");
    let err = Config::from_toml(&text).unwrap().validate().unwrap_err();
    assert!(
        err.contains("swarm.gcs_system_id must be 1..=255, got 0"),
        "{err}"
    );
    let text = with(
        "[swarm]",
        "[swarm]\ngcs_system_id = 200\ngcs_component_id = 191",
    );
    let setup = Config::from_toml(&text).unwrap().validate().unwrap();
    assert!(setup.links.iter().all(|l| l.own_ids == (200, 191)));
}
