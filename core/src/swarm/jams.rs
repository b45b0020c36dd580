//! Breaking jams in the control tick: the jam watch fed with the filter's active rows of
//! the last tick, what it took of each command, and each vehicle's distance to its place; jammed vehicles then pass on
//! the jam layer (`crate::safety::layers`: their altitude target moves, from the next
//! tick's altitude loop on), or are turned past each other by a bias added to the
//! commands before the saturation (`crate::safety::jam`).

use nalgebra::Vector2;
use ringswarm_wire::time::SimTime;

use super::{Swarm, SwarmPhase};
use crate::safety::jam::{JamSettings, rotation_bias};
use crate::safety::layers::{LayerRule, clear_to_come_back, update_layers};

impl Swarm {
    /// On consensus ticks with `[safety]` and jam breaking on: which vehicles are jammed
    /// now, logged when that changes, and the turn of their active pairs added to the
    /// horizontal commands (it keeps `Σ wᵢuᵢ`; the saturation and the filter follow).
    pub(super) fn break_jams(&mut self, now: SimTime) {
        let Some(settings) = self.setup.safety.and_then(|s| s.jams) else {
            return;
        };
        if !matches!(self.phase, SwarmPhase::Consensus(_)) {
            // Landing, a vehicle comes down where it is or waits (`super::landing`).
            if let Some(rule) = settings.layer
                && !matches!(self.phase, SwarmPhase::Landing(_))
            {
                self.leave_the_jam_layer(now, &rule);
            }
            return;
        }
        // Nobody held, jammed or on the layer, and no pair row active: the tick changes
        // nothing (with shards, another shard's vehicles may be on the layer).
        let quiet = self.peers.is_none()
            && self.safety.jams.watch.idle()
            && !self.safety.jams.layered.iter().any(Option::is_some)
            && self
                .safety
                .filter
                .active_rows()
                .iter()
                .all(|&(i, j)| i == j);
        if quiet {
            return;
        }
        let n = self.vehicle_count();
        let work = &mut self.safety.jams;
        work.read_motions(&self.law.states);
        // Each vehicle's distance to its place: `pᵢ − placeᵢ` from their w-weighted mean
        // (the centre the position consensus goes to).
        let (mut sum, mut w_sum) = (Vector2::zeros(), 0.0);
        for (i, p) in work.positions.iter().enumerate() {
            if let Some(p) = p {
                sum += (p - self.slots[i].place_m) * self.law.w[i];
                w_sum += self.law.w[i];
            }
        }
        let centre = (w_sum > 0.0).then(|| sum / w_sum);
        work.offsets.clear();
        work.offsets
            .extend(work.positions.iter().enumerate().map(|(i, p)| {
                let (p, c) = ((*p)?, centre?);
                Some(p - self.slots[i].place_m - c)
            }));
        work.errors.clear();
        work.errors
            .extend(work.offsets.iter().map(|o| o.map(|o| o.norm())));
        let active = self.safety.filter.active_rows();
        let was_jammed = work.watch.any();
        let change = work
            .watch
            .update(&settings, now, active, &work.restrained, &work.errors);
        if work.watch.any() {
            self.safety.stats.jam_ticks += 1;
            if !was_jammed {
                self.safety.stats.jams += 1;
            }
        }
        if !change.jammed.is_empty() {
            let names = self.labels(&change.jammed);
            self.log.push(
                now,
                true,
                format!(
                    "jam: vehicle(s) {} held by the safety filter for {:.1} s without closing on \
                     their places: {}",
                    names,
                    settings.hold_s,
                    if settings.layer.is_some() {
                        "passing it on the jam layer"
                    } else {
                        "turning them past each other"
                    }
                ),
            );
        }
        if !change.released.is_empty() {
            let names = self.labels(&change.released);
            self.log
                .push(now, false, format!("jam over for vehicle(s) {names}"));
        }
        if let Some(rule) = settings.layer {
            self.pass_on_the_layer(now, &settings, &rule);
            return;
        }
        if !self.safety.jams.watch.any() {
            return;
        }
        let work = &mut self.safety.jams;
        work.commands.clear();
        work.commands
            .extend(self.law.commands.iter().map(|u| u.xy()));
        rotation_bias(
            &settings,
            &work.watch,
            self.safety.filter.active_rows(),
            &work.positions,
            &self.law.w,
            &mut work.commands,
        );
        for i in 0..n {
            // Only the vehicles flown here: another shard turns its own side of a pair.
            if self.slots[i].link().is_some() {
                let u = work.commands[i];
                self.law.commands[i].x = u.x;
                self.law.commands[i].y = u.y;
            }
        }
    }
}

impl Swarm {
    /// Vehicle `i`'s altitude target (m, up, common frame): the formation's, the jam
    /// layer's while it passes a jam there, or the one it holds while it waits to land.
    pub(super) fn altitude_target_m(&self, i: usize) -> f64 {
        if let Some(altitude_m) = self.slots.get(i).and_then(|s| s.waits_to_land) {
            return altitude_m;
        }
        let layer = self
            .setup
            .safety
            .as_ref()
            .and_then(|s| s.jams.as_ref())
            .and_then(|j| j.layer.as_ref())
            .filter(|_| self.safety.jams.layered.get(i).is_some_and(Option::is_some));
        self.setup.altitude_m + layer.map_or(0.0, |rule| rule.offset_up_m())
    }

    /// Which vehicles fly on the jam layer now, each move logged.
    fn pass_on_the_layer(&mut self, now: SimTime, settings: &JamSettings, rule: &LayerRule) {
        let n = self.vehicle_count();
        let work = &mut self.safety.jams;
        work.layered.resize(n, None);
        // Another shard's vehicle is on the layer when its own shard sent it there: seen
        // from here, when it flies above half the layer's height (below, for a layer
        // below).
        let half_up_m = rule.offset_up_m() / 2.0;
        let sharded = self.peers.is_some();
        for (k, slot) in self.slots.iter().enumerate() {
            if !sharded || !slot.is_remote() {
                continue;
            }
            let up = self.law.states[k].is_some_and(|s| {
                let climb_m = s.pos_enu_m.z - self.setup.altitude_m;
                climb_m * half_up_m.signum() > half_up_m.abs()
            });
            match (up, work.layered[k]) {
                (true, None) => work.layered[k] = Some(now),
                (false, Some(_)) => work.layered[k] = None,
                _ => {}
            }
        }
        // A vehicle climbs or comes down only while the filter keeps finishing
        // (`super::safety::LAYER_CALM_S`): on a tick out of time it checks horizontal
        // braking alone, and moving vehicles through the block's altitude then lost the
        // separation in real time (docs/dense.md).
        if !work.filter_finished {
            return;
        }
        work.remote_layered.clear();
        if sharded {
            work.remote_layered.extend_from_slice(&work.layered);
        }
        let mut change = update_layers(
            rule,
            now,
            settings.min_error_m,
            |k| work.watch.is_jammed(k),
            self.safety.filter.active_rows(),
            &work.offsets,
            (&work.positions, &work.velocities),
            &mut work.layered,
        );
        // Only this shard's vehicles move on its decisions; another shard's follow theirs.
        if sharded {
            for (k, slot) in self.slots.iter().enumerate() {
                if slot.is_remote() {
                    work.layered[k] = work.remote_layered[k];
                }
            }
            change.left.retain(|&k| !self.slots[k].is_remote());
            change.back.retain(|&k| !self.slots[k].is_remote());
        }
        self.safety.stats.layer_climbs += change.left.len() as u64;
        let side = if rule.above { "above" } else { "below" };
        for k in change.left {
            let name = self.setup.links[k].file_label();
            self.log.push(
                now,
                false,
                format!(
                    "vehicle {name} leaves for the jam layer {:.1} m {side} the formation to pass \
                     the vehicles holding it",
                    rule.height_m
                ),
            );
        }
        for k in change.back {
            let name = self.setup.links[k].file_label();
            self.log.push(
                now,
                false,
                format!("vehicle {name} back from the jam layer: nobody in its way"),
            );
        }
    }

    /// The vehicles `ks` as the files name them, comma-separated.
    fn labels(&self, ks: &[usize]) -> String {
        let names: Vec<String> = ks
            .iter()
            .map(|&k| self.setup.links[k].file_label())
            .collect();
        names.join(", ")
    }

    /// Out of consensus every vehicle comes back to the formation's altitude, each once
    /// nobody is within the layer's clearance of it and while the filter keeps finishing:
    /// all at once, a holding block had vehicles come down onto it.
    fn leave_the_jam_layer(&mut self, now: SimTime, rule: &LayerRule) {
        let work = &mut self.safety.jams;
        if !work.layered.iter().any(Option::is_some) || !work.filter_finished {
            return;
        }
        work.read_motions(&self.law.states);
        let layered = &work.layered;
        let back = clear_to_come_back(
            rule,
            (0..layered.len()).filter(|&k| layered[k].is_some() && self.slots[k].link().is_some()),
            (&work.positions, &work.velocities),
        );
        for &k in &back {
            work.layered[k] = None;
        }
        if back.is_empty() {
            return;
        }
        let names = self.labels(&back);
        self.log.push(
            now,
            false,
            format!(
                "consensus over: vehicle(s) {names} come back from the jam layer to the \
                 formation's altitude: nobody near"
            ),
        );
    }
}
