//! The command line (clap derive). Parsing only: the work is in [`crate::report`].
//!
//! The doc comments of the argument structs are `--help`'s text, printed as written:
//! `<scenario>` and `[[vehicle]]` there are words for the terminal, not HTML or links.
#![allow(rustdoc::invalid_html_tags, rustdoc::broken_intra_doc_links)]

use clap::{Args, Parser, Subcommand};
use nalgebra::Vector2;

use crate::error::InputError;

/// Ring-digraph consensus formation flight over MAVLink.
#[derive(Debug, Parser)]
#[command(name = "ringswarm", version, about, long_about = None)]
pub struct Cli {
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Stability of a ring (bound on k, eigenvalues of L, Yu's bound, closed loop) and,
    /// without --alpha/--beta, recommended gains. Exit code 0 stable, 1 unstable.
    Analyze(AnalyzeArgs),
    /// Plan the gain k (and, if needed, one agent's new initial velocity, or every agent's
    /// when one cannot do it within the speed limit) that makes the
    /// swarm reach a target velocity. Exit code 0 feasible, 1 infeasible.
    Plan(PlanArgs),
    /// Run N emulated PX4-like quadrotors on PX4's SITL ports until Ctrl-C.
    #[cfg(feature = "emulator")]
    Sitl(SitlArgs),
    /// Fly the vehicles of a config over UDP (PX4, PX4 SITL or `ringswarm sitl`) with the
    /// consensus law, then land them; writes a run directory.
    Fly(FlyArgs),
    /// Fly a built-in scenario in lockstep with the emulator (virtual time), print the
    /// summary and write a run directory.
    #[cfg(feature = "emulator")]
    Demo(DemoArgs),
    /// Fly a sweep's lockstep flights (a grid of settings over a scenario, replicates
    /// seeded) on every core, a row each in DIR/results.parquet; `sweep merge DIR...
    /// --out DIR` joins the parts of a split sweep (docs/sweeps.md).
    #[cfg(feature = "emulator")]
    Sweep(SweepArgs),
    /// Write a new MAVLink 2 signing key (64 hex characters, mode 0600) to FILE; an
    /// existing file is never overwritten.
    Keygen(KeygenArgs),
    /// Give every vehicle of a config the key of its `[security] signing_key_file`, with
    /// SETUP_SIGNING over its link (vehicles must be disarmed); says which took it.
    SignSetup(SignSetupArgs),
    /// Replay a run directory of `fly` or `demo` in a browser (play, pause, speed, a time
    /// slider) until Ctrl-C; or, with --zenoh, watch a distributed swarm live.
    View(ViewArgs),
}

/// The live view and the traffic mirrors of a flight over UDP.
#[derive(Debug, Args, Clone, Default)]
pub struct LiveArgs {
    /// Serve a live view of the flight at ADDR (HOST:PORT or PORT; alone, 127.0.0.1:8080):
    /// open http://ADDR/ in a browser; the API is `GET /api/state` and the WebSocket
    /// `/api/ws`. Read-only; any other host than the loopback shows it to the network.
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = DEFAULT_WEB, value_parser = parse_web_addr)]
    pub web: Option<std::net::SocketAddr>,
    /// Forward every datagram the coordinator sends and receives, unchanged, to the UDP
    /// address ADDR (HOST:PORT; repeatable), for pymavlink, MAVProxy or QGroundControl to
    /// watch. What comes back from it is dropped (counted in summary.json).
    #[arg(long, value_name = "ADDR", value_parser = parse_mirror_addr)]
    pub mirror: Vec<std::net::SocketAddr>,
}

/// Where the web view listens when `--web` has no address.
pub const DEFAULT_WEB: &str = "127.0.0.1:8080";

/// Arguments of `ringswarm view`.
#[derive(Debug, Args)]
pub struct ViewArgs {
    /// The run directory (with setup.json, the vehicle CSVs, events.csv, summary.json).
    #[arg(required_unless_present = "zenoh", conflicts_with = "zenoh")]
    pub run_dir: Option<std::path::PathBuf>,
    /// Watch a distributed swarm live instead, from its shards' Zenoh traffic, through
    /// the endpoint ENDPOINT of a shard (`tcp/10.0.0.1:7447`; repeatable: Zenoh peers
    /// relay nothing for others, so give every shard that does not listen). Flies and
    /// commands nothing. Needs --config.
    #[arg(long, value_name = "ENDPOINT", requires = "config")]
    pub zenoh: Vec<String>,
    /// The swarm's file (its [distributed] and [[shard]] split), with --zenoh.
    #[arg(long)]
    pub config: Option<std::path::PathBuf>,
    /// Where to serve the page (HOST:PORT or PORT).
    #[arg(long, value_name = "ADDR", default_value = DEFAULT_WEB, value_parser = parse_web_addr)]
    pub web: std::net::SocketAddr,
}

/// `HOST:PORT`, `localhost:PORT` or a bare `PORT` (on 127.0.0.1).
pub fn parse_web_addr(s: &str) -> Result<std::net::SocketAddr, String> {
    let s = s.trim();
    if let Ok(port) = s.parse::<u16>() {
        return Ok(([127, 0, 0, 1], port).into());
    }
    localhost(s).unwrap_or_else(|| {
        s.parse().map_err(|_| {
            format!("\"{s}\" is not an address: give HOST:PORT or PORT, like {DEFAULT_WEB} or 8080")
        })
    })
}

/// `HOST:PORT` (or `localhost:PORT`) of a mirror; port 0 cannot be sent to.
pub fn parse_mirror_addr(s: &str) -> Result<std::net::SocketAddr, String> {
    let s = s.trim();
    let addr = localhost(s).unwrap_or_else(|| {
        s.parse().map_err(|_| {
            format!("\"{s}\" is not a UDP address: give HOST:PORT, like 127.0.0.1:14551")
        })
    })?;
    if addr.port() == 0 {
        return Err(format!("\"{s}\": port 0 cannot be sent to"));
    }
    Ok(addr)
}

/// `localhost:PORT` as 127.0.0.1 (`None` for anything else).
fn localhost(s: &str) -> Option<Result<std::net::SocketAddr, String>> {
    let port = s.strip_prefix("localhost:")?;
    Some(
        port.parse::<u16>()
            .map(|p| ([127, 0, 0, 1], p).into())
            .map_err(|_| format!("\"{s}\": the port is not a number from 0 to 65535")),
    )
}

/// Arguments of `ringswarm sign-setup`.
#[derive(Debug, Args)]
pub struct SignSetupArgs {
    /// The coordinator's TOML file, with `[security] signing_key_file`.
    #[arg(long)]
    pub config: std::path::PathBuf,
}

/// Arguments of `ringswarm keygen`.
#[derive(Debug, Args)]
pub struct KeygenArgs {
    /// Where to write the key (must not exist).
    pub file: std::path::PathBuf,
}

/// Arguments of `ringswarm demo`.
#[derive(Debug, Args)]
pub struct DemoArgs {
    /// The scenario (see --list), or a path to a coordinator .toml file.
    #[arg(long, default_value = "paper-sim1")]
    pub scenario: String,
    /// Override the scenario's saturation mode: conserve or clip.
    #[arg(long, value_parser = parse_saturation)]
    pub saturation: Option<crate::control::SaturationMode>,
    /// List the scenarios and exit.
    #[arg(long)]
    pub list: bool,
    /// The run directory (default runs/demo-<scenario>-<unix time>).
    #[arg(long)]
    pub out: Option<std::path::PathBuf>,
    /// Do not draw the plots.
    #[arg(long)]
    pub no_plots: bool,
    /// Fly in real time over real UDP sockets, with the emulated vehicles on PX4's SITL
    /// ports in this process (a GCS on udp 14550 sees them).
    #[arg(long)]
    pub realtime: bool,
    /// The live view and the mirrors (with --realtime).
    #[command(flatten)]
    pub live: LiveArgs,
    /// Fly gains the stability analysis calls unstable (not on the command line: a
    /// sweep's cell flown alone, `sweep --cell`, is flown as in its sweep).
    #[arg(skip)]
    pub unstable_gains: bool,
}

/// Arguments of `ringswarm sweep`.
#[derive(Debug, Args)]
pub struct SweepArgs {
    /// The sweep's spec (SPEC.toml), or `merge` and the parts' directories.
    #[arg(required = true, value_name = "SPEC.toml | merge DIR...")]
    pub args: Vec<std::path::PathBuf>,
    /// The sweep's directory (manifest.json, flights.jsonl, results.parquet); with
    /// --cell, the flight's run directory; with merge, where the parts are joined.
    #[arg(long)]
    pub out: std::path::PathBuf,
    /// Fly this part of a split sweep: K/N flies every N-th flight from the K-th.
    #[arg(long, value_name = "K/N")]
    pub part: Option<String>,
    /// Split the sweep in N parts and fly the one a batch scheduler's task is given
    /// (SLURM_ARRAY_TASK_ID, or a Kubernetes Indexed Job's JOB_COMPLETION_INDEX).
    #[arg(long, value_name = "N")]
    pub parts: Option<u64>,
    /// Fly one flight, C (replicate 0) or C.R, with its full run directory in --out.
    #[arg(long, value_name = "ID")]
    pub cell: Option<String>,
    /// Flights flown at once (default: the machine's cores).
    #[arg(long)]
    pub jobs: Option<usize>,
}

/// Arguments of `ringswarm fly`.
#[derive(Debug, Args)]
pub struct FlyArgs {
    /// The coordinator's TOML file (see config/*.toml).
    #[arg(long)]
    pub config: std::path::PathBuf,
    /// The run directory (default runs/<config name>-<unix time>).
    #[arg(long)]
    pub out: Option<std::path::PathBuf>,
    /// Seconds of consensus before the end action (overrides swarm.duration_s).
    #[arg(long)]
    pub duration_s: Option<f64>,
    /// Fly only this `[[shard]]` of the file's split, talking to the other shards over
    /// Zenoh (docs/distributed.md); without it, one process flies every vehicle.
    #[arg(long)]
    pub shard: Option<String>,
    /// Run the control loop at this real-time priority (Linux SCHED_FIFO, 1..=99; needs
    /// root, CAP_SYS_NICE or an rtprio limit): ticks stay on time on a busy machine.
    #[arg(long, value_name = "PRIORITY")]
    pub realtime_priority: Option<u8>,
    /// The live view and the mirrors.
    #[command(flatten)]
    pub live: LiveArgs,
}

/// Arguments of `ringswarm sitl`.
#[derive(Debug, Args)]
pub struct SitlArgs {
    /// Number of vehicles (system ids 1..=N, PX4 ports for instances 0..N-1); default 1,
    /// or the number of [[vehicle]] tables of --config.
    #[arg(long)]
    pub vehicles: Option<u16>,
    /// A TOML file describing the world, the faults and each vehicle (see
    /// `sitl/src/config_file.rs`); the fault and profile flags then do not apply.
    #[arg(long)]
    pub config: Option<std::path::PathBuf>,
    /// Vehicle profile: ideal, x500 or arducopter (default x500; arducopter with
    /// `--autopilot ardupilot`).
    #[arg(long)]
    pub profile: Option<String>,
    /// Whose autopilot the vehicles play on the wire: px4 or ardupilot (ArduCopter's
    /// heartbeat, modes, GUIDED thrust and parameters; nothing streamed until asked).
    #[arg(long, default_value = "px4")]
    pub autopilot: String,
    /// ArduPilot: seconds after boot before a vehicle's EKF has a position and it may arm
    /// (real ArduPilot SITL takes about 40).
    #[arg(long, default_value_t = 5.0)]
    pub ekf_settle_s: f64,
    /// Simulated seconds per real second.
    #[arg(long, default_value_t = 1.0)]
    pub speed: f64,
    /// Address to bind and to send to.
    #[arg(long, default_value = "127.0.0.1")]
    pub host: std::net::IpAddr,
    /// Distance between vehicles on the ground, along east (m).
    #[arg(long, default_value_t = 5.0)]
    pub spacing_m: f64,
    /// Packet loss on every link, each direction (%).
    #[arg(long, default_value_t = 0.0)]
    pub loss_pct: f64,
    /// One-way latency on every link (ms).
    #[arg(long, default_value_t = 0.0)]
    pub latency_ms: f64,
    /// Uniform extra latency 0..jitter (ms).
    #[arg(long, default_value_t = 0.0)]
    pub jitter_ms: f64,
    /// Duplicated datagrams (%).
    #[arg(long, default_value_t = 0.0)]
    pub duplicate_pct: f64,
    /// Seed of the fault injection.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Give every vehicle this MAVLink 2 signing key (a `ringswarm keygen` file): unsigned
    /// frames are then refused but for HEARTBEAT, RADIO_STATUS, ADSB_VEHICLE and
    /// COLLISION, and everything sent is signed. A coordinator file's
    /// `[security] signing_key_file` does the same.
    #[arg(long)]
    pub signing_key: Option<std::path::PathBuf>,
    /// Where each vehicle keeps what survives a restart, as PX4 keeps it under its
    /// instance directory: `vehicle-<id>/mavlink/mavlink-signing-key.bin` (a key set with
    /// SETUP_SIGNING or --signing-key, and its clock).
    #[arg(long, default_value = "sitl-state")]
    pub state_dir: std::path::PathBuf,
    /// With a coordinator --config split into shards: emulate only this `[[shard]]`'s
    /// vehicles (each still on its PX4 instance's ports), as the ground station that
    /// flies that shard would.
    #[arg(long)]
    pub shard: Option<String>,
}

/// Arguments of `ringswarm analyze`.
#[derive(Debug, Args)]
pub struct AnalyzeArgs {
    /// Number of macro-vertices m (N = 2m vehicles).
    #[arg(long, short = 'm')]
    pub macro_vertices: usize,
    /// The ring gain k.
    #[arg(long, short = 'k', allow_negative_numbers = true)]
    pub k: f64,
    /// Position coupling α (1/s²); give it with --beta.
    #[arg(long, requires = "beta", allow_negative_numbers = true)]
    pub alpha: Option<f64>,
    /// Velocity coupling β (1/s); give it with --alpha.
    #[arg(long, requires = "alpha", allow_negative_numbers = true)]
    pub beta: Option<f64>,
    /// Design gain k̂ ≤ k for the recommended gains: they then hold for every k in [k̂, k]
    /// (default: k itself).
    #[arg(long, allow_negative_numbers = true)]
    pub design_k: Option<f64>,
    /// Relative margin of the recommended gains over Yu's bound (0.25 = 25 %).
    #[arg(long, default_value_t = 0.25)]
    pub gain_margin: f64,
    /// The airframe's attitude bandwidth (rad/s, about its attitude P gain: PX4's
    /// MC_ROLL_P, 6.5 by default): with the gains, checks that the airframe can fly them
    /// and recommends a time scale.
    #[arg(long, requires = "alpha")]
    pub attitude_bandwidth: Option<f64>,
    /// The control rate (Hz) for the bandwidth gate.
    #[arg(long, default_value_t = 50.0)]
    pub control_rate: f64,
    /// List every eigenvalue of L and the left null vector (listed anyway up to 64 agents).
    #[arg(long)]
    pub eigenvalues: bool,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Arguments of `ringswarm plan`.
#[derive(Debug, Args)]
pub struct PlanArgs {
    /// Initial horizontal velocities, one "vx,vy" per agent separated by ';' (m/s,
    /// paper frame: x east, y north), in ring order.
    #[arg(long, value_parser = parse_velocity_list, allow_hyphen_values = true)]
    pub initial_velocities: VelocityList,
    /// The target final velocity "vx,vy" (m/s).
    #[arg(long, value_parser = parse_target, allow_hyphen_values = true)]
    pub target: Vector2<f64>,
    /// How far above the stability bound the chosen k must stay.
    #[arg(long, default_value_t = 0.1)]
    pub margin: f64,
    /// The largest k the planner may choose.
    #[arg(long, default_value_t = 10.0, allow_negative_numbers = true)]
    pub k_max: f64,
    /// Refuse plans whose re-targeted agent would fly faster than this (m/s).
    #[arg(long)]
    pub max_speed: Option<f64>,
    /// When one agent cannot reach the target within the limits, every agent is
    /// re-targeted by the least change of their velocities with this k (default 1: weights
    /// 1 and 2 per macro-vertex; kept within [k_min + margin, k_max]).
    #[arg(long)]
    pub k: Option<f64>,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

/// A parsed list of horizontal velocities (m/s).
#[derive(Debug, Clone, PartialEq)]
pub struct VelocityList(pub Vec<Vector2<f64>>);

/// Parses `"vx,vy;vx,vy;…"`.
///
/// # Errors
/// [`InputError::BadVector`] naming the first malformed entry (1-based), or
/// [`InputError::Empty`].
pub fn parse_velocity_list(text: &str) -> Result<VelocityList, InputError> {
    let entries: Vec<&str> = text.split(';').map(str::trim).collect();
    if entries.iter().all(|e| e.is_empty()) {
        return Err(InputError::Empty("the velocity list"));
    }
    entries
        .iter()
        .enumerate()
        .map(|(i, entry)| parse_vector2("initial velocity", i + 1, entry))
        .collect::<Result<Vec<_>, _>>()
        .map(VelocityList)
}

fn parse_target(text: &str) -> Result<Vector2<f64>, InputError> {
    parse_vector2("target velocity", 1, text.trim())
}

fn parse_vector2(what: &'static str, index: usize, text: &str) -> Result<Vector2<f64>, InputError> {
    let bad = |reason: String| InputError::BadVector {
        what,
        index,
        text: text.to_owned(),
        reason,
    };
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    if parts.len() != 2 {
        return Err(bad(format!("{} components", parts.len())));
    }
    let mut values = [0.0; 2];
    for (slot, part) in values.iter_mut().zip(&parts) {
        let value: f64 = part
            .parse()
            .map_err(|_| bad(format!("\"{part}\" is not a number")))?;
        if !value.is_finite() {
            return Err(bad(format!("{part} is not finite")));
        }
        *slot = value;
    }
    Ok(Vector2::new(values[0], values[1]))
}

fn parse_saturation(s: &str) -> Result<crate::control::SaturationMode, String> {
    match s {
        "conserve" => Ok(crate::control::SaturationMode::Conserve),
        "clip" => Ok(crate::control::SaturationMode::Clip),
        other => Err(format!(
            "unknown saturation mode \"{other}\" (known: conserve, clip)"
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn web_and_mirror_addresses_parse_or_say_what_is_wrong() {
        let local = |p: u16| std::net::SocketAddr::from(([127, 0, 0, 1], p));
        assert_eq!(parse_web_addr("8080"), Ok(local(8080)));
        assert_eq!(parse_web_addr("localhost:9000"), Ok(local(9000)));
        assert_eq!(
            parse_web_addr("0.0.0.0:8081"),
            Ok(std::net::SocketAddr::from(([0, 0, 0, 0], 8081)))
        );
        assert_eq!(parse_web_addr("[::1]:80").map(|a| a.port()), Ok(80));
        assert_eq!(
            parse_web_addr("web"),
            Err(
                "\"web\" is not an address: give HOST:PORT or PORT, like 127.0.0.1:8080 or 8080"
                    .into()
            )
        );
        assert_eq!(parse_mirror_addr("127.0.0.1:14551"), Ok(local(14551)));
        assert_eq!(parse_mirror_addr("localhost:14552"), Ok(local(14552)));
        assert_eq!(
            parse_mirror_addr("127.0.0.1:0"),
            Err("\"127.0.0.1:0\": port 0 cannot be sent to".into())
        );
        assert!(
            parse_mirror_addr("14551")
                .unwrap_err()
                .contains("HOST:PORT")
        );
    }

    #[test]
    fn velocity_list_parses_with_spaces_and_negatives() {
        let list = parse_velocity_list(" 1, 2; -1 ,3 ;-2.5,4e1").unwrap();
        assert_eq!(
            list.0,
            vec![
                Vector2::new(1.0, 2.0),
                Vector2::new(-1.0, 3.0),
                Vector2::new(-2.5, 40.0)
            ]
        );
    }

    #[test]
    fn malformed_velocity_lists_name_the_entry() {
        let err = parse_velocity_list("1,2;3").unwrap_err();
        assert!(
            matches!(err, InputError::BadVector { index: 2, .. }),
            "{err}"
        );
        let err = parse_velocity_list("1,2;x,4").unwrap_err();
        assert!(err.to_string().contains("\"x\" is not a number"), "{err}");
        let err = parse_velocity_list("1,nan").unwrap_err();
        assert!(err.to_string().contains("not finite"), "{err}");
        assert_eq!(
            parse_velocity_list(" ; "),
            Err(InputError::Empty("the velocity list"))
        );
    }
}
