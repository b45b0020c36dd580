//! A finished run directory, loaded for replay: each vehicle's rows (sampled every
//! [`REPLAY_PERIOD_S`]), the events and the predicted velocity, and the swarm as a
//! [`ViewState`] at any time. Pure but for [`Replay::load`], which reads the files.

use std::path::Path;

use nalgebra::{Vector2, Vector3};

use super::state::{
    EventView, PairView, RECENT_EVENTS, VehicleView, ViewState, closest_pair, formation_targets,
};
use crate::record::RunSetup;
use crate::record::metrics::{altitude_error_m, formation_error_m};

/// The finest a replay is sampled: the live view's rate, and memory for a thousand
/// vehicles' long flight (a thousand vehicles × ten minutes at 20 Hz ≈ 12 M rows).
pub const REPLAY_PERIOD_S: f64 = 0.05;

/// Positions and velocities are kept in units of 10⁻⁴ m and m/s: the CSV's resolution,
/// exactly (a replayed value prints as it was written), in half the memory of an f64.
const FIXED_PER_UNIT: f64 = 1e4;

/// One recorded row, as much as a replay shows.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Row {
    t_s: f64,
    swarm_phase: u8,
    link_phase: u8,
    /// Units of 10⁻⁴ m.
    pos_enu: [i32; 3],
    /// Units of 10⁻⁴ m/s.
    vel_enu: [i32; 3],
    age_ms: f32,
}

impl Row {
    fn pos_enu_m(&self) -> Vector3<f64> {
        Vector3::from(self.pos_enu.map(|x| f64::from(x) / FIXED_PER_UNIT))
    }

    fn vel_enu_mps(&self) -> Vector3<f64> {
        Vector3::from(self.vel_enu.map(|x| f64::from(x) / FIXED_PER_UNIT))
    }
}

/// `x` in units of 10⁻⁴, if it fits (±214 km, ±214 km/s).
fn fixed(x: f64) -> Option<i32> {
    let scaled = (x * FIXED_PER_UNIT).round();
    (scaled.abs() <= f64::from(i32::MAX)).then_some(scaled as i32)
}

/// A run directory in memory.
#[derive(Debug, Clone)]
pub struct Replay {
    setup: RunSetup,
    /// Phase names, indexed by the rows' `swarm_phase` and `link_phase`.
    names: Vec<String>,
    tracks: Vec<Vec<Row>>,
    events: Vec<EventView>,
    predicted: Option<[f64; 2]>,
    consensus_started_s: Option<f64>,
    duration_s: f64,
}

impl Replay {
    /// Reads `dir` (a run directory of `fly` or `demo`).
    ///
    /// # Errors
    /// A missing or malformed file, named with its line.
    pub fn load(dir: &Path) -> Result<Self, String> {
        let setup_path = dir.join("setup.json");
        let text = std::fs::read_to_string(&setup_path).map_err(|e| {
            format!(
                "{}: {e} (a run directory written by `ringswarm fly` or `demo` has one)",
                setup_path.display()
            )
        })?;
        let setup: RunSetup =
            serde_json::from_str(&text).map_err(|e| format!("{}: {e}", setup_path.display()))?;
        let mut names = Vec::new();
        let mut tracks = Vec::with_capacity(setup.vehicles.len());
        for v in &setup.vehicles {
            let path = dir.join(&v.csv);
            let text =
                std::fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))?;
            let rows =
                parse_rows(&text, &mut names).map_err(|e| format!("{}: {e}", path.display()))?;
            tracks.push(rows);
        }
        let events_path = dir.join("events.csv");
        let events = match std::fs::read_to_string(&events_path) {
            Ok(text) => {
                parse_events(&text).map_err(|e| format!("{}: {e}", events_path.display()))?
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Vec::new(),
            Err(e) => return Err(format!("{}: {e}", events_path.display())),
        };
        // summary.json is written when the flight ends: an interrupted run has none.
        let (predicted, consensus_started_s) =
            match std::fs::read_to_string(dir.join("summary.json")) {
                Ok(text) => {
                    let summary: serde_json::Value = serde_json::from_str(&text)
                        .map_err(|e| format!("{}: {e}", dir.join("summary.json").display()))?;
                    let predicted = summary["predicted_final_velocity"]
                        .as_array()
                        .and_then(|a| Some([a.first()?.as_f64()?, a.get(1)?.as_f64()?]));
                    (predicted, summary["consensus_started_s"].as_f64())
                }
                Err(_) => (None, None),
            };
        let last_row = tracks.iter().filter_map(|t| t.last()).map(|r| r.t_s);
        let last_event = events.iter().map(|e| e.t_s);
        let duration_s = last_row.chain(last_event).fold(0.0, f64::max);
        Ok(Self {
            setup,
            names,
            tracks,
            events,
            predicted,
            consensus_started_s,
            duration_s,
        })
    }

    /// What the flight was asked.
    pub fn setup(&self) -> &RunSetup {
        &self.setup
    }

    /// The events, in time.
    pub fn events(&self) -> &[EventView] {
        &self.events
    }

    /// The time of the last row or event (s).
    pub fn duration_s(&self) -> f64 {
        self.duration_s
    }

    /// The swarm as recorded at `t_s` (each vehicle's last row at or before it).
    pub fn state_at(&self, t_s: f64) -> ViewState {
        let rows: Vec<Option<&Row>> = self
            .tracks
            .iter()
            .map(|track| {
                let after = track.partition_point(|r| r.t_s <= t_s);
                after.checked_sub(1).map(|i| &track[i])
            })
            .collect();
        let pos = Row::pos_enu_m;
        let vel = Row::vel_enu_mps;
        let xy: Vec<Option<Vector2<f64>>> = rows.iter().map(|r| r.map(|r| pos(r).xy())).collect();
        let offsets: Vec<Vector2<f64>> = self
            .setup
            .vehicles
            .iter()
            .map(|v| Vector2::from(v.offset_enu_m))
            .collect();
        let w: Vec<f64> = self.setup.vehicles.iter().map(|v| v.weight).collect();
        let targets = formation_targets(&xy, &offsets, &w);
        let newest = rows.iter().flatten().max_by(|a, b| a.t_s.total_cmp(&b.t_s));
        let phase = newest.map_or("handshake", |r| self.name(r.swarm_phase));
        let all: Option<Vec<&Row>> = rows.iter().copied().collect();
        let (mean, formation, altitude) = match &all {
            Some(all) if !all.is_empty() => {
                let n = all.len() as f64;
                let mean = all.iter().map(|r| vel(r).xy()).sum::<Vector2<f64>>() / n;
                let xy: Vec<Vector2<f64>> = all.iter().map(|r| pos(r).xy()).collect();
                let z: Vec<f64> = all.iter().map(|r| pos(r).z).collect();
                (
                    Some(mean),
                    Some(formation_error_m(&xy, &offsets)),
                    Some(altitude_error_m(&z, self.setup.altitude_m)),
                )
            }
            _ => (None, None, None),
        };
        let started = self.consensus_started_s.is_some_and(|s| s <= t_s);
        let predicted = self.predicted.filter(|_| started).map(Vector2::from);
        let vehicles = self
            .setup
            .vehicles
            .iter()
            .zip(&rows)
            .enumerate()
            .map(|(i, (v, row))| VehicleView {
                sysid: v.sysid,
                network: v.network.clone(),
                position_enu_m: row.map(|r| pos(r).into()),
                velocity_enu_mps: row.map(|r| vel(r).into()),
                target_enu_m: targets.as_ref().map(|(_, t)| t[i].into()),
                link_phase: row
                    .map_or("discovering", |r| self.name(r.link_phase))
                    .to_owned(),
                mode: None,
                armed: None,
                telemetry_age_ms: row.map(|r| f64::from(r.age_ms)).filter(|a| a.is_finite()),
                speed_mps: row.map(|r| vel(r).xy().norm()),
                saturated: None,
                constrained: None,
            })
            .collect();
        let positions: Vec<_> = rows.iter().map(|r| r.map(pos)).collect();
        let vertical_per_horizontal = self
            .setup
            .separation
            .map_or(1.0, |s| s.vertical_m / s.horizontal_m);
        let closest = closest_pair(&positions, vertical_per_horizontal).map(|(i, j, d)| PairView {
            vehicles: [i, j],
            sysids: [self.setup.vehicles[i].sysid, self.setup.vehicles[j].sysid],
            distance_m: d,
        });
        let happened = self.events.partition_point(|e| e.t_s <= t_s);
        ViewState {
            t_s,
            phase: phase.to_owned(),
            predicted_final_velocity: predicted.map(Into::into),
            mean_velocity_enu_mps: mean.map(Into::into),
            velocity_error_mps: mean.zip(predicted).map(|(m, p)| (m - p).norm()),
            formation_error_m: formation,
            altitude_error_m: altitude,
            altitude_target_m: self.setup.altitude_m,
            formation_centre_enu_m: targets.map(|(c, _)| c.into()),
            closest_pair: closest,
            active_pairs: Vec::new(),
            vehicles,
            events: self.events[happened.saturating_sub(RECENT_EVENTS)..happened].to_vec(),
            events_total: happened,
        }
    }

    fn name(&self, index: u8) -> &str {
        self.names
            .get(usize::from(index))
            .map_or("", String::as_str)
    }
}

/// The index of `name` in `names`, added if new.
fn intern(names: &mut Vec<String>, name: &str) -> Result<u8, String> {
    if let Some(i) = names.iter().position(|n| n == name) {
        return Ok(i as u8);
    }
    if names.len() > usize::from(u8::MAX) {
        return Err(format!("too many phase names (\"{name}\")"));
    }
    names.push(name.to_owned());
    Ok((names.len() - 1) as u8)
}

/// The rows of a vehicle CSV (`record::CSV_HEADER`): of the rows in each period
/// `((k − 1)·P, k·P]` ([`REPLAY_PERIOD_S`] = P), the last, so that the state at `k·P` is
/// the newest row at or before it, exactly as the CSV has it; the file's last row is kept.
fn parse_rows(text: &str, names: &mut Vec<String>) -> Result<Vec<Row>, String> {
    let mut lines = text.lines().enumerate();
    match lines.next() {
        Some((_, header)) if header == crate::record::CSV_HEADER => {}
        Some((_, header)) => {
            return Err(format!(
                "line 1: not the header of a vehicle CSV: \"{header}\""
            ));
        }
        None => return Err("empty file".into()),
    }
    let period = |t_s: f64| (t_s / REPLAY_PERIOD_S - 1e-9).ceil() as i64;
    let mut rows: Vec<Row> = Vec::new();
    // The last row seen, parsed only once the next one is in a later period.
    let mut pending: Option<(usize, &str, f64)> = None;
    for (i, line) in lines {
        let line_no = i + 1;
        let t = line.split(',').next().unwrap_or("");
        let t_s = t
            .parse::<f64>()
            .map_err(|_| format!("line {line_no}: column t_s is not a number: \"{t}\""))?;
        if !t_s.is_finite() {
            return Err(format!("line {line_no}: t_s is not finite"));
        }
        if let Some((before_no, before, before_s)) = pending {
            if t_s < before_s {
                return Err(format!("line {line_no}: t_s {t_s} goes back in time"));
            }
            if period(t_s) > period(before_s) {
                rows.push(parse_row(before_no, before, before_s, names)?);
            }
        }
        pending = Some((line_no, line, t_s));
    }
    if let Some((line_no, line, t_s)) = pending {
        rows.push(parse_row(line_no, line, t_s, names)?);
    }
    Ok(rows)
}

/// One row of a vehicle CSV, line `line_no`, whose time `t_s` is already read.
fn parse_row(line_no: usize, line: &str, t_s: f64, names: &mut Vec<String>) -> Result<Row, String> {
    let mut fields = line.split(',').skip(1);
    let mut next = |name: &str| {
        fields
            .next()
            .ok_or_else(|| format!("line {line_no}: no column {name}"))
    };
    let number = |name: &str, text: &str| -> Result<f64, String> {
        text.parse::<f64>()
            .map_err(|_| format!("line {line_no}: column {name} is not a number: \"{text}\""))
    };
    let swarm_phase = intern(names, next("swarm_phase")?)?;
    let link_phase = intern(names, next("link_phase")?)?;
    let mut values = [0i32; 6];
    for (value, name) in values
        .iter_mut()
        .zip(["x_m", "y_m", "z_m", "vx_mps", "vy_mps", "vz_mps"])
    {
        let x = number(name, next(name)?)?;
        *value = fixed(x)
            .ok_or_else(|| format!("line {line_no}: column {name} is out of range: {x}"))?;
    }
    // Attitude, command and setpoint columns are not replayed.
    let age = fields
        .nth(9)
        .ok_or_else(|| format!("line {line_no}: no column last_heard_age_ms"))?;
    let age_ms = number("last_heard_age_ms", age)? as f32;
    Ok(Row {
        t_s,
        swarm_phase,
        link_phase,
        pos_enu: [values[0], values[1], values[2]],
        vel_enu: [values[3], values[4], values[5]],
        age_ms,
    })
}

/// The events of `events.csv` (`t_s,system_id,network,level,event`, the event quoted).
fn parse_events(text: &str) -> Result<Vec<EventView>, String> {
    let mut events = Vec::new();
    for (i, line) in text.lines().enumerate().skip(1) {
        let line_no = i + 1;
        let mut fields = line.splitn(5, ',');
        let mut next = |name: &str| {
            fields
                .next()
                .ok_or_else(|| format!("line {line_no}: no column {name}"))
        };
        let t = next("t_s")?;
        let t_s = t
            .parse::<f64>()
            .map_err(|_| format!("line {line_no}: t_s is not a number: \"{t}\""))?;
        let id = next("system_id")?;
        let sysid = if id.is_empty() {
            None
        } else {
            Some(id.parse::<u8>().map_err(|_| {
                format!("line {line_no}: system_id is not a MAVLink system id: \"{id}\"")
            })?)
        };
        let network = Some(next("network")?)
            .filter(|n| !n.is_empty())
            .map(str::to_owned);
        let warning = match next("level")? {
            "warning" => true,
            "info" => false,
            other => {
                return Err(format!(
                    "line {line_no}: level is neither warning nor info: \"{other}\""
                ));
            }
        };
        let quoted = next("event")?;
        let text = quoted
            .strip_prefix('"')
            .and_then(|q| q.strip_suffix('"'))
            .ok_or_else(|| format!("line {line_no}: the event is not quoted"))?
            .replace("\"\"", "\"");
        events.push(EventView {
            t_s,
            sysid,
            network,
            warning,
            text,
        });
    }
    events.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
    Ok(events)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn events_parse_with_quotes_commas_and_an_empty_vehicle() {
        let text = "t_s,system_id,network,level,event\n\
                    1.5000,3,b,warning,\"link lost, \"\"no frame\"\" for 1.0 s\"\n\
                    0.2500,,,info,\"consensus started\"\n";
        let events = parse_events(text).expect("parses");
        assert_eq!(events.len(), 2);
        assert_eq!(events[0].t_s, 0.25);
        assert_eq!(events[0].sysid, None);
        assert_eq!(events[1].sysid, Some(3));
        assert_eq!(events[1].network.as_deref(), Some("b"));
        assert!(events[1].warning);
        assert_eq!(events[1].text, "link lost, \"no frame\" for 1.0 s");
        let bad = "h\n1.0,300,,info,\"x\"\n";
        assert_eq!(
            parse_events(bad).unwrap_err(),
            "line 2: system_id is not a MAVLink system id: \"300\""
        );
    }

    #[test]
    fn rows_are_sampled_every_period_and_bad_numbers_are_named() {
        let row = |t: f64, x: f64| {
            format!("{t:.4},consensus,flying,{x},2,3,0.5,0,0,0,0,0,0,0,0,0,0,0.5,12.5\n")
        };
        let mut text = format!("{}\n", crate::record::CSV_HEADER);
        for i in 0..30 {
            // 250 Hz rows: every 4 ms (written to 0.1 ms, as the recorder does).
            text += &row(f64::from(i) * 0.004, f64::from(i));
        }
        let mut names = Vec::new();
        let rows = parse_rows(&text, &mut names).expect("parses");
        // The last row of each 50 ms period ending at 0, 0.05, 0.1 and 0.15 s: 0, 0.048,
        // 0.1 and the file's last, 0.116.
        let times: Vec<f64> = rows.iter().map(|r| r.t_s).collect();
        assert_eq!(times, vec![0.0, 0.048, 0.1, 0.116]);
        assert_eq!(rows[1].pos_enu_m(), Vector3::new(12.0, 2.0, 3.0));
        assert_eq!(rows[1].vel_enu_mps(), Vector3::new(0.5, 0.0, 0.0));
        assert_eq!(rows[1].age_ms, 12.5);
        assert_eq!(names, vec!["consensus", "flying"]);
        let bad = format!(
            "{}\n0.0,consensus,flying,1,two,3,0,0,0,0,0,0,0,0,0,0,0,0,1\n",
            crate::record::CSV_HEADER
        );
        assert_eq!(
            parse_rows(&bad, &mut names).unwrap_err(),
            "line 2: column y_m is not a number: \"two\""
        );
    }
}
