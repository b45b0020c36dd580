//! `ringswarm sweep` end to end: the same spec gives the same rows, parts merged give the
//! whole, an interrupted sweep resumes, a cell flown alone is the cell of the sweep, and
//! a key the config does not know is refused before any flight.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn ringswarm(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_ringswarm"))
        .args(args)
        .output()
        .expect("ringswarm runs")
}

fn dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("ringswarm-sweep-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

/// `lossy` (paper-sim1 with 20 % loss and jittered latency: the seed matters), 8 s of
/// consensus, k × beta = 2 × 2 cells, 2 replicates.
const SPEC: &str = r#"
[sweep]
scenario = "lossy"
seed = 11
replicates = 2

[set]
"swarm.duration_s" = 8.0

[[axis]]
key = "gains.k"
values = [1.0, 5.0]

[[axis]]
key = "gains.beta"
values = [3.0, 5.0]
"#;

fn spec(root: &Path, text: &str) -> String {
    std::fs::create_dir_all(root).unwrap();
    let path = root.join("spec.toml");
    std::fs::write(&path, text).unwrap();
    path.to_string_lossy().into_owned()
}

fn sweep(args: &[&str]) {
    let out = ringswarm(args);
    assert!(
        out.status.success(),
        "sweep {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The rows of a sweep's journal, by index, without what the wall clock measured (the
/// flight's wall time, the safety filter's solve times).
fn rows(dir: &Path) -> Vec<serde_json::Value> {
    let text = std::fs::read_to_string(dir.join("flights.jsonl")).expect("journal");
    let mut rows: Vec<serde_json::Value> = text
        .lines()
        .map(|l| {
            let mut v: serde_json::Value = serde_json::from_str(l).expect("a row");
            let obj = v.as_object_mut().unwrap();
            obj.remove("wall_s");
            if let Some(s) = obj.get_mut("summary").and_then(|s| s.as_object_mut()) {
                s.remove("wall_seconds");
                if let Some(safety) = s.get_mut("safety").and_then(|s| s.as_object_mut()) {
                    safety.remove("filter_time");
                }
            }
            v
        })
        .collect();
    rows.sort_by_key(|r| r["index"].as_u64());
    rows
}

#[test]
fn the_same_spec_gives_the_same_rows_and_its_parts_merged_give_the_whole() {
    let root = dir("same");
    let spec = spec(&root, SPEC);
    let (a, b) = (root.join("a"), root.join("b"));
    sweep(&["sweep", &spec, "--out", a.to_str().unwrap()]);
    sweep(&["sweep", &spec, "--out", b.to_str().unwrap(), "--jobs", "1"]);
    let whole = rows(&a);
    assert_eq!(whole.len(), 8);
    assert_eq!(whole, rows(&b), "two runs of one spec differ");
    assert!(a.join("results.parquet").is_file());
    // Every flight flew its 8 s of consensus and ended on its duration.
    for r in &whole {
        assert_eq!(r["exit_code"], 0, "{r}");
        assert_eq!(r["summary"]["stop_reason"], "duration", "{r}");
        let flown = r["summary"]["consensus_ended_s"].as_f64().unwrap()
            - r["summary"]["consensus_started_s"].as_f64().unwrap();
        assert!((7.9..8.1).contains(&flown), "{flown} s of consensus");
    }
    // Replicates of one cell are seeded apart: 20 % loss falls differently.
    assert_ne!(
        whole[0]["summary"]["formation_error_m"], whole[1]["summary"]["formation_error_m"],
        "replicates flew alike"
    );
    assert_eq!(whole[6]["values"], serde_json::json!([5.0, 5.0]));
    // In three parts, merged: row for row the whole.
    let parts: Vec<PathBuf> = (1..=3).map(|k| root.join(format!("part{k}"))).collect();
    for (k, p) in parts.iter().enumerate() {
        let part = format!("{}/3", k + 1);
        sweep(&[
            "sweep",
            &spec,
            "--out",
            p.to_str().unwrap(),
            "--part",
            &part,
        ]);
    }
    assert_eq!(rows(&parts[1]).len(), 3); // flights 1, 4, 7
    let merged = root.join("merged");
    let mut args = vec!["sweep", "merge"];
    args.extend(parts.iter().map(|p| p.to_str().unwrap()));
    args.extend(["--out", merged.to_str().unwrap()]);
    sweep(&args);
    assert_eq!(
        rows(&merged),
        whole,
        "the parts merged differ from the whole"
    );
    // A part missing is named.
    let out = ringswarm(&[
        "sweep",
        "merge",
        parts[0].to_str().unwrap(),
        parts[2].to_str().unwrap(),
        "--out",
        root.join("m2").to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("parts missing: 2/3"));
    std::fs::remove_dir_all(&root).unwrap();
}

#[test]
fn an_interrupted_sweep_flies_only_what_is_left_and_ends_with_the_same_rows() {
    let root = dir("resume");
    let spec = spec(&root, SPEC);
    let a = root.join("a");
    sweep(&["sweep", &spec, "--out", a.to_str().unwrap()]);
    let whole = rows(&a);
    // Cut after three rows, in the middle of the fourth, as a kill would.
    let text = std::fs::read_to_string(a.join("flights.jsonl")).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    let cut = format!("{}\n{}", lines[..3].join("\n"), &lines[3][..40]);
    std::fs::write(a.join("flights.jsonl"), cut).unwrap();
    let out = ringswarm(&["sweep", &spec, "--out", a.to_str().unwrap()]);
    assert!(out.status.success());
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(said.contains("3 done before, 5 to fly"), "{said}");
    assert_eq!(rows(&a), whole);
    // Another spec into the same directory is refused.
    let other = spec.replace("spec.toml", "other.toml");
    std::fs::write(&other, SPEC.replace("seed = 11", "seed = 12")).unwrap();
    let out = ringswarm(&["sweep", &other, "--out", a.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("holds another sweep"));
    std::fs::remove_dir_all(&root).unwrap();
}

#[test]
fn a_cell_flown_alone_ends_its_consensus_as_it_did_in_the_sweep() {
    let root = dir("cell");
    let spec = spec(&root, SPEC);
    let a = root.join("a");
    sweep(&["sweep", &spec, "--out", a.to_str().unwrap()]);
    let row = rows(&a)[5].clone(); // cell 2 (k = 5, beta = 3), replicate 1
    assert_eq!(row["cell"], 2);
    let run = root.join("cell-2.1");
    let out = ringswarm(&[
        "sweep",
        &spec,
        "--cell",
        "2.1",
        "--out",
        run.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read_to_string(run.join("summary.json")).unwrap();
    let summary: serde_json::Value = serde_json::from_str(&text).unwrap();
    // The same flight to the end of its consensus (then it lands, which the sweep skips).
    for key in [
        "formation_error_m",
        "velocity_error_fraction",
        "achieved_final_velocity",
        "predicted_final_velocity",
        "consensus_ended_s",
    ] {
        assert_eq!(summary[key], row["summary"][key], "{key}");
    }
    let config = std::fs::read_to_string(run.join("config.toml")).unwrap();
    assert!(
        config.contains("k = 5") && config.contains("beta = 3"),
        "{config}"
    );
    let seed = format!("seed = {}", row["seed"]);
    assert!(config.contains(&seed), "{config}");
    std::fs::remove_dir_all(&root).unwrap();
}

#[test]
fn a_key_or_value_the_config_refuses_stops_the_sweep_before_any_flight() {
    let root = dir("refused");
    let cases = [
        (
            SPEC.replace("gains.beta", "gains.bta"),
            "cell 0 (gains.k = 1, gains.bta = 3): unknown field `bta`",
        ),
        (
            SPEC.replace("values = [3.0, 5.0]", "values = [3.0, -5.0]"),
            "cell 1 (gains.k = 1, gains.beta = -5): ",
        ),
        (
            SPEC.replace("gains.k\"", "vehicle.7.drag_per_s\""),
            "`vehicle` has 6 entries, no entry 7",
        ),
    ];
    for (text, expected) in cases {
        let spec = spec(&root, &text);
        let out_dir = root.join("out");
        let _ = std::fs::remove_dir_all(&out_dir);
        let out = ringswarm(&["sweep", &spec, "--out", out_dir.to_str().unwrap()]);
        let said = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{said}");
        assert!(said.contains(expected), "{expected}: {said}");
        assert!(!out_dir.join("flights.jsonl").exists(), "a flight flew");
    }
    std::fs::remove_dir_all(&root).unwrap();
}

/// Every shipped sweep (`sweeps/*.toml`): its maps name its axes, and every flight's
/// settings make a config the lockstep driver accepts (no flight flown).
#[test]
fn every_shipped_sweep_sets_only_keys_the_config_accepts() {
    use ringswarm::sweep::{Sweep, config_of, spec::check_map};
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut specs: Vec<PathBuf> = std::fs::read_dir(root.join("sweeps"))
        .expect("sweeps/")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    specs.sort();
    assert!(specs.len() >= 2, "{specs:?}");
    for path in specs {
        let text = std::fs::read_to_string(&path).expect("spec");
        let sweep = Sweep::from_toml(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let scenario = root.join("config").join(format!("{}.toml", sweep.scenario));
        let base: toml::Table =
            toml::from_str(&std::fs::read_to_string(&scenario).expect("scenario")).expect("toml");
        for m in &sweep.maps {
            check_map(m, &sweep).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        }
        for i in 0..sweep.flights() {
            let flight = sweep.flight(i).expect("a flight");
            config_of(&base, &sweep, &flight).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        }
    }
}

/// Two flights of the shipped latency × loss sweep below the bandwidth gate that came
/// inside the separation before the safety filter put every vehicle's state at one
/// instant (the newest report's arrival): at 10 % loss and 100 ms the closest pair
/// really came to 2.80 m of 3 m (flight 263); at 40 % loss and 20 ms the coordinator saw
/// 2.39 m between two states of different ages while the vehicles were 4.30 m apart,
/// and held the swarm for nothing (flight 524). Both now fly their 60 s out.
#[test]
fn lossy_links_below_the_gate_keep_the_separation_in_truth_and_in_the_coordinators_view() {
    use ringswarm::sweep::{Sweep, config_of, fly};
    let text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("sweeps/latency-loss.toml"),
    )
    .expect("the shipped sweep");
    let sweep = Sweep::from_toml(&text).expect("spec");
    let base: toml::Table =
        toml::from_str(include_str!("../../config/paper-sim1.toml")).expect("paper-sim1");
    for index in [263, 524] {
        let flight = sweep.flight(index).expect("flight");
        let (_, config) = config_of(&base, &sweep, &flight).expect("config");
        let flown = fly(&config).expect("flies");
        let s = &flown.summary;
        let (seen, truth) = (
            s.min_separation_m.expect("seen"),
            s.true_min_separation_m.expect("true"),
        );
        eprintln!(
            "flight {index}: exit {}, seen {seen:.3} m, true {truth:.3} m",
            flown.exit_code
        );
        assert_eq!(flown.exit_code, 0, "flight {index}");
        assert!(truth >= 3.0, "flight {index}: {truth} m");
        assert!(seen >= 0.95 * 3.0, "flight {index}: {seen} m");
    }
}
