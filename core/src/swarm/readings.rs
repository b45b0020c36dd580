//! What the swarm tells its drivers, recorders and the live view: its phase, its links,
//! each vehicle's estimates and commands, its events. Read-only.

use nalgebra::{Vector2, Vector3};
use ringswarm_wire::time::SimTime;

use super::VehicleIndex;
use super::slot::VehicleSlot;
use super::{
    CommonState, GuardTrip, PlanDecision, StopReason, Swarm, SwarmEvent, SwarmFailure, SwarmPhase,
    SwarmSetup, timing,
};
use crate::control::{AttitudeThrust, VehicleModel};
use crate::vehicle::VehicleLink;

impl Swarm {
    /// The control loop's punctuality so far: tick lateness and the age of the states
    /// flown on.
    pub fn timing(&self) -> timing::TimingReport {
        self.timing.report()
    }

    /// The phase.
    pub fn phase(&self) -> SwarmPhase {
        self.phase
    }

    /// Every vehicle's index, in ring order.
    pub fn indices(&self) -> impl DoubleEndedIterator<Item = VehicleIndex> + Clone + 'static {
        VehicleIndex::all(self.slots.len())
    }

    /// How many vehicles the swarm has (flown here or, in a shard, elsewhere).
    pub fn vehicle_count(&self) -> usize {
        self.slots.len()
    }

    /// Vehicle `i`'s link, when this process flies it.
    pub fn link(&self, i: VehicleIndex) -> Option<&VehicleLink> {
        self.slots.get(i.0)?.link()
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
    pub fn hover_estimate(&self, i: VehicleIndex) -> Option<(f64, f64)> {
        self.slots.get(i.0).map(|s| s.flown.hover_estimate())
    }

    /// Vehicle `i`'s drag estimate and its standard deviation (1/s), and the drag fed
    /// forward now (1/s).
    pub fn drag_estimate(&self, i: VehicleIndex) -> Option<(f64, f64, f64)> {
        self.slots.get(i.0).map(|s| &s.flown).map(|f| {
            let (d, std) = f.drag_estimate();
            (d, std, f.drag_fed_forward_per_s())
        })
    }

    /// The acceleration vehicle `i`'s commands do not explain, as its disturbance observer
    /// estimated it last while the vehicle flew on our commands in the air (m/s², ENU;
    /// zero while the observer is off).
    pub fn disturbance_estimate_mps2(&self, i: VehicleIndex) -> Option<Vector2<f64>> {
        self.slots.get(i.0).map(|s| s.flown.disturbance_seen_mps2())
    }

    /// The model vehicle `i` is flown with now.
    pub fn flown_model(&self, i: VehicleIndex) -> Option<VehicleModel> {
        self.law.flown_models.get(i.0).copied()
    }

    /// Whether vehicle `i` was handed to its own Hold because its command could not be
    /// computed.
    pub fn is_isolated(&self, i: VehicleIndex) -> bool {
        self.slots.get(i.0).is_some_and(|s| s.isolated)
    }

    /// Why the flight stopped, once it has (or is stopping).
    pub fn stop_reason(&self) -> Option<StopReason> {
        self.stop
    }

    /// Vehicle `i`'s attitude response as measured so far (`None` before enough
    /// commanded motion has been seen, or with acceleration setpoints).
    pub fn attitude_response(&self, i: VehicleIndex) -> Option<crate::control::AttitudeResponse> {
        self.slots
            .get(i.0)
            .and_then(|s| s.flown.attitude_response())
    }

    /// Whether the divergence guard ended the consensus (`fly` and `demo` exit non-zero).
    pub fn guard_trip(&self) -> Option<GuardTrip> {
        match self.stop {
            Some(StopReason::Guard(trip)) => Some(trip),
            _ => None,
        }
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
    pub fn command_limited(&self, i: VehicleIndex) -> bool {
        self.law.law_commands.get(i.0) != self.law.commands.get(i.0)
    }

    /// The last attitude and thrust setpoint of each vehicle.
    pub fn setpoints(&self) -> &[AttitudeThrust] {
        &self.law.setpoints
    }

    /// When vehicle `i`'s position in [`Swarm::common_state`] came: its link's last
    /// accepted report's arrival, or when another shard measured it.
    pub fn state_time(&self, i: VehicleIndex) -> Option<SimTime> {
        let slot = self.slots.get(i.0)?;
        match slot.link() {
            Some(link) => link.state().last_position,
            None => slot.remote().map(|r| r.measured),
        }
    }

    /// How far (s) vehicle `i`'s state is behind a state that came at `newest`: what its
    /// position is carried forward by its velocity to put the two at one instant; 0 when
    /// either time is unknown.
    pub fn state_behind_s(&self, i: VehicleIndex, newest: Option<SimTime>) -> f64 {
        match (newest, self.state_time(i)) {
            (Some(newest), Some(at)) => newest.saturating_since(at).as_secs_f64(),
            _ => 0.0,
        }
    }

    /// Vehicle `i` in the common frame, once its origin and a position are known (whatever
    /// the age of its position; the control tick uses only fresh ones).
    pub fn common_state(&self, i: VehicleIndex) -> Option<CommonState> {
        let slot = self.slots.get(i.0)?;
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
}
