//! Ordering the landing (`crate::safety::landing`): with `[safety]` on, a vehicle in the
//! air above another closer than the horizontal separation waits. It holds its altitude,
//! flies to the nearest spot clear of every other vehicle's way down, and is told to land
//! once nobody is within the clearance of it horizontally, or after
//! [`LANDING_CLEAR_WAIT`] (with a warning). Every other vehicle lands at once.

use std::time::Duration;

use nalgebra::Vector2;
use ringswarm_wire::time::SimTime;

use super::{Swarm, SwarmPhase, VehicleIndex};
use crate::safety::landing::{SPOT_REACH_CLEARANCES, below_within, landing_spot_m, nearest_within};
use crate::safety::layers::LAYER_CLEAR_SHARE;

/// How long a vehicle waits to come down clear of the others before it lands anyway.
pub const LANDING_CLEAR_WAIT: Duration = Duration::from_secs(60);

impl Swarm {
    /// Tells every vehicle flown here to land, except those that must first fly clear of
    /// a vehicle below them (decided once, when the landing is first ordered).
    pub(super) fn order_landing(&mut self, now: SimTime, first: bool) {
        if first {
            self.choose_who_waits(now);
        }
        for (k, slot) in self.slots.iter_mut().enumerate() {
            if slot.waits_to_land.is_some() {
                continue;
            }
            if let Some(link) = slot.link_mut() {
                link.land(now);
                // Coming down where it is: no longer on the jam layer.
                if let Some(layered) = self.safety.jams.layered.get_mut(k) {
                    *layered = None;
                }
            }
        }
    }

    /// The clearance a vehicle coming down keeps from every other (m, horizontal): the
    /// jam layer's, or as many separations as it counts; `None` without `[safety]`.
    fn landing_clearance(&self) -> Option<(f64, f64)> {
        let safety = self.setup.safety.as_ref()?;
        let horizontal_m = safety.separation.horizontal_m;
        let clear_m = safety
            .jams
            .and_then(|j| j.layer)
            .map_or(LAYER_CLEAR_SHARE * horizontal_m, |rule| rule.clear_m);
        Some((horizontal_m, clear_m))
    }

    /// Which vehicles in the air wait to land, and where each first flies.
    fn choose_who_waits(&mut self, now: SimTime) {
        let Some((horizontal_m, clear_m)) = self.landing_clearance() else {
            return;
        };
        let positions: Vec<_> = self
            .law
            .states
            .iter()
            .map(|s| s.map(|s| s.pos_enu_m))
            .collect();
        let waiting: Vec<(VehicleIndex, usize, f64)> = self
            .indices()
            .filter(|&i| self.ours_in_air(i))
            .filter_map(|i| below_within(horizontal_m, i.get(), &positions).map(|(j, d)| (i, j, d)))
            .collect();
        if waiting.is_empty() {
            return;
        }
        // Where the others come down: every vehicle that does not wait, then each spot
        // as it is chosen.
        let mut taken: Vec<Vector2<f64>> = positions
            .iter()
            .enumerate()
            .filter(|(k, _)| !waiting.iter().any(|w| w.0.get() == *k))
            .filter_map(|(_, p)| p.map(|p| p.xy()))
            .collect();
        let fence = self.setup.fence.as_ref().map(|f| (&f.fence, f.margin_m));
        for &(i, j, d) in &waiting {
            let Some(p) = positions[i.get()] else {
                continue;
            };
            let spot = landing_spot_m(clear_m, p.xy(), &taken, fence);
            taken.push(spot.unwrap_or(p.xy()));
            let altitude_m = p.z.max(self.altitude_target_m(i.get()));
            let slot = &mut self.slots[i];
            slot.waits_to_land = Some(altitude_m);
            slot.hold_point = spot;
            self.safety.stats.landing_moves += 1;
            let name = self.setup.links[i.get()].file_label();
            let below = self.setup.links[j].file_label();
            let dz = p.z - positions[j].map_or(p.z, |q| q.z);
            let text = match spot {
                Some(s) => format!(
                    "vehicle {name} waits to land: vehicle {below} is {dz:.1} m below it and \
                     {d:.2} m away horizontally; it first flies at {altitude_m:.1} m to \
                     ({:.1}, {:.1}) m, {clear_m:.1} m clear of every other vehicle's way down",
                    s.x, s.y
                ),
                None => format!(
                    "vehicle {name} waits to land: vehicle {below} is {dz:.1} m below it and \
                     {d:.2} m away horizontally, and no spot within {:.0} m is {clear_m:.1} m \
                     clear of the others: it holds at {altitude_m:.1} m until nobody is near \
                     (at most {:.0} s)",
                    SPOT_REACH_CLEARANCES * clear_m,
                    LANDING_CLEAR_WAIT.as_secs_f64()
                ),
            };
            self.log.push(now, spot.is_none(), text);
        }
    }

    /// While landing: each waiting vehicle with nobody within the clearance of it
    /// horizontally is told to land; one that has waited [`LANDING_CLEAR_WAIT`] lands
    /// anyway, with a warning naming the nearest.
    pub(super) fn land_when_clear(&mut self, now: SimTime) {
        let SwarmPhase::Landing(since) = self.phase else {
            return;
        };
        if self.slots.iter().all(|s| s.waits_to_land.is_none()) {
            return;
        }
        let Some((_, clear_m)) = self.landing_clearance() else {
            return;
        };
        let positions: Vec<_> = self
            .law
            .states
            .iter()
            .map(|s| s.map(|s| s.pos_enu_m.xy()))
            .collect();
        let waited_out = now.saturating_since(since) >= LANDING_CLEAR_WAIT;
        for i in self.indices() {
            if self.slots[i].waits_to_land.is_none() {
                continue;
            }
            // Without a fresh state it cannot be seen clear: it waits out its time.
            let known = positions[i.get()].is_some();
            let nearest = nearest_within(clear_m, i.get(), &positions);
            if (!known || nearest.is_some()) && !waited_out {
                continue;
            }
            let slot = &mut self.slots[i];
            slot.waits_to_land = None;
            if let Some(link) = slot.link_mut() {
                link.land(now);
            }
            if let Some(layered) = self.safety.jams.layered.get_mut(i.get()) {
                *layered = None;
            }
            let name = self.setup.links[i.get()].file_label();
            let text = match nearest {
                None if !known => format!(
                    "vehicle {name} lands after waiting {:.0} s to come clear, its position \
                     unknown",
                    LANDING_CLEAR_WAIT.as_secs_f64()
                ),
                None => format!("vehicle {name} lands: nobody within {clear_m:.1} m of it"),
                Some((j, d)) => format!(
                    "vehicle {name} lands after waiting {:.0} s to come clear: vehicle {} is \
                     {d:.2} m away horizontally",
                    LANDING_CLEAR_WAIT.as_secs_f64(),
                    self.setup.links[j].file_label()
                ),
            };
            self.log.push(now, nearest.is_some() || !known, text);
        }
    }
}
