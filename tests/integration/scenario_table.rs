//! The scenario table of docs/performance.md is what `ringswarm demo` flies: every row is
//! flown here as a user would (`demo --scenario config/NAME.toml`), and each figure of
//! its `summary.json` must round to the figure printed. The lockstep flights are
//! deterministic (and the same in debug and release builds), so the margin is the
//! printing's own: half a unit of the last digit shown ("< 1 mm" means below 0.001 m).
//! A change that moves a flight fails here until the table is measured again.

use std::path::{Path, PathBuf};
use std::process::Command;

/// One figure as printed: its value and half a unit of its last digit, or an upper bound.
#[derive(Debug, Clone, Copy)]
enum Printed {
    Rounded { value: f64, half_unit: f64 },
    Below(f64),
}

impl Printed {
    /// The first number of a cell ("0.23 % (pure law …)", "2.4 m (altitude 0.23 m)",
    /// "< 1 mm"), scaled to the summary's unit by `scale` (0.01 for %, 1 for m).
    fn parse(cell: &str, scale: f64) -> Self {
        let cell = cell.trim();
        if let Some(rest) = cell.strip_prefix("< ") {
            let (num, unit) = rest.split_once(' ').expect("a unit after the number");
            let mm = match unit.trim() {
                "mm" => 1e-3,
                "m" => 1.0,
                other => panic!("unit {other}"),
            };
            return Self::Below(num.parse::<f64>().expect("a number") * mm);
        }
        let num: String = cell
            .chars()
            .take_while(|c| c.is_ascii_digit() || *c == '.')
            .collect();
        let decimals = num.split_once('.').map_or(0, |(_, d)| d.len());
        Self::Rounded {
            value: num.parse::<f64>().expect("a number") * scale,
            half_unit: 0.5 * 10f64.powi(-(decimals as i32)) * scale,
        }
    }

    fn holds(self, measured: f64) -> bool {
        match self {
            // A hair over half a unit: the printed figure was rounded from this value.
            Self::Rounded { value, half_unit } => (measured - value).abs() <= half_unit * 1.0001,
            Self::Below(bound) => measured < bound,
        }
    }
}

struct Row {
    config: PathBuf,
    velocity_error: Printed,
    formation: Printed,
    min_separation: Printed,
}

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The rows of the table under "## Scenarios" in docs/performance.md.
fn table() -> Vec<Row> {
    let text = std::fs::read_to_string(root().join("docs/performance.md")).unwrap();
    let section = text
        .split("## Scenarios")
        .nth(1)
        .expect("a Scenarios section");
    section
        .lines()
        .skip_while(|l| !l.starts_with("| scenario |"))
        .skip(2)
        .take_while(|l| l.starts_with('|'))
        .map(|line| {
            let cells: Vec<&str> = line.split('|').map(str::trim).collect();
            let name = cells[1].trim_matches('`');
            let config = if name.ends_with(".toml") {
                root().join(name)
            } else {
                root().join("config").join(format!("{name}.toml"))
            };
            Row {
                config,
                velocity_error: Printed::parse(cells[3], 0.01),
                formation: Printed::parse(cells[4], 1.0),
                min_separation: Printed::parse(cells[5], 1.0),
            }
        })
        .collect()
}

fn fly(config: &Path, out: &Path) -> serde_json::Value {
    let status = Command::new(env!("CARGO_BIN_EXE_ringswarm"))
        .args(["demo", "--no-plots", "--scenario"])
        .arg(config)
        .arg("--out")
        .arg(out)
        .env("RUST_LOG", "off")
        .output()
        .unwrap();
    assert!(
        status.status.success(),
        "{}: {}",
        config.display(),
        String::from_utf8_lossy(&status.stderr)
    );
    serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap()
}

#[test]
fn every_row_of_the_scenario_table_is_what_demo_flies() {
    let rows = table();
    assert_eq!(rows.len(), 11, "the table's rows");
    let dir = std::env::temp_dir().join(format!("ringswarm-table-{}", std::process::id()));
    let mut wrong = Vec::new();
    for row in &rows {
        assert!(row.config.exists(), "{}", row.config.display());
        let name = row
            .config
            .file_stem()
            .unwrap()
            .to_string_lossy()
            .into_owned();
        let summary = fly(&row.config, &dir.join(&name));
        let figure = |key: &str| summary[key].as_f64().unwrap_or(f64::NAN);
        for (what, printed, key) in [
            (
                "velocity error",
                row.velocity_error,
                "velocity_error_fraction",
            ),
            ("formation", row.formation, "formation_error_m"),
            ("min separation", row.min_separation, "min_separation_m"),
        ] {
            if !printed.holds(figure(key)) {
                wrong.push(format!(
                    "{name} {what}: printed {printed:?}, flown {}",
                    figure(key)
                ));
            }
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
}

#[test]
fn the_table_parser_reads_every_kind_of_cell() {
    let close = |a: f64, b: f64| (a - b).abs() < 1e-12;
    let Printed::Rounded { value, half_unit } =
        Printed::parse("0.23 % (pure law, `clip`: 39 %)", 0.01)
    else {
        panic!()
    };
    assert!(close(value, 0.0023) && close(half_unit, 0.00005));
    let Printed::Rounded { value, half_unit } = Printed::parse("2.4 m (altitude 0.23 m)", 1.0)
    else {
        panic!()
    };
    assert!(close(value, 2.4) && close(half_unit, 0.05));
    let Printed::Below(bound) = Printed::parse("< 1 mm", 1.0) else {
        panic!()
    };
    assert!(close(bound, 0.001));
    assert!(Printed::parse("3.04 m", 1.0).holds(3.036));
    assert!(!Printed::parse("3.04 m", 1.0).holds(3.0349));
    assert!(!Printed::parse("< 1 mm", 1.0).holds(0.001));
}
