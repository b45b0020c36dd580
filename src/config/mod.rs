//! The coordinator's TOML configuration: the schema (serde structs with
//! `deny_unknown_fields`, defaults), [`Config::validate`] in `validate` (every number
//! checked, every problem reported at once, the typed [`crate::swarm::SwarmSetup`]
//! built), what the file means for the built-in emulator in `emulator` (with the
//! `emulator` feature) and for the transport in `transport`. docs/configuration.md lists every key with its unit, range and default.
//!
//! Frames: vehicle start states and formation offsets are in the paper's ENU frame (x
//! east, y north, z up, metres) about the common reference point.

#[cfg(feature = "emulator")]
mod emulator;
mod formation_checks;
mod gate;
mod problems;
mod safety_checks;
mod shards;
mod transport;
mod validate;

use std::net::SocketAddr;

use serde::Deserialize;

use crate::control::SaturationMode;
use crate::swarm::{EndAction, LossPolicy, SetpointKind};

#[cfg(feature = "emulator")]
pub use emulator::EMULATOR_FAULT_NAMES;
pub use gate::warn_if_too_fast;
pub(crate) use problems::show;
pub use shards::{
    DistributedSection, ShardLayout, ShardSection, ShardVehicle, WatchName, endpoint_problem,
};
pub use validate::{MAX_DISTANCE_M, MAX_DURATION_S, MAX_GAIN, MAX_SPEED_MPS, Stability};

/// The whole file.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    /// Rates, duration and end of flight.
    #[serde(default)]
    pub swarm: SwarmSection,
    /// Consensus and altitude gains.
    pub gains: GainsSection,
    /// The formation and its altitude.
    pub formation: FormationSection,
    /// Tilt and thrust limits.
    #[serde(default)]
    pub envelope: EnvelopeSection,
    /// The common frame's reference point.
    #[serde(default)]
    pub frame: FrameSection,
    /// The world of the built-in emulator.
    #[serde(default)]
    pub emulator: EmulatorSection,
    /// MAVLink networks: one coordinator socket each, its vehicles told apart by system
    /// id (as a ground station on 14550 tells PX4 instances apart).
    #[serde(default)]
    pub network: Vec<NetworkSection>,
    /// One table per vehicle, in ring order.
    #[serde(default)]
    pub vehicle: Vec<VehicleSection>,
    /// A final velocity to reach with the planner (optional).
    pub target: Option<TargetSection>,
    /// MAVLink 2 signing.
    #[serde(default)]
    pub security: SecuritySection,
    /// The divergence guard.
    #[serde(default)]
    pub guard: GuardSection,
    /// The separation the safety filter enforces.
    #[serde(default)]
    pub safety: SafetySection,
    /// Where the swarm may fly (optional).
    pub fence: Option<FenceSection>,
    /// The swarm split into shards (optional; docs/distributed.md).
    pub distributed: Option<DistributedSection>,
    /// One table per shard, with `[distributed]`.
    #[serde(default)]
    pub shard: Vec<ShardSection>,
}

/// The fence's horizontal shape.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FenceKind {
    /// `centre_enu_m` and `radius_m`.
    Circle,
    /// `vertices_enu_m`, at least three, a simple polygon.
    Polygon,
}

/// `[fence]`: an inclusion circle or polygon in the common frame with an altitude band.
/// The swarm applies `action` as soon as one vehicle's stopping point comes within
/// `margin_m` of it (docs/math.md, "The fence").
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FenceSection {
    /// `circle` or `polygon`.
    pub kind: FenceKind,
    /// The circle's centre (m, ENU).
    pub centre_enu_m: Option<[f64; 2]>,
    /// The circle's radius (m).
    pub radius_m: Option<f64>,
    /// The polygon's vertices (m, ENU).
    pub vertices_enu_m: Option<Vec<[f64; 2]>>,
    /// Lowest altitude in flight (m, up, common frame).
    pub min_altitude_m: f64,
    /// Highest altitude (m, up, common frame).
    pub max_altitude_m: f64,
    /// How close to the fence a stopping point may come (m, default 5).
    #[serde(default = "default_fence_margin_m")]
    pub margin_m: f64,
    /// What the swarm does: `hold` (brake and hover; default) or `land`.
    #[serde(default)]
    pub action: crate::swarm::LossPolicy,
    /// Give the fence to every vehicle over the mission protocol (mission type FENCE)
    /// before it is armed, so that its own geofence backs the coordinator's (default
    /// true). A vehicle that refuses it is not flown.
    #[serde(default = "default_true")]
    pub upload: bool,
}

fn default_fence_margin_m() -> f64 {
    5.0
}

/// How `[safety]` breaks jams.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum JamBreak {
    /// The northbound vehicle of a jam passes over the others on the jam layer.
    Layer,
    /// Every held pair turns about its midpoint.
    Turn,
}

/// `[safety]`: no command brings two vehicles closer than a downwash ellipsoid of
/// `horizontal_m` by `vertical_m` (centre to centre), by a control-barrier-function
/// filter between the law and the saturation (docs/math.md, "Keeping vehicles apart").
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SafetySection {
    /// Whether the filter acts (default true).
    pub enabled: bool,
    /// Horizontal separation, centre to centre (m, default 3: Skybrush's outdoor
    /// proximity limit; at least 2 m for the x500 class).
    pub horizontal_m: f64,
    /// Vertical separation (m, default 9: three times the horizontal, the ratio of the
    /// Crazyflie's downwash ellipsoid).
    pub vertical_m: f64,
    /// The share of each vehicle's horizontal envelope the barrier counts on for braking
    /// (default 0.5: the rest stays for the law and the disturbances).
    pub braking_share: f64,
    /// What the swarm does when the filter cannot keep a pair apart (a pair closer than
    /// 95 % of the separation, or a fallback) while it flies its law: `hold` (default),
    /// `land` or `continue`.
    pub action: crate::swarm::BreachAction,
    /// Break jams (default true): vehicles the filter has held (an active row, and at
    /// least half of the command taken away) for `jam_hold_s` without closing on their
    /// places are broken as `jam_break` says, on the layer only while the filter keeps up
    /// (docs/dense.md).
    pub resolve_jams: bool,
    /// How long a vehicle is held without progress before it counts as jammed (s,
    /// default 5).
    pub jam_hold_s: f64,
    /// How jams are broken (default `layer`): `layer` sends the jammed vehicle whose way
    /// points north over the others on a layer `jam_layer_m` above the formation (below
    /// when the fence's band has no room above); `turn` turns every held pair about its
    /// midpoint at `jam_turn_mps2`.
    pub jam_break: JamBreak,
    /// The jam layer's distance from the formation's altitude (m, default
    /// `vertical_m + horizontal_m`: clear of the downwash ellipsoid by a horizontal
    /// separation; at least `vertical_m`).
    pub jam_layer_m: Option<f64>,
    /// The least time a vehicle stays on the jam layer unless it reaches its place (s,
    /// default 20).
    pub jam_layer_s: f64,
    /// The turning acceleration of a jammed pair of equal weights, each (m/s², default 1).
    pub jam_turn_mps2: f64,
    /// The share of the control period the filter may take in a flight in real time
    /// (default 0.2): past it, the tick goes out with the answer so far, where every
    /// vehicle whose command and then braking would not keep the separation brakes
    /// (counted as `unfinished_ticks`, `unfinished_braked`). Lockstep
    /// flights are limited by sweeps only.
    pub budget_share: f64,
}

impl Default for SafetySection {
    fn default() -> Self {
        Self {
            enabled: true,
            horizontal_m: 3.0,
            vertical_m: 9.0,
            braking_share: 0.5,
            action: crate::swarm::BreachAction::Hold,
            resolve_jams: true,
            jam_hold_s: 5.0,
            jam_break: JamBreak::Layer,
            jam_layer_m: None,
            jam_layer_s: 20.0,
            jam_turn_mps2: 1.0,
            budget_share: 0.2,
        }
    }
}

/// `[guard]`: the divergence guard ends the consensus (the swarm applies
/// `swarm.on_link_loss`: brake and hold, or land; `fly` and `demo` exit with code 4) when
/// the swarm runs away from what the law promises.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GuardSection {
    /// Whether the guard watches (default true).
    pub enabled: bool,
    /// Bound on `|v̄_w − v_f|`, the w-weighted mean velocity against the predicted final
    /// velocity (m/s, default 1.0), or this fraction of the predicted speed, the larger
    /// (default 0.1) ...
    pub velocity_error_mps: f64,
    /// See `velocity_error_mps`.
    pub velocity_error_fraction: f64,
    /// How long the velocity error may stay beyond its bound (s, default 1.0).
    pub velocity_error_s: f64,
    /// How far the formation error may rise above the lowest it reached in this
    /// consensus (m, default 2.0), or this fraction of that lowest value, the larger
    /// (default 0.5) ...
    pub formation_growth_m: f64,
    /// See `formation_growth_m`.
    pub formation_growth_fraction: f64,
    /// ... for how long (s, default 10).
    pub formation_growth_s: f64,
}

impl Default for GuardSection {
    fn default() -> Self {
        Self {
            enabled: true,
            velocity_error_mps: 1.0,
            velocity_error_fraction: 0.1,
            velocity_error_s: 1.0,
            formation_growth_m: 2.0,
            formation_growth_fraction: 0.5,
            formation_growth_s: 10.0,
        }
    }
}

/// `[security]`: MAVLink 2 signing of every link.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SecuritySection {
    /// The key file (`ringswarm keygen FILE` writes one), relative to the current
    /// directory. Every frame sent is signed, and only authentic, fresh signed frames
    /// from the vehicles are taken; the signing clock is kept in `<file>.timestamp`.
    pub signing_key_file: Option<std::path::PathBuf>,
}

/// `[target]`: the planner chooses `k` (and re-targets one agent if needed) so that the
/// swarm's consensus velocity is `velocity_enu_mps`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TargetSection {
    /// The final velocity (ENU, m/s).
    pub velocity_enu_mps: [f64; 2],
    /// `k ≥ k_min + k_margin` (default 0.1).
    #[serde(default = "default_k_margin")]
    pub k_margin: f64,
    /// `k ≤ k_max` (default 10).
    #[serde(default = "default_k_max")]
    pub k_max: f64,
    /// Largest speed a re-targeted agent may be asked for (m/s).
    pub max_speed_mps: Option<f64>,
    /// Stage 1 ends when the w-weighted mean velocity is this close to the target, times
    /// the re-targeted agents' share of the weights (default 0.05 m/s), and every
    /// re-targeted agent within 0.5 m/s of its planned one.
    #[serde(default = "default_tolerance")]
    pub tolerance_mps: f64,
    /// Stage 1 ends at the latest after this long (s, default 30): consensus then starts
    /// from the velocities reached, with a warning.
    #[serde(default = "default_retarget_timeout")]
    pub timeout_s: f64,
    /// Plan once every vehicle flies level at the commanded altitude (default true): a
    /// plan made from velocities on the ground is spoilt by the climb. False plans as soon
    /// as every vehicle flies (the paper's second simulation plans from its initial
    /// velocities).
    #[serde(default = "default_true")]
    pub wait_for_altitude: bool,
}

fn default_retarget_timeout() -> f64 {
    30.0
}

fn default_k_margin() -> f64 {
    0.1
}

fn default_k_max() -> f64 {
    10.0
}

fn default_tolerance() -> f64 {
    0.05
}

/// The coordinator's default system id: not QGroundControl's 255, not MAVSDK's 245.
pub const DEFAULT_GCS_SYSTEM_ID: u8 = 253;
/// The coordinator's default component id (MAV_COMP_ID_MISSIONPLANNER).
pub const DEFAULT_GCS_COMPONENT_ID: u8 = 190;

/// `[swarm]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SwarmSection {
    /// Control (and setpoint stream) rate, 1..=250 Hz; LOCAL_POSITION_NED is asked for at
    /// this rate.
    pub control_rate_hz: f64,
    /// ATTITUDE_QUATERNION rate, 1 Hz up to the control rate (default: the control rate).
    /// The attitude only tilts the hover-thrust estimator's view of the thrust, so a large
    /// swarm can ask for it at 10 Hz: one datagram per vehicle-tick instead of two.
    pub attitude_rate_hz: Option<f64>,
    /// Flight duration after consensus starts (s).
    pub duration_s: f64,
    /// Silence after which a vehicle is lost (ms).
    pub link_timeout_ms: u64,
    /// Sends of a command (arm, mode, land, disarm, a parameter write) before its link
    /// fails, one per 0.5 s without an answer (default 10). A send is answered when the
    /// command and its COMMAND_ACK both get through, so with a loss fraction p each way one
    /// attempt fails with probability 1 − (1 − p)²; MAVSDK's 4 attempts then fail a command
    /// 6.8 % of the time at 30 % loss, 10 attempts 0.12 % (docs/sweeps.md, the latency ×
    /// loss sweep).
    pub command_attempts: u8,
    /// At the end of the duration: `land` (default) or `hold`.
    pub end: EndAction,
    /// When a vehicle is lost during consensus: `hold` (default) or `land`.
    pub on_link_loss: LossPolicy,
    /// The coordinator's own MAVLink system id, in its 1 Hz ground-station heartbeat and
    /// every frame it sends (default 253: neither QGroundControl's 255 nor MAVSDK's 245,
    /// so either can watch the same vehicles).
    pub gcs_system_id: u8,
    /// The coordinator's own MAVLink component id (default 190, MAV_COMP_ID_MISSIONPLANNER).
    pub gcs_component_id: u8,
    /// How long the vehicles have to be flying in OFFBOARD (s, default 30); those that
    /// are not by then are named, the others land, and `fly` exits with code 3.
    pub handshake_timeout_s: f64,
    /// Age (ms) after which a vehicle's position and velocity are too old to fly on
    /// (default 300: 15 telemetry samples at 50 Hz, a fifth of the link timeout); the
    /// vehicle then counts as lost for the swarm even while its heartbeat goes on.
    pub state_timeout_ms: u64,
    /// Whether a vehicle that left OFFBOARD by itself (its failsafe, a pilot, another
    /// station) is re-armed and taken back (default false: its own decision wins).
    pub retake_offboard: bool,
    /// Estimate each vehicle's hover thrust in flight (PX4's hover thrust EKF) and fly
    /// with it instead of the configured `hover_throttle` (default true).
    pub estimate_hover: bool,
    /// Estimate each vehicle's linear drag in flight (default true): the drag fed forward
    /// is then never more than the estimate's lower confidence bound, and the estimate is
    /// flown once it is settled and differs from `drag_per_s`.
    pub estimate_drag: bool,
    /// Time constant (s) of each vehicle's disturbance observer (default 0.5; 0 turns it
    /// off): the horizontal acceleration the commands do not explain (a vehicle's own
    /// attitude estimate off the truth, a drag mistaken), low-pass filtered and taken off
    /// the next commands.
    pub disturbance_time_constant_s: f64,
    /// What is streamed: `attitude` (SET_ATTITUDE_TARGET, the paper's outputs; default)
    /// or `acceleration` (SET_POSITION_TARGET_LOCAL_NED: PX4 closes thrust itself).
    pub setpoint: SetpointKind,
}

impl Default for SwarmSection {
    fn default() -> Self {
        Self {
            control_rate_hz: 50.0,
            attitude_rate_hz: None,
            duration_s: 60.0,
            link_timeout_ms: 1500,
            command_attempts: 10,
            end: EndAction::Land,
            on_link_loss: LossPolicy::Hold,
            gcs_system_id: DEFAULT_GCS_SYSTEM_ID,
            gcs_component_id: DEFAULT_GCS_COMPONENT_ID,
            handshake_timeout_s: 30.0,
            state_timeout_ms: 300,
            retake_offboard: false,
            estimate_hover: true,
            estimate_drag: true,
            disturbance_time_constant_s: 0.5,
            setpoint: SetpointKind::Attitude,
        }
    }
}

/// `[gains]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GainsSection {
    /// Ring gain k.
    pub k: f64,
    /// Position coupling α (1/s²).
    pub alpha: f64,
    /// Velocity coupling β (1/s).
    pub beta: f64,
    /// Altitude P (1/s²).
    pub k_pz: f64,
    /// Altitude D (1/s).
    pub k_vz: f64,
    /// Time scale `c` of the horizontal law: flies `α·c²` and `β·c`, which slows every
    /// mode by `c` and keeps the final velocity and stability (default 1).
    #[serde(default = "default_time_scale")]
    pub time_scale: f64,
    /// Altitude integral (1/s³): removes a steady altitude error; default
    /// `k_pz·k_vz/40` (a fortieth of the Routh bound), 0 turns it off.
    pub k_iz: Option<f64>,
    /// Rate (1/s) at which a uniform correction drives the w-weighted mean velocity to
    /// the predicted final velocity (default 0.5); 0 flies the paper's law as printed.
    #[serde(default = "default_k_vmean")]
    pub k_vmean: f64,
}

fn default_k_vmean() -> f64 {
    0.5
}

fn default_time_scale() -> f64 {
    1.0
}

/// `[formation]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FormationSection {
    /// `polygon` (radius_m), `line` (spacing_m) or `offsets` (offsets_m).
    pub kind: String,
    /// Polygon radius (m).
    pub radius_m: Option<f64>,
    /// Line spacing (m).
    pub spacing_m: Option<f64>,
    /// Explicit ENU offsets (m), one per vehicle.
    pub offsets_m: Option<Vec<[f64; 2]>>,
    /// Commanded altitude in the common frame (m, z up).
    pub altitude_m: f64,
    /// `optimal`: the places are interchangeable, and at each start of consensus every
    /// vehicle is given the place of minimum total squared distance; `fixed`: vehicle `i`
    /// keeps place `i`. Default `optimal` for `polygon` and `offsets`, `fixed` for `line`.
    pub assign: Option<String>,
}

/// `[envelope]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EnvelopeSection {
    /// Largest tilt (deg).
    pub max_tilt_deg: f64,
    /// Thrust limits, normalised 0..1.
    pub min_thrust: f64,
    /// Upper thrust limit, normalised.
    pub max_thrust: f64,
    /// `conserve` (default) or `clip`.
    pub saturation: SaturationMode,
    /// Thrust kept for horizontal control when the vertical command saturates
    /// (normalised, like PX4's MPC_THR_XY_MARG; default 0.3).
    pub xy_margin: f64,
}

impl Default for EnvelopeSection {
    fn default() -> Self {
        Self {
            max_tilt_deg: 35.0,
            min_thrust: 0.1,
            max_thrust: 0.9,
            saturation: SaturationMode::Conserve,
            xy_margin: 0.3,
        }
    }
}

/// `[frame]`: the common reference point.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FrameSection {
    /// Latitude (deg).
    pub latitude_deg: f64,
    /// Longitude (deg).
    pub longitude_deg: f64,
    /// Altitude AMSL (m).
    pub altitude_amsl_m: f64,
}

impl Default for FrameSection {
    fn default() -> Self {
        Self {
            latitude_deg: 47.397742,
            longitude_deg: 8.545594,
            altitude_amsl_m: 488.0,
        }
    }
}

/// `[emulator]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EmulatorSection {
    /// Height of the paper's z = 0 above the ground (m).
    pub ground_below_m: f64,
    /// Lockstep links (`demo`, tests): one-way latency (ms).
    pub latency_ms: f64,
    /// Lockstep links: uniform extra latency `0..jitter` (ms).
    pub jitter_ms: f64,
    /// Lockstep links: datagrams lost, each direction (%).
    pub loss_pct: f64,
    /// Seed of the loss and jitter draws.
    pub seed: u64,
    /// Lockstep links silenced for a while: `[[emulator.silence]]`.
    pub silence: Vec<SilenceSection>,
    /// White noise on each reported position axis (m, one standard deviation).
    pub position_noise_m: f64,
    /// White noise on each reported velocity axis (m/s, one standard deviation).
    pub velocity_noise_mps: f64,
    /// Standard deviation of a slow GPS-like horizontal position drift (m).
    pub drift_std_m: f64,
    /// Correlation time of that drift (s).
    pub drift_tau_s: f64,
    /// Age of the reported position and velocity (ms).
    pub estimator_latency_ms: f64,
    /// Fraction of the motors' thrust lost when a battery is empty (0..0.5, linear in the
    /// charge used; 0 = no sag).
    pub battery_sag: f64,
    /// Battery capacity (mAh; default the profile's BAT1_CAPACITY): a small one makes the
    /// sag show within a test flight.
    pub battery_capacity_mah: Option<f64>,
    /// Telemetry faults of one vehicle for a while: `[[emulator.fault]]`.
    pub fault: Vec<FaultSection>,
    /// Vehicles with `autopilot = "ardupilot"`: seconds after boot before their EKF has
    /// a position and they may arm (default 5; real ArduPilot SITL takes about 40).
    pub ekf_settle_s: f64,
    /// Rate (Hz) at which the emulated PX4s stream their position and attitude from boot,
    /// before a ground station sets each stream (default 50, about PX4's `onboard` MAVLink
    /// mode; its `normal` mode sends LOCAL_POSITION_NED at 1 Hz). A thousand vehicles at
    /// 50 Hz are 200 000 datagrams a second until the coordinator's handshake sets them.
    pub telemetry_rate_hz: f64,
}

/// `[[emulator.fault]]`: vehicle `vehicle` (1-based) reports something wrong between
/// `from_s` and `until_s` (simulated seconds).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FaultSection {
    /// Which vehicle (1-based position in the `[[vehicle]]` list).
    pub vehicle: usize,
    /// Start (s).
    pub from_s: f64,
    /// End (s).
    pub until_s: f64,
    /// `nan_position` (LOCAL_POSITION_NED all NaN), `no_position` (not sent, the
    /// heartbeat goes on), `origin_shift` (GPS_GLOBAL_ORIGIN moves by `shift_ned_m`) or
    /// `position_lost` (ESTIMATOR_STATUS says only the attitude is good while
    /// LOCAL_POSITION_NED goes on, dead-reckoned).
    pub kind: FaultKindName,
    /// For `origin_shift`: where the new origin is from the old one (m, NED).
    pub shift_ned_m: Option<[f64; 3]>,
    /// For `origin_shift`: whether LOCAL_POSITION_NED moves with the origin, as PX4's
    /// estimator does (default true).
    #[serde(default = "default_true")]
    pub positions_follow: bool,
}

fn default_true() -> bool {
    true
}

/// The kinds of `[[emulator.fault]]`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FaultKindName {
    /// LOCAL_POSITION_NED all NaN.
    NanPosition,
    /// LOCAL_POSITION_NED not sent.
    NoPosition,
    /// The estimator's origin moves.
    OriginShift,
    /// The estimator loses its position; its reports go on, dead-reckoned.
    PositionLost,
}

impl Default for EmulatorSection {
    fn default() -> Self {
        Self {
            ground_below_m: 0.0,
            latency_ms: 0.0,
            jitter_ms: 0.0,
            loss_pct: 0.0,
            seed: 1,
            silence: Vec::new(),
            position_noise_m: 0.0,
            velocity_noise_mps: 0.0,
            drift_std_m: 0.0,
            drift_tau_s: 60.0,
            estimator_latency_ms: 0.0,
            battery_sag: 0.0,
            battery_capacity_mah: None,
            fault: Vec::new(),
            ekf_settle_s: 5.0,
            telemetry_rate_hz: 50.0,
        }
    }
}

/// `[[emulator.silence]]`: vehicle `vehicle` (1-based, in table order) neither sends nor
/// receives between `from_s` and `until_s` (simulated seconds).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SilenceSection {
    /// Which vehicle (1-based position in the `[[vehicle]]` list).
    pub vehicle: usize,
    /// Start (s).
    pub from_s: f64,
    /// End (s).
    pub until_s: f64,
}

/// Link faults of a lockstep run.
#[cfg(feature = "emulator")]
#[derive(Debug, Clone, PartialEq)]
pub struct LockstepFaults {
    /// Latency, jitter, loss and seed on every link.
    pub conditions: ringswarm_sitl::link_faults::LinkConditions,
    /// `(vehicle index, from, until)`.
    pub silences: Vec<(
        usize,
        ringswarm_wire::time::SimTime,
        ringswarm_wire::time::SimTime,
    )>,
}

/// `[[network]]`: one UDP socket of the coordinator, shared by the vehicles that name it.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NetworkSection {
    /// The name `[[vehicle]] network` uses.
    pub name: String,
    /// Where the coordinator's socket is bound (`0.0.0.0:14550` as a ground station).
    /// The emulator's vehicles on this network send to it (to 127.0.0.1 for 0.0.0.0).
    pub bind: SocketAddr,
}

/// `[[vehicle]] serial = { device, baud }`: the autopilot on a serial port.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SerialSection {
    /// The device (`/dev/ttyAMA0`, `/dev/serial/by-id/…`, or the path `ringswarm sitl`
    /// links to the pseudo-terminal it serves the vehicle on).
    pub device: String,
    /// Line rate, bits per second (PX4's TELEM ports: 57600 for a radio, 921600 for a
    /// companion computer).
    pub baud: u32,
}

/// `[[vehicle]]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VehicleSection {
    /// MAVLink system id: unique among the vehicles of its network, or among those
    /// without one.
    pub system_id: u8,
    /// The `[[network]]` it is reached on; without one it gets a socket of its own, on
    /// PX4 SITL's ports.
    pub network: Option<String>,
    /// Where its link listens. Without a network: default PX4's 127.0.0.1:14580+i. On a
    /// network: optional, the coordinator contacts it there first (otherwise it waits
    /// for the vehicle's frames and answers where they come from).
    pub address: Option<SocketAddr>,
    /// Where the coordinator's socket for it is bound (default 0.0.0.0:14540+i, the
    /// port PX4 SITL sends its offboard link to); not on a network.
    pub bind: Option<SocketAddr>,
    /// A serial port to its autopilot instead of UDP (companion mode: a shard on the
    /// vehicle's own computer, a cable to the flight controller's TELEM port).
    pub serial: Option<SerialSection>,
    /// The autopilot it runs: `auto` (default: whatever its first HEARTBEAT names, PX4
    /// or ArduPilot), `px4` or `ardupilot` (a vehicle whose heartbeat says otherwise is
    /// refused). The emulator serves `ardupilot` with its ArduPilot personality, `auto`
    /// and `px4` with PX4's.
    #[serde(default = "default_autopilot")]
    pub autopilot: String,
    /// Emulator profile (`ideal`, `x500`, `arducopter`).
    #[serde(default = "default_profile")]
    pub profile: String,
    /// Mass (kg) for the law's thrust.
    pub mass_kg: f64,
    /// Hover throttle (0..1).
    pub hover_throttle: f64,
    /// Linear drag fed forward (1/s).
    #[serde(default)]
    pub drag_per_s: f64,
    /// Start position (ENU, m) for the emulator.
    #[serde(default)]
    pub start_enu_m: [f64; 3],
    /// Start velocity (ENU, m/s) for the emulator.
    #[serde(default)]
    pub start_velocity_enu_mps: [f64; 3],
    /// Started in the air (armed, a pilot holds the start velocity).
    #[serde(default)]
    pub in_air: bool,
    /// The emulated airframe where it differs from the model above (the coordinator's
    /// model is never exactly right): `airframe = { hover_throttle = 0.55 }`.
    pub airframe: Option<AirframeSection>,
    /// The vehicle's attitude bandwidth (rad/s, about its attitude P gain, PX4's
    /// MC_ROLL_P) for the bandwidth gate; default the profile's (x500 6.5, ideal 40).
    pub attitude_bandwidth_rps: Option<f64>,
}

/// `[[vehicle]] airframe`: the emulated airframe's true numbers, each defaulting to the
/// profile's.
#[derive(Debug, Clone, Copy, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AirframeSection {
    /// True mass (kg).
    pub mass_kg: Option<f64>,
    /// True hover throttle (0..1): sets the motors' thrust for the true mass.
    pub hover_throttle: Option<f64>,
    /// True linear drag (1/s).
    pub drag_per_s: Option<f64>,
}

fn default_autopilot() -> String {
    "auto".to_owned()
}

fn default_profile() -> String {
    "x500".to_owned()
}

impl Config {
    /// Parses a TOML text.
    ///
    /// # Errors
    /// The parser's message (syntax, unknown keys, wrong types).
    pub fn from_toml(text: &str) -> Result<Self, String> {
        toml::from_str(text).map_err(|e| e.to_string())
    }
}
