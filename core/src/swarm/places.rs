//! Each vehicle's formation place: as configured, or assigned at each start of consensus
//! when the places are interchangeable (`[formation] assign = "optimal"`). Shards agree
//! on one assignment as they agree on a plan: each sends its vehicles' positions at the
//! adopted start, and every shard assigns from all of them, to the same places.

use nalgebra::Vector2;
use ringswarm_wire::time::SimTime;

use super::{Swarm, VehicleIndex};
use crate::assignment::{AssignError, Assignment, assign_places};

/// A place assignment to solve off the control loop: every vehicle's position (ring
/// order) and the formation's places, both m, ENU.
#[derive(Debug, Clone, PartialEq)]
pub struct AssignJob {
    /// Which start of consensus it is for: an answer to an older one is dropped.
    pub id: u64,
    /// Every vehicle's horizontal position at the start (m, ENU).
    pub positions_m: Vec<Vector2<f64>>,
    /// The formation's places (m, ENU, from its centre).
    pub places_m: Vec<Vector2<f64>>,
}

impl AssignJob {
    /// Solves it (the work the driver takes off the control loop).
    ///
    /// # Errors
    /// The assignment's ([`crate::assignment::assign_places`]).
    pub fn solve(&self) -> Result<Assignment, AssignError> {
        assign_places(&self.positions_m, &self.places_m)
    }
}

/// The assignment jobs of a swarm that solves off the control loop.
#[derive(Debug, Clone, Default)]
pub(super) struct PendingAssignment {
    /// The last job made (its id is the one an answer must carry).
    last_id: u64,
    /// Made and not yet handed out.
    outbox: Option<AssignJob>,
    /// Handed out and not yet answered: its id.
    waiting: Option<u64>,
}

impl Swarm {
    /// At a start of consensus (at `start`): gives every vehicle the place of minimum
    /// total squared distance from where it is now (one process), or takes this shard's
    /// vehicles' positions for the other shards (the places follow in
    /// [`Swarm::assign_places_in_shards`]). Nothing changes when a position is unknown or
    /// the solver fails (logged).
    pub(super) fn assign_places(&mut self, now: SimTime, start: SimTime) {
        if !self.setup.assign_places {
            return;
        }
        if self.peers.is_some() {
            let own: Option<Vec<Vector2<f64>>> = self
                .indices()
                .filter(|i| !self.is_remote(*i))
                .map(|i| self.law.states[i].map(|s| s.pos_enu_m.xy()))
                .collect();
            if let Some(p) = self.peers.as_mut() {
                p.places_own = own.map(|own| (start, own));
                p.places_assigned = false;
            }
            return;
        }
        let positions: Option<Vec<Vector2<f64>>> = self
            .law
            .states
            .iter()
            .map(|s| s.map(|s| s.pos_enu_m.xy()))
            .collect();
        self.assign_from(now, positions);
    }

    /// With shards, every consensus tick until done: the places once every shard's
    /// positions at the adopted start are in.
    pub(super) fn assign_places_in_shards(&mut self, now: SimTime) {
        if !matches!(self.phase, super::SwarmPhase::Consensus(_)) {
            return;
        }
        let Some(p) = self.peers.as_ref() else {
            return;
        };
        if p.places_assigned || p.places_own.is_none() {
            return;
        }
        let Some(positions) = p.place_inputs() else {
            return;
        };
        self.assign_from(now, Some(positions));
        if let Some(p) = self.peers.as_mut() {
            p.places_assigned = true;
        }
    }

    /// The assignment from every vehicle's position (ring order; `None`: one unknown).
    fn assign_from(&mut self, now: SimTime, positions: Option<Vec<Vector2<f64>>>) {
        let Some(positions) = positions else {
            self.log.push(
                now,
                true,
                "places not assigned: a vehicle's position is unknown".to_owned(),
            );
            return;
        };
        if self.setup.assign_off_tick {
            let pending = &mut self.assignment;
            pending.last_id += 1;
            pending.outbox = Some(AssignJob {
                id: pending.last_id,
                positions_m: positions,
                places_m: self.setup.offsets_m.clone(),
            });
            return;
        }
        let result = assign_places(&positions, &self.setup.offsets_m);
        self.apply_assignment(now, result);
    }

    /// The assignment to solve off the control loop, once per start of consensus (with
    /// [`crate::swarm::SwarmSetup::assign_off_tick`]): the driver solves it
    /// ([`AssignJob::solve`]) and hands the answer to [`Swarm::finish_assignment`].
    /// Meanwhile the swarm flies the places it had.
    pub fn take_assignment_job(&mut self) -> Option<AssignJob> {
        let job = self.assignment.outbox.take()?;
        self.assignment.waiting = Some(job.id);
        Some(job)
    }

    /// The answer to the job `id` (at `now`): its places from now on, logged. An answer to
    /// a job a newer start of consensus has replaced is dropped.
    pub fn finish_assignment(
        &mut self,
        now: SimTime,
        id: u64,
        result: Result<Assignment, AssignError>,
    ) {
        if self.assignment.waiting != Some(id) || id != self.assignment.last_id {
            return;
        }
        self.assignment.waiting = None;
        if result
            .as_ref()
            .is_ok_and(|a| a.place_of.len() != self.slots.len())
        {
            self.log.push(
                now,
                true,
                "places not assigned: the answer is for another number of vehicles".to_owned(),
            );
            return;
        }
        self.apply_assignment(now, result);
    }

    fn apply_assignment(&mut self, now: SimTime, result: Result<Assignment, AssignError>) {
        match result {
            Ok(a) => {
                for (slot, &place) in self.slots.iter_mut().zip(&a.place_of) {
                    slot.place_m = self.setup.offsets_m[place];
                }
                self.log.push(now, false, a.event_text());
            }
            Err(e) => self
                .log
                .push(now, true, format!("places not assigned: {e}")),
        }
    }

    /// The formation place vehicle `i` flies to (m, ENU, from the formation's centre).
    pub fn place_m(&self, i: VehicleIndex) -> Vector2<f64> {
        self.slots[i].place_m
    }

    /// Every vehicle's formation place, in ring order.
    pub fn places_m(&self) -> impl ExactSizeIterator<Item = Vector2<f64>> + '_ {
        self.slots.iter().map(|s| s.place_m)
    }
}
