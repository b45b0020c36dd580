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

mod io;
mod jams;
mod landing;
mod laws;
mod lost;
mod model;
mod peers;
mod phases;
mod places;
mod plan;
mod readings;
mod safety;
mod scheduler;
mod setup;
mod shard;
mod slot;
mod status;
mod tick;
pub mod timing;

use nalgebra::{Vector2, Vector3};
use ringswarm_wire::time::SimTime;

use std::time::Duration;

use crate::consensus::HorizontalState;
use crate::control::{AttitudeThrust, VehicleModel, attitude_thrust_from_acceleration};
pub use crate::index::VehicleIndex;
use crate::vehicle::{Phase, Setpoint, VehicleLink};
use events::EventLog;
pub use events::{MAX_KEPT_EVENTS, REPEAT_WINDOW, SwarmEvent};
pub use guard::{DivergenceGuard, GuardLimits, GuardTrip};
pub use io::{LISTEN_LAG_FLOOR, MAX_TICK_DEFER};
pub use landing::LANDING_CLEAR_WAIT;
use model::FlownModel;
pub use phases::LOST_LANDING_WAIT;
pub use places::AssignJob;
pub use safety::{ClosestSeen, SafetyStats};
use scheduler::LinkScheduler;
pub use setup::{
    BREACH_SHARE, BreachAction, EndAction, FenceSetup, LossPolicy, PlanDecision, Retargeted,
    SAFETY_GAMMA, SafetySetup, SetpointKind, SwarmSetup, TargetVelocity,
};
use slot::{Member, VehicleSlot};
pub use status::{NotFlying, StopReason, SwarmFailure, SwarmPhase};

/// Largest speed (m/s) a start velocity or target velocity may have, and the speed
/// limit the planner assumes for a vehicle that states none.
pub const MAX_SPEED_MPS: f64 = 100.0;

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
    /// The vehicles still lost when the landing stopped waiting for them
    /// ([`LOST_LANDING_WAIT`]): left to their own failsafes.
    left_lost: Option<Vec<String>>,
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
    peers: Option<Box<peers::Peers>>,
    /// The place assignment handed out and not yet answered, and the one waiting to be
    /// handed out ([`Swarm::take_assignment_job`]).
    assignment: places::PendingAssignment,
}

impl Swarm {
    /// A swarm that starts handshaking every vehicle.
    pub fn new(setup: SwarmSetup) -> Self {
        let n = setup.links.len();
        let w = (0..n).map(|i| setup.ring.w(i)).collect();
        let links = setup
            .links
            .iter()
            .zip(&setup.models)
            .enumerate()
            .map(|(k, (cfg, model))| {
                let level = attitude_thrust_from_acceleration(Vector3::zeros(), 0.0, model);
                let mut link = match setup.setpoint {
                    SetpointKind::Attitude => VehicleLink::new(cfg.clone(), level),
                    SetpointKind::Acceleration => {
                        VehicleLink::new(cfg.clone(), Setpoint::Acceleration(Vector3::zeros()))
                    }
                };
                // A thousand heartbeats and TIMESYNCs in one instant make the next tick late.
                link.spread_heartbeat(k, n);
                link
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
            .zip(&setup.offsets_m)
            .map(|((link, flown), place)| VehicleSlot::new(Member::Local(link), flown, *place))
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
            left_lost: None,
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
            assignment: places::PendingAssignment::default(),
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
        for i in VehicleIndex::all(n).filter(|i| !plan.is_local(i.get())) {
            // Flown by its own shard: no link here, never due.
            swarm.slots[i].member = Member::Remote(None);
            swarm.scheduler.schedule(i, SimTime::MAX);
        }
        swarm.peers = Some(Box::new(peers::Peers::new(plan, &swarm.law.w)));
        Ok(swarm)
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
        let first = !matches!(self.phase, SwarmPhase::Landing(_));
        if first {
            self.log
                .push(now, false, "landing every vehicle".to_owned());
            self.phase = SwarmPhase::Landing(now);
        }
        self.order_landing(now, first);
        self.after_all_links(now);
    }

    /// Every holding vehicle takes a new hold point when it has braked.
    pub(super) fn forget_hold_points(&mut self) {
        self.slots.iter_mut().for_each(|s| s.hold_point = None);
    }

    /// Whether every vehicle has landed and disarmed (or was never armed), or can no
    /// longer be reached (failed, or lost for [`LOST_LANDING_WAIT`] of the landing).
    pub fn is_finished(&self) -> bool {
        matches!(self.phase, SwarmPhase::Landing(_))
            && (self.left_lost.is_some()
                || self
                    .links()
                    .all(|l| matches!(l.phase(), Phase::Done | Phase::Failed | Phase::Overridden)))
    }

    /// The vehicles (`vehicle 3`, `vehicle 3 on n1`) the landing stopped waiting for,
    /// lost [`LOST_LANDING_WAIT`] after it was ordered; empty when none.
    pub fn left_lost(&self) -> &[String] {
        self.left_lost.as_deref().unwrap_or_default()
    }
}
