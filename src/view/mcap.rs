//! `flight.mcap`: a run directory as one MCAP file that Foxglove (and any MCAP reader)
//! opens as it is. JSON messages, each channel with a JSON schema:
//!
//! | topic | schema | what | when |
//! |---|---|---|---|
//! | `/swarm` | `ringswarm.SwarmState` | the swarm as the replay shows it: phase, formation and altitude errors, the mean and predicted velocities, the closest pair, and each vehicle's position and velocity (ENU, common frame), its place in the formation, link phase and telemetry age | every [`REPLAY_PERIOD_S`], or a multiple of it that keeps the file under [`MAX_VEHICLE_SAMPLES`] |
//! | `/setpoints` | `ringswarm.Setpoints` | what the coordinator sent each vehicle: the law's commanded acceleration (ENU, m/s²), the attitude setpoint's roll and pitch (body FRD to NED, rad) and the normalised thrust, from its CSV row | with `/swarm` |
//! | `/log` | `foxglove.Log` | every event of `events.csv` (Foxglove's Log panel): level 2 info, 3 warning; `name` the vehicle (`vehicle 3 on n1`) or `swarm` | as they happened |
//! | `/summary` | `ringswarm.Summary` | `summary.json` | once, at the flight's end |
//!
//! Message times are the flight's Unix time: the run's start (`epoch_us`) plus the flight
//! time. Written from the run directory's own files once the flight has ended (so the
//! control loop pays nothing); uncompressed, in chunks with message indexes.

use std::collections::BTreeMap;
use std::io::BufWriter;
use std::path::Path;

use mcap::records::MessageHeader;
use serde_json::json;

use super::replay::{REPLAY_PERIOD_S, Replay};

/// At most this many vehicle states in `/swarm` (about 200 bytes each): a large or long
/// flight is sampled more sparsely rather than writing gigabytes.
pub const MAX_VEHICLE_SAMPLES: f64 = 1_000_000.0;

/// The period of `/swarm` for `vehicles` over `duration_s`: [`REPLAY_PERIOD_S`], or the
/// smallest multiple of it that keeps `/swarm` within [`MAX_VEHICLE_SAMPLES`].
pub fn swarm_period_s(vehicles: usize, duration_s: f64) -> f64 {
    let states = MAX_VEHICLE_SAMPLES / (vehicles.max(1) as f64);
    let multiple = (duration_s / REPLAY_PERIOD_S / states).ceil().max(1.0);
    multiple * REPLAY_PERIOD_S
}

/// `ringswarm.SwarmState`'s JSON schema.
fn swarm_schema() -> serde_json::Value {
    let vec3 = json!({"type": ["array", "null"], "items": {"type": "number"}, "minItems": 3, "maxItems": 3});
    let vec2 = json!({"type": ["array", "null"], "items": {"type": "number"}, "minItems": 2, "maxItems": 2});
    json!({
        "title": "ringswarm.SwarmState",
        "description": "The swarm at one instant (ENU, common frame; metres, m/s)",
        "type": "object",
        "properties": {
            "t_s": {"type": "number", "description": "seconds since the flight started"},
            "phase": {"type": "string"},
            "formation_error_m": {"type": ["number", "null"]},
            "altitude_error_m": {"type": ["number", "null"]},
            "altitude_target_m": {"type": "number"},
            "mean_velocity_enu_mps": vec2,
            "predicted_final_velocity": vec2,
            "velocity_error_mps": {"type": ["number", "null"]},
            "formation_centre_enu_m": vec2,
            "closest_pair": {"type": ["object", "null"], "properties": {
                "vehicles": {"type": "array", "items": {"type": "integer"}},
                "sysids": {"type": "array", "items": {"type": "integer"}},
                "distance_m": {"type": "number"}
            }},
            "vehicles": {"type": "array", "items": {"type": "object", "properties": {
                "sysid": {"type": "integer"},
                "network": {"type": ["string", "null"]},
                "position_enu_m": vec3,
                "velocity_enu_mps": vec3,
                "target_enu_m": vec2,
                "link_phase": {"type": "string"},
                "telemetry_age_ms": {"type": ["number", "null"]},
                "speed_mps": {"type": ["number", "null"]}
            }}}
        }
    })
}

/// `ringswarm.Setpoints`' JSON schema.
fn setpoints_schema() -> serde_json::Value {
    let number = json!({"type": ["number", "null"]});
    json!({
        "title": "ringswarm.Setpoints",
        "description": "What the coordinator sent each vehicle at one instant (its last row at or before it)",
        "type": "object",
        "properties": {
            "t_s": {"type": "number", "description": "seconds since the flight started"},
            "vehicles": {"type": "array", "items": {"type": "object", "properties": {
                "sysid": {"type": "integer"},
                "network": {"type": ["string", "null"]},
                "t_s": {"type": "number", "description": "the row's own time"},
                "command_enu_mps2": {"type": "array", "items": number, "minItems": 3, "maxItems": 3,
                    "description": "the law's commanded acceleration, ENU (m/s²)"},
                "roll_setpoint_rad": number,
                "pitch_setpoint_rad": number,
                "thrust_norm": number
            }}}
        }
    })
}

/// The CSV columns `/setpoints` carries, in the order of [`SetpointRow::values`].
const SETPOINT_COLUMNS: [&str; 6] = [
    "cmd_ax_mps2",
    "cmd_ay_mps2",
    "cmd_az_mps2",
    "sp_roll_rad",
    "sp_pitch_rad",
    "sp_thrust_norm",
];

/// A vehicle's row as `/setpoints` shows it.
#[derive(Debug, Clone, Copy)]
struct SetpointRow {
    t_s: f64,
    /// [`SETPOINT_COLUMNS`]' values (NaN where the CSV has none).
    values: [f64; 6],
}

/// Each of a vehicle CSV's rows that is the last at or before `step · period_ms` ms, for
/// `step` in `0..=steps` (`None` before its first row).
fn setpoint_track(
    path: &Path,
    period_ms: u64,
    steps: u64,
) -> Result<Vec<Option<SetpointRow>>, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap_or("").split(',').collect();
    let mut columns = [0_usize; 6];
    for (slot, name) in columns.iter_mut().zip(SETPOINT_COLUMNS) {
        *slot = header
            .iter()
            .position(|h| *h == name)
            .ok_or_else(|| format!("{}: no column {name}", path.display()))?;
    }
    let parse = |line: &str, t_s: f64| {
        let fields: Vec<&str> = line.split(',').collect();
        let values = columns.map(|c| {
            fields
                .get(c)
                .and_then(|f| f.parse::<f64>().ok())
                .unwrap_or(f64::NAN)
        });
        SetpointRow { t_s, values }
    };
    let mut track = Vec::with_capacity(usize::try_from(steps + 1).unwrap_or(0));
    let mut last: Option<(&str, f64)> = None;
    for line in lines {
        let Some(t_s) = line.split(',').next().and_then(|t| t.parse::<f64>().ok()) else {
            continue;
        };
        // Every step this row is past closes with the row before it.
        while (track.len() as u64) <= steps
            && t_s > (track.len() as u64 * period_ms) as f64 / 1e3 + 1e-9
        {
            track.push(last.map(|(l, t)| parse(l, t)));
        }
        last = Some((line, t_s));
    }
    while (track.len() as u64) <= steps {
        track.push(last.map(|(l, t)| parse(l, t)));
    }
    Ok(track)
}

/// `/setpoints` at step `step`.
fn setpoints_message(
    t_s: f64,
    step: usize,
    vehicles: &[crate::record::RunVehicle],
    tracks: &[Vec<Option<SetpointRow>>],
) -> serde_json::Value {
    let rows: Vec<serde_json::Value> = vehicles
        .iter()
        .zip(tracks)
        .filter_map(|(v, track)| {
            let row = track.get(step).copied().flatten()?;
            let [ax, ay, az, roll, pitch, thrust] = row.values;
            Some(json!({
                "sysid": v.sysid,
                "network": v.network,
                "t_s": row.t_s,
                "command_enu_mps2": [ax, ay, az],
                "roll_setpoint_rad": roll,
                "pitch_setpoint_rad": pitch,
                "thrust_norm": thrust,
            }))
        })
        .collect();
    json!({"t_s": t_s, "vehicles": rows})
}

/// `foxglove.Log`'s JSON schema (Foxglove's well-known log message).
fn log_schema() -> serde_json::Value {
    json!({
        "title": "foxglove.Log",
        "description": "A log message",
        "type": "object",
        "properties": {
            "timestamp": {"type": "object", "properties": {
                "sec": {"type": "integer", "minimum": 0},
                "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999}
            }},
            "level": {"type": "integer", "description": "0 unknown, 1 debug, 2 info, 3 warning, 4 error, 5 fatal"},
            "message": {"type": "string"},
            "name": {"type": "string"},
            "file": {"type": "string"},
            "line": {"type": "integer", "minimum": 0}
        }
    })
}

/// `ringswarm.Summary`'s JSON schema: `summary.json`'s top-level fields.
fn summary_schema() -> serde_json::Value {
    json!({
        "title": "ringswarm.Summary",
        "description": "The flight's figures (docs/cli.md, summary.json)",
        "type": "object",
        "properties": {
            "vehicles": {"type": "integer"},
            "predicted_final_velocity": {"type": ["array", "null"]},
            "achieved_final_velocity": {"type": ["array", "null"]},
            "velocity_error_fraction": {"type": ["number", "null"]},
            "formation_error_m": {"type": ["number", "null"]},
            "min_separation_m": {"type": ["number", "null"]},
            "stop_reason": {"type": ["string", "null"]},
            "timing": {"type": "object"},
            "safety": {"type": ["object", "null"]}
        }
    })
}

/// Event `i` of `events.csv` as a `foxglove.Log` message at `t_ns`.
fn log_message(e: &super::state::EventView, i: usize, t_ns: u64) -> Vec<u8> {
    let name = match (e.sysid, &e.network) {
        (Some(id), Some(net)) => format!("vehicle {id} on {net}"),
        (Some(id), None) => format!("vehicle {id}"),
        (None, _) => "swarm".to_owned(),
    };
    let message = json!({
        "timestamp": {"sec": t_ns / 1_000_000_000, "nsec": t_ns % 1_000_000_000},
        "level": if e.warning { 3 } else { 2 },
        "message": e.text,
        "name": name,
        "file": "events.csv",
        "line": i + 2,
    });
    serde_json::to_vec(&message).unwrap_or_default()
}

fn mcap_err(e: mcap::McapError) -> String {
    e.to_string()
}

/// Writes `dir/flight.mcap` from the run directory `dir`, whose flight started at
/// `epoch_us` (Unix µs).
///
/// # Errors
/// The run directory cannot be read (named by [`Replay::load`]) or the file written.
pub fn write(dir: &Path, epoch_us: u64) -> Result<(), String> {
    let replay = Replay::load(dir)?;
    let summary: Option<serde_json::Value> = std::fs::read_to_string(dir.join("summary.json"))
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok());
    let path = dir.join("flight.mcap");
    let file =
        std::fs::File::create(&path).map_err(|e| format!("create {}: {e}", path.display()))?;
    let options = mcap::WriteOptions::new()
        .compression(None)
        .profile("")
        .library(concat!("ringswarm ", env!("CARGO_PKG_VERSION")));
    let mut out = options.create(BufWriter::new(file)).map_err(mcap_err)?;
    let mut channel = |name: &str, topic: &str, schema: serde_json::Value| {
        let bytes = serde_json::to_vec(&schema).unwrap_or_default();
        let id = out.add_schema(name, "jsonschema", &bytes)?;
        out.add_channel(id, topic, "json", &BTreeMap::new())
    };
    let swarm = channel("ringswarm.SwarmState", "/swarm", swarm_schema()).map_err(mcap_err)?;
    let setpoints =
        channel("ringswarm.Setpoints", "/setpoints", setpoints_schema()).map_err(mcap_err)?;
    let log = channel("foxglove.Log", "/log", log_schema()).map_err(mcap_err)?;
    let summary_channel =
        channel("ringswarm.Summary", "/summary", summary_schema()).map_err(mcap_err)?;
    let ns = |t_s: f64| epoch_us.saturating_mul(1000) + (t_s.max(0.0) * 1e9).round() as u64;
    // The swarm's states and the events, merged in time.
    let events = replay.events();
    let period_s = swarm_period_s(replay.setup().vehicles.len(), replay.duration_s());
    // Whole milliseconds, so that each time is the one a CSV row written at it parses to.
    let period_ms = (period_s * 1e3).round() as u64;
    let steps = (replay.duration_s() * 1e3 / period_ms as f64 + 1e-9).floor() as u64;
    let vehicles = &replay.setup().vehicles;
    let tracks = vehicles
        .iter()
        .map(|v| setpoint_track(&dir.join(&v.csv), period_ms, steps))
        .collect::<Result<Vec<_>, String>>()?;
    let mut next_event = 0;
    let mut sequence = 0_u32;
    let mut put = |out: &mut mcap::Writer<BufWriter<std::fs::File>>,
                   channel_id: u16,
                   t_ns: u64,
                   data: &[u8]|
     -> Result<(), String> {
        sequence = sequence.wrapping_add(1);
        out.write_to_known_channel(
            &MessageHeader {
                channel_id,
                sequence,
                log_time: t_ns,
                publish_time: t_ns,
            },
            data,
        )
        .map_err(mcap_err)
    };
    for step in 0..=steps {
        let t_s = (step * period_ms) as f64 / 1e3;
        while let Some(e) = events.get(next_event).filter(|e| e.t_s <= t_s) {
            put(
                &mut out,
                log,
                ns(e.t_s),
                &log_message(e, next_event, ns(e.t_s)),
            )?;
            next_event += 1;
        }
        let mut state = replay.state_at(t_s);
        state.events.clear();
        let data = serde_json::to_vec(&state).map_err(|e| e.to_string())?;
        put(&mut out, swarm, ns(t_s), &data)?;
        let sent = setpoints_message(t_s, step as usize, vehicles, &tracks);
        let data = serde_json::to_vec(&sent).map_err(|e| e.to_string())?;
        put(&mut out, setpoints, ns(t_s), &data)?;
    }
    for (i, e) in events.iter().enumerate().skip(next_event) {
        put(&mut out, log, ns(e.t_s), &log_message(e, i, ns(e.t_s)))?;
    }
    if let Some(summary) = summary {
        let end = ns(replay.duration_s());
        put(
            &mut out,
            summary_channel,
            end,
            &serde_json::to_vec(&summary).unwrap_or_default(),
        )?;
    }
    out.finish().map_err(mcap_err)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_schemas_name_foxgloves_log_fields() {
        let log = super::log_schema();
        for field in ["timestamp", "level", "message", "name", "file", "line"] {
            assert!(log["properties"][field].is_object(), "{field}");
        }
        assert_eq!(super::swarm_schema()["title"], "ringswarm.SwarmState");
    }

    #[test]
    fn a_large_flight_is_sampled_sparsely_and_a_small_one_at_the_replay_period() {
        // Six vehicles for 60 s: 1 200 states of 6 = 7 200 samples, under the cap.
        assert_eq!(super::swarm_period_s(6, 60.0), 0.05);
        // 1 000 vehicles for 300 s: 6 000 states at 0.05 s would be 6·10⁶ samples; 1 000
        // states fit, so one every 0.3 s.
        assert!((super::swarm_period_s(1000, 300.0) - 0.3).abs() < 1e-12);
        // Under the cap by a fifth: 20 000 states of 40.
        assert_eq!(super::swarm_period_s(40, 1000.0), 0.05);
        // Over it by a quarter: 20 000 states of 62.5 → every other one.
        assert!((super::swarm_period_s(63, 1000.0) - 0.1).abs() < 1e-12);
    }
}
