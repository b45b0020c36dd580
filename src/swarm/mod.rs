//! The swarm machine (sans-IO): owns one [`VehicleLink`] per vehicle and runs the laws at
//! the control rate.
//!
//! ```text
//!  Handshake ──every vehicle Flying──► Consensus ──duration elapsed──► end action
//!  (each Flying vehicle: altitude          │ a vehicle Lost
//!   loop only, horizontal zero)            ├─ policy hold ─► Holding ──all Flying again──► Consensus
//!                                          └─ policy land ─► Landing
//!  end action: hold ─► Ended (hover in place) ;  land ─► Landing
//!  land() (Ctrl-C) from anywhere ─► Landing ──every link Done──► finished
//!
//!  with a target velocity, Handshake ──every vehicle Flying──► plan (current velocities)
//!     feasible, one agent re-targeted ─► Retargeting (that agent alone accelerates to its
//!                                        planned velocity, the others keep theirs) ─► Consensus
//!     feasible as is ─► Consensus with the planned k;  infeasible or unstable ─► Consensus
//!     with the configured k (warned)
//! ```
//!
//! Holding and Ended run the braking law `u = −k_v·v + k_p·(p_hold − p)`, each vehicle on
//! its own (`clip` saturation), with `p_hold` taken once the vehicle is slower than
//! 1 m/s, so it stops where its braking ends instead of flying back.
//!
//! Each control tick puts every vehicle in the common frame (its GPS origin projected at
//! the common reference, plus its local position), computes the horizontal consensus law
//! over the ring and the altitude PD (z up), adds the drag feed-forward of the vehicle
//! model, saturates the swarm's commands together (`conserve` keeps `Σ wᵢuᵢ`), and turns
//! each acceleration into an attitude and normalised thrust for its link to stream.
//! Horizontal acceleration zero before consensus keeps `w·v`, so the predicted final
//! velocity is computed from the velocities at the start of consensus.

mod events;
mod laws;
mod model;
mod plan;
mod setup;

use nalgebra::{Vector2, Vector3};
use ringswarm_sitl::time::SimTime;

use std::fmt;
use std::time::Duration;

use crate::consensus::{HorizontalState, predicted_final_velocity};
use crate::control::enu_to_ned;
use crate::control::{
    AttitudeThrust, VehicleModel, attitude_thrust_from_acceleration, saturate, tilt_rad,
};
use crate::vehicle::{Phase, Setpoint, VehicleLink};
use events::EventLog;
pub use events::{MAX_KEPT_EVENTS, SwarmEvent};
use model::FlownModel;
pub use setup::{
    EndAction, LossPolicy, PlanDecision, Retargeted, SetpointKind, SwarmSetup, TargetVelocity,
};

/// Where the swarm is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SwarmPhase {
    /// Vehicles are being handshaken; the flying ones hold altitude.
    Handshake,
    /// Planner stage 1: one agent accelerates to its planned velocity, since the given time.
    Retargeting(SimTime),
    /// The consensus law runs, since the given time.
    Consensus(SimTime),
    /// A vehicle was lost: the others hover in place until it flies again.
    Holding(SimTime),
    /// The duration is over; the vehicles hover in place until told to land.
    Ended(SimTime),
    /// Every vehicle was told to land, at the given time.
    Landing(SimTime),
}

impl SwarmPhase {
    /// A short lower-case name (`handshake`, `consensus`, `holding`, `ended`, `landing`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Handshake => "handshake",
            Self::Retargeting(_) => "retarget",
            Self::Consensus(_) => "consensus",
            Self::Holding(_) => "holding",
            Self::Ended(_) => "ended",
            Self::Landing(_) => "landing",
        }
    }
}

/// Why the swarm gave up before its flight (the vehicles that flew were landed).
#[derive(Debug, Clone, PartialEq)]
pub enum SwarmFailure {
    /// Not every vehicle was flying in OFFBOARD within the handshake timeout, or one
    /// vehicle's handshake gave up.
    Handshake {
        /// The vehicles not flying: system id and its link phase.
        not_flying: Vec<(u8, &'static str)>,
        /// When the swarm gave up.
        after: Duration,
    },
}

impl fmt::Display for SwarmFailure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Handshake { not_flying, after } => {
                write!(
                    f,
                    "handshake not complete after {:.1} s: ",
                    after.as_secs_f64()
                )?;
                for (j, (id, phase)) in not_flying.iter().enumerate() {
                    let sep = if j == 0 { "" } else { ", " };
                    let what = match *phase {
                        "discovering" => "never heard",
                        other => other,
                    };
                    write!(f, "{sep}vehicle {id} not flying ({what})")?;
                }
                write!(f, "; the vehicles that flew were landed")
            }
        }
    }
}

/// One vehicle's state in the common frame (ENU, m and m/s).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CommonState {
    /// Position.
    pub pos_enu_m: Vector3<f64>,
    /// Velocity.
    pub vel_enu_mps: Vector3<f64>,
}

/// The swarm.
#[derive(Debug, Clone)]
pub struct Swarm {
    setup: SwarmSetup,
    links: Vec<VehicleLink>,
    phase: SwarmPhase,
    next_control: SimTime,
    predicted_final_velocity: Option<Vector2<f64>>,
    horizontal: Vec<HorizontalState>,
    accel: Vec<Vector2<f64>>,
    commands: Vec<Vector3<f64>>,
    setpoints: Vec<AttitudeThrust>,
    states: Vec<Option<CommonState>>,
    w: Vec<f64>,
    saturated_ticks: u64,
    consensus_ticks: u64,
    next_link: usize,
    log: EventLog,
    failure: Option<SwarmFailure>,
    isolated: Vec<bool>,
    flown: Vec<FlownModel>,
    flown_models: Vec<VehicleModel>,
    altitude_integral: Vec<f64>,
    u_z: Vec<f64>,
    keep_velocity: Vec<Option<Vector2<f64>>>,
    mean_velocity_integral: Vector2<f64>,
    first_consensus: Option<SimTime>,
    hold_points: Vec<Option<Vector2<f64>>>,
    control_ticks: u64,
    plan: Option<PlanDecision>,
}

impl Swarm {
    /// A swarm that starts handshaking every vehicle.
    pub fn new(setup: SwarmSetup) -> Self {
        let n = setup.links.len();
        let w = (0..n).map(|i| setup.ring.w(i)).collect();
        let links: Vec<VehicleLink> = setup
            .links
            .iter()
            .zip(&setup.models)
            .map(|(cfg, model)| {
                let level = attitude_thrust_from_acceleration(Vector3::zeros(), 0.0, model);
                match setup.setpoint {
                    SetpointKind::Attitude => VehicleLink::new(cfg.clone(), level),
                    SetpointKind::Acceleration => {
                        VehicleLink::new(cfg.clone(), Setpoint::Acceleration(Vector3::zeros()))
                    }
                }
            })
            .collect();
        let setpoints = setup
            .models
            .iter()
            .map(|m| attitude_thrust_from_acceleration(Vector3::zeros(), 0.0, m))
            .collect();
        let (lo, hi) = (
            setup.envelope.min_thrust_norm().max(0.05),
            setup.envelope.max_thrust_norm().min(0.95),
        );
        let flown = setup
            .models
            .iter()
            .zip(&setup.drag_per_s)
            .map(|(m, d)| {
                // With acceleration setpoints PX4 estimates its hover thrust itself.
                let estimate = setup.estimate_hover && setup.setpoint == SetpointKind::Attitude;
                FlownModel::new(*m, *d, estimate, (lo, hi))
            })
            .collect();
        let flown_models = setup.models.clone();
        Self {
            w,
            setup,
            links,
            phase: SwarmPhase::Handshake,
            next_control: SimTime::ZERO,
            predicted_final_velocity: None,
            horizontal: vec![HorizontalState::default(); n],
            accel: vec![Vector2::zeros(); n],
            commands: vec![Vector3::zeros(); n],
            setpoints,
            states: vec![None; n],
            saturated_ticks: 0,
            consensus_ticks: 0,
            next_link: 0,
            log: EventLog::default(),
            failure: None,
            isolated: vec![false; n],
            flown,
            flown_models,
            altitude_integral: vec![0.0; n],
            u_z: vec![0.0; n],
            keep_velocity: vec![None; n],
            mean_velocity_integral: Vector2::zeros(),
            first_consensus: None,
            hold_points: vec![None; n],
            control_ticks: 0,
            plan: None,
        }
    }

    /// The phase.
    pub fn phase(&self) -> SwarmPhase {
        self.phase
    }

    /// The links.
    pub fn links(&self) -> &[VehicleLink] {
        &self.links
    }

    /// The setup.
    pub fn setup(&self) -> &SwarmSetup {
        &self.setup
    }

    /// Control ticks run so far (a recorder samples when this changes).
    pub fn control_ticks(&self) -> u64 {
        self.control_ticks
    }

    /// What the planner decided (with a target velocity, once every vehicle flies).
    pub fn plan_decision(&self) -> Option<&PlanDecision> {
        self.plan.as_ref()
    }

    /// When consensus first started.
    pub fn consensus_started(&self) -> Option<SimTime> {
        self.first_consensus
    }

    /// Why the swarm gave up, if it did (`fly` exits non-zero).
    pub fn failure(&self) -> Option<&SwarmFailure> {
        self.failure.as_ref()
    }

    /// Every event so far, in order (at most [`MAX_KEPT_EVENTS`]).
    pub fn events(&self) -> &[SwarmEvent] {
        self.log.events()
    }

    /// Events not kept because the log was full.
    pub fn dropped_events(&self) -> u64 {
        self.log.dropped()
    }

    /// Vehicle `i`'s hover thrust estimate and its standard deviation (the configured
    /// hover throttle while the estimator is off).
    pub fn hover_estimate(&self, i: usize) -> Option<(f64, f64)> {
        self.flown.get(i).map(FlownModel::hover_estimate)
    }

    /// The model vehicle `i` is flown with now.
    pub fn flown_model(&self, i: usize) -> Option<VehicleModel> {
        self.flown_models.get(i).copied()
    }

    /// Whether vehicle `i` was handed to its own Hold because its command could not be
    /// computed.
    pub fn is_isolated(&self, i: usize) -> bool {
        self.isolated.get(i).copied().unwrap_or(false)
    }

    /// Tells every vehicle to land and disarm (Ctrl-C, the end action or the land policy).
    pub fn land(&mut self, now: SimTime) {
        if !matches!(self.phase, SwarmPhase::Landing(_)) {
            self.log
                .push(now, None, false, "landing every vehicle".to_owned());
            self.phase = SwarmPhase::Landing(now);
        }
        for link in &mut self.links {
            link.land(now);
        }
    }

    /// Whether every vehicle has landed and disarmed (or was never armed), or can no
    /// longer be reached (failed).
    pub fn is_finished(&self) -> bool {
        matches!(self.phase, SwarmPhase::Landing(_))
            && self
                .links
                .iter()
                .all(|l| matches!(l.phase(), Phase::Done | Phase::Failed | Phase::Overridden))
    }

    /// The final velocity predicted at the start of consensus (m/s, ENU).
    pub fn predicted_final_velocity(&self) -> Option<Vector2<f64>> {
        self.predicted_final_velocity
    }

    /// Fraction of consensus ticks on which some command was saturated.
    pub fn saturated_fraction(&self) -> f64 {
        if self.consensus_ticks == 0 {
            0.0
        } else {
            self.saturated_ticks as f64 / self.consensus_ticks as f64
        }
    }

    /// The last accelerations commanded (m/s², ENU), after saturation.
    pub fn commands(&self) -> &[Vector3<f64>] {
        &self.commands
    }

    /// The last attitude and thrust setpoint of each vehicle.
    pub fn setpoints(&self) -> &[AttitudeThrust] {
        &self.setpoints
    }

    /// Vehicle `i` in the common frame, once its origin is known (whatever the age of its
    /// position; the control tick uses only fresh ones).
    pub fn common_state(&self, i: usize) -> Option<CommonState> {
        let state = self.links[i].state();
        let origin = state.origin?;
        Some(CommonState {
            pos_enu_m: self
                .setup
                .frame
                .to_common_enu(&origin, &state.pos_local_ned_m),
            vel_enu_mps: crate::control::ned_to_enu(state.vel_ned_mps),
        })
    }

    /// Hands a datagram from vehicle `i` to its link.
    pub fn handle_datagram(&mut self, now: SimTime, i: usize, bytes: &[u8]) {
        if let Some(link) = self.links.get_mut(i) {
            link.handle_datagram(now, bytes);
        }
        self.drain_link_events(now);
    }

    /// When [`Swarm::handle_timeout`] must next be called.
    pub fn poll_timeout(&self) -> SimTime {
        self.links
            .iter()
            .map(VehicleLink::poll_timeout)
            .fold(self.next_control, SimTime::min)
    }

    /// The next datagram and the vehicle it is for (round robin over the links).
    pub fn poll_transmit(&mut self) -> Option<(usize, Vec<u8>)> {
        let n = self.links.len();
        for k in 0..n {
            let i = (self.next_link + k) % n;
            if let Some(bytes) = self.links[i].poll_transmit() {
                self.next_link = (i + 1) % n;
                return Some((i, bytes));
            }
        }
        None
    }

    /// Runs the control tick and the links' timers due at `now`.
    pub fn handle_timeout(&mut self, now: SimTime) {
        if now >= self.next_control {
            self.control(now);
            // A fixed schedule: lateness of one wake-up does not slow the rate down, and
            // a long stall restarts the schedule instead of bursting.
            let next = self.next_control + self.setup.control_interval;
            self.next_control = if next <= now {
                now + self.setup.control_interval
            } else {
                next
            };
        }
        for link in &mut self.links {
            if now >= link.poll_timeout() {
                link.handle_timeout(now);
            }
        }
        self.drain_link_events(now);
    }

    fn drain_link_events(&mut self, now: SimTime) {
        for (i, link) in self.links.iter_mut().enumerate() {
            while let Some(event) = link.poll_event() {
                let id = self.setup.links[i].system_id;
                self.log
                    .push(now, Some(id), event.is_warning(), event.to_string());
            }
        }
    }

    /// Moves between phases; runs at the start of every control tick.
    fn transition(&mut self, now: SimTime) {
        let all_flying = self.links.iter().all(|l| l.phase() == Phase::Flying)
            && self.states.iter().all(Option::is_some);
        // A vehicle taken out of OFFBOARD (pilot, its failsafe) counts as lost: it never
        // comes back on its own, so the swarm holds (or lands) until told otherwise. So
        // does one that flies on a position too old to use, or that was handed to its own
        // Hold.
        let any_lost = self.links.iter().zip(&self.states).any(|(l, s)| {
            matches!(
                l.phase(),
                Phase::Lost | Phase::Overridden | Phase::VehicleHold
            ) || (l.phase() == Phase::Flying && s.is_none())
        });
        if self.phase == SwarmPhase::Handshake && !all_flying && self.handshake_over(now) {
            return;
        }
        let over = |start: Option<SimTime>| {
            start
                .zip(self.setup.duration)
                .is_some_and(|(t0, d)| now >= t0 + d)
        };
        match self.phase {
            SwarmPhase::Handshake
                if all_flying && self.setup.target.is_some() && self.plan.is_none() =>
            {
                self.plan_target(now);
            }
            SwarmPhase::Retargeting(_) if !any_lost => {
                let Some(PlanDecision::Planned {
                    retarget: Some((agent, v)),
                    ..
                }) = self.plan
                else {
                    return;
                };
                let tolerance = self.setup.target.map_or(0.05, |t| t.tolerance_mps);
                let reached =
                    self.states[agent].is_some_and(|s| (s.vel_enu_mps.xy() - v).norm() < tolerance);
                let SwarmPhase::Retargeting(since) = self.phase else {
                    return;
                };
                let timeout = self
                    .setup
                    .target
                    .map_or(Duration::from_secs(30), |t| t.timeout);
                if reached {
                    self.start_consensus(now);
                } else if now - since >= timeout {
                    let at = self.states[agent].map_or(Vector2::zeros(), |s| s.vel_enu_mps.xy());
                    self.log.push(
                        now,
                        Some(self.setup.links[agent].system_id),
                        true,
                        format!(
                            "re-target stage timed out after {:.1} s at ({:.2}, {:.2}) m/s, planned ({:.2}, {:.2}) m/s: consensus from the velocities now",
                            timeout.as_secs_f64(),
                            at.x,
                            at.y,
                            v.x,
                            v.y
                        ),
                    );
                    self.start_consensus(now);
                }
            }
            SwarmPhase::Handshake | SwarmPhase::Holding(_) if all_flying => {
                if over(self.first_consensus) {
                    self.end(now);
                    return;
                }
                self.start_consensus(now);
            }
            SwarmPhase::Consensus(_) | SwarmPhase::Retargeting(_) if any_lost => {
                match self.setup.loss_policy {
                    LossPolicy::Hold => {
                        self.log.push(
                            now,
                            None,
                            true,
                            "a vehicle is lost: the others brake and hold".to_owned(),
                        );
                        self.hold_points.iter_mut().for_each(|p| *p = None);
                        self.phase = SwarmPhase::Holding(now);
                    }
                    LossPolicy::Land => {
                        self.log.push(
                            now,
                            None,
                            true,
                            "a vehicle is lost: landing (on_link_loss = land)".to_owned(),
                        );
                        self.land(now);
                    }
                }
            }
            SwarmPhase::Consensus(_) | SwarmPhase::Holding(_) if over(self.first_consensus) => {
                self.end(now)
            }
            _ => {}
        }
    }

    /// Gives up on the handshake when the timeout is over or a vehicle's handshake failed:
    /// names the vehicles not flying and lands the others. Whether it gave up.
    fn handshake_over(&mut self, now: SimTime) -> bool {
        let failed = self.links.iter().any(|l| l.phase() == Phase::Failed);
        let timed_out = now >= SimTime::ZERO + self.setup.handshake_timeout;
        if !(failed || timed_out) {
            return false;
        }
        let not_flying: Vec<(u8, &'static str)> = self
            .links
            .iter()
            .zip(&self.states)
            .zip(&self.setup.links)
            .filter(|((l, s), _)| l.phase() != Phase::Flying || s.is_none())
            .map(|((l, s), cfg)| {
                let phase = if l.phase() == Phase::Flying && s.is_none() {
                    "no usable position"
                } else {
                    l.phase().name()
                };
                (cfg.system_id, phase)
            })
            .collect();
        let failure = SwarmFailure::Handshake {
            not_flying,
            after: now - SimTime::ZERO,
        };
        self.log.push(now, None, true, failure.to_string());
        self.failure = Some(failure);
        self.land(now);
        true
    }

    fn start_consensus(&mut self, now: SimTime) {
        self.phase = SwarmPhase::Consensus(now);
        self.mean_velocity_integral = Vector2::zeros();
        self.first_consensus.get_or_insert(now);
        let v0: Vec<Vector2<f64>> = self
            .states
            .iter()
            .flatten()
            .map(|s| s.vel_enu_mps.xy())
            .collect(); // once per (re)start
        self.predicted_final_velocity = predicted_final_velocity(&self.setup.ring, &v0).ok();
        let text = match self.predicted_final_velocity {
            Some(v) => format!(
                "consensus started: predicted final velocity ({:.3}, {:.3}) m/s",
                v.x, v.y
            ),
            None => "consensus started".to_owned(),
        };
        self.log.push(now, None, false, text);
    }

    fn end(&mut self, now: SimTime) {
        match self.setup.end_action {
            EndAction::Land => self.land(now),
            EndAction::Hold => {
                self.log
                    .push(now, None, false, "duration over: holding".to_owned());
                self.hold_points.iter_mut().for_each(|p| *p = None);
                self.phase = SwarmPhase::Ended(now);
            }
        }
    }

    /// One control tick. The law and the saturation allocate nothing in consensus (every
    /// buffer was sized at construction); each link encodes its setpoint into a new frame.
    ///
    /// Only fresh states are flown on. A vehicle whose command comes out non-finite is
    /// isolated before the swarm-wide saturation sees it: its command becomes level at
    /// its hover thrust and it is handed to its own Hold; the swarm applies its loss
    /// policy on the next tick.
    fn control(&mut self, now: SimTime) {
        self.control_ticks += 1;
        for i in 0..self.links.len() {
            self.states[i] = if self.links[i].state_fresh(now) {
                self.common_state(i)
            } else {
                None
            };
        }
        self.transition(now);
        self.observe_models(now);
        for (i, state) in self.states.iter().enumerate() {
            let s = state.unwrap_or_default();
            self.horizontal[i] = HorizontalState {
                pos_m: s.pos_enu_m.xy(),
                vel_mps: s.vel_enu_mps.xy(),
                offset_m: self.setup.offsets_m[i],
            };
        }
        let saturation = self.horizontal_law();
        for (i, state) in self.states.iter().enumerate() {
            let s = state.unwrap_or_default();
            let u_z = self.setup.altitude_gains.acceleration_with(
                s.pos_enu_m.z,
                s.vel_enu_mps.z,
                self.setup.altitude_m,
                self.altitude_integral[i],
            );
            self.u_z[i] = u_z;
            let drag = s.vel_enu_mps * self.setup.drag_per_s[i];
            self.commands[i] = Vector3::new(self.accel[i].x, self.accel[i].y, u_z) + drag;
        }
        self.isolate_non_finite(now, "the law's command");
        if let Ok(summary) = saturate(
            saturation,
            &self.setup.envelope,
            &self.flown_models,
            &self.w,
            &mut self.commands,
        ) && matches!(self.phase, SwarmPhase::Consensus(_))
        {
            self.consensus_ticks += 1;
            self.saturated_ticks +=
                u64::from(summary.horizontal_limited + summary.vertical_limited > 0);
        }
        self.isolate_non_finite(now, "the saturated command");
        self.integrate_altitude();
        for (i, link) in self.links.iter_mut().enumerate() {
            // No usable state (or isolated): level at hover thrust, never a motor cut.
            let command = if self.states[i].is_some() && !self.isolated[i] {
                self.commands[i]
            } else {
                Vector3::zeros()
            };
            let sp = attitude_thrust_from_acceleration(command, 0.0, &self.flown_models[i]);
            self.setpoints[i] = sp;
            if self.states[i].is_some() || link.phase() == Phase::Flying {
                match self.setup.setpoint {
                    SetpointKind::Attitude => link.set_setpoint(now, sp),
                    SetpointKind::Acceleration => {
                        link.set_setpoint(now, Setpoint::Acceleration(enu_to_ned(command)))
                    }
                }
            }
            if link.phase() == Phase::Flying
                && let Some(q) = link.state().attitude
            {
                // The thrust's vertical part on the reported tilt: the vehicle's attitude
                // may lag the command, its motors hardly.
                self.flown[i].commanded(sp.thrust_norm * tilt_rad(&q).cos());
            }
        }
        self.drain_link_events(now);
    }

    /// Whether vehicle `i` flies on our commands in the air now.
    pub(super) fn ours_in_air(&self, i: usize) -> bool {
        let link = &self.links[i];
        link.phase() == Phase::Flying && !link.state().landed && !self.isolated[i]
    }

    /// Feeds each vehicle's hover thrust estimator with its latest report and takes the
    /// model to fly this tick.
    fn observe_models(&mut self, now: SimTime) {
        for i in 0..self.links.len() {
            let ours = self.ours_in_air(i);
            let trusted = self.flown[i].trusted();
            if let (Some(s), Some(at)) = (self.states[i], self.links[i].state().last_position) {
                self.flown[i].observe(at, s.vel_enu_mps.z, s.vel_enu_mps.xy().norm(), ours);
            }
            if !trusted && self.flown[i].trusted() {
                let (hover, std) = self.flown[i].hover_estimate();
                self.log.push(
                    now,
                    Some(self.setup.links[i].system_id),
                    true,
                    format!(
                        "hover thrust estimated at {hover:.3} ± {std:.3}, not the configured {:.3}: flying the estimate",
                        self.setup.models[i].hover_throttle()
                    ),
                );
            }
            self.flown_models[i] = self.flown[i].model();
        }
    }

    /// The altitude integrals, for the vehicles flown on our commands in the air (not
    /// while landing), frozen while a vertical command is saturated.
    fn integrate_altitude(&mut self) {
        if matches!(self.phase, SwarmPhase::Landing(_)) {
            return;
        }
        let dt = self.setup.control_interval.as_secs_f64();
        for i in 0..self.links.len() {
            let Some(s) = self.states[i] else { continue };
            if !self.ours_in_air(i) {
                continue;
            }
            let saturated =
                (self.commands[i].z - self.u_z[i] - s.vel_enu_mps.z * self.setup.drag_per_s[i])
                    .abs()
                    > 1e-9;
            self.altitude_integral[i] = self.setup.altitude_gains.integrate(
                self.altitude_integral[i],
                s.pos_enu_m.z,
                self.setup.altitude_m,
                dt,
                saturated,
            );
        }
    }

    /// Isolates every vehicle whose command is not finite: zero acceleration (level at
    /// hover thrust) and its own Hold, for good.
    fn isolate_non_finite(&mut self, now: SimTime, what: &str) {
        for i in 0..self.commands.len() {
            if self.commands[i].iter().all(|x| x.is_finite()) {
                continue;
            }
            self.commands[i] = Vector3::zeros();
            if !self.isolated[i] {
                self.isolated[i] = true;
                let reason = format!("{what} is not a finite number: isolated");
                self.log.push(
                    now,
                    Some(self.setup.links[i].system_id),
                    true,
                    reason.clone(),
                );
                self.links[i].hold_on_own(now, &reason);
            }
        }
    }
}
