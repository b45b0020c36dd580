//! The coordinator's configuration files: the shipped scenarios load, bad files are refused
//! with every problem named.

use std::path::Path;

use ringswarm::config::Config;
use ringswarm::index::SystemId;

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
        "target.velocity_enu_mps[1] must be a finite number in [-100, 100] m/s, got NaN",
        "target.k_margin must be a finite number in [0, 10000], got -1",
        "target.tolerance_mps must be a finite number in (0, 10] m/s, got 0",
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
        err.contains("gains.time_scale must be a finite number in (0, 10], got 0"),
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
        faults.conditions.faults.latency,
        std::time::Duration::from_millis(10)
    );
    assert_eq!(
        faults.conditions.faults.jitter,
        std::time::Duration::from_millis(20)
    );
    assert!((faults.conditions.faults.loss - 0.2).abs() < 1e-12);
    assert_eq!(faults.conditions.seed, 7);
    use ringswarm_wire::time::SimTime;
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
        "emulator.loss_pct must be a percentage in [0, 100], got 150",
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

/// Every float of the file, set to a value that cannot be flown, is refused by its key and
/// value; the config is refused as a whole (no setup, nothing sent).
#[test]
fn every_bad_number_is_refused_by_its_key() {
    let cases: &[(&str, &str, &str)] = &[
        (
            "k = 5.0",
            "k = nan",
            "gains.k must be a finite number in [-2, 10000], got NaN",
        ),
        (
            "alpha = 1.0",
            "alpha = inf",
            "gains.alpha must be a finite number in (0, 10000] 1/s², got inf",
        ),
        (
            "beta = 5.0",
            "beta = -5.0",
            "gains.beta must be a finite number in (0, 10000] 1/s, got -5",
        ),
        (
            "k_pz = 1.0",
            "k_pz = nan",
            "gains.k_pz must be a finite number in (0, 10000] 1/s², got NaN",
        ),
        (
            "k_vz = 4.0",
            "k_vz = 1e300",
            "gains.k_vz must be a finite number in (0, 10000] 1/s, got 1e300",
        ),
        (
            "radius_m = 20.0",
            "radius_m = 1e9",
            "formation.radius_m must be a finite number in (0, 10000] m, got 1e9",
        ),
        (
            "altitude_m = 50.0",
            "altitude_m = nan",
            "formation.altitude_m must be a finite number in [-10000, 10000] m, got NaN",
        ),
        (
            "duration_s = 60.0",
            "duration_s = 1e20",
            "swarm.duration_s must be a finite number in (0, 1000000] s, got 1e20",
        ),
        (
            "control_rate_hz = 250.0",
            "control_rate_hz = nan",
            "swarm.control_rate_hz must be a finite number in [1, 250] Hz, got NaN",
        ),
        (
            "max_tilt_deg = 45.0",
            "max_tilt_deg = 90.0",
            "envelope.max_tilt_deg must be a finite number in (0, 80] deg, got 90",
        ),
        (
            "max_thrust = 0.95",
            "max_thrust = nan",
            "envelope.max_thrust must be a finite number in [0, 1], got NaN",
        ),
        (
            "latitude_deg = 47.397742",
            "latitude_deg = 95.0",
            "frame.latitude_deg must be a finite number in [-85, 85] deg, got 95",
        ),
        (
            "longitude_deg = 8.545594",
            "longitude_deg = nan",
            "frame.longitude_deg must be a finite number in [-180, 180] deg, got NaN",
        ),
        (
            "ground_below_m = 100.0",
            "ground_below_m = inf",
            "emulator.ground_below_m must be a finite number in [-10000, 10000] m, got inf",
        ),
        (
            "mass_kg = 1.0",
            "mass_kg = nan",
            "vehicle[0].mass_kg must be a finite number in (0, 1000] kg, got NaN",
        ),
        (
            "hover_throttle = 0.2",
            "hover_throttle = 1.0",
            "vehicle[0].hover_throttle must be a finite number in [0.01, 0.99], got 1",
        ),
        (
            "drag_per_s = 0.0",
            "drag_per_s = nan",
            "vehicle[0].drag_per_s must be a finite number in [0, 10] 1/s, got NaN",
        ),
        (
            "start_enu_m = [0.0, 20.0, 0.0]",
            "start_enu_m = [0.0, nan, 0.0]",
            "vehicle[0].start_enu_m[1] must be a finite number in [-10000, 10000] m, got NaN",
        ),
        (
            "start_velocity_enu_mps = [9.0, 4.0, 0.0]",
            "start_velocity_enu_mps = [9.0, 4.0, 1e3]",
            "vehicle[0].start_velocity_enu_mps[2] must be a finite number in [-100, 100] m/s, got 1000",
        ),
    ];
    for (from, to, message) in cases {
        let text = with(from, to);
        let err = Config::from_toml(&text)
            .unwrap()
            .validate()
            .expect_err(&format!("{to} accepted"));
        assert!(
            err.lines().any(|l| l == *message),
            "{message}\nnot in:\n{err}"
        );
    }
}

#[test]
fn a_nan_offset_is_refused_by_its_index() {
    let text = with(
        "kind = \"polygon\"\nradius_m = 20.0",
        "kind = \"offsets\"\noffsets_m = [[20.0, 0.0], [10.0, 17.32], [-10.0, nan], [-20.0, 0.0], [-10.0, -17.32], [10.0, -17.32]]",
    );
    let err = Config::from_toml(&text).unwrap().validate().unwrap_err();
    assert_eq!(
        err,
        "formation.offsets_m[2][1] must be a finite number in [-10000, 10000] m, got NaN"
    );
}

#[test]
fn timeouts_are_checked_against_the_rates() {
    let text = with(
        "link_timeout_ms = 1500",
        "handshake_timeout_s = 0.5\nstate_timeout_ms = 5\nlink_timeout_ms = 99\ncommand_attempts = 0",
    );
    let err = Config::from_toml(&text).unwrap().validate().unwrap_err();
    for needle in [
        "swarm.handshake_timeout_s must be a finite number in [1, 3600] s, got 0.5",
        // 250 Hz: three control periods are 12 ms.
        "swarm.state_timeout_ms must be a finite number in [12, 99] ms (three control periods up to swarm.link_timeout_ms), got 5",
        "swarm.link_timeout_ms must be a finite number in [100, 60000] ms, got 99",
        "swarm.command_attempts must be a finite number in [1, 50] (sends of a command before its link fails), got 0",
    ] {
        assert!(err.lines().any(|l| l == needle), "{needle}\nnot in:\n{err}");
    }
    // The defaults: 30 s, 300 ms, 10 sends of a command, no retake.
    let setup = Config::from_toml(&with("k = 5.0", "k = 5.0"))
        .unwrap()
        .validate()
        .unwrap();
    assert_eq!(setup.handshake_timeout, std::time::Duration::from_secs(30));
    assert!(
        setup
            .links
            .iter()
            .all(|l| l.state_timeout == std::time::Duration::from_millis(300)
                && l.max_attempts == 10
                && !l.retake_offboard)
    );
}

/// Every shipped scenario flies gains its airframes can follow at its control rate (the
/// bandwidth gate of docs/math.md), and the gate is what fixed hexagon-x500's time scale.
#[test]
fn shipped_scenarios_pass_the_bandwidth_gate() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("config");
    let mut names: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    names.sort();
    for path in names {
        let config = Config::from_toml(&std::fs::read_to_string(&path).unwrap()).unwrap();
        let gate = config.bandwidth_check().unwrap();
        eprintln!(
            "{}: fastest {:.2} 1/s, allowed {:.2} ({}), scale that fits {:.3}",
            path.display(),
            gate.fastest_mode_per_s,
            gate.allowed_per_s,
            gate.limited_by,
            gate.scale_that_fits
        );
        assert!(gate.fits, "{}: {gate:?}", path.display());
    }
}

/// A ring of `n` ideal vehicles hovering in formation, `vehicle_lines(i)` added to
/// vehicle `i`'s table, then `extra`.
fn ring_config(n: usize, vehicle_lines: impl Fn(usize) -> String, extra: &str) -> String {
    let mut text = String::from(
        "[swarm]\ncontrol_rate_hz = 50.0\n\n[gains]\nk = 1.0\nalpha = 1.0\nbeta = 400.0\n\
         k_pz = 1.0\nk_vz = 4.0\ntime_scale = 0.02\n\n[formation]\nkind = \"polygon\"\n\
         radius_m = 500.0\naltitude_m = 50.0\n\n",
    );
    for i in 0..n {
        text += &format!(
            "[[vehicle]]\nprofile = \"ideal\"\nmass_kg = 1.0\nhover_throttle = 0.2\nin_air = true\n{}\n",
            vehicle_lines(i)
        );
    }
    text + extra
}

#[test]
fn forty_one_vehicles_on_px4_ports_are_refused_with_the_way_out() {
    let text = ring_config(42, |i| format!("system_id = {}", i + 1), "");
    let err = Config::from_toml(&text).unwrap().validate().unwrap_err();
    assert!(
        err.contains(
            "the coordinator's socket for vehicle[40] binds 0.0.0.0:14580, where vehicle[0] listens (127.0.0.1:14580): \
             PX4 SITL's ports collide from the 41st vehicle on; put the vehicles on a [[network]]"
        ),
        "{err}"
    );
    // Forty fit.
    let text = ring_config(40, |i| format!("system_id = {}", i + 1), "");
    Config::from_toml(&text).unwrap().validate().unwrap();
}

#[test]
fn a_thousand_vehicles_fit_on_four_networks_with_repeated_ids() {
    let networks = (0..4)
        .map(|j| {
            format!(
                "[[network]]\nname = \"n{j}\"\nbind = \"0.0.0.0:{}\"\n\n",
                14600 + j
            )
        })
        .collect::<String>();
    let text = ring_config(
        1000,
        |i| format!("system_id = {}\nnetwork = \"n{}\"", i % 250 + 1, i / 250),
        &networks,
    );
    let config = Config::from_toml(&text).unwrap();
    let setup = config.validate().unwrap();
    assert_eq!(setup.ring.agents(), 1000);
    let plan = config.transport_layout().unwrap();
    assert_eq!(plan.sockets.len(), 4, "one socket per network");
    assert_eq!(plan.routes[999].socket, 3);
    assert_eq!(plan.routes[999].system_id, SystemId(250));
    assert!(plan.routes.iter().all(|r| r.address.is_none()));
}

#[test]
fn network_mistakes_are_all_named() {
    let text = ring_config(
        6,
        |i| match i {
            0 => "system_id = 1\nnetwork = \"a\"".to_owned(),
            1 => "system_id = 1\nnetwork = \"a\"".to_owned(),
            2 => "system_id = 1\nnetwork = \"b\"\nbind = \"0.0.0.0:15000\"".to_owned(),
            3 => "system_id = 2\nnetwork = \"nowhere\"".to_owned(),
            4 => "system_id = 3\nnetwork = \"b\"\naddress = \"127.0.0.1:14551\"".to_owned(),
            _ => "system_id = 1".to_owned(),
        },
        "[[network]]\nname = \"a\"\nbind = \"0.0.0.0:14550\"\n\n\
         [[network]]\nname = \"b\"\nbind = \"127.0.0.1:14551\"\n\n\
         [[network]]\nname = \"a\"\nbind = \"0.0.0.0:14552\"\n\n\
         [[network]]\nname = \"c\"\nbind = \"127.0.0.1:14550\"\n",
    );
    let err = Config::from_toml(&text).unwrap().validate().unwrap_err();
    for needle in [
        "network[2].name \"a\" is used twice",
        "vehicle[1].system_id 1 is used twice on network \"a\"",
        "vehicle[2].bind: a vehicle on network \"b\" is reached through the network's socket",
        "vehicle[3].network \"nowhere\" is not a [[network]] name",
        "network \"a\" and network \"c\" both bind port 14550",
        "network \"b\" binds 127.0.0.1:14551, where vehicle[4] listens (127.0.0.1:14551)",
    ] {
        assert!(err.contains(needle), "{needle} not in:\n{err}");
    }
    // System id 1 on network a, on network b and without a network: three vehicles.
    assert!(!err.contains("vehicle[2].system_id"), "{err}");
    assert!(!err.contains("vehicle[5].system_id"), "{err}");
}

#[test]
fn the_shipped_500_vehicle_ring_validates_on_two_networks() {
    let config = load("ring-500.toml");
    let setup = config.validate().unwrap();
    assert_eq!(setup.ring.agents(), 500);
    let plan = config.transport_layout().unwrap();
    assert_eq!(plan.sockets.len(), 2);
    // Vehicle 251 is system id 1 again, on the second network.
    assert_eq!(
        (plan.routes[250].socket, plan.routes[250].system_id),
        (1, SystemId(1))
    );
    // Its files are told apart by network: vehicle-n0-1.csv and vehicle-n1-1.csv.
    assert_eq!(setup.links[0].file_label(), "n0-1");
    assert_eq!(setup.links[250].file_label(), "n1-1");
}

#[test]
fn the_attitude_rate_defaults_to_the_control_rate_and_may_be_lower_only() {
    use std::time::Duration;
    let intervals = |attitude_line: &str| {
        let setup = Config::from_toml(&with(
            "link_timeout_ms = 1500",
            &format!("link_timeout_ms = 1500\n{attitude_line}"),
        ))
        .unwrap()
        .validate()
        .unwrap();
        setup
            .links
            .iter()
            .map(|l| (l.telemetry_interval, l.attitude_interval))
            .collect::<Vec<_>>()
    };
    // paper-sim1 controls at 250 Hz: both streams every 4 ms by default; 10 Hz is 100 ms.
    let ms = Duration::from_millis;
    assert_eq!(intervals(""), vec![(ms(4), ms(4)); 6]);
    assert_eq!(
        intervals("attitude_rate_hz = 10.0"),
        vec![(ms(4), ms(100)); 6]
    );
    for (bad, shown) in [("300.0", "300"), ("0.5", "0.5"), ("nan", "NaN")] {
        let err = Config::from_toml(&with(
            "link_timeout_ms = 1500",
            &format!("link_timeout_ms = 1500\nattitude_rate_hz = {bad}"),
        ))
        .unwrap()
        .validate()
        .unwrap_err();
        assert_eq!(
            err,
            format!(
                "swarm.attitude_rate_hz must be a finite number in [1, 250] Hz (1 Hz up to swarm.control_rate_hz), got {shown}"
            )
        );
    }
}

#[test]
fn the_safety_keys_are_checked_by_name_and_close_places_are_refused() {
    let text = with(
        "[formation]",
        "[safety]\nhorizontal_m = 0.1\nvertical_m = 400.0\nbraking_share = 0.0\n\n[formation]",
    );
    let err = Config::from_toml(&text).unwrap().validate().unwrap_err();
    for needle in [
        "safety.horizontal_m must be a finite number in [0.5, 100] m, got 0.1",
        "safety.vertical_m must be a finite number in [0.5, 300] m (at least safety.horizontal_m), got 400",
        "safety.braking_share must be a finite number in (0, 1], got 0",
    ] {
        assert!(err.lines().any(|l| l == needle), "{needle}\nnot in:\n{err}");
    }
    // The paper's hexagon has 20 m sides: a separation of 25 m cannot hold it.
    let text = with(
        "[formation]",
        "[safety]\nhorizontal_m = 25.0\nvertical_m = 30.0\n\n[formation]",
    );
    let err = Config::from_toml(&text).unwrap().validate().unwrap_err();
    assert!(
        err.lines().any(|l| l.starts_with(
            "formation.offsets_m[0] and formation.offsets_m[1] are 20.000 m apart, closer than safety.horizontal_m = 25 m"
        )),
        "{err}"
    );
    // Off, nothing is checked against it and the setup carries no filter.
    let text = with(
        "[formation]",
        "[safety]\nenabled = false\nhorizontal_m = 25.0\nvertical_m = 30.0\n\n[formation]",
    );
    let setup = Config::from_toml(&text).unwrap().validate().unwrap();
    assert!(setup.safety.is_none());
    // The defaults: 3 m by 9 m, half the envelope for braking.
    let setup = Config::from_toml(&with("k = 5.0", "k = 5.0"))
        .unwrap()
        .validate()
        .unwrap();
    let s = setup.safety.expect("on by default");
    assert_eq!(
        (
            s.separation.horizontal_m,
            s.separation.vertical_m,
            s.braking_share
        ),
        (3.0, 9.0, 0.5)
    );
    assert_eq!(s.action, ringswarm::swarm::BreachAction::Hold);
    // The action is one of three words, and a wrong one is named.
    let text = with("[formation]", "[safety]\naction = \"brake\"\n\n[formation]");
    let err = Config::from_toml(&text).unwrap_err();
    assert!(
        err.contains("unknown variant `brake`, expected one of `continue`, `hold`, `land`"),
        "{err}"
    );
    let text = with("[formation]", "[safety]\naction = \"land\"\n\n[formation]");
    let setup = Config::from_toml(&text).unwrap().validate().unwrap();
    assert_eq!(
        setup.safety.map(|s| s.action),
        Some(ringswarm::swarm::BreachAction::Land)
    );
}

#[test]
fn a_fence_is_checked_by_name() {
    let fence = |body: &str| with("[formation]", &format!("[fence]\n{body}\n\n[formation]"));
    let err = |body: &str| {
        Config::from_toml(&fence(body))
            .unwrap()
            .validate()
            .unwrap_err()
    };
    // A bow tie is no fence.
    let e = err(
        "kind = \"polygon\"\nvertices_enu_m = [[-500.0, -500.0], [500.0, 500.0], [500.0, -500.0], [-500.0, 500.0]]\nmin_altitude_m = 0.0\nmax_altitude_m = 100.0",
    );
    assert!(
        e.lines().any(|l| l == "fence.vertices_enu_m: the polygon's edges cross each other (a fence must be a simple polygon)"),
        "{e}"
    );
    // Two vertices, a circle without its radius, a band upside down.
    let e = err(
        "kind = \"polygon\"\nvertices_enu_m = [[0.0, 0.0], [1.0, 1.0]]\nmin_altitude_m = 0.0\nmax_altitude_m = 100.0",
    );
    assert!(
        e.lines()
            .any(|l| l == "fence.vertices_enu_m needs at least 3 vertices, got 2"),
        "{e}"
    );
    let e = err(
        "kind = \"circle\"\ncentre_enu_m = [0.0, 0.0]\nmin_altitude_m = 0.0\nmax_altitude_m = 100.0",
    );
    assert!(
        e.lines().any(
            |l| l == "fence.centre_enu_m and fence.radius_m are required for kind = \"circle\""
        ),
        "{e}"
    );
    let e = err(
        "kind = \"circle\"\ncentre_enu_m = [0.0, 0.0]\nradius_m = 1000.0\nmin_altitude_m = 100.0\nmax_altitude_m = 10.0",
    );
    assert!(
        e.lines()
            .any(|l| l.starts_with("fence.max_altitude_m must be a finite number in [100, ")),
        "{e}"
    );
    // The paper's formation flies at 50 m; its vehicle 2 starts at (50, -20) m.
    let e = err(
        "kind = \"circle\"\ncentre_enu_m = [0.0, 0.0]\nradius_m = 40.0\nmin_altitude_m = 48.0\nmax_altitude_m = 100.0",
    );
    assert!(
        e.lines().any(|l| l == "formation.altitude_m = 50 m is not inside the fence's altitudes [48, 100] m by its margin of 5 m"),
        "{e}"
    );
    assert!(
        e.lines()
            .any(|l| l == "vehicle[1] (system id 2) starts at (50, -20) m, outside the fence"),
        "{e}"
    );
    // A good one.
    let setup = Config::from_toml(&fence(
        "kind = \"circle\"\ncentre_enu_m = [0.0, 0.0]\nradius_m = 400.0\nmin_altitude_m = 20.0\nmax_altitude_m = 80.0\naction = \"land\"",
    ))
    .unwrap()
    .validate()
    .unwrap();
    let f = setup.fence.expect("a fence");
    assert_eq!(f.margin_m, 5.0);
    assert_eq!(f.action, ringswarm::swarm::LossPolicy::Land);
}

#[test]
fn the_jam_layer_fits_the_fence_band_above_or_below_or_is_refused() {
    // paper-sim1 flies at 50 m; the layer defaults to vertical_m + horizontal_m.
    let file = |safety: &str, band: Option<(f64, f64)>| {
        let fence = band.map_or(String::new(), |(lo, hi)| {
            format!(
                "[fence]\nkind = \"circle\"\ncentre_enu_m = [0.0, 0.0]\nradius_m = 1000.0\n\
                 min_altitude_m = {lo}\nmax_altitude_m = {hi}\nmargin_m = 2.0\n\n"
            )
        });
        with(
            "[formation]",
            &format!("[safety]\nresolve_jams = true\n{safety}\n\n{fence}[formation]"),
        )
    };
    let rule = |safety: &str, band| {
        Config::from_toml(&file(safety, band))
            .unwrap()
            .validate()
            .map(|s| s.safety.and_then(|s| s.jams).and_then(|j| j.layer))
    };
    // No fence: 12 m above (9 + 3), back with nobody within 1.2 × 3 m.
    let up = rule("", None).unwrap().unwrap();
    assert_eq!(
        (up.height_m, up.above, up.offset_up_m()),
        (12.0, true, 12.0)
    );
    assert!((up.clear_m - 3.6).abs() < 1e-12);
    assert_eq!(up.dwell_s, 20.0);
    let e = rule("jam_layer_s = 0.0", None).unwrap_err();
    assert!(
        e.lines()
            .any(|l| l.starts_with("safety.jam_layer_s must be a finite number in (0, 3600] s")),
        "{e}"
    );
    // A band up to 63 m (margin 2): 50 + 12 > 61, so below, 50 - 12 ≥ 0 + 2.
    let down = rule("", Some((0.0, 63.0))).unwrap().unwrap();
    assert_eq!((down.above, down.offset_up_m()), (false, -12.0));
    // Exactly room above: 50 + 12 = 64 - 2.
    assert!(rule("", Some((0.0, 64.0))).unwrap().unwrap().above);
    // No room either way: refused, naming the numbers and the ways out.
    let e = rule("", Some((40.0, 63.0))).unwrap_err();
    assert!(
        e.lines().any(|l| l == "safety.jam_break = \"layer\": a jam layer 12 m above or below formation.altitude_m = 50 m leaves the fence's altitudes [40, 63] m (margin 2 m): lower safety.jam_layer_m (at least safety.vertical_m = 9 m), widen the band, set safety.jam_break = \"turn\", or stop breaking jams with safety.resolve_jams = false"),
        "{e}"
    );
    // ... which the turn needs no room for, and a smaller layer fits.
    assert_eq!(
        rule("jam_break = \"turn\"", Some((40.0, 63.0))).unwrap(),
        None
    );
    let small = rule("jam_layer_m = 9.5", Some((40.0, 63.0)))
        .unwrap()
        .unwrap();
    assert_eq!((small.height_m, small.above), (9.5, true));
    // A layer inside the downwash ellipsoid is refused by its key; so is an unknown way.
    let e = rule("jam_layer_m = 8.0", None).unwrap_err();
    assert!(
        e.lines()
            .any(|l| l.starts_with("safety.jam_layer_m must be a finite number in [9, 300] m")),
        "{e}"
    );
    let e = Config::from_toml(&file("jam_break = \"climb\"", None)).unwrap_err();
    assert!(
        e.contains("unknown variant `climb`, expected `layer` or `turn`"),
        "{e}"
    );
    // The watch's share of a command taken, at its default.
    let jams = Config::from_toml(&file("", None))
        .unwrap()
        .validate()
        .unwrap()
        .safety
        .and_then(|s| s.jams)
        .unwrap();
    assert_eq!(jams.restrained_share, 0.5);
    // On by default; off when the file says so.
    let default = Config::from_toml(&with("[formation]", "[safety]\n\n[formation]"))
        .unwrap()
        .validate()
        .unwrap();
    assert!(default.safety.and_then(|s| s.jams).is_some());
    let off = with(
        "[formation]",
        "[safety]\nresolve_jams = false\njam_layer_m = 12.0\n\n[formation]",
    );
    let setup = Config::from_toml(&off).unwrap().validate().unwrap();
    assert_eq!(setup.safety.and_then(|s| s.jams), None);
}

#[test]
fn a_coordinator_file_and_a_sitl_file_are_read_into_one_emulator_schema() {
    // paper-sim1's vehicle 1 (ENU start 20 m north, 9 east / 4 north m/s, 100 m above the
    // ground) with a true airframe and an estimator of its own…
    let coordinator = with(
        "ground_below_m = 100.0   # the paper's z = 0 is 100 m above the ground",
        "ground_below_m = 100.0\nposition_noise_m = 0.2\nestimator_latency_ms = 40.0\nbattery_sag = 0.1",
    )
    .replacen(
        "start_velocity_enu_mps = [9.0, 4.0, 0.0]\nin_air = true",
        "start_velocity_enu_mps = [9.0, 4.0, 0.0]\nin_air = true\nairframe = { mass_kg = 1.2 }",
        1,
    );
    let (_, from_coordinator) = Config::from_toml(&coordinator).unwrap().emulator().unwrap();
    // …is the sitl file's vehicle with the same numbers in NED.
    let sitl = ringswarm_sitl::config_file::SitlConfig::from_toml(
        "[world]\nground_down_m = 100.0\n[[vehicle]]\nsystem_id = 1\nprofile = \"ideal\"\n\
         start_ned_m = [20.0, 0.0, 0.0]\nvelocity_ned_mps = [4.0, 9.0, 0.0]\nin_air = true\n\
         mass_kg = 1.2\nposition_noise_m = 0.2\nestimator_latency_ms = 40.0\nbattery_sag = 0.1\n",
    )
    .unwrap();
    assert_eq!(from_coordinator[0], sitl.vehicles[0]);
    // The shared estimator's problems are named as the coordinator file has them, once.
    let bad = with(
        "ground_below_m = 100.0   # the paper's z = 0 is 100 m above the ground",
        "ground_below_m = 100.0\nposition_noise_m = -1.0\ntelemetry_rate_hz = 0.0",
    )
    .replacen(
        "start_enu_m = [0.0, 20.0, 0.0]",
        "start_enu_m = [0.0, 20.0, 0.0]\nairframe = { hover_throttle = 1.5 }",
        1,
    );
    let err = Config::from_toml(&bad).unwrap().emulator().unwrap_err();
    assert_eq!(
        err,
        "emulator.position_noise_m must be a finite number in [0, 100] m, got -1\n\
         emulator.telemetry_rate_hz must be a finite number in (0, 1000] Hz, got 0\n\
         vehicle[0].airframe.hover_throttle must be in [0.01, 0.99], got 1.5"
    );
    // The emulated vehicles' boot stream rate reaches each of them.
    let slow = with(
        "ground_below_m = 100.0   # the paper's z = 0 is 100 m above the ground",
        "ground_below_m = 100.0\ntelemetry_rate_hz = 10.0",
    );
    let (_, vehicles) = Config::from_toml(&slow).unwrap().emulator().unwrap();
    assert!(vehicles.iter().all(|v| v.fast_rate_hz == 10.0));
    assert_eq!(from_coordinator[0].fast_rate_hz, 50.0);
}

#[test]
fn serial_vehicles_get_a_port_each_and_their_mistakes_are_named() {
    let text = ring_config(
        4,
        |i| {
            match i {
            0 => "system_id = 1\nserial = { device = \"/dev/ttyAMA0\", baud = 921600 }".to_owned(),
            1 => "system_id = 2\nserial = { device = \"/dev/ttyAMA0\", baud = 57600 }\nnetwork = \"a\""
                .to_owned(),
            2 => "system_id = 3\nserial = { device = \" \", baud = 0 }\naddress = \"127.0.0.1:14582\""
                .to_owned(),
            _ => "system_id = 4".to_owned(),
        }
        },
        "[[network]]\nname = \"a\"\nbind = \"0.0.0.0:14550\"\n",
    );
    let err = Config::from_toml(&text).unwrap().validate().unwrap_err();
    for needle in [
        "vehicle[1].network: a vehicle on a serial port is reached over that port only",
        "vehicle[1].serial.device \"/dev/ttyAMA0\" is vehicle[0]'s too: a serial port reaches one vehicle",
        "vehicle[2].address: a vehicle on a serial port is reached over that port only",
        "vehicle[2].serial.device is empty",
        "vehicle[2].serial.baud must be 1200..=4000000 bits per second, got 0",
    ] {
        assert!(err.contains(needle), "{needle} not in:\n{err}");
    }
    // A sound one: its own port, reached at the serial peer; the emulator serves it on
    // a pseudo-terminal linked at the device path.
    let text = ring_config(
        2,
        |i| match i {
            0 => "system_id = 1\nserial = { device = \"/tmp/ringswarm-tty-1\", baud = 921600 }"
                .to_owned(),
            _ => "system_id = 2".to_owned(),
        },
        "",
    );
    let config = Config::from_toml(&text).unwrap();
    config.validate().unwrap();
    let plan = config.transport_layout().unwrap();
    assert_eq!(
        plan.sockets[plan.routes[0].socket].endpoint,
        ringswarm::link::router::Endpoint::Serial {
            device: "/tmp/ringswarm-tty-1".to_owned(),
            baud: 921_600
        }
    );
    assert_eq!(
        plan.routes[0].address,
        Some(ringswarm::link::router::SERIAL_PEER)
    );
    assert_eq!(
        plan.sockets[plan.routes[1].socket].udp_bind(),
        Some("0.0.0.0:14541".parse().unwrap())
    );
    let placements = config.emulator_placements().unwrap();
    assert_eq!(
        placements[0],
        ringswarm_sitl::udp::Placement::Serial {
            device: "/tmp/ringswarm-tty-1".into()
        }
    );
}

#[test]
fn the_gate_counts_the_hop_between_shards_and_the_lead_must_exceed_two_hops() {
    let base = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/paper-sim1-shards.toml"),
    )
    .unwrap();
    // 20 ms (the default): 3.5 / 0.02 = 175 1/s, looser than the ideal frame's attitude
    // limit (1.5 × 40 = 60 1/s): the paper's 34.8 1/s fits, limited by attitude.
    let config = Config::from_toml(&base).unwrap();
    let b = config.bandwidth_check().unwrap();
    assert!(b.fits && b.limited_by == "attitude", "{b:?}");
    assert_eq!(b.hop_s, 0.02);
    // 140 ms: 25 1/s, the tightest; the time scale that fits is 25 / 34.8.
    let slow = base.replace(
        "swarm = \"paper-sim1\"",
        "swarm = \"paper-sim1\"\nhop_ms = 140\nstart_lead_ms = 350",
    );
    let config = Config::from_toml(&slow).unwrap();
    config.validate().unwrap();
    let b = config.bandwidth_check().unwrap();
    assert!(!b.fits && b.limited_by == "hop between shards", "{b:?}");
    assert!((b.scale_that_fits - 25.0 / b.fastest_mode_per_s).abs() < 1e-12);
    assert!(ringswarm::report::bandwidth_text(&b, 1.0).contains("3.5 / hop between shards 140 ms"));
    // A start lead within two hops cannot be vouched for in time.
    let short = base.replace(
        "swarm = \"paper-sim1\"",
        "swarm = \"paper-sim1\"\nhop_ms = 100",
    );
    let err = Config::from_toml(&short).unwrap().validate().unwrap_err();
    assert!(
        err.contains(
            "distributed.start_lead_ms (200 ms) must exceed two hops (2 × hop_ms = 200 ms)"
        ),
        "{err}"
    );
}

#[test]
fn each_vehicle_s_autopilot_is_read_by_name_and_ardupilot_flies_attitude_setpoints_only() {
    use ringswarm::vehicle::{Autopilot, AutopilotChoice};
    let setup = load("mixed-autopilots.toml").validate().unwrap();
    let px4 = AutopilotChoice::Only(Autopilot::Px4);
    let ap = AutopilotChoice::Only(Autopilot::ArduPilot);
    let chosen: Vec<AutopilotChoice> = setup.links.iter().map(|l| l.autopilot).collect();
    assert_eq!(chosen, [px4, ap, px4, ap, px4, ap]);
    // Without the key: whatever the first heartbeat says.
    let sim1 = load("paper-sim1.toml").validate().unwrap();
    assert!(
        sim1.links
            .iter()
            .all(|l| l.autopilot == AutopilotChoice::Auto)
    );
    let text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("config/mixed-autopilots.toml"),
    )
    .unwrap()
    .replacen("autopilot = \"px4\"", "autopilot = \"apm\"", 1)
    .replace(
        "link_timeout_ms = 1500",
        "link_timeout_ms = 1500\nsetpoint = \"acceleration\"",
    );
    let err = Config::from_toml(&text).unwrap().validate().unwrap_err();
    assert!(
        err.contains(
            "vehicle[0].autopilot = \"apm\" is not one of \"auto\", \"px4\", \"ardupilot\""
        ),
        "{err}"
    );
    assert!(
        err.contains("vehicle[1].autopilot = \"ardupilot\" is flown with attitude setpoints only: swarm.setpoint = \"acceleration\" is PX4's"),
        "{err}"
    );
}

#[test]
fn formation_assign_is_checked_by_name_and_defaults_by_kind() {
    let err = Config::from_toml(&with("assign = \"fixed\"", "assign = \"nearest\""))
        .unwrap()
        .validate()
        .unwrap_err();
    assert!(
        err.contains("formation.assign \"nearest\" is not one of optimal, fixed"),
        "{err}"
    );
    // paper-sim1 keeps the paper's places; without the key a polygon is assigned.
    let fixed = Config::from_toml(&with("[formation]", "[formation]")).unwrap();
    assert!(!fixed.validate().unwrap().assign_places);
    let default = Config::from_toml(&with("assign = \"fixed\"", "")).unwrap();
    assert!(default.validate().unwrap().assign_places);
    let line = Config::from_toml(&with(
        "kind = \"polygon\"\nradius_m = 20.0",
        "kind = \"line\"\nspacing_m = 5.0",
    ))
    .unwrap();
    let mut line = line;
    line.formation.assign = None;
    assert!(!line.validate().unwrap().assign_places);
}
