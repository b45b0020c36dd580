//! Each vehicle's formation place: as configured, or assigned at each start of consensus
//! when the places are interchangeable (`[formation] assign = "optimal"`). Shards agree
//! on one assignment as they agree on a plan: each sends its vehicles' positions at the
//! adopted start, and every shard assigns from all of them, to the same places.

use nalgebra::Vector2;
use ringswarm_wire::time::SimTime;

use super::{Swarm, VehicleIndex};
use crate::assignment::assign_places;

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
        match assign_places(&positions, &self.setup.offsets_m) {
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
