//! What the swarm machine is given: the validated setup and its policies.

use std::time::Duration;

use nalgebra::Vector2;

use crate::consensus::{BandwidthCheck, CouplingGains, RingDigraph};
use crate::control::{AltitudeGains, Envelope, SaturationMode, VehicleModel};
use crate::frame::CommonFrame;
use crate::vehicle::LinkConfig;

/// Everything the swarm machine needs, validated by the caller (see `config`).
#[derive(Debug, Clone)]
pub struct SwarmSetup {
    /// The ring.
    pub ring: RingDigraph,
    /// `(α, β)`.
    pub gains: CouplingGains,
    /// `(k_pz, k_vz)`.
    pub altitude_gains: AltitudeGains,
    /// Commanded altitude in the common frame (m, z up).
    pub altitude_m: f64,
    /// Formation offsets `dᵢ` (m, ENU), one per vehicle.
    pub offsets_m: Vec<Vector2<f64>>,
    /// Whether the places are interchangeable: at each start of consensus every vehicle
    /// is given the place of minimum total squared distance (`crate::assignment`);
    /// otherwise vehicle `i` flies to `offsets_m[i]`.
    pub assign_places: bool,
    /// Whether the assignment is solved off the control loop: the swarm hands it out
    /// ([`crate::swarm::Swarm::take_assignment_job`]) and flies the places it had until the
    /// answer comes back. Set by flights in real time, where a thousand vehicles' solve
    /// (about 0.2 s) would make its control tick late; lockstep flights solve in the tick,
    /// so that they do not depend on the machine.
    pub assign_off_tick: bool,
    /// Vehicle models, one per vehicle.
    pub models: Vec<VehicleModel>,
    /// Linear drag of each vehicle (1/s), fed forward.
    pub drag_per_s: Vec<f64>,
    /// Envelope and saturation mode.
    pub envelope: Envelope,
    /// How commands are saturated.
    pub saturation: SaturationMode,
    /// Control period.
    pub control_interval: Duration,
    /// The common frame.
    pub frame: CommonFrame,
    /// One link configuration per vehicle.
    pub links: Vec<LinkConfig>,
    /// How long consensus runs before the end action (`None`: until told to land).
    pub duration: Option<Duration>,
    /// How long the vehicles have to be flying before the swarm gives up and lands.
    pub handshake_timeout: Duration,
    /// Estimate each vehicle's hover thrust in flight and fly with it.
    pub estimate_hover: bool,
    /// Estimate each vehicle's drag in flight; the drag fed forward never exceeds the
    /// estimate's lower confidence bound.
    pub estimate_drag: bool,
    /// Time constant (s) of each vehicle's disturbance observer, whose estimate is taken
    /// off the commands; 0: off.
    pub disturbance_time_constant_s: f64,
    /// Rate (1/s) at which the w-weighted mean velocity is driven to the predicted final
    /// velocity during consensus; 0 flies the paper's law as printed.
    pub mean_velocity_gain: f64,
    /// What the links stream.
    pub setpoint: SetpointKind,
    /// The bandwidth gate of the gains as configured (`None`: not run); the planner keeps
    /// its `k` within the fastest mode it allows.
    pub bandwidth: Option<BandwidthCheck>,
    /// What the swarm does when the duration is over.
    pub end_action: EndAction,
    /// What the swarm does when a vehicle is lost during consensus.
    pub loss_policy: LossPolicy,
    /// A final velocity to reach with the planner (stage 1), if any.
    pub target: Option<TargetVelocity>,
    /// The divergence guard's bounds (`None`: off).
    pub guard: Option<super::GuardLimits>,
    /// The safety filter's separation (`None`: off).
    pub safety: Option<SafetySetup>,
    /// The fence (`None`: none).
    pub fence: Option<FenceSetup>,
}

/// The fence and what the swarm does at it.
#[derive(Debug, Clone, PartialEq)]
pub struct FenceSetup {
    /// Where the swarm may fly.
    pub fence: crate::safety::Fence,
    /// How close to it a stopping point may come (m).
    pub margin_m: f64,
    /// `Hold` (brake and hover) or `Land`.
    pub action: LossPolicy,
}

/// What the safety filter enforces.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SafetySetup {
    /// The downwash ellipsoid and the barrier's gain.
    pub separation: crate::safety::Separation,
    /// The share of each vehicle's horizontal envelope counted on for braking.
    pub braking_share: f64,
    /// What the swarm does when the filter cannot keep a pair apart.
    pub action: BreachAction,
    /// Breaking jams (`None`: off): vehicles the filter holds without progress are
    /// turned past each other (`crate::safety::jam`).
    pub jams: Option<crate::safety::jam::JamSettings>,
    /// The share of the control period the filter may take (wall clock), when
    /// `wall_clock_budget`.
    pub budget_share: f64,
    /// Whether the filter's time is limited by the wall clock (flights in real time).
    /// Off in lockstep, where only the sweep limit applies and a flight does not depend
    /// on the machine.
    pub wall_clock_budget: bool,
}

/// The barrier's class-K gain `γ` in `ḣ ≥ −γh³` (s/m²): a pair 1 m/s from its braking
/// curve may close on it at 1 m/s².
pub const SAFETY_GAMMA: f64 = 1.0;

/// The planner's job: reach `velocity_mps` by choosing `k` and, if needed, re-targeting
/// one agent (the paper's plan) or several (the least change of every velocity) before
/// consensus starts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TargetVelocity {
    /// Desired final velocity (m/s, ENU).
    pub velocity_mps: Vector2<f64>,
    /// `k ≥ k_min + k_margin`.
    pub k_margin: f64,
    /// `k ≤ k_max`.
    pub k_max: f64,
    /// Largest speed a re-targeted agent may be asked for (m/s).
    pub max_speed_mps: Option<f64>,
    /// Stage 1 ends when every re-targeted agent is this close to its planned velocity
    /// (m/s).
    pub tolerance_mps: f64,
    /// Stage 1 ends at the latest after this long; consensus then starts from the
    /// velocities reached (with a warning).
    pub timeout: Duration,
    /// Plan only once every vehicle flies level at the commanded altitude (within 1 m,
    /// under 0.5 m/s vertically; at most 30 s of waiting).
    pub wait_for_altitude: bool,
}

/// A re-targeted agent (0-based) and its planned velocity (m/s, ENU).
pub type Retargeted = (usize, Vector2<f64>);

/// What the planner decided when consensus was about to start.
#[derive(Debug, Clone, PartialEq)]
pub enum PlanDecision {
    /// Flying the planned `k`, after re-targeting the listed agents (0-based) to their
    /// planned velocities: none, the paper's one agent, or as many as the least change
    /// of every velocity needs.
    Planned {
        /// The gain flown.
        k: f64,
        /// The re-targeted agents and their planned velocities (empty: none).
        retarget: Vec<Retargeted>,
    },
    /// Not used: the configured `k` is flown. Why, in words.
    Rejected(String),
}

/// What the links stream to the vehicles.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum SetpointKind {
    /// Attitude and normalised thrust (SET_ATTITUDE_TARGET), from the coordinator's model.
    #[default]
    Attitude,
    /// Acceleration (SET_POSITION_TARGET_LOCAL_NED): PX4 turns it into thrust with its own
    /// hover thrust estimate.
    Acceleration,
}

/// What the swarm does at the end of the configured duration.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum EndAction {
    /// Every vehicle lands and disarms.
    #[default]
    Land,
    /// Every vehicle brakes and hovers in place until told to land.
    Hold,
}

/// What the swarm does when the safety filter could not keep two vehicles apart (a pair
/// closer than [`BREACH_SHARE`] of the separation, or a fallback).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum BreachAction {
    /// The flight goes on (the filter keeps pushing the pair apart); a warning is logged.
    Continue,
    /// Every vehicle brakes and hovers where it is, the filter still acting.
    #[default]
    Hold,
    /// Every vehicle lands.
    Land,
}

/// A pair closer than this share of the separation counts as the filter not keeping it
/// (the 5 % below the separation the relaxed rows and the state's age may take).
pub const BREACH_SHARE: f64 = 0.95;

/// What the swarm does when a vehicle's link is lost during consensus.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum LossPolicy {
    /// The others brake and hover in place; when the vehicle is handshaken again the
    /// consensus resumes (with a new predicted final velocity).
    #[default]
    Hold,
    /// Every vehicle lands.
    Land,
}
