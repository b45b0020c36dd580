//! `ringswarm sweep SPEC.toml --out DIR`: the spec's flights in lockstep on every core,
//! each a row of `DIR/results.parquet`; `--cell ID` flies one with its full run
//! directory; `--part K/N` flies a part of a split sweep; `ringswarm sweep merge DIR...
//! --out DIR` joins the parts. An I/O edge (files, terminal, threads); the sweep itself
//! is `crate::sweep`.
//!
//! ```text
//! DIR/manifest.json    the spec (its text), the version, the seed, the flights, the part
//! DIR/flights.jsonl    a line per flight as it ends: what a sweep interrupted resumes
//!                      from and what `merge` reads
//! DIR/results.parquet  a row per flight (docs/sweeps.md lists the columns)
//! ```

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, bail};
use rayon::prelude::*;

use crate::cli::SweepArgs;
use crate::sweep::{self, FlightRow, Part, Sweep};

/// The manifest's form, bumped when it or the rows change.
const MANIFEST_VERSION: u32 = 1;

/// `DIR/manifest.json`.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Manifest {
    /// The manifest's form.
    pub manifest_version: u32,
    /// The spec file's text, as read.
    pub spec: String,
    /// The base scenario's text, as read (a shipped one's or the file's).
    pub scenario: String,
    /// `ringswarm`'s version.
    pub version: String,
    /// The sweep's seed.
    pub seed: u64,
    /// Cells of the grid.
    pub cells: u64,
    /// Replicates per cell.
    pub replicates: u64,
    /// Every flight of the sweep (cells × replicates).
    pub flights: u64,
    /// The axes' keys, in order (the rows' `values`).
    pub axes: Vec<String>,
    /// This directory's part (`1/1`: the whole sweep).
    pub part: String,
}

/// Runs `sweep`, `sweep --cell` or `sweep merge`.
///
/// # Errors
/// A spec, scenario or key refused (named, before the first flight), a directory that
/// holds another sweep, a file that cannot be written.
pub fn run(args: &SweepArgs) -> anyhow::Result<()> {
    let Some(first) = args.args.first() else {
        bail!("give a sweep spec (ringswarm sweep SPEC.toml --out DIR) or `merge DIR...`");
    };
    if first.as_os_str() == "merge" {
        return merge(&args.args[1..], &args.out);
    }
    if args.args.len() > 1 {
        bail!(
            "one spec at a time (got {} paths); `merge` joins parts",
            args.args.len()
        );
    }
    let spec_text =
        std::fs::read_to_string(first).with_context(|| format!("read {}", first.display()))?;
    let sweep =
        Sweep::from_toml(&spec_text).map_err(|e| anyhow::anyhow!("{}: {e}", first.display()))?;
    let scenario_text = scenario_text(&sweep.scenario, first)?;
    let base: toml::Table = toml::from_str(&scenario_text)
        .map_err(|e| anyhow::anyhow!("scenario {}: {e}", sweep.scenario))?;
    if let Some(id) = &args.cell {
        return fly_cell(&sweep, &base, id, &args.out);
    }
    let part = match (&args.part, args.parts) {
        (Some(_), Some(_)) => bail!("give --part K/N or --parts N, not both"),
        (Some(p), None) => Part::parse(p).map_err(anyhow::Error::msg)?,
        (None, Some(n)) => {
            Part::from_scheduler(n, |v| std::env::var(v).ok()).map_err(anyhow::Error::msg)?
        }
        (None, None) => Part::WHOLE,
    };
    let manifest = Manifest {
        manifest_version: MANIFEST_VERSION,
        spec: spec_text,
        scenario: scenario_text,
        version: env!("CARGO_PKG_VERSION").to_owned(),
        seed: sweep.seed,
        cells: sweep.cells(),
        replicates: sweep.replicates,
        flights: sweep.flights(),
        axes: sweep.axes.iter().map(|a| a.key.clone()).collect(),
        part: part.to_string(),
    };
    fly_part(&sweep, &base, &manifest, part, &args.out, args.jobs)
}

/// The base scenario's text: a shipped one by name, or a file (relative to the spec's
/// directory when not absolute).
fn scenario_text(scenario: &str, spec: &Path) -> anyhow::Result<String> {
    if scenario.ends_with(".toml") {
        let path = spec.parent().unwrap_or(Path::new(".")).join(scenario);
        return std::fs::read_to_string(&path)
            .with_context(|| format!("read the scenario {}", path.display()));
    }
    match super::demo::SCENARIOS.iter().find(|s| s.name == scenario) {
        Some(s) => Ok(s.toml.to_owned()),
        None => {
            let known: Vec<&str> = super::demo::SCENARIOS.iter().map(|s| s.name).collect();
            bail!(
                "unknown scenario \"{scenario}\" (known: {}; or a path to a .toml file, relative to the spec)",
                known.join(", ")
            )
        }
    }
}

/// Flies part `part` of `sweep` into `out`, resuming what its journal holds.
fn fly_part(
    sweep: &Sweep,
    base: &toml::Table,
    manifest: &Manifest,
    part: Part,
    out: &Path,
    jobs: Option<usize>,
) -> anyhow::Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("create {}", out.display()))?;
    let manifest_path = out.join("manifest.json");
    if let Ok(text) = std::fs::read_to_string(&manifest_path) {
        let found: Manifest = serde_json::from_str(&text)
            .with_context(|| format!("{} is not a sweep's manifest", manifest_path.display()))?;
        if found.spec != manifest.spec
            || found.scenario != manifest.scenario
            || found.part != manifest.part
        {
            bail!(
                "{} holds another sweep (its spec, scenario or part differ): give another --out",
                out.display()
            );
        }
    }
    let text = serde_json::to_string_pretty(manifest)? + "\n";
    std::fs::write(&manifest_path, text)
        .with_context(|| format!("write {}", manifest_path.display()))?;
    let journal = out.join("flights.jsonl");
    sweep::rows::trim_cut_line(&journal)
        .with_context(|| format!("repair {}", journal.display()))?;
    let done = sweep::rows::read(&journal).map_err(anyhow::Error::msg)?;
    let todo: Vec<sweep::Flight> = (0..sweep.flights())
        .filter(|i| part.has(*i) && !done.contains_key(i))
        .filter_map(|i| sweep.flight(i))
        .collect();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(jobs.unwrap_or_else(crate::driver::cores).max(1))
        .build()
        .context("start the sweep's threads")?;
    // Every flight's settings checked before the first flies; the first refused (in
    // flight order) named, and how many were.
    let refused: Vec<String> = pool.install(|| {
        todo.par_iter()
            .filter_map(|f| sweep::config_of(base, sweep, f).err())
            .collect()
    });
    if let Some(first) = refused.first() {
        bail!(
            "{first}\n({} of the {} flights to fly are refused; none flew)",
            refused.len(),
            todo.len()
        );
    }
    let total = (0..sweep.flights()).filter(|i| part.has(*i)).count() as u64;
    eprintln!(
        "sweep: {} flights ({} cells × {} replicates){}; {} done before, {} to fly",
        sweep.flights(),
        sweep.cells(),
        sweep.replicates,
        if part == Part::WHOLE {
            String::new()
        } else {
            format!(", part {part}: {total}")
        },
        total - todo.len() as u64,
        todo.len()
    );
    let bar = progress(todo.len() as u64);
    let wall = Instant::now();
    let (tx, rx) = std::sync::mpsc::channel::<FlightRow>();
    let mut written: anyhow::Result<()> = Ok(());
    std::thread::scope(|scope| {
        scope.spawn(|| {
            pool.install(|| {
                todo.par_iter().for_each_with(tx, |tx, f| {
                    let _ = tx.send(fly_one(base, sweep, f));
                });
            });
        });
        for row in rx {
            if written.is_ok() {
                written = sweep::rows::append(&journal, &row)
                    .with_context(|| format!("append to {}", journal.display()));
            }
            bar.inc(1);
        }
    });
    bar.finish_and_clear();
    written?;
    let secs = wall.elapsed().as_secs_f64();
    let rows = sweep::rows::read(&journal).map_err(anyhow::Error::msg)?;
    let rows: Vec<FlightRow> = rows.into_values().filter(|r| part.has(r.index)).collect();
    let results = out.join("results.parquet");
    sweep::parquet::write(&results, &manifest.axes, &rows)
        .with_context(|| format!("write {}", results.display()))?;
    if part == Part::WHOLE {
        for m in &sweep.maps {
            draw_map(out, sweep, base, m, &rows)?;
        }
    }
    let failed = rows.iter().filter(|r| r.exit_code != 0).count();
    println!(
        "{} flights in {secs:.1} s ({:.1} flights/s); {} ended other than exit 0; {}",
        todo.len(),
        todo.len() as f64 / secs.max(1e-9),
        failed,
        results.display()
    );
    Ok(())
}

/// One `[[map]]`: `DIR/map-<metric>.png` and `.svg`, `DIR/map-<metric>.json` (the
/// cells, the theory's boundary, the flown one and whether they agree), and the worst
/// cells and the agreement printed.
fn draw_map(
    out: &Path,
    sweep: &Sweep,
    base: &toml::Table,
    m: &sweep::spec::MapSpec,
    rows: &[FlightRow],
) -> anyhow::Result<()> {
    use sweep::map;
    let grid = map::grid(m, sweep, rows).map_err(anyhow::Error::msg)?;
    let theory = match m.theory {
        Some(map::Theory::Stability) => {
            Some(map::stability_boundary(base, sweep, m, &grid).map_err(anyhow::Error::msg)?)
        }
        Some(map::Theory::Gate) => {
            Some(map::gate_boundary(base, sweep, m, &grid).map_err(anyhow::Error::msg)?)
        }
        None => None,
    };
    let above = m.theory.is_none_or(map::Theory::good_above);
    let name: String = m
        .metric
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '_' {
                c
            } else {
                '-'
            }
        })
        .collect();
    let stem = out.join(format!("map-{name}"));
    sweep::draw::heat_map(&stem, m, &grid, theory.as_deref()).map_err(anyhow::Error::msg)?;
    println!(
        "{} of {} over {} × {}: {}",
        m.reduce.name(),
        m.metric,
        m.x,
        m.y,
        stem.with_extension("png").display()
    );
    println!("| {} | {} | {} |", m.x, m.y, m.metric);
    println!("|---|---|---|");
    for (x, y, v) in map::worst(&grid, 5) {
        println!("| {x} | {y} | {v} |");
    }
    let mut sorted_ys = grid.ys.clone();
    sorted_ys.sort_by(f64::total_cmp);
    let flown = if above {
        map::flown_boundary(&grid, m.good_at_most, m.require_exit_0)
    } else {
        map::flown_boundary_below(&grid, m.good_at_most, m.require_exit_0)
    };
    let mut columns = Vec::new();
    for (i, x) in grid.xs.iter().enumerate() {
        let theory_y = theory.as_ref().and_then(|t| t[i]);
        let flown_y = flown[i].map(|j| sorted_ys[j]);
        let agrees = match (theory_y, flown[i]) {
            (Some(t), Some(j)) if above => Some(map::agrees(&sorted_ys, j, t)),
            (Some(t), Some(j)) => Some(map::agrees_below(&sorted_ys, j, t)),
            _ => None,
        };
        if theory.is_some() {
            println!(
                "{} = {x}: theory's boundary {}, cells with {} <= {}{} {} {} {}: {}",
                m.x,
                theory_y.map_or("outside the map".to_owned(), |t| format!("{t:.4}")),
                m.metric,
                m.good_at_most,
                if m.require_exit_0 { " and exit 0" } else { "" },
                if above { "from" } else { "up to" },
                flown_y.map_or("nowhere".to_owned(), |y| y.to_string()),
                if above { "up" } else { "from the bottom" },
                match agrees {
                    Some(true) => "agree within one cell",
                    Some(false) => "DISAGREE",
                    None => "-",
                }
            );
        }
        columns.push(serde_json::json!({
            "x": x,
            "values": grid.values[i],
            "theory_boundary": theory_y,
            "flown_boundary": flown_y,
            "good": if above { "above" } else { "below" },
            "agree_within_one_cell": agrees,
        }));
    }
    let json = serde_json::json!({
        "x": m.x, "y": m.y, "metric": m.metric, "reduce": m.reduce.name(),
        "good_at_most": m.good_at_most, "require_exit_0": m.require_exit_0,
        "ys": grid.ys, "columns": columns,
    });
    let path = stem.with_extension("json");
    std::fs::write(&path, serde_json::to_string_pretty(&json)? + "\n")
        .with_context(|| format!("write {}", path.display()))?;
    Ok(())
}

/// Flies one flight; a flight that cannot be flown is a row saying why.
fn fly_one(base: &toml::Table, sweep: &Sweep, f: &sweep::Flight) -> FlightRow {
    let start = Instant::now();
    let flown = sweep::config_of(base, sweep, f).and_then(|(_, config)| sweep::fly(&config));
    let (exit_code, error, wall_s, summary) = match flown {
        Ok(flown) => (
            flown.exit_code,
            None,
            flown.wall_s,
            serde_json::to_value(&flown.summary).unwrap_or(serde_json::Value::Null),
        ),
        Err(e) => (
            2,
            Some(e),
            start.elapsed().as_secs_f64(),
            serde_json::Value::Null,
        ),
    };
    FlightRow {
        index: f.index,
        cell: f.cell,
        replicate: f.replicate,
        seed: f.seed,
        values: f.values.clone(),
        exit_code,
        error,
        wall_s,
        summary,
    }
}

fn progress(len: u64) -> indicatif::ProgressBar {
    if !std::io::stderr().is_terminal() {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(len);
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{bar:30.cyan/blue} {pos}/{len} flights ({per_sec}, {eta} left)",
        )
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    bar
}

/// `--cell C` or `--cell C.R` (replicate R, from 0): that flight with its full run
/// directory in `out` (and its coordinator file as `out/config.toml`), as `demo` flies it.
fn fly_cell(sweep: &Sweep, base: &toml::Table, id: &str, out: &Path) -> anyhow::Result<()> {
    let bad = || {
        anyhow::anyhow!(
            "--cell wants C or C.R (cell C from 0, replicate R from 0), got `{id}`; the sweep has {} cells of {} replicates",
            sweep.cells(),
            sweep.replicates
        )
    };
    let (cell, replicate) = match id.split_once('.') {
        Some((c, r)) => (
            c.parse::<u64>().map_err(|_| bad())?,
            r.parse::<u64>().map_err(|_| bad())?,
        ),
        None => (id.parse::<u64>().map_err(|_| bad())?, 0),
    };
    if cell >= sweep.cells() || replicate >= sweep.replicates {
        return Err(bad());
    }
    let flight = sweep
        .flight(cell * sweep.replicates + replicate)
        .ok_or_else(bad)?;
    let (doc, _) = sweep::config_of(base, sweep, &flight).map_err(anyhow::Error::msg)?;
    std::fs::create_dir_all(out).with_context(|| format!("create {}", out.display()))?;
    let path = out.join("config.toml");
    std::fs::write(&path, toml::to_string(&doc)?)
        .with_context(|| format!("write {}", path.display()))?;
    let args = crate::cli::DemoArgs {
        scenario: path.to_string_lossy().into_owned(),
        saturation: None,
        list: false,
        out: Some(out.to_path_buf()),
        no_plots: false,
        realtime: false,
        live: crate::cli::LiveArgs::default(),
        unstable_gains: true,
    };
    super::demo::run(&args)
}

/// Joins the parts in `dirs` into `out`: one sweep (the same spec and scenario), every
/// part present once, every flight of each part flown; the rows by flight.
fn merge(dirs: &[PathBuf], out: &Path) -> anyhow::Result<()> {
    if dirs.is_empty() {
        bail!("sweep merge wants the parts' directories: ringswarm sweep merge DIR... --out DIR");
    }
    let mut first: Option<Manifest> = None;
    let mut seen: Vec<Part> = Vec::new();
    let mut rows: std::collections::BTreeMap<u64, FlightRow> = std::collections::BTreeMap::new();
    for dir in dirs {
        let path = dir.join("manifest.json");
        let text =
            std::fs::read_to_string(&path).with_context(|| format!("read {}", path.display()))?;
        let m: Manifest = serde_json::from_str(&text)
            .with_context(|| format!("{} is not a sweep's manifest", path.display()))?;
        let part = Part::parse(&m.part).map_err(anyhow::Error::msg)?;
        if let Some(f) = &first {
            if f.spec != m.spec || f.scenario != m.scenario || f.version != m.version {
                bail!(
                    "{} is a part of another sweep (its spec, scenario or version differ from {})",
                    dir.display(),
                    dirs[0].display()
                );
            }
            if Part::parse(&f.part).map_err(anyhow::Error::msg)?.n != part.n {
                bail!(
                    "{} is part {} but {} is part {}",
                    dir.display(),
                    m.part,
                    dirs[0].display(),
                    f.part
                );
            }
        }
        if seen.contains(&part) {
            bail!("part {} is given twice ({})", m.part, dir.display());
        }
        seen.push(part);
        let journal = sweep::rows::read(&dir.join("flights.jsonl")).map_err(anyhow::Error::msg)?;
        let expected = (0..m.flights).filter(|i| part.has(*i)).count();
        let got = journal.values().filter(|r| part.has(r.index)).count();
        if got != expected {
            bail!(
                "{} (part {}) has {got} of its {expected} flights: fly it again to finish it",
                dir.display(),
                m.part
            );
        }
        rows.extend(journal.into_iter().filter(|(i, _)| part.has(*i)));
        first.get_or_insert(m);
    }
    let Some(mut manifest) = first else {
        bail!("no part given");
    };
    let n = Part::parse(&manifest.part).map_err(anyhow::Error::msg)?.n;
    if seen.len() as u64 != n {
        let missing: Vec<String> = (1..=n)
            .filter(|k| !seen.iter().any(|p| p.k == *k))
            .map(|k| format!("{k}/{n}"))
            .collect();
        bail!("parts missing: {}", missing.join(", "));
    }
    manifest.part = Part::WHOLE.to_string();
    std::fs::create_dir_all(out).with_context(|| format!("create {}", out.display()))?;
    std::fs::write(
        out.join("manifest.json"),
        serde_json::to_string_pretty(&manifest)? + "\n",
    )?;
    let journal = out.join("flights.jsonl");
    let _ = std::fs::remove_file(&journal);
    for row in rows.values() {
        sweep::rows::append(&journal, row)?;
    }
    let rows: Vec<FlightRow> = rows.into_values().collect();
    let results = out.join("results.parquet");
    sweep::parquet::write(&results, &manifest.axes, &rows)
        .with_context(|| format!("write {}", results.display()))?;
    println!("{} parts, {} flights: {}", n, rows.len(), results.display());
    Ok(())
}
