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

use std::collections::VecDeque;
use std::time::Duration;

use nalgebra::{Vector2, Vector3};
use ringswarm_sitl::time::SimTime;

use crate::consensus::{
    CouplingGains, HorizontalState, PlanOutcome, PlanRequest, RingDigraph, analyze,
    predicted_final_velocity, ring_accelerations,
};
use crate::control::{
    AltitudeGains, AttitudeThrust, Envelope, SaturationMode, VehicleModel,
    attitude_thrust_from_acceleration, saturate,
};
use crate::frame::CommonFrame;
use crate::vehicle::{LinkConfig, LinkEvent, Phase, VehicleLink};

/// Link events kept for the driver before the oldest are dropped.
pub const MAX_EVENTS: usize = 256;

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
    /// What the swarm does when the duration is over.
    pub end_action: EndAction,
    /// What the swarm does when a vehicle is lost during consensus.
    pub loss_policy: LossPolicy,
    /// A final velocity to reach with the planner (stage 1), if any.
    pub target: Option<TargetVelocity>,
}

/// The planner's job: reach `velocity_mps` by choosing `k` and, if needed, re-targeting
/// one agent before consensus starts.
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
    /// Stage 1 ends when the re-targeted agent is this close to its planned velocity (m/s).
    pub tolerance_mps: f64,
}

/// A re-targeted agent (0-based) and its planned velocity (m/s, ENU).
pub type Retargeted = (usize, Vector2<f64>);

/// What the planner decided when consensus was about to start.
#[derive(Debug, Clone, PartialEq)]
pub enum PlanDecision {
    /// Flying the planned `k`, after re-targeting `agent` (0-based) to `velocity_mps`.
    Planned {
        /// The gain flown.
        k: f64,
        /// The re-targeted agent and its planned velocity, if any.
        retarget: Option<Retargeted>,
    },
    /// Not used: the configured `k` is flown. Why, in words.
    Rejected(String),
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

/// Braking law gains: velocity (1/s) and position (1/s²), about critically damped.
const HOLD_K_V: f64 = 2.5;
const HOLD_K_P: f64 = 1.5;
/// Below this speed (m/s) a braking vehicle takes its hold point.
const HOLD_CAPTURE_MPS: f64 = 1.0;
/// Stage 1 velocity gain (1/s): the re-targeted agent's acceleration per m/s of error.
const RETARGET_K_V: f64 = 2.0;

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
    events: VecDeque<(usize, LinkEvent)>,
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
                VehicleLink::new(
                    cfg.clone(),
                    attitude_thrust_from_acceleration(Vector3::zeros(), 0.0, model),
                )
            })
            .collect();
        let setpoints = links.iter().map(VehicleLink::setpoint).collect();
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
            events: VecDeque::new(),
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

    /// Tells every vehicle to land and disarm (Ctrl-C, the end action or the land policy).
    pub fn land(&mut self, now: SimTime) {
        if !matches!(self.phase, SwarmPhase::Landing(_)) {
            tracing::info!(at = ?now, "swarm landing");
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

    /// Vehicle `i` in the common frame, once its origin is known.
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
        for (i, link) in self.links.iter_mut().enumerate() {
            if now >= link.poll_timeout() {
                link.handle_timeout(now);
            }
            while let Some(event) = link.poll_event() {
                tracing::info!(vehicle = i, ?event, "link event");
                if self.events.len() == MAX_EVENTS {
                    self.events.pop_front();
                }
                self.events.push_back((i, event));
            }
        }
    }

    /// The next link event and the vehicle it concerns. Drivers should drain these; the
    /// queue keeps at most [`MAX_EVENTS`] and drops the oldest beyond that.
    pub fn poll_event(&mut self) -> Option<(usize, LinkEvent)> {
        self.events.pop_front()
    }

    /// Moves between phases; runs at the start of every control tick.
    fn transition(&mut self, now: SimTime) {
        let all_flying = self.links.iter().all(|l| l.phase() == Phase::Flying)
            && self.states.iter().all(Option::is_some);
        // A vehicle taken out of OFFBOARD (pilot, its failsafe) counts as lost: it never
        // comes back on its own, so the swarm holds (or lands) until told otherwise.
        let any_lost = self
            .links
            .iter()
            .any(|l| matches!(l.phase(), Phase::Lost | Phase::Overridden));
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
                if reached {
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
                        tracing::warn!("a vehicle was lost: holding");
                        self.hold_points.iter_mut().for_each(|p| *p = None);
                        self.phase = SwarmPhase::Holding(now);
                    }
                    LossPolicy::Land => {
                        tracing::warn!("a vehicle was lost: landing");
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

    fn start_consensus(&mut self, now: SimTime) {
        self.phase = SwarmPhase::Consensus(now);
        self.first_consensus.get_or_insert(now);
        let v0: Vec<Vector2<f64>> = self
            .states
            .iter()
            .flatten()
            .map(|s| s.vel_enu_mps.xy())
            .collect(); // once per (re)start
        self.predicted_final_velocity = predicted_final_velocity(&self.setup.ring, &v0).ok();
        tracing::info!(predicted = ?self.predicted_final_velocity, "consensus started");
    }

    /// Planner stage 0: choose `k` (and an agent to re-target) from the velocities now.
    /// Runs once; allocates (the planner and the stability check), like the start of
    /// consensus.
    fn plan_target(&mut self, now: SimTime) {
        let Some(target) = self.setup.target else {
            return;
        };
        let velocities: Vec<Vector2<f64>> = self
            .states
            .iter()
            .flatten()
            .map(|s| s.vel_enu_mps.xy())
            .collect();
        let decision = match self.planned_ring(&target, velocities) {
            Ok((ring, retarget)) => {
                let k = ring.k();
                self.w = (0..self.links.len()).map(|i| ring.w(i)).collect();
                self.setup.ring = ring;
                PlanDecision::Planned { k, retarget }
            }
            Err(reason) => {
                tracing::warn!(%reason, "target velocity not used; flying the configured k");
                PlanDecision::Rejected(reason)
            }
        };
        tracing::info!(?decision, "plan");
        let retargeting = matches!(
            decision,
            PlanDecision::Planned {
                retarget: Some(_),
                ..
            }
        );
        self.plan = Some(decision);
        if retargeting {
            self.phase = SwarmPhase::Retargeting(now);
        } else {
            self.start_consensus(now);
        }
    }

    fn planned_ring(
        &self,
        target: &TargetVelocity,
        velocities: Vec<Vector2<f64>>,
    ) -> Result<(RingDigraph, Option<Retargeted>), String> {
        let plan = crate::consensus::plan(&PlanRequest {
            velocities_mps: velocities,
            target_mps: target.velocity_mps,
            k_margin: target.k_margin,
            k_max: target.k_max,
            max_speed_mps: target.max_speed_mps,
        })
        .map_err(|e| e.to_string())?;
        let (k, retarget) = match plan.outcome {
            PlanOutcome::Feasible { k, retarget, .. } => (k, retarget),
            PlanOutcome::Infeasible { reason } => return Err(reason),
        };
        let ring =
            RingDigraph::new(self.setup.ring.macro_vertices(), k).map_err(|e| e.to_string())?;
        let report = analyze(&ring, Some(self.setup.gains)).map_err(|e| e.to_string())?;
        if !report.stable {
            return Err(format!(
                "the planned k = {k:.6} is unstable with alpha = {}, beta = {}",
                self.setup.gains.alpha, self.setup.gains.beta
            ));
        }
        Ok((ring, retarget.map(|r| (r.agent, r.new_velocity_mps))))
    }

    fn end(&mut self, now: SimTime) {
        match self.setup.end_action {
            EndAction::Land => self.land(now),
            EndAction::Hold => {
                tracing::info!("duration over: holding");
                self.hold_points.iter_mut().for_each(|p| *p = None);
                self.phase = SwarmPhase::Ended(now);
            }
        }
    }

    /// One control tick. The law and the saturation allocate nothing in consensus (every
    /// buffer was sized at construction); each link encodes its setpoint into a new frame.
    fn control(&mut self, now: SimTime) {
        self.control_ticks += 1;
        for i in 0..self.links.len() {
            self.states[i] = self.common_state(i);
        }
        self.transition(now);
        let states = &self.states;
        for (i, state) in states.iter().enumerate() {
            let s = state.unwrap_or_default();
            self.horizontal[i] = HorizontalState {
                pos_m: s.pos_enu_m.xy(),
                vel_mps: s.vel_enu_mps.xy(),
                offset_m: self.setup.offsets_m[i],
            };
        }
        let saturation = match self.phase {
            SwarmPhase::Consensus(_) => {
                ring_accelerations(
                    &self.setup.ring,
                    self.setup.gains,
                    &self.horizontal,
                    &mut self.accel,
                );
                self.setup.saturation
            }
            SwarmPhase::Holding(_) | SwarmPhase::Ended(_) | SwarmPhase::Landing(_) => {
                for ((a, h), hold) in self
                    .accel
                    .iter_mut()
                    .zip(&self.horizontal)
                    .zip(&mut self.hold_points)
                {
                    if hold.is_none() && h.vel_mps.norm() < HOLD_CAPTURE_MPS {
                        *hold = Some(h.pos_m);
                    }
                    *a = -HOLD_K_V * h.vel_mps
                        + hold.map_or(Vector2::zeros(), |p| HOLD_K_P * (p - h.pos_m));
                }
                SaturationMode::Clip
            }
            SwarmPhase::Handshake => {
                self.accel.iter_mut().for_each(|a| *a = Vector2::zeros());
                self.setup.saturation
            }
            SwarmPhase::Retargeting(_) => {
                self.accel.iter_mut().for_each(|a| *a = Vector2::zeros());
                if let Some(PlanDecision::Planned {
                    retarget: Some((agent, v)),
                    ..
                }) = self.plan
                {
                    self.accel[agent] = RETARGET_K_V * (v - self.horizontal[agent].vel_mps);
                }
                SaturationMode::Clip
            }
        };
        for (i, state) in states.iter().enumerate() {
            let s = state.unwrap_or_default();
            let u_z = self.setup.altitude_gains.acceleration(
                s.pos_enu_m.z,
                s.vel_enu_mps.z,
                self.setup.altitude_m,
            );
            let drag = s.vel_enu_mps * self.setup.drag_per_s[i];
            self.commands[i] = Vector3::new(self.accel[i].x, self.accel[i].y, u_z) + drag;
        }
        if let Ok(summary) = saturate(
            saturation,
            &self.setup.envelope,
            &self.setup.models,
            &self.w,
            &mut self.commands,
        ) && matches!(self.phase, SwarmPhase::Consensus(_))
        {
            self.consensus_ticks += 1;
            self.saturated_ticks +=
                u64::from(summary.horizontal_limited + summary.vertical_limited > 0);
        }
        for (i, link) in self.links.iter_mut().enumerate() {
            if states[i].is_some() {
                self.setpoints[i] =
                    attitude_thrust_from_acceleration(self.commands[i], 0.0, &self.setup.models[i]);
                link.set_setpoint(now, self.setpoints[i]);
            }
        }
    }
}
