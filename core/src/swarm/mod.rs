//! The swarm machine (sans-IO): owns one [`VehicleLink`] per vehicle and runs the laws at
//! the control rate.
//!
//! ```text
//!  Handshake ──every vehicle Flying──► Consensus ──duration elapsed──► end action
//!  (flying vehicles: altitude loop,        │ a vehicle lost (silent, stale position,
//!   velocity kept by feedback)             │ left OFFBOARD, handed to its own Hold)
//!   │                                      ├─ policy hold ─► Holding ──all Flying again──► Consensus
//!   │ handshake_timeout, or a link Failed  └─ policy land ─► Landing
//!   └─► Landing, the vehicles not flying named (failure(): `fly` exits 3)
//!  end action: hold ─► Ended (hover in place) ;  land ─► Landing
//!  land() (Ctrl-C) from anywhere ─► Landing ──every link Done──► finished
//!
//!  with a target velocity, Handshake ──every vehicle Flying──► plan (current velocities,
//!     never above 0.8 of the drag-limited top speed)
//!     feasible, one agent re-targeted ─► Retargeting (that agent goes to its planned
//!                                        velocity, the others hold theirs) ─► Consensus
//!                                        (reached, or target.timeout_s with a warning)
//!     feasible as is ─► Consensus with the planned k;  infeasible or unstable ─► Consensus
//!     with the configured k (warned)
//!
//!  Consensus ──divergence guard trips (guard.rs)──► policy hold: Stopped (brake, hover;
//!     never resumes; the end action at the end of the duration) ; policy land: Landing
//! ```
//!
//! Each control tick (`tick.rs`) takes every vehicle's fresh state (a position older than
//! the state timeout is not flown on) into the common frame (its GPS origin projected at
//! the common reference, plus its local position), runs the phase's horizontal law
//! (`laws.rs`: consensus over the ring with the mean-velocity correction, braking, velocity
//! keeping) and the altitude PID (z up), adds the drag feed-forward, saturates the swarm's
//! commands together (`conserve` keeps `Σ wᵢuᵢ`) and turns each acceleration into an
//! attitude and normalised thrust with the vehicle's flown model (`model.rs`: the hover
//! thrust estimated in flight), or streams the acceleration itself. A command that is not
//! finite isolates its vehicle (level at hover thrust, handed to its own Hold) before the
//! saturation sees it. Every link event and swarm decision goes to the event log
//! (`events.rs`).

mod agreement;
mod events;
mod fence;
mod guard;
mod horizon;
mod laws;
mod model;
mod phases;
mod plan;
mod safety;
mod scheduler;
mod setup;
mod shard;
mod slot;
mod tick;
pub mod timing;

use nalgebra::{Vector2, Vector3};
use ringswarm_wire::time::SimTime;

use std::fmt;
use std::time::Duration;

use crate::consensus::HorizontalState;
use crate::control::{AttitudeThrust, VehicleModel, attitude_thrust_from_acceleration};
use crate::vehicle::{LinkEvent, Phase, Setpoint, VehicleLink};
use events::EventLog;
pub use events::{MAX_KEPT_EVENTS, REPEAT_WINDOW, SwarmEvent};
pub use guard::{DivergenceGuard, GuardLimits, GuardTrip};
use model::FlownModel;
pub use safety::SafetyStats;
use scheduler::LinkScheduler;
pub use setup::{
    BREACH_SHARE, BreachAction, EndAction, FenceSetup, LossPolicy, PlanDecision, Retargeted,
    SAFETY_GAMMA, SafetySetup, SetpointKind, SwarmSetup, TargetVelocity,
};
use slot::{Member, VehicleSlot};

/// Largest speed (m/s) a start velocity or target velocity may have, and the speed
/// limit the planner assumes for a vehicle that states none.
pub const MAX_SPEED_MPS: f64 = 100.0;

/// A listen lag shorter than this is none: the link and state timeouts are hundreds of
/// milliseconds, and a lag that comes and goes every loop would reschedule every link.
pub const LISTEN_LAG_FLOOR: Duration = Duration::from_millis(20);

/// The longest a control tick waits for the unread datagrams of the coordinator's own
/// stall ([`Swarm::set_listen_lag`]).
pub const MAX_TICK_DEFER: Duration = Duration::from_millis(100);

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
    /// The divergence guard ended the consensus: the vehicles brake and hover in place,
    /// since the given time, until the end of the duration.
    Stopped(SimTime),
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
            Self::Stopped(_) => "stopped",
        }
    }
}

/// Why the swarm gave up before its flight (the vehicles that flew were landed).
#[derive(Debug, Clone, PartialEq)]
pub enum SwarmFailure {
    /// Not every vehicle was flying in OFFBOARD within the handshake timeout, or one
    /// vehicle's handshake gave up.
    Handshake {
        /// The vehicles not flying: system id and its link phase (with what its handshake
        /// waits for, when it says).
        not_flying: Vec<(u8, String)>,
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
                    let what = match phase.as_str() {
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

/// Why the flight stopped (`summary.json`'s `stop_reason`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum StopReason {
    /// The configured duration is over.
    DurationOver,
    /// The divergence guard ended the consensus.
    Guard(GuardTrip),
    /// The handshake was not complete in time.
    Handshake,
    /// A vehicle was lost and the loss policy is `land`.
    LinkLoss,
    /// Landing was asked for from outside (Ctrl-C, a signal, the live view).
    Requested,
    /// A vehicle could no longer stop inside the fence's margin.
    Fence,
    /// The safety filter could not keep two vehicles apart.
    Separation,
}

impl StopReason {
    /// A short name: `duration`, `guard`, `handshake`, `link_loss`, `requested`, `fence`,
    /// `separation`.
    pub fn name(&self) -> &'static str {
        match self {
            Self::DurationOver => "duration",
            Self::Guard(_) => "guard",
            Self::Handshake => "handshake",
            Self::LinkLoss => "link_loss",
            Self::Requested => "requested",
            Self::Fence => "fence",
            Self::Separation => "separation",
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

/// The law's inputs and outputs, an entry per vehicle in the links' order: arrays, because
/// the pure laws (consensus, saturation, the safety filter) take them as slices.
#[derive(Debug, Clone)]
struct LawArrays {
    /// The ring's weights `w_i` (the prediction is Σ wᵢ vᵢ / Σ wᵢ).
    w: Vec<f64>,
    /// Each vehicle's fresh state in the common frame, `None` when stale or unknown.
    states: Vec<Option<CommonState>>,
    /// Horizontal position, velocity and formation offset, as the law reads them.
    horizontal: Vec<HorizontalState>,
    /// The horizontal law's output (m/s², ENU).
    accel: Vec<Vector2<f64>>,
    /// Each command after the saturation and the safety filter (m/s², ENU, z up).
    commands: Vec<Vector3<f64>>,
    /// Each vehicle's command as the law gave it, before the saturation.
    law_commands: Vec<Vector3<f64>>,
    /// The attitude and thrust streamed to each vehicle.
    setpoints: Vec<AttitudeThrust>,
    /// The vehicle model each command is made for (the configured one, corrected by
    /// the flown estimates).
    flown_models: Vec<VehicleModel>,
    /// Each vehicle's horizontal box in the saturation, kept between ticks.
    boxes: Vec<Vector2<f64>>,
}

/// The swarm.
#[derive(Debug, Clone)]
pub struct Swarm {
    setup: SwarmSetup,
    phase: SwarmPhase,
    next_control: SimTime,
    predicted_final_velocity: Option<Vector2<f64>>,
    /// The safety filter, its inputs' buffers, what it did, and the closest pair.
    safety: safety::SafetyWork,
    /// Each vehicle: its link (or its shard's report of it) and what the laws keep of it.
    slots: Vec<VehicleSlot>,
    /// The law's inputs and outputs, an entry per vehicle.
    law: LawArrays,
    saturated_ticks: u64,
    consensus_ticks: u64,
    /// Which links have output, and when each is next due.
    scheduler: LinkScheduler,
    log: EventLog,
    failure: Option<SwarmFailure>,
    mean_velocity_integral: Vector2<f64>,
    all_flying_since: Option<SimTime>,
    first_consensus: Option<SimTime>,
    /// When the swarm first flew on a law of the flight (the re-target stage or
    /// consensus): a swarm that holds before consensus ever started (a vehicle lost in
    /// the re-target stage) ends its flight the duration after this.
    first_law: Option<SimTime>,
    control_ticks: u64,
    plan: Option<PlanDecision>,
    timing: timing::TickTiming,
    /// How far behind its sockets the coordinator is ([`Swarm::set_listen_lag`]).
    listen_lag: Duration,
    /// Since when a control tick has waited for a stall's unread datagrams.
    tick_due_since: Option<SimTime>,
    /// The divergence guard, if on.
    guard: Option<DivergenceGuard>,
    /// Why the flight stopped (or is stopping), once it does.
    stop: Option<StopReason>,
    /// The other shards, when this swarm is one shard of several.
    peers: Option<Box<shard::Peers>>,
}

/// The finest a link timer is looked at again when it stays due: the emulator's and the
/// lockstep driver's step.
const TIMER_GRANULARITY: Duration = Duration::from_millis(1);

impl Swarm {
    /// A swarm that starts handshaking every vehicle.
    pub fn new(setup: SwarmSetup) -> Self {
        let n = setup.links.len();
        let w = (0..n).map(|i| setup.ring.w(i)).collect();
        let links = setup.links.iter().zip(&setup.models).map(|(cfg, model)| {
            let level = attitude_thrust_from_acceleration(Vector3::zeros(), 0.0, model);
            match setup.setpoint {
                SetpointKind::Attitude => VehicleLink::new(cfg.clone(), level),
                SetpointKind::Acceleration => {
                    VehicleLink::new(cfg.clone(), Setpoint::Acceleration(Vector3::zeros()))
                }
            }
        });
        let setpoints = setup
            .models
            .iter()
            .map(|m| attitude_thrust_from_acceleration(Vector3::zeros(), 0.0, m))
            .collect();
        let (lo, hi) = (
            setup.envelope.min_thrust_norm().max(0.05),
            setup.envelope.max_thrust_norm().min(0.95),
        );
        let flown: Vec<FlownModel> = setup
            .models
            .iter()
            .zip(&setup.drag_per_s)
            .map(|(m, d)| {
                // With acceleration setpoints PX4 estimates its hover thrust itself.
                let estimate = setup.estimate_hover && setup.setpoint == SetpointKind::Attitude;
                let allowance = 0.5 * setup.mean_velocity_gain;
                FlownModel::new(
                    *m,
                    (*d, allowance),
                    (
                        estimate,
                        setup.estimate_drag,
                        setup.disturbance_time_constant_s,
                    ),
                    (lo, hi),
                    setup.control_interval.as_secs_f64(),
                )
            })
            .collect::<Vec<_>>();
        let slots = links
            .zip(flown)
            .map(|(link, flown)| VehicleSlot::new(Member::Local(link), flown))
            .collect();
        let flown_models = setup.models.clone();
        let setup_interval = setup.control_interval;
        let setup_guard = setup.guard;
        Self {
            law: LawArrays {
                w,
                horizontal: vec![HorizontalState::default(); n],
                accel: vec![Vector2::zeros(); n],
                commands: vec![Vector3::zeros(); n],
                law_commands: vec![Vector3::zeros(); n],
                setpoints,
                states: vec![None; n],
                flown_models,
                boxes: Vec::with_capacity(n),
            },
            setup,
            phase: SwarmPhase::Handshake,
            next_control: SimTime::ZERO,
            predicted_final_velocity: None,
            safety: safety::SafetyWork::new(n),
            slots,
            saturated_ticks: 0,
            consensus_ticks: 0,
            scheduler: LinkScheduler::new(n),
            log: EventLog::default(),
            failure: None,
            mean_velocity_integral: Vector2::zeros(),
            all_flying_since: None,
            first_consensus: None,
            first_law: None,
            control_ticks: 0,
            plan: None,
            timing: timing::TickTiming::new(setup_interval),
            listen_lag: Duration::ZERO,
            tick_due_since: None,
            guard: setup_guard.map(DivergenceGuard::new),
            stop: None,
            peers: None,
        }
    }

    /// One shard of a swarm flown by several ([`crate::distributed`]): it handshakes and
    /// commands the vehicles `plan` gives it, and takes the others from the other
    /// shards' messages ([`Swarm::handle_shard_message`], [`Swarm::poll_shard_message`]).
    ///
    /// # Errors
    /// When the plan is not for this ring, or the setup asks for what shards do not fly
    /// yet (a target velocity: its planner needs every vehicle's velocity at one instant).
    pub fn new_shard(
        setup: SwarmSetup,
        plan: crate::distributed::ShardPlan,
    ) -> Result<Self, String> {
        let n = setup.links.len();
        if plan.vehicles_of(plan.this()) == 0 || (0..n).any(|i| plan.owner(i).is_none()) {
            return Err(format!(
                "the shard plan does not give each of the {n} vehicles a shard"
            ));
        }
        let mut swarm = Self::new(setup);
        for i in (0..n).filter(|i| !plan.is_local(*i)) {
            // Flown by its own shard: no link here, never due.
            swarm.slots[i].member = Member::Remote(None);
            swarm.scheduler.schedule(i, SimTime::MAX);
        }
        swarm.peers = Some(Box::new(shard::Peers::new(plan, &swarm.law.w)));
        Ok(swarm)
    }

    /// The control loop's punctuality so far: tick lateness and the age of the states
    /// flown on.
    pub fn timing(&self) -> timing::TimingReport {
        self.timing.report()
    }

    /// The phase.
    pub fn phase(&self) -> SwarmPhase {
        self.phase
    }

    /// How many vehicles the swarm has (flown here or, in a shard, elsewhere).
    pub fn vehicle_count(&self) -> usize {
        self.slots.len()
    }

    /// Vehicle `i`'s link, when this process flies it.
    pub fn link(&self, i: usize) -> Option<&VehicleLink> {
        self.slots.get(i)?.link()
    }

    /// The links of the vehicles this process flies (every vehicle without shards), in
    /// vehicle order.
    pub fn links(&self) -> impl Iterator<Item = &VehicleLink> {
        self.slots.iter().filter_map(VehicleSlot::link)
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

    /// A vehicle's warnings left out of the log as repeats of one of the same kind (the
    /// same words, whatever their numbers) logged less than
    /// [`REPEAT_WINDOW`] before.
    pub fn repeated_warnings(&self) -> u64 {
        self.log.repeated()
    }

    /// Vehicle `i`'s hover thrust estimate and its standard deviation (the configured
    /// hover throttle while the estimator is off).
    pub fn hover_estimate(&self, i: usize) -> Option<(f64, f64)> {
        self.slots.get(i).map(|s| s.flown.hover_estimate())
    }

    /// Vehicle `i`'s drag estimate and its standard deviation (1/s), and the drag fed
    /// forward now (1/s).
    pub fn drag_estimate(&self, i: usize) -> Option<(f64, f64, f64)> {
        self.slots.get(i).map(|s| &s.flown).map(|f| {
            let (d, std) = f.drag_estimate();
            (d, std, f.drag_fed_forward_per_s())
        })
    }

    /// The acceleration vehicle `i`'s commands do not explain, as its disturbance observer
    /// estimated it last while the vehicle flew on our commands in the air (m/s², ENU;
    /// zero while the observer is off).
    pub fn disturbance_estimate_mps2(&self, i: usize) -> Option<Vector2<f64>> {
        self.slots.get(i).map(|s| s.flown.disturbance_seen_mps2())
    }

    /// The model vehicle `i` is flown with now.
    pub fn flown_model(&self, i: usize) -> Option<VehicleModel> {
        self.law.flown_models.get(i).copied()
    }

    /// Whether vehicle `i` was handed to its own Hold because its command could not be
    /// computed.
    pub fn is_isolated(&self, i: usize) -> bool {
        self.slots.get(i).is_some_and(|s| s.isolated)
    }

    /// Why the flight stopped, once it has (or is stopping).
    pub fn stop_reason(&self) -> Option<StopReason> {
        self.stop
    }

    /// Vehicle `i`'s attitude response as measured so far (`None` before enough
    /// commanded motion has been seen, or with acceleration setpoints).
    pub fn attitude_response(&self, i: usize) -> Option<crate::control::AttitudeResponse> {
        self.slots.get(i).and_then(|s| s.flown.attitude_response())
    }

    /// Whether the divergence guard ended the consensus (`fly` and `demo` exit non-zero).
    pub fn guard_trip(&self) -> Option<GuardTrip> {
        match self.stop {
            Some(StopReason::Guard(trip)) => Some(trip),
            _ => None,
        }
    }

    /// Tells every vehicle to land and disarm, asked from outside (Ctrl-C, a signal).
    pub fn land(&mut self, now: SimTime) {
        self.land_because(now, StopReason::Requested);
    }

    /// Tells every vehicle to land and disarm; `reason` is kept unless the flight was
    /// already stopping for another.
    /// Ends the law for `reason` with the warning `text`: every vehicle brakes and hovers
    /// where it is (`land` false: the swarm is Stopped), or every vehicle lands. What the
    /// divergence guard, the fence and the safety action do.
    pub(super) fn stop_law(&mut self, now: SimTime, reason: StopReason, land: bool, text: String) {
        self.stop = Some(reason);
        self.log.push(now, true, text);
        if land {
            self.land_because(now, reason);
        } else {
            self.forget_hold_points();
            self.phase = SwarmPhase::Stopped(now);
        }
    }

    pub(crate) fn land_because(&mut self, now: SimTime, reason: StopReason) {
        self.stop.get_or_insert(reason);
        if !matches!(self.phase, SwarmPhase::Landing(_)) {
            self.log
                .push(now, false, "landing every vehicle".to_owned());
            self.phase = SwarmPhase::Landing(now);
        }
        for link in self.slots.iter_mut().filter_map(VehicleSlot::link_mut) {
            link.land(now);
        }
        self.after_all_links(now);
    }

    /// Every holding vehicle takes a new hold point when it has braked.
    pub(super) fn forget_hold_points(&mut self) {
        self.slots.iter_mut().for_each(|s| s.hold_point = None);
    }

    /// Whether every vehicle has landed and disarmed (or was never armed), or can no
    /// longer be reached (failed).
    pub fn is_finished(&self) -> bool {
        matches!(self.phase, SwarmPhase::Landing(_))
            && self
                .links()
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
        &self.law.commands
    }

    /// Whether the saturation changed vehicle `i`'s command on the last control tick (the
    /// envelope limited it).
    pub fn command_limited(&self, i: usize) -> bool {
        self.law.law_commands.get(i) != self.law.commands.get(i)
    }

    /// The last attitude and thrust setpoint of each vehicle.
    pub fn setpoints(&self) -> &[AttitudeThrust] {
        &self.law.setpoints
    }

    /// Vehicle `i` in the common frame, once its origin and a position are known (whatever
    /// the age of its position; the control tick uses only fresh ones).
    pub fn common_state(&self, i: usize) -> Option<CommonState> {
        let slot = self.slots.get(i)?;
        let Some(link) = slot.link() else {
            return slot.remote().map(|r| r.state);
        };
        let state = link.state();
        let origin = state.origin?;
        // No position yet (ArduPilot reports its origin before its first
        // LOCAL_POSITION_NED): nothing to place.
        state.last_position?;
        let pos_common_ned_m = match slot.origin_offset {
            Some((known, offset_ned_m)) if known == origin => offset_ned_m + state.pos_local_ned_m,
            _ => self
                .setup
                .frame
                .to_common_ned(&origin, &state.pos_local_ned_m),
        };
        Some(CommonState {
            pos_enu_m: crate::control::ned_to_enu(pos_common_ned_m),
            vel_enu_mps: crate::control::ned_to_enu(state.vel_ned_mps),
        })
    }

    /// Hands a datagram from vehicle `i` to its link; `true` when the link took a frame
    /// of it as the vehicle's (see [`VehicleLink::handle_datagram`]).
    ///
    /// Costs the link's work only: nothing here visits the other links.
    pub fn handle_datagram(&mut self, now: SimTime, i: usize, bytes: &[u8]) -> bool {
        let Some(link) = self.slots.get_mut(i).and_then(VehicleSlot::link_mut) else {
            return false;
        };
        let taken = link.handle_datagram(now, bytes);
        self.after_link(now, i);
        taken
    }

    /// When [`Swarm::handle_timeout`] must next be called (never later than needed; a
    /// deadline that moved later may cause one early call).
    pub fn poll_timeout(&self) -> SimTime {
        self.scheduler
            .next_deadline()
            .map_or(self.next_control, |t| self.next_control.min(t))
    }

    /// Whether some link may have a datagram queued ([`Swarm::poll_transmit`] may still
    /// find none).
    pub fn has_output(&self) -> bool {
        self.scheduler.any_output()
    }

    /// Gives a sent datagram's buffer back to link `i` (any link will do: the buffer is
    /// only memory) so that the next frame reuses it.
    pub fn recycle(&mut self, i: usize, bytes: Vec<u8>) {
        if let Some(link) = self.slots.get_mut(i).and_then(VehicleSlot::link_mut) {
            link.recycle(bytes);
        }
    }

    /// The next datagram and the vehicle it is for (round robin over the links).
    pub fn poll_transmit(&mut self) -> Option<(usize, Vec<u8>)> {
        loop {
            let i = self.scheduler.next_output()?;
            let Some(link) = self.slots[i].link_mut() else {
                continue;
            };
            let Some(bytes) = link.poll_transmit() else {
                continue;
            };
            if link.has_output() {
                self.scheduler.has_output(i);
            }
            return Some((i, bytes));
        }
    }

    /// Tells every link that the coordinator had read everything received only up to
    /// `now − lag` (the UDP driver measures it: `ringswarm::driver::listening`): a stall of its own is not taken for
    /// its vehicles going silent. Lags under [`LISTEN_LAG_FLOOR`] count as none.
    pub fn set_listen_lag(&mut self, now: SimTime, lag: Duration) {
        let lag = if lag < LISTEN_LAG_FLOOR {
            Duration::ZERO
        } else {
            lag
        };
        if lag == self.listen_lag {
            return;
        }
        let shrank = lag < self.listen_lag;
        self.listen_lag = lag;
        for link in self.slots.iter_mut().filter_map(VehicleSlot::link_mut) {
            link.set_listen_lag(lag);
        }
        if shrank {
            // Deadlines moved earlier: the timers must know.
            self.after_all_links(now);
        }
    }

    /// Whether a tick due now waits for the unread datagrams of a stall: while there is a
    /// listen lag, for at most [`MAX_TICK_DEFER`]; an overload that lasts longer is flown
    /// through (its old states then hold the swarm as one).
    fn defer_tick(&mut self, now: SimTime) -> bool {
        if self.listen_lag.is_zero() {
            return false;
        }
        let since = *self.tick_due_since.get_or_insert(now);
        now.saturating_since(since) < MAX_TICK_DEFER
    }

    /// Runs the control tick and the links' timers due at `now`.
    pub fn handle_timeout(&mut self, now: SimTime) {
        if now >= self.next_control && self.defer_tick(now) {
            // The coordinator's own stall: what its vehicles sent meanwhile is still
            // unread. The tick waits for it, a millisecond at a time, rather than fly on
            // states it knows to be old (and hold the swarm for them).
            self.next_control = now + Duration::from_millis(1);
        } else if now >= self.next_control {
            self.tick_due_since = None;
            self.timing.tick(self.next_control, now);
            self.control(now);
            // A fixed schedule: lateness of one wake-up does not slow the rate down, and
            // a long stall restarts the schedule instead of bursting.
            let next = self.next_control + self.setup.control_interval;
            self.next_control = if next <= now {
                now + self.setup.control_interval
            } else {
                next
            };
            // The law touched every link.
            self.after_all_links(now);
        }
        while let Some(i) = self.scheduler.next_due(now) {
            if let Some(link) = self.slots[i].link_mut()
                && now >= link.poll_timeout()
            {
                link.handle_timeout(now);
            }
            // Scheduled again here.
            self.after_link(now, i);
            self.scheduler.defer_if_still_due(i, now, TIMER_GRANULARITY);
        }
    }

    /// After something that may have touched every link (landing): O(N), rare.
    fn after_all_links(&mut self, now: SimTime) {
        for i in 0..self.slots.len() {
            self.after_link(now, i);
        }
    }

    /// After link `i` ran: its output, its next deadline, its events.
    fn after_link(&mut self, now: SimTime, i: usize) {
        let Some(slot) = self.slots.get_mut(i) else {
            return;
        };
        let Some(link) = slot.link() else {
            return;
        };
        let (origin, output, deadline) =
            (link.state().origin, link.has_output(), link.poll_timeout());
        if let Some(origin) = origin
            && slot.origin_offset.is_none_or(|(known, _)| known != origin)
        {
            slot.origin_offset = Some((origin, self.setup.frame.offset_ned_m(&origin)));
        }
        if output {
            self.scheduler.has_output(i);
        }
        self.scheduler.schedule(i, deadline);
        self.drain_events_of(now, i);
    }

    /// The hover throttle vehicle `i` reports of itself (ArduPilot's learnt
    /// MOT_THST_HOVER): with the hover estimator on, the estimate starts from it (the
    /// estimator corrects it in the air); with it off, the configured one is flown and a
    /// disagreement of more than the estimator's significance is warned of.
    fn take_reported_hover(&mut self, now: SimTime, i: usize, hover_throttle: f64) {
        let configured = self.setup.models[i].hover_throttle();
        let differs =
            (hover_throttle - configured).abs() > model::SIGNIFICANT_FRACTION * configured;
        let text = if !self.setup.estimate_hover {
            differs.then(|| {
                format!(
                    "reports a hover throttle of {hover_throttle:.3}, the configured {configured:.3} is flown (swarm.estimate_hover is off)"
                )
            })
        } else if self
            .slots
            .get_mut(i)
            .is_some_and(|s| s.flown.seed_hover(hover_throttle))
        {
            differs.then(|| {
                format!(
                    "reports a hover throttle of {hover_throttle:.3}, not the configured {configured:.3}: the estimate starts from it"
                )
            })
        } else {
            Some(format!(
                "reported hover throttle {hover_throttle:.3} is outside the estimator's bounds: the configured one is flown"
            ))
        };
        if let Some(text) = text {
            self.log.push_vehicle(now, &self.setup.links[i], true, text);
        }
    }

    fn drain_events_of(&mut self, now: SimTime, i: usize) {
        while let Some(event) = self
            .slots
            .get_mut(i)
            .and_then(VehicleSlot::link_mut)
            .and_then(VehicleLink::poll_event)
        {
            self.log.push_vehicle(
                now,
                &self.setup.links[i],
                event.is_warning(),
                event.to_string(),
            );
            if let LinkEvent::HoverReported { hover_throttle } = event {
                self.take_reported_hover(now, i, hover_throttle);
            }
        }
    }
}
