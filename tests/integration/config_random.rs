//! Random values in every key of the shipped configs never make the coordinator panic:
//! each is parsed, validated, turned into the emulator's world and flown for a moment
//! when valid. A valid setup holds only finite numbers. Seeded: every run checks the same
//! 3 000 cases.

use std::time::Duration;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use ringswarm::config::Config;
use ringswarm::driver::lockstep::Lockstep;
use ringswarm_wire::time::SimTime;
use toml::{Table, Value};

/// Every leaf of a TOML table, as a path of keys and array indices.
fn leaves(value: &Value, path: &mut Vec<String>, out: &mut Vec<Vec<String>>) {
    match value {
        Value::Table(t) => {
            for (k, v) in t {
                path.push(k.clone());
                leaves(v, path, out);
                path.pop();
            }
        }
        Value::Array(a) => {
            out.push(path.clone()); // the whole array
            for (i, v) in a.iter().enumerate() {
                path.push(i.to_string());
                leaves(v, path, out);
                path.pop();
            }
        }
        _ => out.push(path.clone()),
    }
}

fn at<'a>(value: &'a mut Value, path: &[String]) -> Option<&'a mut Value> {
    let mut v = value;
    for key in path {
        v = match v {
            Value::Table(t) => t.get_mut(key)?,
            Value::Array(a) => a.get_mut(key.parse::<usize>().ok()?)?,
            _ => return None,
        };
    }
    Some(v)
}

/// A value meant to break things.
fn nasty(rng: &mut ChaCha8Rng) -> Value {
    let floats = [
        f64::NAN,
        f64::INFINITY,
        f64::NEG_INFINITY,
        0.0,
        -0.0,
        -1.0,
        1e-300,
        1e20,
        -1e20,
        1e308,
        f64::MIN_POSITIVE,
        0.999_999,
        250.000_001,
    ];
    match rng.random_range(0..8) {
        0 => Value::Float(floats[rng.random_range(0..floats.len())]),
        1 => Value::Float(rng.random_range(-1e4..1e4)),
        2 => Value::Integer(rng.random_range(i64::MIN..i64::MAX)),
        3 => Value::Integer(rng.random_range(-3..300)),
        4 => Value::Boolean(rng.random()),
        5 => Value::String(
            ["", "nan", "polygon", "x500", "clip", "hold"][rng.random_range(0..6)].into(),
        ),
        6 => Value::Array(
            (0..rng.random_range(0..4))
                .map(|_| Value::Float(floats[rng.random_range(0..floats.len())]))
                .collect(),
        ),
        _ => Value::Table(Table::new()),
    }
}

#[test]
fn random_values_in_any_key_never_panic() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config");
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let mut valid = 0;
    let mut flown = 0;
    for name in [
        "paper-sim1",
        "paper-sim2",
        "hexagon-x500",
        "link-loss",
        "ground-start",
    ] {
        let text = std::fs::read_to_string(root.join(format!("{name}.toml"))).unwrap();
        let base: Value = Value::Table(text.parse::<Table>().unwrap());
        let mut paths = Vec::new();
        leaves(&base, &mut Vec::new(), &mut paths);
        for _ in 0..600 {
            let mut case = base.clone();
            for _ in 0..rng.random_range(1..=3) {
                let path = &paths[rng.random_range(0..paths.len())];
                if let Some(slot) = at(&mut case, path) {
                    *slot = nasty(&mut rng);
                }
            }
            let Ok(text) = toml::to_string(&case) else {
                continue;
            };
            let Ok(config) = Config::from_toml(&text) else {
                continue;
            };
            let _ = config.lockstep_faults();
            let _ = config.emulator();
            let _ = config.transport_layout();
            let Ok(setup) = config.validate() else {
                continue;
            };
            valid += 1;
            let finite = |x: f64| x.is_finite();
            assert!(
                finite(setup.altitude_m) && finite(setup.gains.alpha) && finite(setup.gains.beta)
            );
            assert!(
                setup
                    .offsets_m
                    .iter()
                    .all(|d| d.iter().all(|x| x.is_finite()))
            );
            assert!(setup.drag_per_s.iter().all(|x| x.is_finite()));
            assert!(setup.control_interval > Duration::ZERO);
            if let Ok(mut run) = Lockstep::from_config(&config) {
                flown += 1;
                run.run_until(SimTime::from_millis(50), |_| {});
                let setpoints = run.swarm().setpoints();
                assert!(setpoints.iter().all(|s| s.thrust_norm.is_finite()
                    && s.attitude_ned_frd.coords.iter().all(|x| x.is_finite())));
            }
        }
    }
    // Most cases break the file; enough stay valid to be flown.
    assert!(valid > 100 && flown > 100, "valid {valid}, flown {flown}");
}
