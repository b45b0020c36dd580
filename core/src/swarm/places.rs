//! Each vehicle's formation place: as configured, or assigned at each start of consensus
//! when the places are interchangeable (`[formation] assign = "optimal"`).

use nalgebra::Vector2;
use ringswarm_wire::time::SimTime;

use super::{Swarm, VehicleIndex};
use crate::assignment::assign_places;

impl Swarm {
    /// Gives every vehicle the place of minimum total squared distance from where it is
    /// now (one process; shards keep the configured places, and say so in the events).
    /// Nothing changes when a position is unknown or the solver fails (logged).
    pub(super) fn assign_places(&mut self, now: SimTime) {
        if !self.setup.assign_places {
            return;
        }
        if self.peers.is_some() {
            self.log.push(
                now,
                false,
                "places as configured: shards do not assign places yet".to_owned(),
            );
            return;
        }
        let positions: Option<Vec<Vector2<f64>>> = self
            .law
            .states
            .iter()
            .map(|s| s.map(|s| s.pos_enu_m.xy()))
            .collect();
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
                self.log.push(
                    now,
                    false,
                    format!(
                        "places assigned: {} of {} vehicles away from their configured place; \
                         total squared distance {:.1} m² (configured {:.1} m²)",
                        a.moved(),
                        a.place_of.len(),
                        a.cost_m2,
                        a.identity_cost_m2
                    ),
                );
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
