//! The `ringswarm` binary end to end: outputs, exit codes and error messages.

use std::process::{Command, Output};

fn ringswarm(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_ringswarm"))
        .args(args)
        .output()
        .expect("the test binary runs")
}

fn json(output: &Output) -> serde_json::Value {
    serde_json::from_slice(&output.stdout).expect("stdout is one JSON object")
}

fn stderr(output: &Output) -> String {
    String::from_utf8_lossy(&output.stderr).into_owned()
}

#[test]
fn analyze_example_1_is_stable() {
    let out = ringswarm(&[
        "analyze",
        "--macro-vertices",
        "4",
        "--k",
        "-0.5",
        "--alpha",
        "1",
        "--beta",
        "6",
        "--json",
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let v = json(&out);
    assert!((v["k_min"].as_f64().unwrap() + 1.0).abs() < 1e-12);
    assert!((v["k_margin"].as_f64().unwrap() - 0.5).abs() < 1e-12);
    assert!((v["yu_bound"].as_f64().unwrap() - 5.389_377_276_613_346).abs() < 1e-9);
    assert!((v["closed_loop_abscissa"].as_f64().unwrap() + 0.167_392_671_721_78).abs() < 1e-9);
    assert_eq!(v["stable"], serde_json::json!(true));
    assert_eq!(v["laplacian_eigenvalues"].as_array().unwrap().len(), 8);
    assert_eq!(
        v["w"],
        serde_json::json!([1.0, 0.5, 1.0, 0.5, 1.0, 0.5, 1.0, 0.5])
    );
}

#[test]
fn analyze_a_ring_of_two_hundred_thousand_without_listing_it() {
    let out = ringswarm(&["analyze", "-m", "100000", "-k", "1", "--json"]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let v = json(&out);
    assert_eq!(v["agents"], serde_json::json!(200_000));
    assert!(v["laplacian_eigenvalues"].is_null() && v["w"].is_null());
    // Large-ring asymptote of Yu's bound, 2c³/((c² − 2)θ²) with c = 3, θ = 2π/m
    // (tests/integration/properties.rs derives it; the remainder is 5·10⁻¹⁰ here).
    let theta = 2.0 * std::f64::consts::PI / 100_000.0;
    let asymptote = 54.0 / (7.0 * theta * theta);
    let bound = v["yu_bound"].as_f64().unwrap();
    assert!(
        (bound / asymptote - 1.0).abs() < 2e-9,
        "{bound} vs {asymptote}"
    );
    // The slowest mode: Re μ ≈ θ²(c² − 2)/(2c³) = 7θ²/54.
    let slowest = v["smallest_nonzero_real_part"].as_f64().unwrap();
    assert!(
        (slowest / (7.0 * theta * theta / 54.0) - 1.0).abs() < 1e-6,
        "{slowest}"
    );
    assert!((v["largest_modulus"].as_f64().unwrap() - 3.0).abs() < 1e-12);
    let k_min = -2.0 + std::f64::consts::SQRT_2 * (std::f64::consts::PI / 100_000.0).cos();
    assert!((v["k_min_numeric"].as_f64().unwrap() - k_min).abs() < 1e-8);
    // Listing is asked for: all 2m eigenvalues.
    let out = ringswarm(&["analyze", "-m", "40", "-k", "1", "--eigenvalues", "--json"]);
    assert_eq!(
        json(&out)["laplacian_eigenvalues"]
            .as_array()
            .unwrap()
            .len(),
        80
    );
}

#[test]
fn analyze_unstable_gains_exit_with_one() {
    let out = ringswarm(&[
        "analyze", "-m", "4", "-k", "-0.8", "--alpha", "1", "--beta", "3", "--json",
    ]);
    assert_eq!(out.status.code(), Some(1));
    let v = json(&out);
    assert_eq!(v["stable"], serde_json::json!(false));
    assert!(v["closed_loop_abscissa"].as_f64().unwrap() > 0.0);
    // k below the bound is an answer with its (negative) margin, not a crash.
    let out = ringswarm(&["analyze", "-m", "4", "-k", "-1.2", "--json"]);
    assert_eq!(out.status.code(), Some(1));
    let v = json(&out);
    assert!((v["k_margin"].as_f64().unwrap() + 0.2).abs() < 1e-12);
    assert!(v["yu_bound"].is_null());
}

#[test]
fn analyze_without_gains_recommends_gains_that_meet_the_bound() {
    let out = ringswarm(&["analyze", "-m", "3", "-k", "5", "--json"]);
    assert_eq!(out.status.code(), Some(0));
    let v = json(&out);
    let rec = &v["recommended"];
    let (alpha, beta) = (
        rec["alpha"].as_f64().unwrap(),
        rec["beta"].as_f64().unwrap(),
    );
    assert!(beta * beta / alpha > 1.25 * 1.221_422_976 - 1e-6);
}

#[test]
fn bad_input_gets_a_specific_message_and_exit_code_two() {
    let cases: [(&[&str], &str); 6] = [
        (
            &["analyze", "-m", "0", "-k", "1"],
            "at least one macro-vertex",
        ),
        (
            &["analyze", "-m", "3", "-k", "nan"],
            "k must be a finite number",
        ),
        (
            &[
                "analyze", "-m", "3", "-k", "1", "--alpha", "0", "--beta", "2",
            ],
            "alpha must be greater than zero",
        ),
        (
            &[
                "analyze", "-m", "3", "-k", "1", "--alpha", "1", "--beta", "-2",
            ],
            "beta must be greater than zero",
        ),
        (
            &["plan", "--initial-velocities", "1,2;3", "--target", "1,1"],
            "initial velocity #2",
        ),
        (
            &[
                "plan",
                "--initial-velocities",
                "1,2;3,4;5,6",
                "--target",
                "1,1",
            ],
            "even number of agents",
        ),
    ];
    for (args, message) in cases {
        let out = ringswarm(args);
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        assert!(stderr(&out).contains(message), "{args:?}: {}", stderr(&out));
        assert!(!stderr(&out).contains("panicked"));
    }
}

#[test]
fn plan_reports_agent_velocity_gain_and_prediction() {
    let out = ringswarm(&[
        "plan",
        "--initial-velocities",
        "9,4;15,8;18,-2;13,1;-8,-7;14,18",
        "--target",
        "20,30",
        "--json",
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let v = json(&out);
    assert_eq!(v["feasible"], serde_json::json!(true));
    assert_eq!(v["method"], serde_json::json!("one agent"));
    assert_eq!(v["agent"], serde_json::json!(4));
    assert!((v["k"].as_f64().unwrap() - 10.0).abs() < 1e-12);
    let vf = v["predicted_final_velocity"].as_array().unwrap();
    assert!((vf[0].as_f64().unwrap() - 20.0).abs() < 1e-9);
    assert!((vf[1].as_f64().unwrap() - 30.0).abs() < 1e-9);
    let new = v["new_velocity"].as_array().unwrap();
    assert!((new[0].as_f64().unwrap() - (31.0 + 41.0 / 11.0)).abs() < 1e-9);
}

#[test]
fn plan_with_a_speed_limit_re_targets_every_agent_or_names_the_nearest_reachable() {
    let velocities = "9,4;15,8;18,-2;13,1;-8,-7;14,18";
    // At 50 m/s agent 4 alone cannot do it (it would need 72.6 m/s at k = 10); every
    // agent can, within 50 m/s.
    let out = ringswarm(&[
        "plan",
        "--initial-velocities",
        velocities,
        "--target",
        "20,30",
        "--max-speed",
        "50",
        "--json",
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let v = json(&out);
    assert_eq!(v["method"], serde_json::json!("every agent"));
    assert!(v["reason"].as_str().unwrap().contains("50 m/s"), "{v}");
    for r in v["retargeted"].as_array().unwrap() {
        let n = r["new_velocity"].as_array().unwrap();
        let speed = n[0].as_f64().unwrap().hypot(n[1].as_f64().unwrap());
        assert!(speed <= 50.0 + 1e-9, "{r}");
    }
    // A target faster than the limit is out of reach for every plan: refused, with the
    // nearest reachable final velocity, (20, 30) scaled to 30 m/s at most.
    let out = ringswarm(&[
        "plan",
        "--initial-velocities",
        velocities,
        "--target",
        "20,30",
        "--max-speed",
        "30",
        "--json",
    ]);
    assert_eq!(out.status.code(), Some(1));
    let v = json(&out);
    assert_eq!(v["feasible"], serde_json::json!(false));
    assert!(v["reason"].as_str().unwrap().contains("30 m/s"), "{v}");
    let best = v["best_reachable_velocity"].as_array().unwrap();
    let (bx, by) = (best[0].as_f64().unwrap(), best[1].as_f64().unwrap());
    assert!(bx.hypot(by) <= 30.0 + 1e-6, "{best:?}");
    assert!((by / bx - 1.5).abs() < 1e-3, "along the target: {best:?}");
}

#[test]
fn plan_re_targets_every_agent_by_the_weighted_least_norm_change() {
    // From (nearly) rest one agent would need W·|v_t|/w ≥ 16 m/s against a 5.49 m/s limit.
    // With k = 1 the left null vector of L is w = (1, 2) per macro-vertex (W = 9,
    // Σw² = 15), and min Σ|Δvᵢ|² subject to Σwᵢ(vᵢ + Δvᵢ) = W·v_t gives Δvᵢ = wᵢ·λ,
    // λ = (W·v_t − Σwᵢvᵢ)/Σwᵢ² = ((27, 18) − (0.2, 0.1))/15 = (1.786667, 1.193333), no
    // limit binding (the fastest new velocity is 4.59 m/s).
    let out = ringswarm(&[
        "plan",
        "--initial-velocities",
        "0.5,0;0,0.5;-0.5,0;0,-0.5;0.2,0.1;0,0",
        "--target",
        "3,2",
        "--max-speed",
        "5.49",
        "--k",
        "1",
        "--json",
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let v = json(&out);
    assert_eq!(v["method"], serde_json::json!("every agent"));
    assert!((v["k"].as_f64().unwrap() - 1.0).abs() < 1e-12);
    let old = [
        (0.5, 0.0),
        (0.0, 0.5),
        (-0.5, 0.0),
        (0.0, -0.5),
        (0.2, 0.1),
        (0.0, 0.0),
    ];
    let lambda = (26.8 / 15.0, 17.9 / 15.0);
    let retargeted = v["retargeted"].as_array().unwrap();
    assert_eq!(retargeted.len(), 6);
    for (i, r) in retargeted.iter().enumerate() {
        assert_eq!(r["agent"], serde_json::json!(i + 1));
        let w = if i % 2 == 0 { 1.0 } else { 2.0 };
        let n = r["new_velocity"].as_array().unwrap();
        let expected = (old[i].0 + w * lambda.0, old[i].1 + w * lambda.1);
        assert!((n[0].as_f64().unwrap() - expected.0).abs() < 1e-6, "{r}");
        assert!((n[1].as_f64().unwrap() - expected.1).abs() < 1e-6, "{r}");
    }
    let vf = v["predicted_final_velocity"].as_array().unwrap();
    assert!((vf[0].as_f64().unwrap() - 3.0).abs() < 1e-9);
    assert!((vf[1].as_f64().unwrap() - 2.0).abs() < 1e-9);
}

#[test]
fn sitl_refuses_a_bad_config_listing_every_problem() {
    let dir = std::env::temp_dir().join(format!("ringswarm-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("bad.toml");
    std::fs::write(
        &path,
        "[faults]\nloss_pct = 150.0\n[[vehicle]]\nprofile = \"x600\"\n",
    )
    .unwrap();
    let out = ringswarm(&["sitl", "--config", path.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    let err = stderr(&out);
    assert!(
        err.contains("faults.loss_pct must be a percentage"),
        "{err}"
    );
    assert!(err.contains("unknown vehicle profile \"x600\""), "{err}");
    std::fs::write(&path, "[[vehicle]]\nin_ar = true\n").unwrap();
    let out = ringswarm(&["sitl", "--config", path.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr(&out).contains("unknown field `in_ar`"),
        "{}",
        stderr(&out)
    );
    let out = ringswarm(&["sitl", "--vehicles", "1", "--profile", "x600"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("unknown vehicle profile"));
}

#[test]
fn sitl_reports_a_port_already_in_use() {
    // Instance 0's offboard port on a loopback address of its own, so that nothing else
    // running on the machine can interfere.
    let host = "127.0.0.57";
    let _held =
        std::net::UdpSocket::bind((host, 14580)).expect("all of 127.0.0.0/8 is loopback on Linux");
    let out = ringswarm(&["sitl", "--vehicles", "1", "--host", host]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr(&out).contains("cannot bind UDP 127.0.0.57:14580"),
        "{}",
        stderr(&out)
    );
}

#[test]
fn a_reader_that_closes_the_pipe_early_is_not_a_crash() {
    // `ringswarm analyze … | head -1`: the pipe is closed before the long output is
    // written. The command must end normally (stable: exit 0), never panic (101).
    use std::process::Stdio;
    let mut child = Command::new(env!("CARGO_BIN_EXE_ringswarm"))
        .args(["analyze", "--macro-vertices", "32", "--k", "1"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the test binary runs");
    drop(child.stdout.take());
    let out = child.wait_with_output().expect("it ends");
    let err = stderr(&out);
    assert!(!err.contains("panicked"), "{err}");
    assert_eq!(out.status.code(), Some(0), "{err}");
}

#[test]
fn demo_names_an_unknown_scenario_and_the_known_ones() {
    let out = ringswarm(&["demo", "--scenario", "nope"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr(&out).contains(
            "unknown scenario \"nope\" (known: paper-sim1, paper-sim2, hexagon-x500, \
             hexagon-x500-wrong-model, hexagon-x500-noisy, ground-start, mixed-autopilots, \
             link-loss, lossy, big-ring; or a path to a .toml file)"
        ),
        "{}",
        stderr(&out)
    );
}

#[test]
fn fly_reports_every_config_problem_before_touching_the_network() {
    let dir = std::env::temp_dir().join(format!("ringswarm-cli-fly-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("bad.toml");
    let text = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/paper-sim1.toml"),
    )
    .unwrap()
    .replacen("beta = 5.0", "beta = 0.5", 1)
    .replacen("control_rate_hz = 250.0", "control_rate_hz = 500.0", 1);
    std::fs::write(&path, text).unwrap();
    let out = ringswarm(&[
        "fly",
        "--config",
        path.to_str().unwrap(),
        "--out",
        dir.join("run").to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(2));
    let err = stderr(&out);
    assert!(err.contains("gains are unstable"), "{err}");
    assert!(
        err.contains("swarm.control_rate_hz must be a finite number in [1, 250] Hz, got 500"),
        "{err}"
    );
    assert!(
        !dir.join("run").exists(),
        "no run directory for a refused config"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// paper-sim1 with `from` replaced by `to`, written to a fresh directory; returns the
/// directory and the file.
fn paper_sim1_with(tag: &str, from: &str, to: &str) -> (std::path::PathBuf, std::path::PathBuf) {
    let dir = std::env::temp_dir().join(format!("ringswarm-cli-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let text = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/paper-sim1.toml"),
    )
    .unwrap();
    assert!(text.contains(from), "{from}");
    let path = dir.join("scenario.toml");
    std::fs::write(&path, text.replacen(from, to, 1)).unwrap();
    (dir, path)
}

#[test]
fn an_absurd_duration_is_refused_by_name_not_a_panic() {
    let (dir, path) = paper_sim1_with("duration", "k = 5.0", "k = 5.0");
    for (value, shown) in [("1e20", "1e20"), ("nan", "NaN"), ("-1", "-1")] {
        let out = ringswarm(&[
            "fly",
            "--config",
            path.to_str().unwrap(),
            "--out",
            dir.join("run").to_str().unwrap(),
            &format!("--duration-s={value}"),
        ]);
        assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
        assert!(
            stderr(&out).contains(&format!(
                "--duration-s must be a finite number in (0, 1000000] s, got {shown}"
            )),
            "{}",
            stderr(&out)
        );
    }
    assert!(!dir.join("run").exists());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_nan_offset_is_refused_before_anything_flies() {
    let (dir, path) = paper_sim1_with(
        "nan-offset",
        "kind = \"polygon\"\nradius_m = 20.0",
        "kind = \"offsets\"\noffsets_m = [[20.0, 0.0], [10.0, 17.3], [-10.0, nan], [-20.0, 0.0], [-10.0, -17.3], [10.0, -17.3]]",
    );
    let out = ringswarm(&[
        "demo",
        "--scenario",
        path.to_str().unwrap(),
        "--no-plots",
        "--out",
        dir.join("run").to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(
        stderr(&out).contains(
            "formation.offsets_m[2][1] must be a finite number in [-10000, 10000] m, got NaN"
        ),
        "{}",
        stderr(&out)
    );
    assert!(!dir.join("run").exists());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_vehicle_never_heard_makes_demo_exit_3_naming_it_and_warnings_show_without_rust_log() {
    let (dir, path) = paper_sim1_with(
        "never-heard",
        "[[vehicle]]",
        "[[emulator.silence]]\nvehicle = 4\nfrom_s = 0.0\nuntil_s = 100000.0\n\n[[vehicle]]",
    );
    let text = std::fs::read_to_string(&path)
        .unwrap()
        .replace(
            "duration_s = 60.0",
            "duration_s = 60.0\nhandshake_timeout_s = 3.0",
        )
        .replace("ground_below_m = 100.0", "ground_below_m = 2.0");
    std::fs::write(&path, text).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_ringswarm"))
        .args([
            "demo",
            "--scenario",
            path.to_str().unwrap(),
            "--no-plots",
            "--out",
            dir.join("run").to_str().unwrap(),
        ])
        .env_remove("RUST_LOG")
        .output()
        .unwrap();
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(3), "{err}");
    assert!(
        err.contains("error: handshake not complete after 3.0 s: vehicle 4 not flying (never heard); the vehicles that flew were landed"),
        "{err}"
    );
    // The warning log line, printed with RUST_LOG unset, and the events file.
    assert!(
        err.contains("WARN") && err.contains("swarm: handshake not complete"),
        "{err}"
    );
    let events = std::fs::read_to_string(dir.join("run/events.csv")).unwrap();
    assert!(
        events.starts_with("t_s,system_id,network,level,event\n"),
        "{events}"
    );
    assert!(
        events.contains("3.0000,,,warning,\"handshake not complete after 3.0 s: vehicle 4 not flying (never heard)"),
        "{events}"
    );
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("run/summary.json")).unwrap())
            .unwrap();
    assert_eq!(summary["final_phase"], "landing");
    assert!(summary["failure"].as_str().unwrap().contains("vehicle 4"));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn analyze_with_an_airframe_runs_the_bandwidth_gate() {
    // The paper's gains on an x500 (attitude P 6.5 rad/s) at 50 Hz: the velocity pole at
    // −34.80 1/s against 1.5 × 6.5 = 9.75 1/s: time scale 9.75 / 34.80 = 0.28.
    let args = [
        "analyze",
        "-m",
        "3",
        "-k",
        "5",
        "--alpha",
        "1",
        "--beta",
        "5",
        "--attitude-bandwidth",
        "6.5",
        "--control-rate",
        "50",
    ];
    let out = ringswarm(&args);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("bandwidth: the law's fastest mode 34.80 1/s is too fast for the airframe (9.75 1/s = 1.5 × attitude bandwidth 6.5 rad/s): fly gains.time_scale = 0.28 or less (now 1)"),
        "{text}"
    );
    let mut json_args = args.to_vec();
    json_args.push("--json");
    let v = json(&ringswarm(&json_args));
    let b = &v["bandwidth"];
    assert!((b["fastest_mode_per_s"].as_f64().unwrap() - 34.80).abs() < 0.01);
    assert_eq!(b["limited_by"], "attitude");
    assert_eq!(b["fits"], false);
    let bad = ringswarm(&[
        "analyze",
        "-m",
        "3",
        "-k",
        "5",
        "--alpha",
        "1",
        "--beta",
        "5",
        "--attitude-bandwidth",
        "nan",
    ]);
    assert_eq!(bad.status.code(), Some(2));
    assert!(
        stderr(&bad)
            .contains("--attitude-bandwidth must be a finite number in (0, 1000] rad/s, got NaN"),
        "{}",
        stderr(&bad)
    );
}

#[test]
fn keygen_writes_a_private_key_once_and_never_overwrites_it() {
    let dir = std::env::temp_dir().join(format!("ringswarm-cli-keygen-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("swarm.key");
    let out = ringswarm(&["keygen", path.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let text = std::fs::read_to_string(&path).unwrap();
    assert_eq!(text.len(), 65, "{text:?}");
    assert!(text.ends_with('\n') && text.trim().chars().all(|c| c.is_ascii_hexdigit()));
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(&path).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, 0o600, "{mode:o}");
    }
    let again = ringswarm(&["keygen", path.to_str().unwrap()]);
    assert_eq!(again.status.code(), Some(2));
    assert!(
        stderr(&again).contains("exists: a key is never overwritten"),
        "{}",
        stderr(&again)
    );
    assert_eq!(std::fs::read_to_string(&path).unwrap(), text);
    let other = dir.join("other.key");
    assert_eq!(
        ringswarm(&["keygen", other.to_str().unwrap()])
            .status
            .code(),
        Some(0)
    );
    assert_ne!(std::fs::read_to_string(&other).unwrap(), text);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn web_and_mirror_without_realtime_and_a_view_of_no_run_directory_are_refused_by_name() {
    let out = ringswarm(&["demo", "--web", "8080"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr(&out).contains("--web and --mirror need --realtime"),
        "{}",
        stderr(&out)
    );
    let out = ringswarm(&["demo", "--realtime", "--mirror", "14551"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("HOST:PORT"), "{}", stderr(&out));
    let out = ringswarm(&["view", "/nonexistent/run", "--web", "127.0.0.1:0"]);
    assert_eq!(out.status.code(), Some(2));
    let err = stderr(&out);
    assert!(err.contains("/nonexistent/run/setup.json"), "{err}");
    // A web address already taken is named (this port is held by the test).
    let held = std::net::TcpListener::bind("127.0.0.1:0").expect("a port");
    let port = held.local_addr().expect("addr").port().to_string();
    let dir = std::env::temp_dir().join(format!("ringswarm-cli-view-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let demo = ringswarm(&[
        "demo",
        "--scenario",
        concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/fixtures/ground-diamond.toml"
        ),
        "--no-plots",
        "--out",
        dir.to_str().expect("utf-8"),
    ]);
    assert_eq!(demo.status.code(), Some(0), "{}", stderr(&demo));
    let out = ringswarm(&["view", dir.to_str().expect("utf-8"), "--web", &port]);
    assert_eq!(out.status.code(), Some(2));
    let err = stderr(&out);
    assert!(
        err.contains(&format!("bind 127.0.0.1:{port} for the web view")),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// `demo --scenario` of `text` (written as `<name>.toml` in a directory of its own):
/// the process's output and the run's `summary.json`.
fn demo_of(name: &str, text: &str) -> (Output, serde_json::Value) {
    let dir = std::env::temp_dir().join(format!("ringswarm-cli-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let config = dir.join(format!("{name}.toml"));
    std::fs::write(&config, text).unwrap();
    let run = dir.join("run");
    let out = ringswarm(&[
        "demo",
        "--scenario",
        config.to_str().unwrap(),
        "--no-plots",
        "--out",
        run.to_str().unwrap(),
    ]);
    let summary = std::fs::read_to_string(run.join("summary.json"))
        .map(|text| serde_json::from_str(&text).unwrap())
        .unwrap_or(serde_json::Value::Null);
    let _ = std::fs::remove_dir_all(&dir);
    (out, summary)
}

#[test]
fn demo_exits_5_when_the_fence_ends_the_consensus() {
    // paper-sim1 in a circle of radius 400 m: it flies out at 14.9 m/s and is held.
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/paper-sim1.toml");
    let text = std::fs::read_to_string(path).unwrap().replacen(
        "[[vehicle]]",
        "[fence]\nkind = \"circle\"\ncentre_enu_m = [0.0, 0.0]\nradius_m = 400.0\n\
         min_altitude_m = -50.0\nmax_altitude_m = 100.0\n\n[[vehicle]]",
        1,
    );
    let (out, summary) = demo_of("fenced", &text);
    assert_eq!(out.status.code(), Some(5), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("the fence ended the consensus"),
        "{}",
        stderr(&out)
    );
    assert_eq!(summary["stop_reason"], "fence");
    assert_eq!(summary["safety"]["fence_actions"], 1);
}

#[test]
fn demo_exits_6_when_two_vehicles_come_too_close() {
    // The crossing with 250 ms each way on every link: more delay than the filter and the
    // gains can fly, a pair comes inside 95 % of the separation and the swarm holds.
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/crossing.toml");
    let text = std::fs::read_to_string(path)
        .unwrap()
        .replacen("[emulator]\n", "[emulator]\nlatency_ms = 250.0\n", 1)
        .replacen("duration_s = 60.0", "duration_s = 20.0", 1);
    let (out, summary) = demo_of("late", &text);
    assert_eq!(out.status.code(), Some(6), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("two vehicles came too close"),
        "{}",
        stderr(&out)
    );
    assert_eq!(summary["stop_reason"], "separation");
    assert_eq!(summary["safety"]["separation_actions"], 1);
}

#[test]
fn a_link_fault_out_of_range_is_named_on_every_path_never_a_panic() {
    // `demo --realtime` used to panic on a negative latency (Duration::from_secs_f64);
    // lockstep, real time and `sitl` now check it in one place.
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/paper-sim1.toml");
    let text = std::fs::read_to_string(path).unwrap();
    let text = if text.contains("[emulator]\n") {
        text.replacen(
            "[emulator]\n",
            "[emulator]\nlatency_ms = -1.0\njitter_ms = nan\n",
            1,
        )
    } else {
        format!("{text}\n[emulator]\nlatency_ms = -1.0\njitter_ms = nan\n")
    };
    let dir = std::env::temp_dir().join(format!("ringswarm-cli-faults-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let config = dir.join("faults.toml");
    std::fs::write(&config, text).unwrap();
    for realtime in [false, true] {
        let mut args = vec!["demo", "--scenario", config.to_str().unwrap(), "--no-plots"];
        if realtime {
            args.push("--realtime");
        }
        let out = ringswarm(&args);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(2), "realtime {realtime}: {err}");
        assert!(!err.contains("panicked"), "{err}");
        assert!(
            err.contains("emulator.latency_ms must be in [0, 10000] ms, got -1"),
            "{err}"
        );
        assert!(
            err.contains("emulator.jitter_ms must be in [0, 10000] ms, got NaN"),
            "{err}"
        );
    }
    let out = ringswarm(&["sitl", "--vehicles", "1", "--latency-ms=-5"]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("--latency-ms must be in [0, 10000] ms, got -5"),
        "{}",
        stderr(&out)
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// `flight.mcap` holds what the run directory holds: one `/swarm` message per replay
/// period from the flight's start time, every event of `events.csv` on `/log`, and
/// `summary.json` on `/summary`; a vehicle's position in `/swarm` and its commands in
/// `/setpoints` are its CSV row's.
#[test]
fn demo_writes_a_flight_mcap_that_holds_the_run_directory() {
    let dir = std::env::temp_dir().join(format!("ringswarm-cli-mcap-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let demo = ringswarm(&[
        "demo",
        "--scenario",
        concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/fixtures/ground-diamond.toml"
        ),
        "--no-plots",
        "--out",
        dir.to_str().expect("utf-8"),
    ]);
    assert_eq!(demo.status.code(), Some(0), "{}", stderr(&demo));
    let bytes = std::fs::read(dir.join("flight.mcap")).expect("flight.mcap");
    let mut swarm = Vec::new();
    let mut setpoints = Vec::new();
    let mut logs = Vec::new();
    let mut summaries = Vec::new();
    for message in mcap::MessageStream::new(&bytes).expect("an MCAP file") {
        let message = message.expect("a message");
        assert_eq!(message.channel.message_encoding, "json");
        let schema = message.channel.schema.as_ref().expect("a schema");
        assert_eq!(schema.encoding, "jsonschema");
        let value: serde_json::Value = serde_json::from_slice(&message.data).expect("JSON");
        match message.channel.topic.as_str() {
            "/swarm" => swarm.push((message.log_time, value)),
            "/setpoints" => setpoints.push((message.log_time, value)),
            "/log" => logs.push((message.log_time, value)),
            "/summary" => summaries.push(value),
            other => panic!("unexpected topic {other}"),
        }
    }
    // /swarm: every 50 ms from the flight's start to its last row.
    let csv = std::fs::read_to_string(dir.join("vehicle-1.csv")).expect("vehicle-1.csv");
    let rows: Vec<Vec<f64>> = csv
        .lines()
        .skip(1)
        .map(|line| {
            line.split(',')
                .map(|field| field.parse().unwrap_or(f64::NAN))
                .collect()
        })
        .collect();
    let events = std::fs::read_to_string(dir.join("events.csv")).expect("events.csv");
    let event_times: Vec<f64> = events
        .lines()
        .skip(1)
        .map(|line| line.split(',').next().unwrap().parse().unwrap())
        .collect();
    let last_s = rows
        .iter()
        .map(|r| r[0])
        .chain(event_times.iter().copied())
        .fold(0.0_f64, f64::max);
    assert_eq!(swarm.len() as f64, (last_s / 0.05 + 1e-9).floor() + 1.0);
    let start_ns = swarm[0].0;
    for (i, (time_ns, state)) in swarm.iter().enumerate() {
        assert_eq!(*time_ns - start_ns, i as u64 * 50_000_000);
        assert!((state["t_s"].as_f64().unwrap() - i as f64 * 0.05).abs() < 1e-9);
        assert_eq!(state["vehicles"].as_array().unwrap().len(), 4);
    }
    // Vehicle 1 at 4 s: its last CSV row at or before 4 s (ENU, 10⁻⁴ m resolution).
    let row = rows.iter().rfind(|r| r[0] <= 4.0 + 1e-9).expect("a row");
    let state = &swarm[80].1;
    assert_eq!(state["t_s"].as_f64().unwrap(), 4.0);
    let position = &state["vehicles"][0]["position_enu_m"];
    for (axis, column) in [(0, 3), (1, 4), (2, 5)] {
        let got = position[axis].as_f64().unwrap();
        assert!(
            (got - row[column]).abs() <= 1e-4,
            "axis {axis}: {got} vs {}",
            row[column]
        );
    }
    // /setpoints: at the same times, vehicle 1's commands at 4 s are that row's.
    assert_eq!(setpoints.len(), swarm.len());
    for ((a, _), (b, _)) in setpoints.iter().zip(&swarm) {
        assert_eq!(a, b);
    }
    let sent = &setpoints[80].1["vehicles"][0];
    assert_eq!(sent["sysid"], 1);
    assert_eq!(sent["t_s"].as_f64().unwrap(), row[0]);
    let command = &sent["command_enu_mps2"];
    let got = [
        command[0].as_f64().unwrap(),
        command[1].as_f64().unwrap(),
        command[2].as_f64().unwrap(),
        sent["roll_setpoint_rad"].as_f64().unwrap(),
        sent["pitch_setpoint_rad"].as_f64().unwrap(),
        sent["thrust_norm"].as_f64().unwrap(),
    ];
    assert_eq!(got, [row[12], row[13], row[14], row[15], row[16], row[17]]);
    // The vertical command holds the vehicle up: a thrust well above zero.
    assert!(got[5] > 0.1, "{got:?}");
    // /log: one message per event, in time, from the same start.
    assert_eq!(logs.len(), event_times.len());
    for ((time_ns, log), t_s) in logs.iter().zip(&event_times) {
        let offset_s = (*time_ns - start_ns) as f64 * 1e-9;
        assert!((offset_s - t_s).abs() < 1e-6, "{offset_s} vs {t_s}");
        assert!(log["level"] == 2 || log["level"] == 3);
        assert!(!log["message"].as_str().unwrap().is_empty());
    }
    // /summary: summary.json, once.
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summaries, vec![summary]);
    let _ = std::fs::remove_dir_all(&dir);
}
