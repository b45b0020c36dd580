//! Breaking jams in the control tick: the jam watch fed with the filter's active rows of
//! the last tick and each vehicle's distance to its place, and the turning bias added to
//! the commands before the saturation (`crate::safety::jam`).

use nalgebra::Vector2;
use ringswarm_wire::time::SimTime;

use super::{Swarm, SwarmPhase};
use crate::safety::jam::rotation_bias;

impl Swarm {
    /// On consensus ticks with `[safety]` and jam breaking on: which vehicles are jammed
    /// now, logged when that changes, and the turn of their active pairs added to the
    /// horizontal commands (it keeps `Σ wᵢuᵢ`; the saturation and the filter follow).
    pub(super) fn break_jams(&mut self, now: SimTime) {
        let Some(settings) = self.setup.safety.and_then(|s| s.jams) else {
            return;
        };
        if !matches!(self.phase, SwarmPhase::Consensus(_)) {
            return;
        }
        let n = self.vehicle_count();
        let work = &mut self.safety.jams;
        work.positions.clear();
        work.positions
            .extend(self.law.states.iter().map(|s| s.map(|s| s.pos_enu_m.xy())));
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
        work.errors.clear();
        work.errors
            .extend(work.positions.iter().enumerate().map(|(i, p)| {
                let (p, c) = ((*p)?, centre?);
                Some((p - self.slots[i].place_m - c).norm())
            }));
        let active = self.safety.filter.active_rows();
        let was_jammed = work.watch.any();
        let change = work.watch.update(&settings, now, active, &work.errors);
        if work.watch.any() {
            self.safety.stats.jam_ticks += 1;
            if !was_jammed {
                self.safety.stats.jams += 1;
            }
        }
        if !change.jammed.is_empty() {
            let names: Vec<String> = change
                .jammed
                .iter()
                .map(|&k| self.setup.links[k].file_label())
                .collect();
            self.log.push(
                now,
                true,
                format!(
                    "jam: vehicle(s) {} held by the safety filter for {:.1} s without closing on \
                     their places: turning them past each other",
                    names.join(", "),
                    settings.hold_s
                ),
            );
        }
        if !change.released.is_empty() {
            let names: Vec<String> = change
                .released
                .iter()
                .map(|&k| self.setup.links[k].file_label())
                .collect();
            self.log.push(
                now,
                false,
                format!("jam over for vehicle(s) {}", names.join(", ")),
            );
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
