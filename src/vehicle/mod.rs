//! The coordinator's side of one vehicle: a sans-IO machine for PX4's offboard handshake
//! and link health.
//!
//! ```text
//!  Discovering ──heartbeat from the expected system──► Streaming (setpoints at the stream rate,
//!                                                      intervals requested, origin asked for)
//!  Streaming ──pre_stream elapsed──► Arming ──ack ACCEPTED or heartbeat armed──► Offboarding
//!  Offboarding ──heartbeat OFFBOARD, or ACCEPTED with no other answer within 100 ms──► Flying
//!              (PX4 main answers DO_SET_MODE twice: an early ACCEPTED from its MAVLink
//!              module, then the commander's verdict; a refusal after it is a refusal)
//!  Arming/Offboarding ──no ack, or refused, within ack_timeout──► resend with confirmation+1,
//!                     up to max_attempts, then Failed (a clear reason in the event)
//!  any but Discovering/Failed ──nothing heard for link_timeout──► Lost ──heartbeat──► Streaming again
//!
//!  Flying ──two heartbeats in a row not in OFFBOARD (a pilot, the vehicle's own failsafe,
//!          another station)──► Overridden: never commanded again
//!
//!  land() ──► Landing (NAV_LAND, acked or heartbeat AUTO.LAND; setpoints until then)
//!  Landing ──EXTENDED_SYS_STATE on ground──► Disarming (ARM_DISARM 0, acked or heartbeat
//!  disarmed) ──► Done. A vehicle lost while landing is sent NAV_LAND again when heard.
//! ```
//!
//! From its first timeout on, in every phase, the link sends a ground-station HEARTBEAT
//! (type GCS, autopilot INVALID) every `heartbeat_interval` from its own ids, as
//! QGroundControl and MAVSDK do; PX4 watches it for its data-link-loss failsafe. A first
//! heartbeat whose `autopilot` is not PX4 fails the link at discovery, with a message
//! naming the vehicle and its autopilot: PX4's mode numbers mean something else elsewhere.
//!
//! Drive it with [`VehicleLink::handle_datagram`] for every datagram from the vehicle's
//! address, [`VehicleLink::handle_timeout`] at [`VehicleLink::poll_timeout`], and send what
//! [`VehicleLink::poll_transmit`] returns. It never reads a clock or touches a socket.
//! Frames from another system id are never acted on, and nothing is ever addressed to a
//! system other than the configured one.

use std::collections::VecDeque;
use std::time::Duration;

use mavlink::dialects::common::{COMMAND_LONG_DATA, MavCmd, MavMessage};
use nalgebra::{UnitQuaternion, Vector3};
use ringswarm_sitl::time::SimTime;

use crate::control::AttitudeThrust;
use crate::frame::Geodetic;
use crate::link::{
    AUTOPILOT_PX4, Encoder, Inbound, autopilot_name, decode_datagram, gcs_heartbeat, inbound,
    set_attitude_target,
};

/// PX4's OFFBOARD main mode.
const PX4_MAIN_OFFBOARD: u32 = 6;
/// MAV_RESULT_ACCEPTED.
const ACCEPTED: u8 = 0;
/// How long an ACCEPTED for DO_SET_MODE waits for a second, real answer (PX4 main sends
/// it a few milliseconds after its early ACCEPTED).
const MODE_ACK_SETTLE: Duration = Duration::from_millis(100);
/// Message ids the coordinator asks to be streamed, and GPS_GLOBAL_ORIGIN asked once.
const LOCAL_POSITION_NED: f32 = 32.0;
const ATTITUDE_QUATERNION: f32 = 31.0;
const GPS_GLOBAL_ORIGIN: f32 = 49.0;
/// PX4's AUTO main mode and its LAND sub mode.
const PX4_MAIN_AUTO: u32 = 4;
const PX4_SUB_AUTO_LAND: u32 = 6;

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
    /// Period asked for LOCAL_POSITION_NED and ATTITUDE_QUATERNION.
    pub telemetry_interval: Duration,
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
}

impl LinkConfig {
    /// Defaults for `system_id`: our ids 253/190, a 1 Hz heartbeat, 50 Hz setpoints and
    /// telemetry, 1.2 s pre-stream, 0.5 s ack timeout and 4 attempts (MAVSDK's), 1.5 s link
    /// timeout.
    pub fn new(system_id: u8) -> Self {
        Self {
            system_id,
            own_ids: (253, 190),
            heartbeat_interval: Duration::from_secs(1),
            setpoint_interval: Duration::from_millis(20),
            telemetry_interval: Duration::from_millis(20),
            pre_stream: Duration::from_millis(1200),
            ack_timeout: Duration::from_millis(500),
            max_attempts: 4,
            link_timeout: Duration::from_millis(1500),
            discovery_warning: Duration::from_secs(10),
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
}

/// What the swarm should know.
#[derive(Debug, Clone, PartialEq)]
pub enum LinkEvent {
    /// First heartbeat from the expected system.
    Discovered,
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
    /// Left OFFBOARD while flying; PX4's custom mode it reports now.
    LeftOffboard {
        /// The heartbeat's custom mode.
        custom_mode: u32,
    },
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
    /// PX4 custom mode of the last heartbeat.
    pub custom_mode: u32,
    /// On the ground, as EXTENDED_SYS_STATE said.
    pub landed: bool,
    /// When the last heartbeat arrived.
    pub last_heartbeat: Option<SimTime>,
    /// When any valid frame from the vehicle last arrived (link health).
    pub last_heard: Option<SimTime>,
    /// When the last local position arrived.
    pub last_position: Option<SimTime>,
}

impl VehicleState {
    /// Whether the heartbeat says OFFBOARD.
    pub fn in_offboard(&self) -> bool {
        (self.custom_mode >> 16) & 0xFF == PX4_MAIN_OFFBOARD
    }

    /// Whether the heartbeat says AUTO.LAND.
    pub fn in_land(&self) -> bool {
        (self.custom_mode >> 16) & 0xFF == PX4_MAIN_AUTO
            && (self.custom_mode >> 24) & 0xFF == PX4_SUB_AUTO_LAND
    }
}

/// A command waiting for its acknowledgement.
#[derive(Debug, Clone, Copy)]
struct Pending {
    command: MavCmd,
    params: [f32; 7],
    attempt: u8,
    deadline: SimTime,
    /// An ACCEPTED that may still be followed by the real answer.
    accepted: bool,
}

/// One vehicle link.
#[derive(Debug, Clone)]
pub struct VehicleLink {
    cfg: LinkConfig,
    phase: Phase,
    state: VehicleState,
    setpoint: AttitudeThrust,
    next_setpoint: SimTime,
    next_heartbeat: SimTime,
    pending: Option<Pending>,
    encoder: Encoder,
    outbox: VecDeque<Vec<u8>>,
    events: VecDeque<LinkEvent>,
    ignored_frames: u64,
    wrong_system: Option<u8>,
    land_requested: bool,
    never_heard_reported: bool,
    heartbeats_out_of_offboard: u8,
}

impl VehicleLink {
    /// A link that starts discovering, with `idle` as the setpoint to stream until the law
    /// takes over (normally level at hover throttle).
    pub fn new(cfg: LinkConfig, idle: AttitudeThrust) -> Self {
        let encoder = Encoder::new(cfg.own_ids.0, cfg.own_ids.1);
        Self {
            cfg,
            phase: Phase::Discovering,
            state: VehicleState::default(),
            setpoint: idle,
            next_setpoint: SimTime::ZERO,
            next_heartbeat: SimTime::ZERO,
            pending: None,
            encoder,
            outbox: VecDeque::new(),
            events: VecDeque::new(),
            ignored_frames: 0,
            wrong_system: None,
            land_requested: false,
            never_heard_reported: false,
            heartbeats_out_of_offboard: 0,
        }
    }

    /// The phase.
    pub fn phase(&self) -> Phase {
        self.phase
    }

    /// What is known of the vehicle.
    pub fn state(&self) -> &VehicleState {
        &self.state
    }

    /// The setpoint being streamed.
    pub fn setpoint(&self) -> AttitudeThrust {
        self.setpoint
    }

    /// Frames ignored (undecodable, another system, another component).
    pub fn ignored_frames(&self) -> u64 {
        self.ignored_frames
    }

    /// Replaces the setpoint. While streaming it is sent at once, so the stream follows
    /// the control ticks; the link's own timer only resends it if no new setpoint comes
    /// within one and a half periods (it never doubles the rate when the two timers drift).
    pub fn set_setpoint(&mut self, now: SimTime, setpoint: AttitudeThrust) {
        self.setpoint = setpoint;
        if self.streams() {
            self.send_setpoint(now);
            self.next_setpoint = now + self.cfg.setpoint_interval.mul_f64(1.5);
        }
    }

    fn send_setpoint(&mut self, now: SimTime) {
        let msg = set_attitude_target(&self.setpoint, self.cfg.system_id, now.boot_ms());
        self.outbox.push_back(self.encoder.encode(&msg));
    }

    /// The next datagram to send to the vehicle.
    pub fn poll_transmit(&mut self) -> Option<Vec<u8>> {
        self.outbox.pop_front()
    }

    /// The next event.
    pub fn poll_event(&mut self) -> Option<LinkEvent> {
        self.events.pop_front()
    }

    /// When [`VehicleLink::handle_timeout`] must next be called.
    pub fn poll_timeout(&self) -> SimTime {
        let mut next = self
            .state
            .last_heard
            .map_or(SimTime::from_millis(100), |t| t + self.cfg.link_timeout)
            .min(self.next_heartbeat);
        if self.streams() {
            next = next.min(self.next_setpoint);
        }
        if let Some(p) = self.pending {
            next = next.min(p.deadline);
        }
        if let Phase::Streaming(since) = self.phase {
            next = next.min(since + self.cfg.pre_stream);
        }
        if self.phase == Phase::Discovering && !self.never_heard_reported {
            next = next.min(SimTime::ZERO + self.cfg.discovery_warning);
        }
        next
    }

    fn streams(&self) -> bool {
        match self.phase {
            Phase::Discovering
            | Phase::Lost
            | Phase::Failed
            | Phase::Disarming
            | Phase::Done
            | Phase::Overridden => false,
            // Keep OFFBOARD fed until the vehicle has taken NAV_LAND.
            Phase::Landing => self.pending.is_some() && self.state.in_offboard(),
            _ => true,
        }
    }

    /// Tells the vehicle to land where it is and to disarm on the ground. Idempotent. A
    /// vehicle never heard from, or heard but never armed, is done at once.
    pub fn land(&mut self, now: SimTime) {
        if self.land_requested {
            return;
        }
        self.land_requested = true;
        match self.phase {
            Phase::Discovering => self.phase = Phase::Done,
            Phase::Overridden => {} // someone else flies it
            Phase::Streaming(_) if !self.state.armed => {
                self.pending = None;
                self.phase = Phase::Done;
            }
            Phase::Lost => {} // sent when the vehicle is heard again
            _ => self.request_land(now),
        }
    }

    /// Whether [`VehicleLink::land`] was called.
    pub fn land_requested(&self) -> bool {
        self.land_requested
    }

    fn request_land(&mut self, now: SimTime) {
        self.phase = Phase::Landing;
        let nan = f32::NAN; // PX4: NaN lat/lon/alt/yaw = here, current heading
        let params = [0.0, 0.0, 0.0, nan, nan, nan, nan];
        self.send_pending(now, MavCmd::MAV_CMD_NAV_LAND, params, 1);
    }

    fn request_disarm(&mut self, now: SimTime) {
        self.phase = Phase::Disarming;
        self.events.push_back(LinkEvent::Landed);
        let params = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        self.send_pending(now, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, params, 1);
    }

    fn finish(&mut self) {
        self.pending = None;
        self.phase = Phase::Done;
        self.events.push_back(LinkEvent::Disarmed);
    }

    /// Handles one datagram from the vehicle's address.
    pub fn handle_datagram(&mut self, now: SimTime, bytes: &[u8]) {
        for frame in decode_datagram(bytes) {
            let Ok(frame) = frame else {
                self.ignored_frames += 1;
                continue;
            };
            let system_id = frame.header.system_id as u8;
            if system_id != self.cfg.system_id {
                self.ignored_frames += 1;
                if self.wrong_system != Some(system_id) {
                    // Reported once per foreign system id, not per frame.
                    self.wrong_system = Some(system_id);
                    self.events.push_back(LinkEvent::WrongSystem { system_id });
                }
                continue;
            }
            if frame.header.component_id != 1 {
                self.ignored_frames += 1;
                continue;
            }
            if let MavMessage::COMMAND_ACK(ack) = &frame.msg
                && (ack.target_system != 0 && ack.target_system != self.cfg.own_ids.0)
            {
                continue; // an acknowledgement meant for another ground station
            }
            self.state.last_heard = Some(now);
            if let Some(update) = inbound(&frame.msg) {
                self.apply(now, update);
            }
        }
    }

    fn apply(&mut self, now: SimTime, update: Inbound) {
        match update {
            Inbound::Heartbeat {
                armed,
                custom_mode,
                autopilot,
            } => {
                if self.phase == Phase::Discovering && autopilot != AUTOPILOT_PX4 {
                    self.refuse_autopilot(autopilot);
                    return;
                }
                self.state.last_heartbeat = Some(now);
                self.state.custom_mode = custom_mode;
                if armed && !self.state.armed {
                    self.events.push_back(LinkEvent::Armed);
                }
                self.state.armed = armed;
                match self.phase {
                    Phase::Discovering => {
                        self.events.push_back(LinkEvent::Discovered);
                        self.start_streaming(now);
                    }
                    Phase::Lost => {
                        self.events.push_back(LinkEvent::Recovered);
                        if self.land_requested {
                            self.request_land(now);
                        } else {
                            self.start_streaming(now);
                        }
                    }
                    Phase::Flying => {
                        // Two in a row: a heartbeat sent just before the switch may still
                        // arrive after the acknowledgement.
                        if self.state.in_offboard() {
                            self.heartbeats_out_of_offboard = 0;
                        } else {
                            self.heartbeats_out_of_offboard += 1;
                            if self.heartbeats_out_of_offboard >= 2 {
                                tracing::warn!(
                                    sysid = self.cfg.system_id,
                                    custom_mode,
                                    "vehicle left OFFBOARD: no longer commanded"
                                );
                                self.phase = Phase::Overridden;
                                self.pending = None;
                                self.events
                                    .push_back(LinkEvent::LeftOffboard { custom_mode });
                            }
                        }
                    }
                    _ => self.advance_on_state(now),
                }
            }
            Inbound::LocalPosition {
                pos_ned_m,
                vel_ned_mps,
            } => {
                self.state.pos_local_ned_m = pos_ned_m;
                self.state.vel_ned_mps = vel_ned_mps;
                self.state.last_position = Some(now);
            }
            Inbound::Attitude(q) => self.state.attitude = Some(q),
            Inbound::Origin(origin) => self.state.origin = Some(origin),
            Inbound::Landed(landed) => {
                self.state.landed = landed;
                self.advance_on_state(now);
            }
            Inbound::Ack { command, result } => self.on_ack(now, command, result),
        }
    }

    /// A vehicle whose autopilot is not PX4 is never commanded: PX4's mode numbers and
    /// offboard rules would mean something else to it.
    fn refuse_autopilot(&mut self, autopilot: u8) {
        let reason = format!(
            "vehicle {}: autopilot is {}, not PX4: refused (ringswarm speaks PX4's modes only)",
            self.cfg.system_id,
            autopilot_name(autopilot)
        );
        tracing::error!(sysid = self.cfg.system_id, autopilot, "autopilot not PX4");
        self.phase = Phase::Failed;
        self.pending = None;
        self.events.push_back(LinkEvent::Failed(reason));
    }

    fn start_streaming(&mut self, now: SimTime) {
        self.phase = Phase::Streaming(now);
        self.pending = None;
        self.next_setpoint = now;
        let interval_us = self.cfg.telemetry_interval.as_micros() as f32;
        for id in [LOCAL_POSITION_NED, ATTITUDE_QUATERNION] {
            self.send_command(
                MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
                [id, interval_us, 0.0, 0.0, 0.0, 0.0, 0.0],
                0,
            );
        }
        self.send_command(
            MavCmd::MAV_CMD_REQUEST_MESSAGE,
            [GPS_GLOBAL_ORIGIN, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            0,
        );
    }

    /// A heartbeat may show that a command took effect even if its ack was lost.
    fn advance_on_state(&mut self, now: SimTime) {
        if self.phase == Phase::Arming && self.state.armed {
            self.request_offboard(now);
        }
        if self.phase == Phase::Offboarding && self.state.armed && self.state.in_offboard() {
            self.pending = None;
            self.phase = Phase::Flying;
            self.events.push_back(LinkEvent::Flying);
        }
        if self.phase == Phase::Landing {
            if self
                .pending
                .is_some_and(|p| p.command == MavCmd::MAV_CMD_NAV_LAND)
                && self.state.in_land()
            {
                self.pending = None;
                self.events.push_back(LinkEvent::Landing);
            }
            if self.state.landed {
                if self.state.armed {
                    self.request_disarm(now);
                } else {
                    self.events.push_back(LinkEvent::Landed);
                    self.finish();
                }
            }
        }
        if self.phase == Phase::Disarming && !self.state.armed {
            self.finish();
        }
    }

    fn on_ack(&mut self, now: SimTime, command: u16, result: u8) {
        let Some(pending) = self.pending else { return };
        if pending.command as u16 != command {
            return;
        }
        if result != ACCEPTED {
            tracing::warn!(
                sysid = self.cfg.system_id,
                command,
                result,
                "command refused"
            );
            if let Some(p) = &mut self.pending
                && p.accepted
            {
                // The real answer after an early ACCEPTED: refused after all.
                p.accepted = false;
                p.deadline = now + self.cfg.ack_timeout;
            }
            return; // resent at the deadline
        }
        match self.phase {
            Phase::Arming => self.request_offboard(now),
            Phase::Offboarding => {
                if let Some(p) = &mut self.pending {
                    p.accepted = true;
                    p.deadline = now + MODE_ACK_SETTLE;
                }
            }
            Phase::Landing => {
                self.pending = None;
                self.events.push_back(LinkEvent::Landing);
            }
            Phase::Disarming => self.finish(),
            _ => {}
        }
    }

    fn request_arm(&mut self, now: SimTime) {
        self.phase = Phase::Arming;
        self.send_pending(
            now,
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            1,
        );
    }

    fn request_offboard(&mut self, now: SimTime) {
        self.phase = Phase::Offboarding;
        let params = [1.0, PX4_MAIN_OFFBOARD as f32, 0.0, 0.0, 0.0, 0.0, 0.0];
        self.send_pending(now, MavCmd::MAV_CMD_DO_SET_MODE, params, 1);
    }

    fn send_pending(&mut self, now: SimTime, command: MavCmd, params: [f32; 7], attempt: u8) {
        self.send_command(command, params, attempt - 1);
        self.pending = Some(Pending {
            command,
            params,
            attempt,
            deadline: now + self.cfg.ack_timeout,
            accepted: false,
        });
    }

    fn send_command(&mut self, command: MavCmd, params: [f32; 7], confirmation: u8) {
        let msg = MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
            target_system: self.cfg.system_id,
            target_component: 1,
            command,
            confirmation,
            param1: params[0],
            param2: params[1],
            param3: params[2],
            param4: params[3],
            param5: params[4],
            param6: params[5],
            param7: params[6],
        });
        self.outbox.push_back(self.encoder.encode(&msg));
    }

    /// Runs the timers due at `now`: the setpoint stream, the pre-stream, command
    /// deadlines and link loss.
    pub fn handle_timeout(&mut self, now: SimTime) {
        if now >= self.next_heartbeat {
            self.outbox.push_back(self.encoder.encode(&gcs_heartbeat()));
            let next = self.next_heartbeat + self.cfg.heartbeat_interval;
            self.next_heartbeat = if next <= now {
                now + self.cfg.heartbeat_interval
            } else {
                next
            };
        }
        if self.phase == Phase::Discovering
            && !self.never_heard_reported
            && now >= SimTime::ZERO + self.cfg.discovery_warning
        {
            self.never_heard_reported = true;
            tracing::warn!(
                sysid = self.cfg.system_id,
                "no heartbeat from the vehicle yet"
            );
            self.events.push_back(LinkEvent::NeverHeard {
                after: self.cfg.discovery_warning,
            });
        }
        if let Some(last) = self.state.last_heard
            && now - last > self.cfg.link_timeout
            && !matches!(
                self.phase,
                Phase::Lost | Phase::Failed | Phase::Discovering | Phase::Done | Phase::Overridden
            )
        {
            self.phase = Phase::Lost;
            self.pending = None;
            self.events.push_back(LinkEvent::Lost);
            tracing::warn!(
                sysid = self.cfg.system_id,
                silent_ms = (now - last).as_millis() as u64,
                "vehicle lost"
            );
        }
        if let Phase::Streaming(since) = self.phase
            && now - since >= self.cfg.pre_stream
        {
            if self.state.armed {
                self.request_offboard(now)
            } else {
                self.request_arm(now)
            }
        }
        if let Some(p) = self.pending
            && now >= p.deadline
            && p.accepted
            && self.phase == Phase::Offboarding
        {
            // ACCEPTED and nothing else came: OFFBOARD it is.
            self.pending = None;
            self.phase = Phase::Flying;
            self.events.push_back(LinkEvent::Flying);
        }
        if let Some(p) = self.pending
            && now >= p.deadline
        {
            if p.attempt >= self.cfg.max_attempts {
                self.pending = None;
                self.phase = Phase::Failed;
                let reason = format!(
                    "vehicle {}: {:?} not accepted after {} attempts",
                    self.cfg.system_id, p.command, p.attempt
                );
                tracing::error!(sysid = self.cfg.system_id, %reason, "handshake failed");
                self.events.push_back(LinkEvent::Failed(reason));
            } else {
                self.events.push_back(LinkEvent::Retrying {
                    command: p.command as u16,
                    attempt: p.attempt + 1,
                });
                self.send_pending(now, p.command, p.params, p.attempt + 1);
            }
        }
        if self.streams() && now >= self.next_setpoint {
            self.send_setpoint(now);
            let next = self.next_setpoint + self.cfg.setpoint_interval;
            self.next_setpoint = if next <= now {
                now + self.cfg.setpoint_interval
            } else {
                next
            };
        }
    }
}
