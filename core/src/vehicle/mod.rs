//! The coordinator's side of one vehicle: a sans-IO machine for its autopilot's handshake
//! (PX4's or ArduPilot's, the dialect in [`crate::link::Autopilot`]) and link health.
//! Below, OFFBOARD is the mode the vehicle is flown in and AUTO.LOITER the one it is
//! handed to: GUIDED and BRAKE on ArduPilot.
//!
//! ```text
//!  Discovering ──heartbeat from the expected system──► Streaming (setpoints at the stream rate,
//!                                                      intervals requested, origin asked for)
//!  Streaming ──pre_stream elapsed (origin known, fence held)──► Arming ──ack ACCEPTED or
//!            heartbeat armed──► Offboarding
//!  Streaming with a fence: the fence upload (`fence_upload`) runs first; a refusal or
//!            silence ──► Failed (the MISSION_ACK result named)
//!  Offboarding ──heartbeat OFFBOARD, or ACCEPTED with no other answer within 100 ms──► Flying
//!              (PX4 main answers DO_SET_MODE twice: an early ACCEPTED from its MAVLink
//!              module, then the commander's verdict; a refusal after it is a refusal)
//!  Arming/Offboarding ──no ack, or refused, within ack_timeout──► resend with confirmation+1,
//!                     up to max_attempts, then Failed (a clear reason in the event)
//!  any but Discovering/Failed ──nothing heard for link_timeout──► Lost ──heartbeat──► Streaming again
//!
//!  Flying ──two heartbeats in a row not in OFFBOARD, or disarmed (a pilot, the vehicle's
//!          own failsafe, another station)──► Overridden: never commanded again
//!          (with retake_offboard: Streaming, re-armed and taken back)
//!  Lost ──heard again, after it had flown──► Flying if still armed in OFFBOARD, else
//!          Overridden (with retake_offboard: Streaming); back to VehicleHold if it was there
//!
//!  Flying ──position older than state_timeout (silent, refused or implausible reports),
//!          or hold_on_own()──► VehicleHold (DO_SET_MODE AUTO.LOITER: the vehicle brakes
//!          and holds on its own estimate; no setpoints)
//!  VehicleHold ──fresh positions again (stale hold only)──► Streaming ──► … ──► Flying
//!
//!  land() ──► Landing (NAV_LAND, acked or heartbeat AUTO.LAND; setpoints until then)
//!  Landing ──EXTENDED_SYS_STATE on ground──► Disarming (ARM_DISARM 0, acked or heartbeat
//!  disarmed) ──► Done. A vehicle lost while landing is sent NAV_LAND again when heard.
//! ```
//!
//! From its first timeout on, in every phase, the link sends a ground-station HEARTBEAT
//! (type GCS, autopilot INVALID) every `heartbeat_interval` from its own ids, as
//! QGroundControl and MAVSDK do; PX4 watches it for its data-link-loss failsafe. The
//! first heartbeat's `autopilot` picks the dialect (`LinkConfig::autopilot`: `Auto`, or
//! only the one configured); an autopilot the coordinator does not speak, or not the one
//! configured, fails the link at discovery with a message naming the vehicle and both.
//!
//! Drive it with [`VehicleLink::handle_datagram`] for every datagram from the vehicle's
//! address, [`VehicleLink::handle_timeout`] at [`VehicleLink::poll_timeout`], and send what
//! [`VehicleLink::poll_transmit`] returns. It never reads a clock or touches a socket.
//! Frames from another system id are never acted on, and nothing is ever addressed to a
//! system other than the configured one. Position reports and origins pass the
//! [`telemetry::TelemetryGate`] first: what is non-finite, implausible or jumps is refused,
//! named in an event, and never reaches the swarm.

mod fence_upload;
mod link;
pub mod params;
pub mod telemetry;

pub use crate::link::{Autopilot, AutopilotChoice, LinkSigning};
use crate::link::{command_name, result_name};
pub use crate::safety::{FenceItem, FenceItemKind};
pub use fence_upload::{FencePlan, FenceUpload, UploadAnswer, UploadSend, UploadState};
pub use link::VehicleLink;

use std::fmt;
use std::sync::Arc;
use std::time::Duration;

use nalgebra::{UnitQuaternion, Vector3};
use ringswarm_wire::time::SimTime;

use crate::control::AttitudeThrust;
use crate::frame::Geodetic;

/// What a link streams to keep OFFBOARD and fly the vehicle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Setpoint {
    /// SET_ATTITUDE_TARGET: attitude and normalised thrust (the paper's outputs).
    Attitude(AttitudeThrust),
    /// SET_POSITION_TARGET_LOCAL_NED with an acceleration (m/s², NED): PX4 closes thrust
    /// with its own hover thrust estimate.
    Acceleration(Vector3<f64>),
}

impl From<AttitudeThrust> for Setpoint {
    fn from(sp: AttitudeThrust) -> Self {
        Self::Attitude(sp)
    }
}

/// Timing and identity of one vehicle link.
#[derive(Debug, Clone, PartialEq)]
pub struct LinkConfig {
    /// The vehicle's system id (component 1).
    pub system_id: u8,
    /// Our own system and component ids.
    pub own_ids: (u8, u8),
    /// Period of our ground-station heartbeat.
    pub heartbeat_interval: Duration,
    /// Period of the setpoint stream.
    pub setpoint_interval: Duration,
    /// Period asked for LOCAL_POSITION_NED.
    pub telemetry_interval: Duration,
    /// Period asked for ATTITUDE_QUATERNION.
    pub attitude_interval: Duration,
    /// How long to stream before arming (PX4 wants more than 1 s).
    pub pre_stream: Duration,
    /// How long to wait for an acknowledgement before resending.
    pub ack_timeout: Duration,
    /// Attempts per command before giving up.
    pub max_attempts: u8,
    /// Silence after which the vehicle is lost.
    pub link_timeout: Duration,
    /// How long to wait for a first heartbeat before reporting the vehicle as never heard.
    pub discovery_warning: Duration,
    /// Age of the last accepted position after which a flying vehicle is handed to its
    /// own Hold (and a position jump followed this long is taken).
    pub state_timeout: Duration,
    /// Re-arm and take back a vehicle that left OFFBOARD by itself (default false).
    pub retake_offboard: bool,
    /// MAVLink 2 signing of this link (default none: unsigned frames both ways).
    pub signing: Option<LinkSigning>,
    /// The MAVLink network the vehicle is reached on (system ids repeat across
    /// networks): part of its name in files.
    pub network: Option<String>,
    /// The fence to give the vehicle before it is armed (mission type FENCE), if any.
    pub fence: Option<Arc<FencePlan>>,
    /// The autopilot it must run (default: whichever its first heartbeat names).
    pub autopilot: AutopilotChoice,
}

impl LinkConfig {
    /// The vehicle's name in file names: `<system id>`, or `<network>-<system id>` on a
    /// network.
    pub fn file_label(&self) -> String {
        match &self.network {
            Some(network) => format!("{network}-{}", self.system_id),
            None => self.system_id.to_string(),
        }
    }
}

impl LinkConfig {
    /// Defaults for `system_id`: our ids 253/190, a 1 Hz heartbeat, 50 Hz setpoints and
    /// telemetry, 1.2 s pre-stream, 0.5 s ack timeout and 4 attempts (MAVSDK's), 1.5 s link
    /// timeout, 0.3 s state timeout, no retake.
    pub fn new(system_id: u8) -> Self {
        Self {
            system_id,
            own_ids: (253, 190),
            heartbeat_interval: Duration::from_secs(1),
            setpoint_interval: Duration::from_millis(20),
            telemetry_interval: Duration::from_millis(20),
            attitude_interval: Duration::from_millis(20),
            pre_stream: Duration::from_millis(1200),
            ack_timeout: Duration::from_millis(500),
            max_attempts: 4,
            link_timeout: Duration::from_millis(1500),
            discovery_warning: Duration::from_secs(10),
            network: None,
            state_timeout: Duration::from_millis(300),
            retake_offboard: false,
            signing: None,
            fence: None,
            autopilot: AutopilotChoice::Auto,
        }
    }
}

/// Where the handshake is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    /// Waiting for a heartbeat from the expected system.
    Discovering,
    /// Streaming setpoints before arming, since the given time.
    Streaming(SimTime),
    /// Waiting for the arm acknowledgement.
    Arming,
    /// Waiting for the OFFBOARD acknowledgement.
    Offboarding,
    /// Armed and in OFFBOARD.
    Flying,
    /// Silent for longer than the link timeout.
    Lost,
    /// Gave up on a command.
    Failed,
    /// Told to land; waiting for the touchdown.
    Landing,
    /// On the ground, waiting for the disarm.
    Disarming,
    /// Landed and disarmed (or never armed when told to land).
    Done,
    /// Left OFFBOARD while flying (a pilot, its own failsafe or another station took it):
    /// nothing is sent to it any more.
    Overridden,
    /// Handed to its own Hold mode (AUTO.LOITER) because it could not be flown on (stale or
    /// refused position, or a command that could not be computed): no setpoints.
    VehicleHold,
}

impl Phase {
    /// A short lower-case name, as written in the run directory.
    pub fn name(self) -> &'static str {
        match self {
            Self::Discovering => "discovering",
            Self::Streaming(_) => "streaming",
            Self::Arming => "arming",
            Self::Offboarding => "offboarding",
            Self::Flying => "flying",
            Self::Lost => "lost",
            Self::Failed => "failed",
            Self::Landing => "landing",
            Self::Disarming => "disarming",
            Self::Done => "done",
            Self::Overridden => "overridden",
            Self::VehicleHold => "vehicle_hold",
        }
    }
}

/// What the swarm should know.
#[derive(Debug, Clone, PartialEq)]
pub enum LinkEvent {
    /// First heartbeat from the expected system, and the autopilot it names.
    Discovered {
        /// Its autopilot.
        autopilot: Autopilot,
    },
    /// The vehicle reports armed.
    Armed,
    /// The vehicle is in OFFBOARD and armed.
    Flying,
    /// A command was refused or not acknowledged and is being resent.
    Retrying {
        /// MAV_CMD id.
        command: u16,
        /// The attempt about to be sent (1-based).
        attempt: u8,
    },
    /// The handshake gave up.
    Failed(String),
    /// A frame from another system arrived on this vehicle's link (ignored).
    WrongSystem {
        /// Its system id.
        system_id: u8,
    },
    /// Silent for longer than the link timeout.
    Lost,
    /// Heard again after being lost.
    Recovered,
    /// Nothing heard from the expected system since the link started (reported once).
    NeverHeard {
        /// How long the link has waited.
        after: Duration,
    },
    /// NAV_LAND accepted: the vehicle is descending.
    Landing,
    /// On the ground (EXTENDED_SYS_STATE).
    Landed,
    /// Disarmed on the ground: the link is done.
    Disarmed,
    /// Left OFFBOARD (GUIDED) while flying; the custom mode it reports now.
    LeftOffboard {
        /// Its autopilot (whose mode numbers `custom_mode` is in).
        autopilot: Autopilot,
        /// The heartbeat's custom mode.
        custom_mode: u32,
        /// Armed, as that heartbeat says.
        armed: bool,
    },
    /// A command was refused (it is resent until its attempts run out).
    Refused {
        /// MAV_CMD id.
        command: u16,
        /// MAV_RESULT value.
        result: u8,
    },
    /// A telemetry report was refused (first of a run of refusals; the field named).
    TelemetryRefused(String),
    /// The vehicle reported a new GPS_GLOBAL_ORIGIN: re-anchored.
    OriginChanged {
        /// Distance between the old and the new origin (m).
        shift_m: f64,
    },
    /// A position jump followed consistently for the state timeout was taken.
    PositionReset {
        /// The jump (m).
        jump_m: f64,
    },
    /// Its estimator says the position and velocity it reports are not good (ESTIMATOR_STATUS
    /// flags as sent): they are not flown on.
    EstimateLost {
        /// The flags.
        flags: u16,
    },
    /// Its estimator says they are good again.
    EstimateGood {
        /// The flags.
        flags: u16,
    },
    /// Handed to its own Hold mode, and why.
    HandedToHold(String),
    /// The vehicle acknowledged the fence (this many items).
    FenceUploaded {
        /// Items uploaded.
        items: usize,
    },
    /// A frame from the vehicle failed the signing rules (reported once per link; the
    /// count is in [`crate::vehicle::VehicleLink::refused_frames`]).
    SigningRefused(String),
    /// The vehicle said this (a STATUSTEXT of severity WARNING or worse; a repeat of the
    /// last one is not reported again).
    VehicleSays(String),
    /// The hover throttle the vehicle reports of itself (ArduPilot's learnt
    /// MOT_THST_HOVER): the swarm starts its hover estimate from it.
    HoverReported {
        /// Normalised thrust at hover (0..1).
        hover_throttle: f64,
    },
    /// A vehicle parameter written by the handshake (`from` → `to`), or put back at the
    /// end (`restored`).
    ParamWritten {
        /// The vehicle's name for it.
        name: &'static str,
        /// The value before.
        from: f32,
        /// The value after.
        to: f32,
        /// Whether this is the end-of-flight restore.
        restored: bool,
    },
}

impl LinkEvent {
    /// Whether an operator must see it (lost, refused, timeouts, failsafes, origin
    /// changes); the others are the handshake's progress.
    pub fn is_warning(&self) -> bool {
        !matches!(
            self,
            Self::Discovered { .. }
                | Self::Armed
                | Self::HoverReported { .. }
                | Self::ParamWritten { .. }
                | Self::Flying
                | Self::Recovered
                | Self::EstimateGood { .. }
                | Self::FenceUploaded { .. }
                | Self::Landing
                | Self::Landed
                | Self::Disarmed
        )
    }
}

impl fmt::Display for LinkEvent {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Discovered { autopilot } => write!(f, "discovered ({})", autopilot.name()),
            Self::Armed => write!(f, "armed"),
            Self::Flying => write!(f, "flying"),
            Self::Retrying { command, attempt } => write!(
                f,
                "{} not acknowledged: attempt {attempt}",
                command_name(*command)
            ),
            Self::Failed(reason) => write!(f, "failed: {reason}"),
            Self::WrongSystem { system_id } => {
                write!(f, "frames from system {system_id} on this link ignored")
            }
            Self::Lost => write!(f, "lost (link timeout)"),
            Self::Recovered => write!(f, "heard again"),
            Self::NeverHeard { after } => {
                write!(f, "never heard after {:.1} s", after.as_secs_f64())
            }
            Self::Landing => write!(f, "landing"),
            Self::Landed => write!(f, "landed"),
            Self::Disarmed => write!(f, "disarmed"),
            Self::LeftOffboard {
                autopilot,
                custom_mode,
                armed,
            } => write!(
                f,
                "left {} by itself: now in {} ({})",
                autopilot.fly_mode_name(),
                autopilot.mode_name(*custom_mode),
                if *armed { "armed" } else { "disarmed" }
            ),
            Self::Refused { command, result } => write!(
                f,
                "{} refused: {}",
                command_name(*command),
                result_name(*result)
            ),
            Self::TelemetryRefused(why) => write!(f, "telemetry refused: {why}"),
            Self::OriginChanged { shift_m } => {
                write!(f, "GPS_GLOBAL_ORIGIN moved {shift_m:.2} m: re-anchored")
            }
            Self::PositionReset { jump_m } => write!(
                f,
                "position jump of {jump_m:.2} m taken after it was followed consistently"
            ),
            Self::EstimateLost { flags } => write!(
                f,
                "estimator reports no good position and velocity (ESTIMATOR_STATUS flags 0x{flags:03x}): not flown on"
            ),
            Self::EstimateGood { flags } => write!(
                f,
                "estimator reports a good position and velocity again (flags 0x{flags:03x})"
            ),
            Self::HandedToHold(why) => write!(f, "handed to its own Hold: {why}"),
            Self::FenceUploaded { items } => {
                let s = if *items == 1 { "" } else { "s" };
                write!(f, "holds the fence ({items} fence item{s})")
            }
            Self::SigningRefused(why) => write!(
                f,
                "frames refused by signing ({why}); is the vehicle provisioned with this key?"
            ),
            Self::VehicleSays(text) => write!(f, "says \"{text}\""),
            Self::HoverReported { hover_throttle } => {
                write!(f, "reports its hover throttle: {hover_throttle:.3}")
            }
            Self::ParamWritten {
                name,
                from,
                to,
                restored,
            } => {
                let what = if *restored { "put back" } else { "set" };
                write!(f, "parameter {name} {what}: {from} -> {to}")
            }
        }
    }
}

/// What the coordinator knows of the vehicle (its own frames: local NED, body FRD).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct VehicleState {
    /// Position relative to the vehicle's own origin (m).
    pub pos_local_ned_m: Vector3<f64>,
    /// Velocity (m/s).
    pub vel_ned_mps: Vector3<f64>,
    /// Attitude.
    pub attitude: Option<UnitQuaternion<f64>>,
    /// The local frame's geodetic origin, once reported.
    pub origin: Option<Geodetic>,
    /// Armed, as the last heartbeat said.
    pub armed: bool,
    /// The autopilot its first heartbeat named (`None` before it was heard).
    pub autopilot: Option<Autopilot>,
    /// Custom mode of the last heartbeat (in its autopilot's numbering).
    pub custom_mode: u32,
    /// Whether its pre-arm checks pass, where it reports them (SYS_STATUS).
    pub prearm_ok: Option<bool>,
    /// A failsafe acts, as the last heartbeat said (system status CRITICAL).
    pub failsafe: bool,
    /// On the ground, as EXTENDED_SYS_STATE said.
    pub landed: bool,
    /// When the last heartbeat arrived.
    pub last_heartbeat: Option<SimTime>,
    /// When any valid frame from the vehicle last arrived (link health).
    pub last_heard: Option<SimTime>,
    /// When the last accepted local position arrived (cleared when the origin moves, so
    /// no position is read against the wrong origin).
    pub last_position: Option<SimTime>,
    /// The vehicle's estimator flags, when its last ESTIMATOR_STATUS said the position
    /// and velocity it reports are not good (`None`: good, or never said).
    pub estimate_lost: Option<u16>,
}

impl VehicleState {
    /// Its dialect: the autopilot its heartbeat named, PX4 before it was heard.
    pub fn dialect(&self) -> Autopilot {
        self.autopilot.unwrap_or(Autopilot::Px4)
    }

    /// Whether the heartbeat says it is in the mode it is flown in (PX4 OFFBOARD,
    /// ArduPilot GUIDED or GUIDED_NOGPS).
    pub fn in_fly_mode(&self) -> bool {
        self.dialect().in_fly_mode(self.custom_mode)
    }

    /// Whether the heartbeat says its landing mode (AUTO.LAND, LAND).
    pub fn in_land(&self) -> bool {
        self.dialect().in_land(self.custom_mode)
    }

    /// Whether the heartbeat says the hold mode it is handed to (AUTO.LOITER, BRAKE).
    pub fn in_hold(&self) -> bool {
        self.dialect().in_hold(self.custom_mode)
    }

    /// Its autopilot's name for the heartbeat's mode.
    pub fn mode_name(&self) -> String {
        self.dialect().mode_name(self.custom_mode)
    }
}
