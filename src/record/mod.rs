//! The run directory: everything a flight leaves behind.
//!
//! ```text
//! <dir>/traffic.tlog        every frame sent and received: 8-byte big-endian Unix time (µs)
//!                           + the raw MAVLink frame (what MAVProxy and QGC write)
//! <dir>/vehicle-<id>.csv    one row per control tick: state, attitude, command, setpoint
//! <dir>/events.csv          every event with its time: t_s, system_id and network (empty
//!                           for the swarm; network empty on own sockets), level (warning
//!                           or info), event (quoted text)
//! <dir>/summary.json        the flight's figures (see [`metrics::Summary`])
//! <dir>/flight.mcap         the flight for Foxglove: the swarm's states, the events and
//!                           the summary as JSON messages (`view::mcap`; written by the
//!                           commands once the flight has ended)
//! <dir>/setup.json          what the flight was asked (see [`RunSetup`]): each vehicle's
//!                           system id, network, CSV and place in the formation; what a
//!                           replay (`ringswarm view`) needs besides the CSVs
//! ```
//!
//! The files are written by a thread of their own (`sink.rs`): the control loop formats
//! rows into memory and never waits for the disk. A disk error never stops a flight: the
//! first one is kept, recording stops, and [`Recorder::finish`] reports it.

mod fixed;
pub mod growth;
pub mod metrics;
pub mod rows;
mod sink;
pub mod trace;

use std::io::{self, Write};
use std::path::{Path, PathBuf};

use ringswarm_wire::time::SimTime;

use crate::link::raw_frames;
use crate::swarm::Swarm;
use crate::swarm::VehicleIndex;
use metrics::{RunTracker, Summary};
use sink::Sinks;
use trace::Trace;

/// The files' places in [`Sinks`]: the tlog, the events, then one CSV per vehicle.
const TLOG: usize = 0;
const EVENTS: usize = 1;
const FIRST_CSV: usize = 2;

/// How often the in-memory trace (for the plots) samples the swarm.
pub const TRACE_PERIOD: std::time::Duration = std::time::Duration::from_millis(50);

/// The most samples (vehicles × instants) the trace keeps, 104 bytes each: 55 MB. At
/// [`TRACE_PERIOD`], 6 vehicles fly 73 min before it first thins out, 1000 vehicles 26 s.
pub const TRACE_SAMPLES: usize = 1 << 19;

/// The CSV header (frames: position and velocity ENU in the common frame; attitude and
/// setpoint as NED/FRD Euler angles; commands ENU after saturation).
pub const CSV_HEADER: &str = "t_s,swarm_phase,link_phase,x_m,y_m,z_m,vx_mps,vy_mps,vz_mps,\
roll_rad,pitch_rad,yaw_rad,cmd_ax_mps2,cmd_ay_mps2,cmd_az_mps2,sp_roll_rad,sp_pitch_rad,\
sp_thrust_norm,last_heard_age_ms";

/// `setup.json`: what the flight was asked, for a replay.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RunSetup {
    /// The vehicles in the config's order (the ring's order).
    pub vehicles: Vec<RunVehicle>,
    /// The ring gain k.
    pub k: f64,
    /// The altitude the swarm holds (m, up).
    pub altitude_m: f64,
    /// The control rate (Hz).
    pub control_rate_hz: f64,
    /// The separation the safety filter enforces, centre to centre (m; `null`: off).
    #[serde(default)]
    pub separation: Option<SeparationView>,
    /// The fence (`null`: none).
    #[serde(default)]
    pub fence: Option<FenceView>,
}

/// The enforced separation in `setup.json`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SeparationView {
    /// Horizontal (m).
    pub horizontal_m: f64,
    /// Vertical (m).
    pub vertical_m: f64,
}

/// The fence in `setup.json` (ENU, common frame): a circle or a polygon and the band.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FenceView {
    /// `circle` or `polygon`.
    pub kind: String,
    /// The circle's centre (m), or `null`.
    pub centre_enu_m: Option<[f64; 2]>,
    /// The circle's radius (m), or `null`.
    pub radius_m: Option<f64>,
    /// The polygon's vertices (m; empty for a circle).
    pub vertices_enu_m: Vec<[f64; 2]>,
    /// The altitude band (m, up).
    pub min_altitude_m: f64,
    /// The altitude band (m, up).
    pub max_altitude_m: f64,
    /// How close a stopping point may come (m).
    pub margin_m: f64,
}

impl FenceView {
    fn of(setup: &crate::swarm::FenceSetup) -> Self {
        use crate::safety::FenceShape;
        let f = &setup.fence;
        let (kind, centre, radius, vertices) = match &f.shape {
            FenceShape::Circle { centre_m, radius_m } => (
                "circle",
                Some([centre_m.x, centre_m.y]),
                Some(*radius_m),
                Vec::new(),
            ),
            FenceShape::Polygon { vertices_m } => (
                "polygon",
                None,
                None,
                vertices_m.iter().map(|v| [v.x, v.y]).collect(),
            ),
        };
        Self {
            kind: kind.to_owned(),
            centre_enu_m: centre,
            radius_m: radius,
            vertices_enu_m: vertices,
            min_altitude_m: f.min_altitude_m,
            max_altitude_m: f.max_altitude_m,
            margin_m: setup.margin_m,
        }
    }
}

/// One vehicle of [`RunSetup`].
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RunVehicle {
    /// MAVLink system id.
    pub sysid: u8,
    /// Its MAVLink network, `null` on a socket of its own.
    pub network: Option<String>,
    /// Its CSV file in the run directory.
    pub csv: String,
    /// Its offset dᵢ in the formation (m, ENU x/y).
    pub offset_enu_m: [f64; 2],
    /// Its component wᵢ of the ring's left null vector (its weight in the consensus value).
    pub weight: f64,
}

impl RunSetup {
    /// The swarm's.
    pub fn of(swarm: &Swarm) -> Self {
        let setup = swarm.setup();
        Self {
            vehicles: setup
                .links
                .iter()
                .zip(&setup.offsets_m)
                .enumerate()
                .map(|(i, (cfg, d))| RunVehicle {
                    sysid: cfg.system_id,
                    network: cfg.network.clone(),
                    csv: csv_name(cfg),
                    offset_enu_m: [d.x, d.y],
                    weight: setup.ring.w(i),
                })
                .collect(),
            k: setup.ring.k(),
            altitude_m: setup.altitude_m,
            control_rate_hz: 1.0 / setup.control_interval.as_secs_f64(),
            separation: setup.safety.map(|s| SeparationView {
                horizontal_m: s.separation.horizontal_m,
                vertical_m: s.separation.vertical_m,
            }),
            fence: setup.fence.as_ref().map(FenceView::of),
        }
    }
}

/// The CSV file of a vehicle.
fn csv_name(cfg: &crate::vehicle::LinkConfig) -> String {
    format!("vehicle-{}.csv", cfg.file_label())
}

/// Writes a run directory while the swarm flies.
#[derive(Debug)]
pub struct Recorder {
    dir: PathBuf,
    /// `None` once recording has stopped on an error.
    sinks: Option<Sinks>,
    vehicles: usize,
    events_written: usize,
    epoch_us: u64,
    tracker: RunTracker,
    trace: Trace,
    last_tick: u64,
    error: Option<io::Error>,
    mirrors: Vec<metrics::MirrorReport>,
    text: RowText,
}

/// Where a vehicle CSV's numbers become text (the files are the same either way).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RowText {
    /// On the control thread, as each row is sampled: the least CPU in all, for flights in
    /// real time, whose cores are shared with everything else on the machine (moved to
    /// the writer thread, a thousand vehicles' rows cost about a tenth more in all).
    Inline,
    /// On the run directory's writer thread: the control thread only copies numbers, for
    /// lockstep runs, which leave a core free.
    Writer,
}

impl Recorder {
    /// Creates `dir` (and its parents) and the files for the swarm's vehicles. Frames are
    /// stamped `epoch_us` (Unix µs) plus the swarm's time; rows become text as `text` says.
    ///
    /// # Errors
    /// The directory or a file cannot be created.
    pub fn create(dir: &Path, swarm: &Swarm, epoch_us: u64, text: RowText) -> io::Result<Self> {
        std::fs::create_dir_all(dir)?;
        // Chunks of about a second of rows (a CSV row is ~150 bytes; a thousand vehicles'
        // telemetry is ~6 MB/s of tlog).
        let mut files: Vec<(PathBuf, usize, Option<sink::Transcode>)> = vec![
            (dir.join("traffic.tlog"), 256 * 1024, None),
            // Events go to the disk as they happen: they are few, and they are what is
            // read after a flight that was killed.
            (dir.join("events.csv"), 1, None),
        ];
        let transcode = (text == RowText::Writer).then_some(rows::to_csv as sink::Transcode);
        for cfg in &swarm.setup().links {
            files.push((dir.join(csv_name(cfg)), 8192, transcode));
        }
        let setup = serde_json::to_string_pretty(&RunSetup::of(swarm)).map_err(io::Error::other)?;
        std::fs::write(dir.join("setup.json"), setup + "\n")?;
        let mut sinks = Sinks::create(files)?;
        writeln!(sinks.buffer(EVENTS), "t_s,system_id,network,level,event")?;
        let header = format!("{CSV_HEADER}\n");
        for i in 0..swarm.vehicle_count() {
            match text {
                RowText::Writer => rows::push_text(sinks.buffer(FIRST_CSV + i), &header),
                RowText::Inline => sinks
                    .buffer(FIRST_CSV + i)
                    .extend_from_slice(header.as_bytes()),
            }
        }
        Ok(Self {
            dir: dir.to_owned(),
            sinks: Some(sinks),
            vehicles: swarm.vehicle_count(),
            events_written: 0,
            epoch_us,
            tracker: RunTracker::new(swarm.vehicle_count()),
            trace: Trace::new(TRACE_PERIOD, TRACE_SAMPLES),
            last_tick: 0,
            error: None,
            mirrors: Vec::new(),
            text,
        })
    }

    /// The directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// When the flight started (Unix µs).
    pub fn epoch_us(&self) -> u64 {
        self.epoch_us
    }

    /// The tracker (for live status).
    pub fn tracker(&self) -> &RunTracker {
        &self.tracker
    }

    fn keep(&mut self, result: io::Result<()>) {
        if let Err(err) = result {
            tracing::error!(error = %err, dir = %self.dir.display(), "recording stopped");
            self.error.get_or_insert(err);
            self.sinks = None;
        }
    }

    /// Records a datagram sent or received at `now`, frame by frame.
    pub fn datagram(&mut self, now: SimTime, bytes: &[u8]) {
        let stamp = (self.epoch_us + now.as_micros()).to_be_bytes();
        let Some(sinks) = self.sinks.as_mut() else {
            return;
        };
        let tlog = sinks.buffer(TLOG);
        for frame in raw_frames(bytes) {
            tlog.extend_from_slice(&stamp);
            tlog.extend_from_slice(frame);
        }
        let result = sinks.appended(TLOG);
        self.keep(result);
    }

    /// Samples the swarm if a control tick ran since the last call.
    pub fn sample(&mut self, swarm: &Swarm, now: SimTime) {
        if swarm.control_ticks() == self.last_tick {
            return;
        }
        self.last_tick = swarm.control_ticks();
        self.tracker.observe(swarm, now);
        self.trace.observe(swarm, now);
        let result = self.write_rows(swarm, now);
        self.keep(result);
        let result = self.write_events(swarm);
        self.keep(result);
    }

    fn write_events(&mut self, swarm: &Swarm) -> io::Result<()> {
        let Some(sinks) = self.sinks.as_mut() else {
            return Ok(());
        };
        let w = sinks.buffer(EVENTS);
        for e in swarm.events().iter().skip(self.events_written) {
            writeln!(
                w,
                "{:.4},{},{},{},\"{}\"",
                e.t.as_secs_f64(),
                e.system_id.map_or(String::new(), |id| id.to_string()),
                e.network.as_deref().unwrap_or(""),
                if e.warning { "warning" } else { "info" },
                e.text.replace('"', "\"\"")
            )?;
        }
        self.events_written = swarm.events().len();
        sinks.appended(EVENTS)
    }

    fn write_rows(&mut self, swarm: &Swarm, now: SimTime) -> io::Result<()> {
        let phase = swarm.phase().name();
        let Some(sinks) = self.sinks.as_mut() else {
            return Ok(());
        };
        for (k, i) in VehicleIndex::all(self.vehicles).enumerate() {
            let link_state = swarm.link(i).map(|l| l.state());
            let attitude = link_state.and_then(|l| l.attitude);
            let Some(s) = swarm.common_state(i) else {
                continue;
            };
            let wijk = |q: &nalgebra::UnitQuaternion<f64>| [q.w, q.i, q.j, q.k];
            let c = swarm.commands()[i];
            let sp = swarm.setpoints()[i];
            let row = rows::Row {
                t_s: now.as_secs_f64(),
                swarm_phase: phase,
                link_phase: swarm.vehicle_phase(i).name(),
                state_enu: [
                    s.pos_enu_m.x,
                    s.pos_enu_m.y,
                    s.pos_enu_m.z,
                    s.vel_enu_mps.x,
                    s.vel_enu_mps.y,
                    s.vel_enu_mps.z,
                ],
                attitude_wijk: attitude.as_ref().map_or([f64::NAN; 4], wijk),
                command_enu_mps2: [c.x, c.y, c.z],
                setpoint_wijk: wijk(&sp.attitude_ned_frd),
                thrust_norm: sp.thrust_norm,
                heard_age_ms: link_state
                    .and_then(|l| l.last_heard)
                    .map_or(f64::NAN, |t| now.saturating_since(t).as_secs_f64() * 1e3),
            };
            match self.text {
                RowText::Writer => rows::push_row(sinks.buffer(FIRST_CSV + k), &row),
                RowText::Inline => row.write_csv(sinks.buffer(FIRST_CSV + k)),
            }
            sinks.appended(FIRST_CSV + k)?;
        }
        Ok(())
    }

    /// What the traffic mirrors carried, for `summary.json`.
    pub fn set_mirrors(&mut self, reports: Vec<metrics::MirrorReport>) {
        self.mirrors = reports;
    }

    /// Flushes everything and writes `summary.json`; returns the summary and the trace
    /// (for the plots).
    ///
    /// # Errors
    /// The first write error of the run, or one while finishing.
    pub fn finish(
        mut self,
        swarm: &Swarm,
        now: SimTime,
        wall_seconds: f64,
    ) -> io::Result<(Summary, Trace)> {
        let mut summary = Summary::new(swarm, &self.tracker, now, wall_seconds);
        summary.mirrors = std::mem::take(&mut self.mirrors);
        let result = self.write_events(swarm);
        self.keep(result);
        if let Some(err) = self.error.take() {
            return Err(err);
        }
        if let Some(sinks) = self.sinks.take() {
            sinks.finish()?;
        }
        let json = serde_json::to_string_pretty(&summary).map_err(io::Error::other)?;
        std::fs::write(self.dir.join("summary.json"), json + "\n")?;
        Ok((summary, self.trace))
    }
}
