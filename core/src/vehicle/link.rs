//! The link machine itself (the phases are drawn in the module above): state, datagrams,
//! telemetry through the gate, timers. What it sends and how answers are read is in
//! `commands`.

use std::collections::VecDeque;
use std::time::Duration;

use ringswarm_wire::codec::FramePool;
use ringswarm_wire::time::SimTime;

use super::fence_upload::FenceUpload;
use super::params::ParamSession;
use super::telemetry::TelemetryGate;
use super::{LinkConfig, LinkEvent, Phase, Setpoint, VehicleState};
use crate::control::UnseenMotion;

use crate::link::{
    Encoder, Frame, Inbound, Outgoing, Signer, VehicleCommand, encode, for_each_frame, inbound,
};

/// How long the fence upload waits for the vehicle before it sends its last message
/// again (PX4 asks again for a missing item every 250 ms by itself).
const FENCE_RETRY: Duration = Duration::from_secs(1);

mod commands;
mod inbound;
mod setup;
mod timers;

/// A command waiting for its acknowledgement.
#[derive(Debug, Clone, Copy)]
struct Pending {
    command: VehicleCommand,
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
    setpoint: Setpoint,
    next_setpoint: SimTime,
    next_heartbeat: SimTime,
    /// How far after the first heartbeat's schedule the later ones go (a share of the
    /// interval, set by [`VehicleLink::spread_heartbeat`]), applied once.
    heartbeat_phase: Option<Duration>,
    pending: Option<Pending>,
    encoder: Encoder,
    signer: Option<Signer>,
    outbox: VecDeque<Vec<u8>>,
    /// Sent datagrams' buffers given back by the driver.
    spare: FramePool,
    events: VecDeque<LinkEvent>,
    ignored_frames: u64,
    /// Foreign system ids already reported (a bit per id): each is reported once, however
    /// their frames interleave.
    wrong_systems: [u64; 4],
    land_requested: bool,
    never_heard_reported: bool,
    heartbeats_out_of_offboard: u8,
    gate: TelemetryGate,
    /// Reached Flying at least once: from then on the vehicle's own decisions count.
    has_flown: bool,
    /// In (or, lost, last in) VehicleHold; `true` when it returns once fresh.
    held: Option<bool>,
    /// When the vehicle confirmed the Hold we asked for (acknowledged, or its heartbeat).
    hold_confirmed: Option<SimTime>,
    /// When the last setpoint was sent.
    last_setpoint_sent: Option<SimTime>,
    /// A run of refused telemetry reports is going on (reported once per run).
    refusing: bool,
    refused_reports: u64,
    next_origin: Option<crate::frame::Geodetic>,
    /// The fence upload, when the link has a fence to give.
    fence: Option<FenceUpload>,
    /// The stamp (ns of the link's clock) of the TIMESYNC request in flight.
    timesync_sent_ns: Option<i64>,
    /// The round trip to the vehicle: the newest TIMESYNC sample when it is longer, else
    /// decaying toward the new one by a tenth (a rise is believed at once).
    round_trip: Option<Duration>,
    /// How far behind its sockets the coordinator is ([`VehicleLink::set_listen_lag`]).
    listen_lag: Duration,
    /// The handshake's parameter reads and writes (its autopilot's), once discovered.
    params: Option<ParamSession>,
    /// The end-of-flight restore of what `params` wrote, once started.
    restore: Option<ParamSession>,
    /// Whether the vehicle multiplies the thrust it is sent by 1/cos(tilt).
    angle_boost: bool,
    /// How long it flies its last setpoint when no new one comes (s), as its handshake
    /// read it; `None` before (its autopilot's default then).
    setpoint_held_s: Option<f64>,
    /// Whether what `params` read was taken (the angle boost, the hover reported).
    params_applied: bool,
    /// The last warning the vehicle sent (STATUSTEXT, severity WARNING or worse).
    last_warning: Option<String>,
    /// The restore's end was told (and acted on).
    restore_reported: bool,
    /// The motion its positions show and its velocities do not.
    unseen: UnseenMotion,
    /// The vehicle's clock at its last position report: `time_boot_ms` and the seconds
    /// counted from the first report (unwrapped).
    vehicle_clock: Option<(u32, f64)>,
}

impl VehicleLink {
    /// A link that starts discovering, with `idle` as the setpoint to stream until the law
    /// takes over (normally level at hover throttle, or zero acceleration).
    pub fn new(cfg: LinkConfig, idle: impl Into<Setpoint>) -> Self {
        let encoder = Encoder::new(cfg.own_ids.0, cfg.own_ids.1);
        let fence = cfg
            .fence
            .clone()
            .map(|plan| FenceUpload::new(plan, FENCE_RETRY, cfg.max_attempts));
        Self {
            params: None,
            restore: None,
            angle_boost: false,
            setpoint_held_s: None,
            params_applied: false,
            last_warning: None,
            restore_reported: false,
            listen_lag: Duration::ZERO,
            timesync_sent_ns: None,
            round_trip: None,
            fence,
            signer: cfg.signing.as_ref().map(Signer::new),
            cfg,
            phase: Phase::Discovering,
            state: VehicleState::default(),
            setpoint: idle.into(),
            next_setpoint: SimTime::ZERO,
            next_heartbeat: SimTime::ZERO,
            heartbeat_phase: None,
            pending: None,
            encoder,
            outbox: VecDeque::new(),
            spare: FramePool::default(),
            events: VecDeque::new(),
            ignored_frames: 0,
            wrong_systems: [0; 4],
            land_requested: false,
            never_heard_reported: false,
            heartbeats_out_of_offboard: 0,
            gate: TelemetryGate::default(),
            has_flown: false,
            held: None,
            hold_confirmed: None,
            last_setpoint_sent: None,
            refusing: false,
            refused_reports: 0,
            next_origin: None,
            unseen: UnseenMotion::default(),
            vehicle_clock: None,
        }
    }

    /// Spreads this link's heartbeats over the interval: link `k` of `n` sends its first at
    /// once and the later ones `k/n` of an interval after the whole intervals, so that a
    /// swarm's links (each with a TIMESYNC) do not all send in the same instant.
    pub fn spread_heartbeat(&mut self, k: usize, n: usize) {
        if n > 1 {
            let share = (k % n) as f64 / n as f64;
            self.heartbeat_phase = Some(self.cfg.heartbeat_interval.mul_f64(share));
        }
    }

    /// Frames from the vehicle refused by the signing rules.
    pub fn refused_frames(&self) -> u64 {
        self.signer.as_ref().map_or(0, |s| s.refused)
    }

    /// The timestamp the next signed frame gets, if the link signs (what a restart must
    /// stay above).
    pub fn signing_timestamp(&self) -> Option<u64> {
        self.signer.as_ref().map(Signer::timestamp)
    }

    /// Moves the signing clock to `now`.
    fn clock(&mut self, now: SimTime) {
        if let Some(signer) = self.signer.as_mut() {
            signer.clock(now);
        }
    }

    /// Encodes `out` (signed when the link signs) and queues it.
    fn queue(&mut self, out: Outgoing<'_>) {
        let mut bytes = self.spare.take();
        encode(&mut self.encoder, self.signer.as_mut(), &out, &mut bytes);
        self.outbox.push_back(bytes);
    }

    /// Gives a sent datagram's buffer back for the next one: a driver that does so makes
    /// the link allocate nothing per frame in steady state.
    pub fn recycle(&mut self, bytes: Vec<u8>) {
        self.spare.give(bytes);
    }

    /// Position reports and origins refused by the telemetry gate.
    pub fn refused_reports(&self) -> u64 {
        self.refused_reports
    }

    /// The round trip to the vehicle as TIMESYNC measures it (a rise at once, a fall a
    /// tenth per sample); `None` before the first answer.
    pub fn round_trip(&self) -> Option<Duration> {
        self.round_trip
    }

    /// When the vehicle confirmed the Hold it was handed to (its acknowledgement or a
    /// heartbeat in that mode), while it is in [`Phase::VehicleHold`] or was last there
    /// before it went silent; `None` before that, or in any other phase.
    pub fn hold_confirmed_at(&self) -> Option<SimTime> {
        let held =
            self.phase == Phase::VehicleHold || (self.phase == Phase::Lost && self.held.is_some());
        self.hold_confirmed.filter(|_| held)
    }

    /// When the last setpoint was sent (`None`: never).
    pub fn last_setpoint_sent(&self) -> Option<SimTime> {
        self.last_setpoint_sent
    }

    /// How long the vehicle goes on flying the last setpoint it got when no new one
    /// comes (s): its autopilot's timeout, as the handshake read it
    /// ([`crate::link::Autopilot::setpoint_held_s`]).
    pub fn setpoint_held_s(&self) -> f64 {
        self.setpoint_held_s
            .unwrap_or_else(|| self.state.dialect().setpoint_held_s(|_| None))
    }

    /// How fast its reported positions may move beyond what its reported velocities say
    /// (m/s, ≥ 0; [`UnseenMotion`]).
    pub fn unseen_speed_mps(&self) -> f64 {
        self.unseen.latest_speed_mps()
    }

    /// Whether the last accepted position is younger than the state timeout (its origin
    /// known, and its estimator not saying it is lost): what the swarm may fly on.
    pub fn state_fresh(&self, now: SimTime) -> bool {
        self.state.origin.is_some()
            && self.state.estimate_lost.is_none()
            && self
                .state
                .last_position
                .is_some_and(|t| now.saturating_since(t) <= self.cfg.state_timeout)
    }

    /// Tells the link that the coordinator has read everything received only up to
    /// `now − lag` (as the driver measured it): the vehicle's silence and its state's
    /// age are judged at that instant, not at `now`, when the link decides that the
    /// vehicle is lost or must be handed to its own Hold.
    pub fn set_listen_lag(&mut self, lag: Duration) {
        self.listen_lag = lag;
    }

    /// Hands a flying vehicle to its own Hold mode (AUTO.LOITER) for good: the swarm could
    /// not compute its command. Nothing more is streamed to it; it can still be landed.
    pub fn hold_on_own(&mut self, now: SimTime, reason: &str) {
        self.clock(now);
        if matches!(
            self.phase,
            Phase::Flying | Phase::Streaming(_) | Phase::Arming | Phase::Offboarding
        ) {
            self.hand_to_hold(now, reason.to_owned(), false);
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
    pub fn setpoint(&self) -> Setpoint {
        self.setpoint
    }

    /// Frames ignored (undecodable, another system, another component).
    pub fn ignored_frames(&self) -> u64 {
        self.ignored_frames
    }

    /// Replaces the setpoint. While streaming it is sent at once, so the stream follows
    /// the control ticks; the link's own timer only resends it if no new setpoint comes
    /// within one and a half periods (it never doubles the rate when the two timers drift).
    pub fn set_setpoint(&mut self, now: SimTime, setpoint: impl Into<Setpoint>) {
        self.clock(now);
        self.setpoint = setpoint.into();
        if self.streams() {
            self.send_setpoint(now);
            self.next_setpoint = now + self.cfg.setpoint_interval.mul_f64(1.5);
        }
    }

    fn send_setpoint(&mut self, now: SimTime) {
        self.last_setpoint_sent = Some(now);
        let (target_system, time_boot_ms) = (self.cfg.system_id, now.boot_ms());
        let setpoint = self.setpoint;
        let written;
        let out = match &setpoint {
            Setpoint::Attitude(setpoint) => {
                // The thrust as this autopilot reads it.
                let thrust = self
                    .state
                    .dialect()
                    .thrust_field(setpoint, self.angle_boost);
                written = crate::control::AttitudeThrust {
                    thrust_norm: thrust,
                    ..*setpoint
                };
                Outgoing::Attitude {
                    setpoint: &written,
                    target_system,
                    time_boot_ms,
                }
            }
            Setpoint::Acceleration(accel_ned_mps2) => Outgoing::Acceleration {
                accel_ned_mps2,
                target_system,
                time_boot_ms,
            },
        };
        self.queue(out);
    }

    /// Whether a datagram is waiting in [`VehicleLink::poll_transmit`].
    pub fn has_output(&self) -> bool {
        !self.outbox.is_empty()
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
        // The link timeout only matters where `handle_timeout` acts on it.
        let watched = !matches!(
            self.phase,
            Phase::Lost | Phase::Failed | Phase::Discovering | Phase::Done | Phase::Overridden
        );
        let mut next = match self.state.last_heard {
            Some(t) if watched => t + self.cfg.link_timeout + self.listen_lag,
            _ => SimTime::MAX,
        }
        .min(self.next_heartbeat);
        if self.streams() {
            next = next.min(self.next_setpoint);
        }
        if let Some(p) = self.pending {
            next = next.min(p.deadline);
        }
        if let Some(fence) = &self.fence
            && matches!(self.phase, Phase::Streaming(_))
        {
            next = next.min(fence.poll_timeout());
        }
        if let Some(params) = &self.params
            && matches!(self.phase, Phase::Streaming(_))
        {
            next = next.min(params.poll_timeout());
        }
        if let Some(restore) = &self.restore {
            next = next.min(restore.poll_timeout());
        }
        if let Phase::Streaming(since) = self.phase
            && self.ready_to_arm()
        {
            next = next.min(since + self.cfg.pre_stream);
        }
        if self.phase == Phase::Discovering && !self.never_heard_reported {
            next = next.min(SimTime::ZERO + self.cfg.discovery_warning);
        }
        if self.phase == Phase::Flying {
            // Stale one microsecond after the state timeout.
            let stale = self.state.last_position.map_or(SimTime::ZERO, |t| {
                t + self.cfg.state_timeout + Duration::from_micros(1)
            });
            next = next.min(stale);
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
            | Phase::Overridden
            | Phase::VehicleHold => false,
            // Keep OFFBOARD fed until the vehicle has taken NAV_LAND.
            Phase::Landing => self.pending.is_some() && self.state.in_fly_mode(),
            _ => true,
        }
    }

    /// Tells the vehicle to land where it is and to disarm on the ground. Idempotent. A
    /// vehicle never heard from, or heard but never armed, is done at once.
    pub fn land(&mut self, now: SimTime) {
        self.clock(now);
        if self.land_requested {
            return;
        }
        self.land_requested = true;
        match self.phase {
            Phase::Discovering => self.phase = Phase::Done,
            Phase::Overridden => {} // someone else flies it
            Phase::Streaming(_) if !self.state.armed => {
                self.pending = None;
                self.close(now);
            }
            Phase::Lost => {} // sent when the vehicle is heard again
            _ => self.request_land(now),
        }
    }

    /// Whether [`VehicleLink::land`] was called.
    pub fn land_requested(&self) -> bool {
        self.land_requested
    }

    /// Handles one datagram from the vehicle's address. `true` when at least one frame
    /// was taken as the vehicle's: decoded, authentic when the link signs, from its
    /// system id and component 1 (what may tell a router where the vehicle is).
    pub fn handle_datagram(&mut self, now: SimTime, bytes: &[u8]) -> bool {
        self.clock(now);
        let mut taken = false;
        let key = self.signer.as_ref().map(|s| s.key().clone());
        for_each_frame(bytes, key.as_ref(), |decoded| match decoded {
            Ok(frame) => taken |= self.take_frame(now, frame),
            Err(_) => self.ignored_frames += 1,
        });
        taken
    }

    /// One decoded frame of [`Self::handle_datagram`]; `true` when it is taken as the
    /// vehicle's.
    fn take_frame(&mut self, now: SimTime, frame: &Frame) -> bool {
        if let Some(signer) = self.signer.as_mut()
            && let Err(why) = signer.check(frame, self.cfg.system_id)
        {
            signer.refused += 1;
            if !signer.reported {
                signer.reported = true;
                self.events.push_back(LinkEvent::SigningRefused(why));
            }
            return false;
        }
        let system_id = frame.system_id();
        if system_id != self.cfg.system_id {
            self.ignored_frames += 1;
            let (word, bit) = (usize::from(system_id / 64), 1u64 << (system_id % 64));
            if self.wrong_systems[word] & bit == 0 {
                // Reported once per foreign system id, not per frame.
                self.wrong_systems[word] |= bit;
                self.events.push_back(LinkEvent::WrongSystem { system_id });
            }
            return false;
        }
        if frame.header.component_id != 1 {
            self.ignored_frames += 1;
            return false;
        }
        let update = inbound(&frame.msg);
        if let Some(Inbound::Ack { target_system, .. }) = update
            && target_system != 0
            && target_system != self.cfg.own_ids.0
        {
            return true; // an acknowledgement meant for another ground station
        }
        self.state.last_heard = Some(now);
        if let Some(update) = update {
            self.apply(now, update);
        }
        true
    }

    /// A vehicle in the Hold we handed it to (to be taken back when fresh) is streamed to
    /// again once its state is usable.
    fn take_back_if_usable(&mut self, now: SimTime) {
        if self.held == Some(true) && self.phase == Phase::VehicleHold && self.state_fresh(now) {
            self.start_streaming(now);
        }
    }

    /// Gives up on the vehicle for `reason`.
    pub(super) fn fail(&mut self, reason: String) {
        self.phase = Phase::Failed;
        self.pending = None;
        self.events.push_back(LinkEvent::Failed(reason));
    }

    /// What keeps the handshake from arming (or switching) the vehicle, if anything: its
    /// origin, the fence, its parameters, and, for an autopilot that reports them, a
    /// position stream that came (arming starts ArduPilot's DISARM_DELAY clock) and its
    /// pre-arm checks.
    fn arm_blocker(&self) -> Option<&'static str> {
        let prearm = self.state.dialect().reports_prearm();
        if self.state.origin.is_none() {
            Some("its position estimate (no GPS_GLOBAL_ORIGIN yet)")
        } else if !self.fence_ready() {
            Some("the fence upload")
        } else if !self.params.as_ref().is_none_or(ParamSession::done) {
            Some("its parameters")
        } else if prearm && self.state.last_position.is_none() {
            Some("its position stream (LOCAL_POSITION_NED)")
        } else if prearm && self.state.prearm_ok != Some(true) {
            Some("its pre-arm checks (EKF)")
        } else {
            None
        }
    }

    /// Whether the handshake may arm (or switch) the vehicle.
    fn ready_to_arm(&self) -> bool {
        self.arm_blocker().is_none()
    }

    /// What the handshake waits for before it arms, for an operator (`None`: nothing).
    pub fn waiting_for(&self) -> Option<String> {
        if !matches!(self.phase, Phase::Streaming(_) | Phase::Arming) {
            return None;
        }
        let said = self
            .last_warning
            .as_ref()
            .map_or(String::new(), |t| format!("; it last said \"{t}\""));
        let what = self.arm_blocker().unwrap_or("arming");
        Some(format!("waiting for {what}{said}"))
    }
}
