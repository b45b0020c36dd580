//! One flight of a sweep: the base file with the flight's settings, flown in lockstep to
//! the end of its duration (no landing), with no run directory; its summary, exit code
//! and wall time.

use std::time::{Duration, Instant};

use ringswarm_wire::time::SimTime;

use super::keys;
use super::spec::{Flight, Sweep};
use crate::config::{Config, Stability};
use crate::driver::lockstep::Lockstep;
use crate::record::metrics::{RunTracker, Summary};
use crate::swarm::{Swarm, SwarmPhase};

/// The longest a sweep flight may run past its duration before it is cut (simulated).
const OVERRUN: Duration = Duration::from_secs(120);

/// What a flight came to.
#[derive(Debug, Clone)]
pub struct Flown {
    /// Its summary, as `summary.json` has it.
    pub summary: Summary,
    /// The exit code `demo` would give it (0, or 3 to 6: `ringswarm demo --help`).
    pub exit_code: u8,
    /// Wall-clock seconds it took.
    pub wall_s: f64,
}

/// The coordinator file of a flight: `base` with the sweep's `[set]`, the flight's axis
/// values and, unless the sweep sets it, its seed as `emulator.seed`; as TOML, and as
/// the config it makes. Gains the analysis calls unstable are flown (a sweep maps where
/// the swarm stops converging): every other check holds.
///
/// # Errors
/// A key that cannot be set, or a file the config refuses (unknown field, wrong type,
/// a value out of its range), named with the flight's cell and settings.
pub fn config_of(
    base: &toml::Table,
    sweep: &Sweep,
    flight: &Flight,
) -> Result<(toml::Table, Config), String> {
    let mut doc = base.clone();
    for (key, value) in &sweep.set {
        keys::set(&mut doc, key, value).map_err(|e| format!("[set] {e}"))?;
    }
    let seeded = sweep.set.iter().any(|(k, _)| k == "emulator.seed")
        || sweep.axes.iter().any(|a| a.key == "emulator.seed");
    if !seeded {
        let seed = toml::Value::Integer(i64::try_from(flight.seed).unwrap_or(i64::MAX));
        keys::set(&mut doc, "emulator.seed", &seed)?;
    }
    for (axis, v) in sweep.axes.iter().zip(&flight.values) {
        keys::set(&mut doc, &axis.key, &keys::number(*v))?;
    }
    let config: Config = toml::Value::Table(doc.clone())
        .try_into()
        .map_err(|e: toml::de::Error| settings_error(sweep, flight, &e.to_string()))?;
    config
        .validate_with(Stability::Unchecked)
        .map_err(|e| settings_error(sweep, flight, &e.to_string()))?;
    Ok((doc, config))
}

fn settings_error(sweep: &Sweep, flight: &Flight, e: &str) -> String {
    let values: Vec<String> = sweep
        .axes
        .iter()
        .zip(&flight.values)
        .map(|(a, v)| format!("{} = {v}", a.key))
        .collect();
    if values.is_empty() {
        format!("cell {}: {}", flight.cell, e.trim_end())
    } else {
        format!(
            "cell {} ({}): {}",
            flight.cell,
            values.join(", "),
            e.trim_end()
        )
    }
}

/// Flies `config` in lockstep until its duration is over (or the swarm gives up, or the
/// guard, the fence or the separation ends it), and sums it up.
///
/// # Errors
/// The config cannot be flown (the lockstep driver refuses it), named.
pub fn fly(config: &Config) -> Result<Flown, String> {
    let wall = Instant::now();
    let mut run = Lockstep::from_config_with(config, Stability::Unchecked)?;
    let limit = SimTime::ZERO
        + run
            .swarm()
            .setup()
            .duration
            .unwrap_or(Duration::from_secs(60))
        + run.swarm().setup().handshake_timeout
        + OVERRUN;
    let mut tracker = RunTracker::new(run.swarm().vehicle_count());
    let mut last_tick = u64::MAX;
    let mut truth = Vec::with_capacity(run.vehicles().len());
    let mut true_min_m = f64::INFINITY;
    let mut observe = |run: &Lockstep| {
        let swarm = run.swarm();
        if swarm.control_ticks() != last_tick {
            last_tick = swarm.control_ticks();
            tracker.observe(swarm, run.now());
            if !matches!(swarm.phase(), SwarmPhase::Landing(_)) {
                truth.clear();
                truth.extend(run.vehicles().iter().map(|v| v.status().pos_world_ned_m));
                true_min_m =
                    true_min_m.min(crate::record::metrics::min_separation_in_place(&mut truth));
            }
        }
    };
    while run.now() < limit && flying(run.swarm()) {
        let next = run.now() + Duration::from_millis(100);
        run.run_until(next, &mut observe);
    }
    let wall_s = wall.elapsed().as_secs_f64();
    let mut summary = Summary::new(run.swarm(), &tracker, run.now(), wall_s);
    summary.true_min_separation_m = Some(true_min_m).filter(|m| m.is_finite());
    let exit_code = crate::error::exit_code(&summary);
    Ok(Flown {
        summary,
        exit_code,
        wall_s,
    })
}

/// Whether the flight is still on: handshaking, re-targeting, in consensus or holding
/// for a lost vehicle.
fn flying(swarm: &Swarm) -> bool {
    !swarm.is_finished()
        && matches!(
            swarm.phase(),
            SwarmPhase::Handshake
                | SwarmPhase::Retargeting(_)
                | SwarmPhase::Consensus(_)
                | SwarmPhase::Holding(_)
        )
}
