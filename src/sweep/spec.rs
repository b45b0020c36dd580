//! A sweep's spec (`ringswarm sweep SPEC.toml`): a base scenario, fixed settings, axes
//! over numeric keys of the coordinator file, and replicates; and its flights, each a
//! cell of the axes' grid and a replicate, with its own seed. Pure: reading the file is
//! the command's.
//!
//! ```toml
//! [sweep]
//! scenario = "paper-sim1"   # a shipped scenario, or a .toml file (relative to the spec)
//! seed = 1                  # every flight's seed is drawn from it, its cell and replicate
//! replicates = 3            # flights per cell
//!
//! [set]                     # applied to every flight, before the axes
//! "swarm.duration_s" = 30.0
//!
//! [[axis]]                  # a list
//! key = "gains.k"
//! values = [1.0, 2.0, 5.0]
//!
//! [[axis]]                  # a range: `count` values from `from` to `to`, both included
//! key = "gains.beta"
//! from = 0.5
//! to = 10.0
//! count = 20
//! scale = "log"             # or "linear" (the default)
//!
//! [[axis]]                  # random draws: `count` values drawn once from the sweep's seed
//! key = "vehicle.*.drag_per_s"
//! draw = "uniform"          # or "normal" (mean, std), "log-uniform" (low, high > 0)
//! low = 0.0
//! high = 0.3
//! count = 4
//! ```
//!
//! Keys are dotted paths into the coordinator file: `gains.k`, `emulator.latency_ms`,
//! `safety.min_separation_m`. A list of tables is entered by position from 1
//! (`vehicle.3.drag_per_s`) or as a whole (`vehicle.*.drag_per_s`: every vehicle). The
//! grid crosses the axes in the order written, the last one fastest; a cell is its
//! index in that order.

use std::fmt;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use serde::Deserialize;

/// The most flights a sweep may have (cells × replicates).
pub const MAX_FLIGHTS: u64 = 10_000_000;

/// The spec as written.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpecFile {
    /// What is swept.
    pub sweep: SweepSection,
    /// Settings applied to every flight (dotted key → value).
    #[serde(default)]
    pub set: toml::Table,
    /// The axes, crossed in this order.
    #[serde(default)]
    pub axis: Vec<AxisSpec>,
    /// Maps of a metric over two axes, drawn when the sweep ends.
    #[serde(default)]
    pub map: Vec<MapSpec>,
}

/// `[sweep]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SweepSection {
    /// A shipped scenario's name, or a path to a coordinator file (`.toml`).
    pub scenario: String,
    /// The sweep's seed.
    #[serde(default = "one")]
    pub seed: u64,
    /// Flights per cell, each with its own seed.
    #[serde(default = "one")]
    pub replicates: u64,
}

fn one() -> u64 {
    1
}

/// `[[axis]]` as written: `values`, or `from`/`to`/`count` (`scale`), or `draw` with its
/// parameters and `count`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AxisSpec {
    /// The dotted key.
    pub key: String,
    /// The values, as listed.
    pub values: Option<Vec<f64>>,
    /// A range's first value.
    pub from: Option<f64>,
    /// A range's last value.
    pub to: Option<f64>,
    /// How many values a range or a draw gives.
    pub count: Option<u64>,
    /// A range's spacing: `linear` (default) or `log`.
    pub scale: Option<String>,
    /// A distribution to draw from: `uniform`, `log-uniform`, `normal`.
    pub draw: Option<String>,
    /// `uniform`, `log-uniform`: the lower bound.
    pub low: Option<f64>,
    /// `uniform`, `log-uniform`: the upper bound.
    pub high: Option<f64>,
    /// `normal`: the mean.
    pub mean: Option<f64>,
    /// `normal`: the standard deviation.
    pub std: Option<f64>,
}

/// `[[map]]` as written.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MapSpec {
    /// The axis across.
    pub x: String,
    /// The axis up.
    pub y: String,
    /// The number mapped.
    pub metric: String,
    /// How a cell's flights become one number.
    #[serde(default)]
    pub reduce: Reduce,
    /// A theory drawn over the map.
    #[serde(default)]
    pub theory: Option<Theory>,
    /// A cell counts as good (for the flown boundary the theory is held against) when
    /// its reduced metric is at most this (default 0: for `exit_code`, every flight ran
    /// its duration out).
    #[serde(default)]
    pub good_at_most: f64,
    /// A cell counts as good only when, besides, every flight of it exited 0: ran its
    /// duration out, not ended by the divergence guard, the fence or the separation
    /// (default false). For a metric measured over the consensus, such as the formation
    /// error's growth, a flight cut short is not one that converged.
    #[serde(default)]
    pub require_exit_0: bool,
}

/// How a cell's flights become one number.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Reduce {
    /// Their mean.
    #[default]
    Mean,
    /// The largest.
    Max,
    /// The smallest.
    Min,
    /// The median (the mean of the middle two for an even count).
    Median,
}

impl Reduce {
    /// Its name in the spec.
    pub fn name(self) -> &'static str {
        match self {
            Self::Mean => "mean",
            Self::Max => "max",
            Self::Min => "min",
            Self::Median => "median",
        }
    }

    /// The values reduced (sorted in place); `None` for none.
    pub fn of(self, v: &mut [f64]) -> Option<f64> {
        if v.is_empty() {
            return None;
        }
        v.sort_by(f64::total_cmp);
        let n = v.len();
        Some(match self {
            Self::Mean => v.iter().sum::<f64>() / n as f64,
            Self::Max => v[n - 1],
            Self::Min => v[0],
            Self::Median if n % 2 == 1 => v[n / 2],
            Self::Median => 0.5 * (v[n / 2 - 1] + v[n / 2]),
        })
    }
}

/// A theory a map can draw.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Theory {
    /// The closed-loop stability boundary (`analyze`): for each x, the y above which the
    /// ring with the flight's gains is stable.
    Stability,
    /// The bandwidth gate's delay limit (`analyze`'s gate): for each x, the one-way
    /// latency `HOP_PRODUCT / ω` (ω the law's fastest mode with the flight's gains) below
    /// which the gate lets the swarm fly; y must be `emulator.latency_ms`.
    Gate,
}

impl Theory {
    /// Whether the theory's good side is above its boundary (stability: gains above it
    /// converge) or below it (the gate: latencies below it fly).
    pub fn good_above(self) -> bool {
        match self {
            Self::Stability => true,
            Self::Gate => false,
        }
    }

    /// What its line is, for a legend.
    pub fn label(self) -> &'static str {
        match self {
            Self::Stability => "theory: closed-loop stability boundary (analyze)",
            Self::Gate => "theory: the bandwidth gate's delay limit (3.5 / fastest mode)",
        }
    }
}

/// The axis the gate's delay limit is drawn along.
pub const GATE_AXIS: &str = "emulator.latency_ms";

/// Checks `spec` against the sweep's axes before any flight.
///
/// # Errors
/// An x or y that is not an axis, or the same axis twice, named.
pub fn check_map(spec: &MapSpec, sweep: &Sweep) -> Result<(), String> {
    for (which, key) in [("x", &spec.x), ("y", &spec.y)] {
        if !sweep.axes.iter().any(|a| a.key == *key) {
            let axes: Vec<&str> = sweep.axes.iter().map(|a| a.key.as_str()).collect();
            return Err(format!(
                "map of {}: {which} = \"{key}\" is not an axis (axes: {})",
                spec.metric,
                axes.join(", ")
            ));
        }
    }
    if spec.theory == Some(Theory::Gate) && spec.y != GATE_AXIS {
        return Err(format!(
            "map of {}: theory = \"gate\" is drawn along y = \"{GATE_AXIS}\", not \"{}\"",
            spec.metric, spec.y
        ));
    }
    if spec.x == spec.y {
        return Err(format!(
            "map of {}: x and y are both {}",
            spec.metric, spec.x
        ));
    }
    Ok(())
}

/// One axis: its key and its values.
#[derive(Debug, Clone, PartialEq)]
pub struct Axis {
    /// The dotted key.
    pub key: String,
    /// The values, in order.
    pub values: Vec<f64>,
}

/// A sweep ready to fly: the base scenario's name, the fixed settings, the axes.
#[derive(Debug, Clone, PartialEq)]
pub struct Sweep {
    /// The base scenario as written in the spec.
    pub scenario: String,
    /// The sweep's seed.
    pub seed: u64,
    /// Flights per cell.
    pub replicates: u64,
    /// Fixed settings (dotted key → value), in the spec's order.
    pub set: Vec<(String, toml::Value)>,
    /// The axes, crossed in order (the last fastest).
    pub axes: Vec<Axis>,
    /// The maps to draw.
    pub maps: Vec<MapSpec>,
}

/// One flight of a sweep.
#[derive(Debug, Clone, PartialEq)]
pub struct Flight {
    /// Its place among all the sweep's flights: `cell × replicates + replicate`.
    pub index: u64,
    /// Its cell of the grid.
    pub cell: u64,
    /// Its replicate in the cell (from 0).
    pub replicate: u64,
    /// Its seed (the emulator's `seed`).
    pub seed: u64,
    /// Each axis's value, in the axes' order.
    pub values: Vec<f64>,
}

/// A spec that cannot be swept, named.
#[derive(Debug, Clone, PartialEq)]
pub struct SpecError(pub String);

impl fmt::Display for SpecError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for SpecError {}

fn err<T>(text: impl Into<String>) -> Result<T, SpecError> {
    Err(SpecError(text.into()))
}

impl Sweep {
    /// The sweep a spec's text describes, its axes' values worked out (draws drawn from
    /// the seed).
    ///
    /// # Errors
    /// The TOML does not parse, a field is unknown, an axis is given two ways or none,
    /// a value is not finite, a range or a distribution's parameters are out of their
    /// domain, the grid is empty or has more than [`MAX_FLIGHTS`] flights; each named.
    pub fn from_toml(text: &str) -> Result<Self, SpecError> {
        let file: SpecFile = toml::from_str(text).map_err(|e| SpecError(e.to_string()))?;
        if file.sweep.replicates == 0 {
            return err("sweep.replicates must be at least 1");
        }
        let mut axes = Vec::with_capacity(file.axis.len());
        for (n, a) in file.axis.iter().enumerate() {
            let values = axis_values(a, file.sweep.seed, n as u64)
                .map_err(|e| SpecError(format!("axis {} ({}): {e}", n + 1, a.key)))?;
            if axes.iter().any(|b: &Axis| b.key == a.key) {
                return err(format!(
                    "axis {} ({}): the key has an axis already",
                    n + 1,
                    a.key
                ));
            }
            axes.push(Axis {
                key: a.key.clone(),
                values,
            });
        }
        let set: Vec<(String, toml::Value)> = file.set.into_iter().collect();
        if let Some((key, _)) = set.iter().find(|(k, _)| axes.iter().any(|a| a.key == *k)) {
            return err(format!("{key} is both in [set] and an axis"));
        }
        let sweep = Self {
            scenario: file.sweep.scenario,
            seed: file.sweep.seed,
            replicates: file.sweep.replicates,
            set,
            axes,
            maps: file.map,
        };
        for m in &sweep.maps {
            check_map(m, &sweep).map_err(SpecError)?;
        }
        let flights = sweep.cells().checked_mul(sweep.replicates);
        if flights.is_none_or(|f| f > MAX_FLIGHTS) {
            return err(format!(
                "the sweep has more than {MAX_FLIGHTS} flights (cells × replicates)"
            ));
        }
        Ok(sweep)
    }

    /// How many cells the grid has (1 with no axis).
    pub fn cells(&self) -> u64 {
        self.axes
            .iter()
            .try_fold(1_u64, |n, a| n.checked_mul(a.values.len() as u64))
            .unwrap_or(u64::MAX)
    }

    /// How many flights: cells × replicates.
    pub fn flights(&self) -> u64 {
        self.cells().saturating_mul(self.replicates)
    }

    /// Flight `index` (`None` past the last).
    pub fn flight(&self, index: u64) -> Option<Flight> {
        if index >= self.flights() {
            return None;
        }
        let cell = index / self.replicates;
        let replicate = index % self.replicates;
        let mut rest = cell;
        let mut values = vec![0.0; self.axes.len()];
        for (slot, axis) in values.iter_mut().zip(&self.axes).rev() {
            let n = axis.values.len() as u64;
            *slot = axis.values[(rest % n) as usize];
            rest /= n;
        }
        Some(Flight {
            index,
            cell,
            replicate,
            seed: flight_seed(self.seed, cell, replicate),
            values,
        })
    }
}

/// A flight's seed: the sweep's seed, its cell and its replicate mixed (splitmix64), so
/// that a cell flown alone has the seed it has in the whole sweep. 63 bits, so that it
/// is a TOML integer as it is (`emulator.seed`).
pub fn flight_seed(seed: u64, cell: u64, replicate: u64) -> u64 {
    let mut x = seed;
    for part in [cell, replicate] {
        x = splitmix64(x ^ splitmix64(part.wrapping_add(0x9E37_79B9_7F4A_7C15)));
    }
    x >> 1
}

fn splitmix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// An axis's values: listed, a range, or drawn (from the sweep's seed and the axis's
/// place, so that adding replicates does not change them).
fn axis_values(a: &AxisSpec, seed: u64, n: u64) -> Result<Vec<f64>, String> {
    let ways = [
        a.values.is_some(),
        a.from.is_some() || a.to.is_some(),
        a.draw.is_some(),
    ];
    match ways.iter().filter(|w| **w).count() {
        0 => return Err("give `values`, `from`/`to`/`count`, or `draw`".to_owned()),
        1 => {}
        _ => return Err("give only one of `values`, `from`/`to`, `draw`".to_owned()),
    }
    let unused = |names: &[(&str, bool)]| -> Result<(), String> {
        match names.iter().find(|(_, given)| *given) {
            Some((name, _)) => Err(format!("`{name}` does not go with this kind of axis")),
            None => Ok(()),
        }
    };
    let values = if let Some(values) = &a.values {
        unused(&[
            ("count", a.count.is_some()),
            ("scale", a.scale.is_some()),
            ("low", a.low.is_some()),
            ("high", a.high.is_some()),
            ("mean", a.mean.is_some()),
            ("std", a.std.is_some()),
        ])?;
        values.clone()
    } else if a.draw.is_none() {
        unused(&[
            ("low", a.low.is_some()),
            ("high", a.high.is_some()),
            ("mean", a.mean.is_some()),
            ("std", a.std.is_some()),
        ])?;
        let (Some(from), Some(to)) = (a.from, a.to) else {
            return Err("a range needs both `from` and `to`".to_owned());
        };
        let count = a.count.ok_or("a range needs `count`")?;
        range(from, to, count, a.scale.as_deref().unwrap_or("linear"))?
    } else {
        unused(&[("scale", a.scale.is_some())])?;
        let count = a.count.ok_or("a draw needs `count`")?;
        draws(a, count, splitmix64(seed ^ splitmix64(n)))?
    };
    if values.is_empty() {
        return Err("no values".to_owned());
    }
    if let Some(v) = values.iter().find(|v| !v.is_finite()) {
        return Err(format!("{v} is not a finite number"));
    }
    Ok(values)
}

fn range(from: f64, to: f64, count: u64, scale: &str) -> Result<Vec<f64>, String> {
    if !(from.is_finite() && to.is_finite()) {
        return Err("`from` and `to` must be finite".to_owned());
    }
    if count == 0 || count > 1_000_000 {
        return Err(format!("`count` must be 1 to 1000000, got {count}"));
    }
    let at = |i: u64| {
        if count == 1 {
            0.0
        } else {
            i as f64 / (count - 1) as f64
        }
    };
    match scale {
        "linear" => Ok((0..count)
            .map(|i| match i {
                0 => from,
                i if i + 1 == count => to,
                i => from + (to - from) * at(i),
            })
            .collect()),
        "log" => {
            if !(from > 0.0 && to > 0.0) {
                return Err(format!(
                    "a log range needs `from` and `to` above zero, got {from} and {to}"
                ));
            }
            let (lf, lt) = (from.ln(), to.ln());
            Ok((0..count)
                .map(|i| match i {
                    0 => from,
                    i if i + 1 == count => to,
                    i => (lf + (lt - lf) * at(i)).exp(),
                })
                .collect())
        }
        other => Err(format!("`scale` is `linear` or `log`, got `{other}`")),
    }
}

fn draws(a: &AxisSpec, count: u64, seed: u64) -> Result<Vec<f64>, String> {
    if count == 0 || count > 1_000_000 {
        return Err(format!("`count` must be 1 to 1000000, got {count}"));
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let draw = a.draw.as_deref().unwrap_or_default();
    let bounds = || -> Result<(f64, f64), String> {
        match (a.low, a.high) {
            (Some(low), Some(high)) if low.is_finite() && high.is_finite() && low < high => {
                Ok((low, high))
            }
            (Some(low), Some(high)) => Err(format!(
                "`{draw}` needs finite `low` < `high`, got {low} and {high}"
            )),
            _ => Err(format!("`{draw}` needs `low` and `high`")),
        }
    };
    let only = |names: &[(&str, bool)]| -> Result<(), String> {
        match names.iter().find(|(_, given)| *given) {
            Some((name, _)) => Err(format!("`{name}` does not go with `draw = \"{draw}\"`")),
            None => Ok(()),
        }
    };
    match draw {
        "uniform" => {
            only(&[("mean", a.mean.is_some()), ("std", a.std.is_some())])?;
            let (low, high) = bounds()?;
            Ok((0..count).map(|_| rng.random_range(low..high)).collect())
        }
        "log-uniform" => {
            only(&[("mean", a.mean.is_some()), ("std", a.std.is_some())])?;
            let (low, high) = bounds()?;
            if low <= 0.0 {
                return Err(format!("`log-uniform` needs `low` above zero, got {low}"));
            }
            let (ll, lh) = (low.ln(), high.ln());
            Ok((0..count).map(|_| rng.random_range(ll..lh).exp()).collect())
        }
        "normal" => {
            only(&[("low", a.low.is_some()), ("high", a.high.is_some())])?;
            let (Some(mean), Some(std)) = (a.mean, a.std) else {
                return Err("`normal` needs `mean` and `std`".to_owned());
            };
            let bad =
                || format!("`normal` needs a finite `mean` and `std` ≥ 0, got {mean} and {std}");
            if !(mean.is_finite() && std.is_finite() && std >= 0.0) {
                return Err(bad());
            }
            let normal = Normal::new(mean, std).map_err(|_| bad())?;
            Ok((0..count).map(|_| normal.sample(&mut rng)).collect())
        }
        other => Err(format!(
            "`draw` is `uniform`, `log-uniform` or `normal`, got `{other}`"
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sweep(text: &str) -> Result<Sweep, String> {
        Sweep::from_toml(text).map_err(|e| e.0)
    }

    const GRID: &str = r#"
        [sweep]
        scenario = "paper-sim1"
        seed = 7
        replicates = 2
        [set]
        "swarm.duration_s" = 30.0
        [[axis]]
        key = "gains.k"
        values = [1.0, 2.0, 5.0]
        [[axis]]
        key = "gains.beta"
        from = 1.0
        to = 100.0
        count = 3
        scale = "log"
    "#;

    #[test]
    fn a_grid_crosses_its_axes_the_last_fastest_with_replicates_inside_a_cell() {
        let s = sweep(GRID).unwrap();
        let beta = &s.axes[1].values;
        assert_eq!((beta.len(), beta[0], beta[2]), (3, 1.0, 100.0));
        assert!((beta[1] - 10.0).abs() < 1e-12, "{beta:?}");
        assert_eq!(s.cells(), 9);
        assert_eq!(s.flights(), 18);
        // Flight 7: cell 3 (k = 2, beta = 1), replicate 1.
        let f = s.flight(7).unwrap();
        assert_eq!((f.cell, f.replicate), (3, 1));
        assert_eq!(f.values, vec![2.0, 1.0]);
        // Cell 8 is the last: k = 5, beta = 100.
        assert_eq!(s.flight(17).unwrap().values, vec![5.0, 100.0]);
        assert!(s.flight(18).is_none());
        assert_eq!(
            s.set,
            vec![("swarm.duration_s".to_owned(), toml::Value::Float(30.0))]
        );
    }

    #[test]
    fn each_flight_has_its_own_seed_and_a_cell_alone_keeps_it() {
        let s = sweep(GRID).unwrap();
        let seeds: std::collections::HashSet<u64> = (0..s.flights())
            .map(|i| s.flight(i).unwrap().seed)
            .collect();
        assert_eq!(seeds.len(), 18);
        assert!(seeds.iter().all(|s| *s <= i64::MAX as u64));
        assert_eq!(s.flight(7).unwrap().seed, flight_seed(7, 3, 1));
        // Another sweep seed moves every flight's seed.
        assert_ne!(flight_seed(8, 3, 1), flight_seed(7, 3, 1));
        // splitmix64's published first output for state 0 (Vigna's reference).
        assert_eq!(splitmix64(0), 0xE220_A839_7B1D_CDAF);
    }

    #[test]
    fn a_linear_range_ends_on_its_last_value_and_a_single_count_is_its_start() {
        assert_eq!(
            range(0.0, 1.0, 5, "linear").unwrap(),
            vec![0.0, 0.25, 0.5, 0.75, 1.0]
        );
        assert_eq!(range(0.1, 0.7, 7, "linear").unwrap()[6], 0.7);
        assert_eq!(range(3.0, 9.0, 1, "linear").unwrap(), vec![3.0]);
        assert!(
            range(0.0, 1.0, 3, "log")
                .unwrap_err()
                .contains("above zero")
        );
        assert!(
            range(0.0, 1.0, 3, "cubic")
                .unwrap_err()
                .contains("`linear` or `log`")
        );
    }

    #[test]
    fn draws_come_from_the_seed_within_their_bounds_and_do_not_move_with_replicates() {
        let text = |reps: u64| {
            format!(
                "[sweep]\nscenario = \"lossy\"\nseed = 3\nreplicates = {reps}\n\
                 [[axis]]\nkey = \"emulator.loss_pct\"\ndraw = \"uniform\"\nlow = 5.0\nhigh = 20.0\ncount = 50\n\
                 [[axis]]\nkey = \"vehicle.*.drag_per_s\"\ndraw = \"log-uniform\"\nlow = 0.01\nhigh = 1.0\ncount = 50\n"
            )
        };
        let a = sweep(&text(1)).unwrap();
        let b = sweep(&text(4)).unwrap();
        assert_eq!(a.axes, b.axes);
        assert!(a.axes[0].values.iter().all(|v| (5.0..20.0).contains(v)));
        assert!(a.axes[1].values.iter().all(|v| (0.01..1.0).contains(v)));
        // Two axes with the same distribution draw different values.
        assert_ne!(a.axes[0].values[0] / 20.0, a.axes[1].values[0]);
        // The mean of 50 uniform draws on [5, 20) is within 4 standard errors of 12.5
        // (sd 15 / sqrt(12) = 4.33, standard error 0.61).
        let mean = a.axes[0].values.iter().sum::<f64>() / 50.0;
        assert!((mean - 12.5).abs() < 2.5, "{mean}");
    }

    #[test]
    fn a_malformed_axis_is_refused_by_its_place_and_key() {
        let base = "[sweep]\nscenario = \"paper-sim1\"\n[[axis]]\nkey = \"gains.k\"\n";
        let cases = [
            (
                "",
                "axis 1 (gains.k): give `values`, `from`/`to`/`count`, or `draw`",
            ),
            ("values = [1.0]\nfrom = 0.0\nto = 1.0\n", "give only one of"),
            ("from = 0.0\nto = 1.0\n", "a range needs `count`"),
            (
                "values = [1.0]\ncount = 3\n",
                "`count` does not go with this kind of axis",
            ),
            ("values = []\n", "no values"),
            ("values = [nan]\n", "NaN is not a finite number"),
            (
                "draw = \"cauchy\"\ncount = 3\n",
                "`draw` is `uniform`, `log-uniform` or `normal`, got `cauchy`",
            ),
            (
                "draw = \"uniform\"\nlow = 2.0\nhigh = 1.0\ncount = 3\n",
                "finite `low` < `high`",
            ),
            (
                "draw = \"normal\"\nmean = 1.0\nstd = -1.0\ncount = 3\n",
                "`std` ≥ 0",
            ),
            (
                "draw = \"normal\"\nmean = 1.0\nstd = 1.0\nlow = 0.0\ncount = 3\n",
                "`low` does not go with `draw = \"normal\"`",
            ),
            ("values = [1.0]\nkee = 3\n", "unknown field `kee`"),
        ];
        for (extra, expected) in cases {
            let got = sweep(&format!("{base}{extra}")).unwrap_err();
            assert!(got.contains(expected), "{extra:?}: {got}");
        }
        let twice = format!("{base}values = [1.0]\n[[axis]]\nkey = \"gains.k\"\nvalues = [2.0]\n");
        assert!(
            sweep(&twice)
                .unwrap_err()
                .contains("axis 2 (gains.k): the key has an axis already")
        );
        let both = format!("{base}values = [1.0]\n[set]\n\"gains.k\" = 2.0\n");
        assert!(
            sweep(&both)
                .unwrap_err()
                .contains("gains.k is both in [set] and an axis")
        );
        let none = "[sweep]\nscenario = \"paper-sim1\"\nreplicates = 0\n";
        assert!(
            sweep(none)
                .unwrap_err()
                .contains("replicates must be at least 1")
        );
        let huge = "[sweep]\nscenario = \"x\"\nreplicates = 1000\n[[axis]]\nkey = \"a\"\nfrom = 0.0\nto = 1.0\ncount = 100000\n";
        assert!(
            sweep(huge)
                .unwrap_err()
                .contains("more than 10000000 flights")
        );
    }

    #[test]
    fn no_axis_is_one_cell_of_replicates() {
        let s = sweep("[sweep]\nscenario = \"paper-sim1\"\nreplicates = 4\n").unwrap();
        assert_eq!((s.cells(), s.flights()), (1, 4));
        assert_eq!(s.flight(3).unwrap().values, Vec::<f64>::new());
    }
}
