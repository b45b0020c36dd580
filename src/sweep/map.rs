//! A metric of a sweep over two of its axes (`[[map]]` in the spec): the flights of each
//! (x, y) cell reduced to one number (over replicates and the other axes), the cells that
//! did worst, and, where the project has a theory of it, the theory's boundary in the
//! same plane: `theory = "stability"` is the closed-loop stability boundary `analyze`
//! computes (the eigenvalues of the double-integrator ring with the flight's `k`, `α`,
//! `β` and `time_scale`), found along y for each x; `theory = "gate"` is the bandwidth
//! gate's delay limit along `emulator.latency_ms` (good below it). Pure.
//!
//! ```toml
//! [[map]]
//! x = "gains.k"
//! y = "gains.beta"
//! metric = "exit_code"     # any number of the row: a summary field by its column name
//!                          # (`formation_error_m`, `timing.late_ticks`), `exit_code`, `wall_s`
//! reduce = "max"           # mean (default), max, min, median
//! theory = "stability"     # optional: "stability", or "gate" (y = "emulator.latency_ms")
//! good_at_most = 0.0       # a cell is good when its number is at most this (default 0)
//! require_exit_0 = false   # and, when true, every flight of it exited 0
//! ```

use super::keys;
use super::rows::{Cell, FlightRow, flatten};
use super::spec::{MapSpec, Sweep, check_map};
pub use super::spec::{Reduce, Theory};
use crate::config::Config;
use crate::consensus::{CouplingGains, HOP_PRODUCT, RingDigraph, analyze};

/// A map's cells: `values[i][j]` for `xs[i]`, `ys[j]` (`None`: no flight had the metric).
#[derive(Debug, Clone, PartialEq)]
pub struct Grid {
    /// The x axis's values, in the spec's order.
    pub xs: Vec<f64>,
    /// The y axis's values, in the spec's order.
    pub ys: Vec<f64>,
    /// The reduced metric per cell.
    pub values: Vec<Vec<Option<f64>>>,
    /// Per cell, whether every flight of it exited 0 (ran its duration out).
    pub exited_0: Vec<Vec<bool>>,
}

impl Grid {
    /// The least and the greatest y.
    fn y_range(&self) -> (f64, f64) {
        let lo = self.ys.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = self.ys.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        (lo, hi)
    }

    /// The indices of `ys` in ascending order of y.
    fn y_order(&self) -> Vec<usize> {
        let mut order: Vec<usize> = (0..self.ys.len()).collect();
        order.sort_by(|a, b| self.ys[*a].total_cmp(&self.ys[*b]));
        order
    }

    /// Whether cell (`i`, `j`) is good: it has the metric, at most `ok`, and, with
    /// `require_exit_0`, every flight of it exited 0.
    pub fn good(&self, i: usize, j: usize, ok: f64, require_exit_0: bool) -> bool {
        self.values[i][j].is_some_and(|v| v <= ok) && (!require_exit_0 || self.exited_0[i][j])
    }
}

/// A row's number under `metric`: `exit_code`, `wall_s`, or a summary column (a yes/no
/// as 1 or 0); `None` when the flight has none.
pub fn metric_of(row: &FlightRow, metric: &str) -> Option<f64> {
    match metric {
        "exit_code" => Some(f64::from(row.exit_code)),
        "wall_s" => Some(row.wall_s),
        name => match flatten(&row.summary).get(name)? {
            Cell::Float(v) => Some(*v),
            Cell::Int(i) => Some(*i as f64),
            Cell::Bool(b) => Some(f64::from(u8::from(*b))),
            Cell::Text(_) => None,
        },
    }
}

/// The map's cells from the sweep's rows.
///
/// # Errors
/// An x or y that is not an axis.
pub fn grid(spec: &MapSpec, sweep: &Sweep, rows: &[FlightRow]) -> Result<Grid, String> {
    check_map(spec, sweep)?;
    let place = |key: &str| sweep.axes.iter().position(|a| a.key == key).unwrap_or(0);
    let (xa, ya) = (place(&spec.x), place(&spec.y));
    let xs = sweep.axes[xa].values.clone();
    let ys = sweep.axes[ya].values.clone();
    let mut samples = vec![vec![Vec::new(); ys.len()]; xs.len()];
    let mut exited_0 = vec![vec![true; ys.len()]; xs.len()];
    for row in rows {
        let (Some(x), Some(y)) = (row.values.get(xa), row.values.get(ya)) else {
            continue;
        };
        let (Some(i), Some(j)) = (
            xs.iter().position(|v| v == x),
            ys.iter().position(|v| v == y),
        ) else {
            continue;
        };
        exited_0[i][j] &= row.exit_code == 0;
        if let Some(v) = metric_of(row, &spec.metric).filter(|v| v.is_finite()) {
            samples[i][j].push(v);
        }
    }
    let values = samples
        .into_iter()
        .map(|col| {
            col.into_iter()
                .map(|mut v| spec.reduce.of(&mut v))
                .collect()
        })
        .collect();
    Ok(Grid {
        xs,
        ys,
        values,
        exited_0,
    })
}

/// The `n` cells with the largest values: (x, y, value), largest first.
pub fn worst(grid: &Grid, n: usize) -> Vec<(f64, f64, f64)> {
    let mut all: Vec<(f64, f64, f64)> = grid
        .values
        .iter()
        .enumerate()
        .flat_map(|(i, col)| {
            col.iter()
                .enumerate()
                .filter_map(move |(j, v)| v.map(|v| (grid.xs[i], grid.ys[j], v)))
        })
        .collect();
    all.sort_by(|a, b| b.2.total_cmp(&a.2));
    all.truncate(n);
    all
}

/// The config of the flight with `x` and `y` set (the other axes at their first value).
///
/// # Errors
/// A file that does not parse as a config.
fn config_at(
    base: &toml::Table,
    sweep: &Sweep,
    spec: &MapSpec,
    x: f64,
    y: f64,
) -> Result<Config, String> {
    let mut doc = base.clone();
    for (key, value) in &sweep.set {
        keys::set(&mut doc, key, value)?;
    }
    for a in &sweep.axes {
        if let Some(v) = a.values.first() {
            keys::set(&mut doc, &a.key, &keys::number(*v))?;
        }
    }
    keys::set(&mut doc, &spec.x, &keys::number(x))?;
    keys::set(&mut doc, &spec.y, &keys::number(y))?;
    toml::Value::Table(doc)
        .try_into()
        .map_err(|e: toml::de::Error| e.to_string())
}

/// Whether the ring of the flight with `x` and `y` set (the other axes at their first
/// value) is stable, as `analyze` judges it.
///
/// # Errors
/// A file that does not parse as a config, or gains `analyze` refuses.
pub fn stable_at(
    base: &toml::Table,
    sweep: &Sweep,
    spec: &MapSpec,
    x: f64,
    y: f64,
) -> Result<bool, String> {
    let config = config_at(base, sweep, spec, x, y)?;
    let g = &config.gains;
    let c = g.time_scale;
    let ring = RingDigraph::for_agents(config.vehicle.len(), g.k).map_err(|e| e.to_string())?;
    let gains = CouplingGains::new(g.alpha * c * c, g.beta * c).map_err(|e| e.to_string())?;
    Ok(analyze(&ring, Some(gains))
        .map_err(|e| e.to_string())?
        .stable)
}

/// For each x of `grid`, the y at which the theory's boundary lies within the map's y
/// range: the least y above which every y is stable, found on 400 steps across the
/// range (geometric when the axis's values are positive and span more than a decade)
/// and refined by bisection to 1e-9 of the range. `None` when every y is stable (the
/// boundary is below the map) or none is (above it).
///
/// # Errors
/// As [`stable_at`].
pub fn stability_boundary(
    base: &toml::Table,
    sweep: &Sweep,
    spec: &MapSpec,
    grid: &Grid,
) -> Result<Vec<Option<f64>>, String> {
    let (lo, hi) = grid.y_range();
    let geometric = lo > 0.0 && hi / lo > 10.0;
    let at = |t: f64| {
        if geometric {
            (lo.ln() + (hi.ln() - lo.ln()) * t).exp()
        } else {
            lo + (hi - lo) * t
        }
    };
    let steps = 400;
    let mut out = Vec::with_capacity(grid.xs.len());
    for &x in &grid.xs {
        let stable: Vec<bool> = (0..=steps)
            .map(|s| stable_at(base, sweep, spec, x, at(s as f64 / steps as f64)))
            .collect::<Result<_, _>>()?;
        // The first step from which every step up is stable.
        let first = (0..=steps).rev().take_while(|&s| stable[s]).last();
        let boundary = match first {
            None | Some(0) => None,
            Some(s) => {
                let (mut a, mut b) = ((s - 1) as f64 / steps as f64, s as f64 / steps as f64);
                while b - a > 1e-9 {
                    let m = 0.5 * (a + b);
                    if stable_at(base, sweep, spec, x, at(m))? {
                        b = m;
                    } else {
                        a = m;
                    }
                }
                Some(at(b))
            }
        };
        out.push(boundary);
    }
    Ok(out)
}

/// For each x of `grid`, the one-way latency (ms) the bandwidth gate allows the flight
/// at x: [`HOP_PRODUCT`] over the law's fastest mode with its gains (time scale
/// applied), or `None` when that lies outside the map's y range.
///
/// # Errors
/// A file that does not parse as a config, or gains the gate refuses.
pub fn gate_boundary(
    base: &toml::Table,
    sweep: &Sweep,
    spec: &MapSpec,
    grid: &Grid,
) -> Result<Vec<Option<f64>>, String> {
    let (lo, hi) = grid.y_range();
    let y0 = grid.ys.first().copied().unwrap_or(0.0);
    grid.xs
        .iter()
        .map(|&x| {
            let omega = config_at(base, sweep, spec, x, y0)?
                .bandwidth_check()?
                .fastest_mode_per_s;
            let limit_ms = 1e3 * HOP_PRODUCT / omega;
            Ok((lo..=hi).contains(&limit_ms).then_some(limit_ms))
        })
        .collect()
}

/// Where a flown boundary lies for each x, for a theory good below it: the greatest
/// index j of `ys` (in ascending order of y) up to which every cell from the bottom has
/// the metric at most `ok` (and, with `require_exit_0`, every flight exited 0); `None`
/// when the bottom cell is not good.
pub fn flown_boundary_below(grid: &Grid, ok: f64, require_exit_0: bool) -> Vec<Option<usize>> {
    let order = grid.y_order();
    (0..grid.xs.len())
        .map(|i| {
            let good = |j: usize| grid.good(i, j, ok, require_exit_0);
            let run = order.iter().take_while(|&&j| good(j)).count();
            (run > 0).then(|| run - 1)
        })
        .collect()
}

/// [`agrees`] for a theory good below its boundary: the flown boundary lies between the
/// last good rank `j` and the next; the theory's y agrees when it lies between the y one
/// rank below `j` and the y two ranks above it.
pub fn agrees_below(sorted_ys: &[f64], j: usize, y_theory: f64) -> bool {
    let below = j.checked_sub(1).map_or(f64::NEG_INFINITY, |b| sorted_ys[b]);
    let above = sorted_ys.get(j + 2).copied().unwrap_or(f64::INFINITY);
    below <= y_theory && y_theory <= above
}

/// Where a flown boundary lies for each x: the least index j of `ys` (in ascending
/// order of y) from which every cell up has the metric at most `ok` (for `exit_code`:
/// 0, no guard, fence or separation stop), and with `require_exit_0` every flight
/// exited 0; `None` when no such run reaches the top.
pub fn flown_boundary(grid: &Grid, ok: f64, require_exit_0: bool) -> Vec<Option<usize>> {
    let order = grid.y_order();
    (0..grid.xs.len())
        .map(|i| {
            let good = |j: usize| grid.good(i, j, ok, require_exit_0);
            let run = order.iter().rev().take_while(|&&j| good(j)).count();
            (run > 0).then(|| order.len() - run)
        })
        .collect()
}

/// Whether a theory boundary `y_theory` and the flown one (the rank `j` of the first good
/// cell in ascending y) agree within one grid cell: the theory's y lies between the
/// y two ranks below `j` and the y one rank above it.
pub fn agrees(sorted_ys: &[f64], j: usize, y_theory: f64) -> bool {
    let below = j.checked_sub(2).map_or(f64::NEG_INFINITY, |b| sorted_ys[b]);
    let above = sorted_ys.get(j + 1).copied().unwrap_or(f64::INFINITY);
    below <= y_theory && y_theory <= above
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(index: u64, values: Vec<f64>, exit_code: u8, fe: f64) -> FlightRow {
        FlightRow {
            index,
            cell: index,
            replicate: 0,
            seed: 0,
            values,
            exit_code,
            error: None,
            wall_s: 0.5,
            summary: serde_json::json!({"formation_error_m": fe, "timing": {"late_ticks": 2}}),
        }
    }

    fn sweep() -> Sweep {
        Sweep::from_toml(
            "[sweep]\nscenario = \"paper-sim1\"\nreplicates = 2\n\
             [[axis]]\nkey = \"gains.k\"\nvalues = [1.0, 5.0]\n\
             [[axis]]\nkey = \"gains.beta\"\nvalues = [0.5, 1.0, 2.0]\n",
        )
        .unwrap()
    }

    fn spec(metric: &str, reduce: Reduce) -> MapSpec {
        MapSpec {
            x: "gains.k".to_owned(),
            y: "gains.beta".to_owned(),
            metric: metric.to_owned(),
            reduce,
            theory: None,
            good_at_most: 0.0,
            require_exit_0: false,
        }
    }

    #[test]
    fn a_cell_reduces_its_replicates_and_the_worst_cells_come_first() {
        let s = sweep();
        let rows: Vec<FlightRow> = (0..s.flights())
            .map(|i| {
                let f = s.flight(i).unwrap();
                let fe = f.values[0] * 10.0 + f.values[1] + f.replicate as f64;
                let code = u8::from(f.values[1] < 1.0) * 4;
                row(i, f.values, code, fe)
            })
            .collect();
        let g = grid(&spec("formation_error_m", Reduce::Mean), &s, &rows).unwrap();
        // k = 5, beta = 2: 50 + 2 + (0 + 1) / 2.
        assert_eq!(g.values[1][2], Some(52.5));
        assert_eq!(g.values[0][0], Some(11.0));
        let g = grid(&spec("formation_error_m", Reduce::Max), &s, &rows).unwrap();
        assert_eq!(g.values[0][0], Some(11.5));
        assert_eq!(worst(&g, 2), vec![(5.0, 2.0, 53.0), (5.0, 1.0, 52.0)]);
        let g = grid(&spec("timing.late_ticks", Reduce::Median), &s, &rows).unwrap();
        assert_eq!(g.values[1][1], Some(2.0));
        let codes = grid(&spec("exit_code", Reduce::Max), &s, &rows).unwrap();
        assert_eq!(codes.values[0], vec![Some(4.0), Some(0.0), Some(0.0)]);
        // beta = 1 is the first rank from which every cell up flew to its end.
        assert_eq!(flown_boundary(&codes, 0.0, false), vec![Some(1), Some(1)]);
        // Formation error at most 60 everywhere; with exit 0 required, beta = 0.5 (exit
        // 4 in both replicates) is not good, whatever its error.
        let fe = grid(&spec("formation_error_m", Reduce::Max), &s, &rows).unwrap();
        assert_eq!(fe.exited_0[0], vec![false, true, true]);
        assert_eq!(flown_boundary(&fe, 60.0, false), vec![Some(0), Some(0)]);
        assert_eq!(flown_boundary(&fe, 60.0, true), vec![Some(1), Some(1)]);
        let none = grid(&spec("no_such", Reduce::Mean), &s, &rows).unwrap();
        assert_eq!(none.values[0][0], None);
    }

    #[test]
    fn a_map_of_an_axis_the_sweep_does_not_have_is_refused_by_name() {
        let mut m = spec("exit_code", Reduce::Max);
        m.y = "gains.alpha".to_owned();
        let e = check_map(&m, &sweep()).unwrap_err();
        assert_eq!(
            e,
            "map of exit_code: y = \"gains.alpha\" is not an axis (axes: gains.k, gains.beta)"
        );
    }

    #[test]
    fn agreement_allows_one_cell_either_side_of_the_flown_boundary() {
        let ys = [0.5, 1.0, 2.0, 4.0];
        // Flown: first good cell at rank 2 (y = 2); the theory between y = 0.5 and y = 4.
        assert!(agrees(&ys, 2, 1.5));
        assert!(agrees(&ys, 2, 0.5));
        assert!(agrees(&ys, 2, 4.0));
        assert!(!agrees(&ys, 3, 0.9));
        assert!(!agrees(&ys, 1, 2.5));
    }

    #[test]
    fn the_gate_limit_of_paper_sim1_is_its_hop_product_over_the_fastest_mode() {
        // paper-sim1: m = 3, k = 5, alpha = 1, beta = 5. The fastest eigenvalue of L is
        // the root 2 + k = 7 of mu^2 - (2 + k) mu + (1 - 1) = 0 (l = 0); the fastest mode
        // the root of s^2 + 35 s + 7: (35 + sqrt(1197)) / 2 = 34.799 1/s. At time scale c
        // every mode scales by c, so the limit 3.5 / omega by 1 / c.
        let s = Sweep::from_toml(
            "[sweep]\nscenario = \"paper-sim1\"\n\
             [[axis]]\nkey = \"gains.time_scale\"\nvalues = [1.0, 0.5, 0.25]\n\
             [[axis]]\nkey = \"emulator.latency_ms\"\nvalues = [0.0, 100.0, 300.0]\n",
        )
        .unwrap();
        let base: toml::Table =
            toml::from_str(include_str!("../../config/paper-sim1.toml")).unwrap();
        let m = MapSpec {
            x: "gains.time_scale".into(),
            y: "emulator.latency_ms".into(),
            metric: "exit_code".into(),
            reduce: Reduce::Max,
            theory: Some(Theory::Gate),
            good_at_most: 0.0,
            require_exit_0: false,
        };
        let g = Grid {
            xs: vec![1.0, 0.5, 0.25],
            ys: vec![0.0, 100.0, 300.0],
            values: vec![vec![None; 3]; 3],
            exited_0: vec![vec![true; 3]; 3],
        };
        let omega = (35.0 + 1197f64.sqrt()) / 2.0;
        let b = gate_boundary(&base, &s, &m, &g).unwrap();
        assert!((b[0].unwrap() - 3500.0 / omega).abs() < 1e-6, "{b:?}");
        assert!((b[1].unwrap() - 7000.0 / omega).abs() < 1e-6, "{b:?}");
        // 402 ms: above the map.
        assert_eq!(b[2], None);
        // The gate along any other y is refused by name.
        let wrong = MapSpec {
            y: "gains.time_scale".into(),
            x: "emulator.latency_ms".into(),
            ..m
        };
        assert_eq!(
            check_map(&wrong, &s).unwrap_err(),
            "map of exit_code: theory = \"gate\" is drawn along y = \"emulator.latency_ms\", not \"gains.time_scale\""
        );
    }

    #[test]
    fn below_a_boundary_the_run_from_the_bottom_counts_and_agreement_allows_one_cell() {
        // ys out of order: ranks 0..4 are 0, 50, 100, 150, 200.
        let g = Grid {
            xs: vec![0.0, 1.0, 2.0],
            ys: vec![100.0, 0.0, 200.0, 50.0, 150.0],
            values: vec![
                // good at 0, 50, 100; bad at 150; good again at 200: the run ends at 100.
                vec![Some(0.0), Some(0.0), Some(0.0), Some(0.0), Some(4.0)],
                // bad at the bottom: nowhere.
                vec![Some(0.0), Some(4.0), Some(0.0), Some(0.0), Some(0.0)],
                // good everywhere: the top.
                vec![Some(0.0); 5],
            ],
            exited_0: vec![vec![true; 5]; 3],
        };
        assert_eq!(
            flown_boundary_below(&g, 0.0, false),
            vec![Some(2), None, Some(4)]
        );
        // The same with exit 0 required, and the top-ranked cell of the last column
        // (y = 150) ended early: the run from the bottom ends at 100 there too.
        let mut h = g.clone();
        h.exited_0[2][4] = false;
        assert_eq!(
            flown_boundary_below(&h, 0.0, true),
            vec![Some(2), None, Some(2)]
        );
        let ys = [0.0, 50.0, 100.0, 150.0, 200.0];
        // Flown: last good at rank 2 (100); the failure starts by 150. Within one cell:
        // from 50 to 200.
        assert!(agrees_below(&ys, 2, 50.0));
        assert!(agrees_below(&ys, 2, 200.0));
        assert!(!agrees_below(&ys, 2, 49.0));
        assert!(!agrees_below(&ys, 2, 201.0));
    }

    #[test]
    fn the_stability_boundary_of_paper_sim1_lies_where_the_closed_loop_crosses_zero() {
        let s = sweep();
        let base: toml::Table =
            toml::from_str(include_str!("../../config/paper-sim1.toml")).unwrap();
        let mut m = spec("exit_code", Reduce::Max);
        m.theory = Some(Theory::Stability);
        let g = Grid {
            xs: vec![1.0, 5.0],
            ys: vec![0.05, 3.0],
            values: vec![vec![None; 2]; 2],
            exited_0: vec![vec![true; 2]; 2],
        };
        let b = stability_boundary(&base, &s, &m, &g).unwrap();
        for (x, y) in g.xs.iter().zip(&b) {
            let y = y.expect("a boundary inside the range");
            // Just above it stable, just below not, as analyze judges.
            assert!(stable_at(&base, &s, &m, *x, y * (1.0 + 1e-6)).unwrap());
            assert!(!stable_at(&base, &s, &m, *x, y * (1.0 - 1e-6)).unwrap());
        }
    }
}
