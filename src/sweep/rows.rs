//! A sweep's rows: one per flight, kept as a line of JSON in `flights.jsonl` as each
//! flight ends (what an interrupted sweep resumes from, and what parts are merged from),
//! and flattened into columns for `results.parquet`. Pure, but for reading and appending
//! the journal.

use std::collections::BTreeMap;
use std::io::{BufRead, Write};
use std::path::Path;

use serde::{Deserialize, Serialize};

/// One flight's row as the journal keeps it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FlightRow {
    /// Its place among the sweep's flights.
    pub index: u64,
    /// Its cell.
    pub cell: u64,
    /// Its replicate in the cell.
    pub replicate: u64,
    /// Its seed.
    pub seed: u64,
    /// The axes' values, in the spec's order.
    pub values: Vec<f64>,
    /// The exit code `demo` would give it (2: it could not be flown, `error` says why).
    pub exit_code: u8,
    /// Why it could not be flown, when it could not.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// Wall-clock seconds.
    pub wall_s: f64,
    /// Its `summary.json` (`null` when it could not be flown).
    pub summary: serde_json::Value,
}

/// A column's value in one row.
#[derive(Debug, Clone, PartialEq)]
pub enum Cell {
    /// A number.
    Float(f64),
    /// A whole number.
    Int(i64),
    /// A yes or no.
    Bool(bool),
    /// Text.
    Text(String),
}

/// The summary's fields as columns: nested objects by dotted path
/// (`safety.filter_time.p99_ms`), short lists of numbers by position
/// (`predicted_final_velocity[0]`, east). Lists of objects (each vehicle's model, the
/// mirrors) are per vehicle, not per flight, and are left out; nulls are left out (the
/// column is null there).
pub fn flatten(summary: &serde_json::Value) -> BTreeMap<String, Cell> {
    let mut out = BTreeMap::new();
    walk("", summary, &mut out);
    out
}

fn walk(prefix: &str, v: &serde_json::Value, out: &mut BTreeMap<String, Cell>) {
    use serde_json::Value;
    match v {
        Value::Null => {}
        Value::Bool(b) => {
            out.insert(prefix.to_owned(), Cell::Bool(*b));
        }
        Value::Number(n) => {
            let cell = match n.as_i64() {
                Some(i) => Cell::Int(i),
                None => Cell::Float(n.as_f64().unwrap_or(f64::NAN)),
            };
            out.insert(prefix.to_owned(), cell);
        }
        Value::String(s) => {
            out.insert(prefix.to_owned(), Cell::Text(s.clone()));
        }
        Value::Array(items) => {
            if items.iter().all(Value::is_number) {
                for (i, item) in items.iter().enumerate() {
                    walk(&format!("{prefix}[{i}]"), item, out);
                }
            }
        }
        Value::Object(map) => {
            for (k, item) in map {
                let key = if prefix.is_empty() {
                    k.clone()
                } else {
                    format!("{prefix}.{k}")
                };
                walk(&key, item, out);
            }
        }
    }
}

/// Appends `row` to the journal at `path` as one line, flushed.
///
/// # Errors
/// The file cannot be opened or written.
pub fn append(path: &Path, row: &FlightRow) -> std::io::Result<()> {
    let mut line = serde_json::to_string(row).map_err(std::io::Error::other)?;
    line.push('\n');
    let mut f = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)?;
    f.write_all(line.as_bytes())?;
    f.flush()
}

/// The rows of the journal at `path` (none when it does not exist), by index, the last of
/// an index kept. A last line cut short by an interruption is left out, as if that
/// flight had not ended.
///
/// # Errors
/// The file cannot be read, or a line before the last is not a row (named by number).
pub fn read(path: &Path) -> Result<BTreeMap<u64, FlightRow>, String> {
    let file = match std::fs::File::open(path) {
        Ok(f) => f,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(BTreeMap::new()),
        Err(e) => return Err(format!("read {}: {e}", path.display())),
    };
    let lines: Vec<String> = std::io::BufReader::new(file)
        .lines()
        .collect::<Result<_, _>>()
        .map_err(|e| format!("read {}: {e}", path.display()))?;
    let mut rows = BTreeMap::new();
    let last = lines.len().saturating_sub(1);
    for (n, line) in lines.iter().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        match serde_json::from_str::<FlightRow>(line) {
            Ok(row) => {
                rows.insert(row.index, row);
            }
            Err(_) if n == last => {}
            Err(e) => {
                return Err(format!(
                    "{} line {}: not a flight's row: {e}",
                    path.display(),
                    n + 1
                ));
            }
        }
    }
    Ok(rows)
}

/// Cuts a last line an interruption left unfinished off the journal at `path` (nothing
/// when it ends in a newline or does not exist), so that rows appended after it start on
/// a line of their own.
///
/// # Errors
/// The file cannot be read or cut.
pub fn trim_cut_line(path: &Path) -> std::io::Result<()> {
    let bytes = match std::fs::read(path) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(e) => return Err(e),
    };
    if bytes.is_empty() || bytes.ends_with(b"\n") {
        return Ok(());
    }
    let keep = bytes.iter().rposition(|b| *b == b'\n').map_or(0, |i| i + 1);
    std::fs::OpenOptions::new()
        .write(true)
        .open(path)?
        .set_len(keep as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(index: u64) -> FlightRow {
        FlightRow {
            index,
            cell: index / 2,
            replicate: index % 2,
            seed: 1000 + index,
            values: vec![0.5, 2.0],
            exit_code: 0,
            error: None,
            wall_s: 0.1,
            summary: serde_json::json!({"formation_error_m": 0.25, "vehicles": 6}),
        }
    }

    #[test]
    fn a_summary_flattens_to_dotted_columns_and_numbered_pairs() {
        let summary = serde_json::json!({
            "vehicles": 6,
            "formation_error_m": 0.125,
            "predicted_final_velocity": [11.0, 4.5],
            "failure": null,
            "stop_reason": "duration",
            "timing": {"late_ticks": 0, "late_fraction": 0.0},
            "safety": {"filter_time": {"p99_ms": 0.41}, "jams": 0},
            "models": [{"system_id": 1, "drag_per_s": 0.1}],
            "flag": true
        });
        let flat = flatten(&summary);
        let names: Vec<&str> = flat.keys().map(String::as_str).collect();
        assert_eq!(
            names,
            [
                "flag",
                "formation_error_m",
                "predicted_final_velocity[0]",
                "predicted_final_velocity[1]",
                "safety.filter_time.p99_ms",
                "safety.jams",
                "stop_reason",
                "timing.late_fraction",
                "timing.late_ticks",
                "vehicles"
            ]
        );
        assert_eq!(flat["vehicles"], Cell::Int(6));
        assert_eq!(flat["predicted_final_velocity[1]"], Cell::Float(4.5));
        assert_eq!(flat["safety.filter_time.p99_ms"], Cell::Float(0.41));
        assert_eq!(flat["stop_reason"], Cell::Text("duration".to_owned()));
        assert_eq!(flat["flag"], Cell::Bool(true));
    }

    #[test]
    fn the_journal_gives_back_its_rows_and_skips_a_last_line_cut_short() {
        let dir = std::env::temp_dir().join(format!("ringswarm-journal-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("flights.jsonl");
        let _ = std::fs::remove_file(&path);
        assert!(read(&path).unwrap().is_empty());
        for i in [0, 2, 1] {
            append(&path, &row(i)).unwrap();
        }
        let rows = read(&path).unwrap();
        assert_eq!(rows.keys().copied().collect::<Vec<_>>(), vec![0, 1, 2]);
        assert_eq!(rows[&2], row(2));
        // An interruption in the middle of a line: that flight is flown again.
        let mut f = std::fs::OpenOptions::new()
            .append(true)
            .open(&path)
            .unwrap();
        f.write_all(br#"{"index":3,"cell":1,"repl"#).unwrap();
        drop(f);
        assert_eq!(read(&path).unwrap().len(), 3);
        // Cut off before the next row goes in after it.
        trim_cut_line(&path).unwrap();
        append(&path, &row(3)).unwrap();
        assert_eq!(read(&path).unwrap()[&3], row(3));
        // A damaged line before the last is refused by its number.
        std::fs::write(&path, "nonsense\n{}\n").unwrap();
        let e = read(&path).unwrap_err();
        assert!(e.contains("line 1: not a flight's row"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
