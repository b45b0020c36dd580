//! The fence in the control tick: while the swarm flies its law (the re-target stage or
//! consensus), each vehicle's stopping point is checked against the fence, and the first
//! that comes within the margin makes the whole swarm hold or land. The altitude band
//! counts for a vehicle once it has been inside it by the margin: a swarm that starts on
//! the ground climbs into its band while the law already flies.

use ringswarm_wire::time::SimTime;

use super::VehicleIndex;
use super::{StopReason, Swarm, SwarmPhase};
use crate::safety::stop_point_m;
use crate::swarm::LossPolicy;

/// The share of each vehicle's horizontal envelope a stopping point counts on when the
/// safety filter is off (as its default `braking_share`).
const BRAKING_SHARE_WITHOUT_FILTER: f64 = 0.5;

impl Swarm {
    /// Applies the fence's action when a vehicle flown on our commands could no longer
    /// stop inside the fence's margin.
    pub(super) fn watch_fence(&mut self, now: SimTime) {
        let Some(setup) = self.setup.fence.as_ref() else {
            return;
        };
        if !matches!(
            self.phase,
            SwarmPhase::Consensus(_) | SwarmPhase::Retargeting(_)
        ) {
            return;
        }
        let share = self
            .setup
            .safety
            .map_or(BRAKING_SHARE_WITHOUT_FILTER, |s| s.braking_share);
        let envelope = &self.setup.envelope;
        let mut worst: Option<(VehicleIndex, f64, nalgebra::Vector3<f64>)> = None;
        for i in self.indices() {
            let Some(s) = self.law.states[i] else {
                continue;
            };
            if !self.ours_in_air(i) {
                continue;
            }
            let in_band = setup.fence.vertical_margin_m(s.pos_enu_m.z) >= setup.margin_m;
            self.slots[i].fence_band_reached |= in_band;
            let model = &self.law.flown_models[i];
            let braking = share * envelope.horizontal_limit_mps2(0.0, model);
            // Vertically: the smaller of what the thrust limits give up and down.
            let up = envelope.limit_vertical(f64::INFINITY, model);
            let down = -envelope.limit_vertical(f64::NEG_INFINITY, model);
            let vertical = share * up.min(down);
            if !(braking > 0.0 && vertical > 0.0) {
                continue;
            }
            let stop = stop_point_m(
                s.pos_enu_m,
                s.vel_enu_mps,
                self.command_age_s(i, now),
                braking,
                vertical,
            );
            let margin = if self.slots[i].fence_band_reached {
                setup.fence.margin_m(stop)
            } else {
                setup.fence.horizontal_margin_m(stop.xy())
            };
            if margin < setup.margin_m && worst.is_none_or(|w| margin < w.1) {
                worst = Some((i, margin, stop));
            }
        }
        let Some((i, margin, stop)) = worst else {
            return;
        };
        let land = setup.action == LossPolicy::Land;
        let text = format!(
            "fence: vehicle {} would stop at ({:.1}, {:.1}, {:.1}) m, {:.1} m inside the fence (margin {} m): the swarm {}",
            self.setup.links[i].system_id,
            stop.x,
            stop.y,
            stop.z,
            margin,
            setup.margin_m,
            if land { "lands" } else { "holds" }
        );
        self.safety.stats.fence_actions += 1;
        self.stop_law(now, StopReason::Fence, land, text);
    }
}
