//! The horizon of a shard's safety filter ([`Watch::Horizon`]): which tiles of other
//! shards' vehicle states it reads, re-reckoned on every control tick.
//!
//! The horizon is the distance at which the safety filter starts to look at a pair
//! ([`look_radius_m`]), for the fastest vehicle of the swarm and a look-ahead of
//! [`LOOKAHEAD_S`] plus [`SUBSCRIPTION_LAG_S`]: a vehicle of another shard that can
//! come within the filter's reach before a new subscription delivers its state is
//! already read. The fastest vehicle is the fastest this shard knows (its own, and the
//! remote ones it reads) or any shard reports, heard within the link timeout.
//!
//! [`Watch::Horizon`]: crate::distributed::Watch::Horizon

use ringswarm_wire::time::SimTime;

use super::Swarm;
use super::VehicleIndex;
use crate::distributed::tiles::SUBSCRIPTION_LAG_S;
use crate::distributed::{TileInterest, VehicleReport};
use crate::safety::{LOOKAHEAD_S, look_radius_m};

impl Swarm {
    /// The fastest of this shard's own vehicles with a fresh state (m/s, the vertical
    /// axis scaled as the safety filter's separation does; plain speed without one).
    pub(super) fn own_top_speed_mps(&self) -> f64 {
        self.top_speed_mps(|i| !self.is_remote(i))
    }

    /// The fastest of the vehicles `which` picks that have a fresh state here, scaled as
    /// [`Self::own_top_speed_mps`].
    fn top_speed_mps(&self, which: impl Fn(VehicleIndex) -> bool) -> f64 {
        self.indices()
            .filter(|i| which(*i))
            .filter_map(|i| self.law.states[i])
            .map(|s| {
                let v = s.vel_enu_mps;
                self.setup
                    .safety
                    .map_or(v.norm(), |s| s.separation.scaled(v).norm())
            })
            .filter(|v| v.is_finite())
            .fold(0.0, f64::max)
    }

    /// Re-reckons the tiles read from this shard's own vehicles' fresh positions: after
    /// the states are in, before the safety filter. Without `[safety]`, none: nothing
    /// but the ring neighbours is needed.
    pub(super) fn update_horizon(&mut self, now: SimTime) {
        let Some(p) = self.peers.as_ref().filter(|p| p.tiles.is_some()) else {
            return;
        };
        let (own, radius) = match self.setup.safety {
            None => (Vec::new(), 0.0),
            Some(safety) => {
                let timeout = self.link_timeout();
                let reported = p
                    .reports
                    .iter()
                    .flatten()
                    .filter(|(at, _)| now.saturating_since(*at) <= timeout)
                    .map(|(_, r)| f64::from(r.top_speed_mps))
                    .filter(|v| v.is_finite())
                    .fold(0.0, f64::max);
                let fastest = self.top_speed_mps(|_| true).max(reported);
                let own: Vec<nalgebra::Vector2<f64>> = self
                    .indices()
                    .filter(|i| !self.is_remote(*i))
                    .filter_map(|i| self.law.states[i])
                    .map(|s| s.pos_enu_m.xy())
                    .collect();
                let lookahead_s = LOOKAHEAD_S + SUBSCRIPTION_LAG_S;
                (own, look_radius_m(&safety.separation, fastest, lookahead_s))
            }
        };
        if let Some(tiles) = self.peers.as_mut().and_then(|p| p.tiles.as_mut()) {
            tiles.update(own, radius);
        }
    }

    /// The tiles this shard reads (`Watch::Horizon` only): its transport subscribes to
    /// them, and declares again when their [`TileInterest::generation`] moves.
    pub fn shard_tiles(&self) -> Option<&TileInterest> {
        self.peers.as_ref()?.tiles.as_ref()
    }

    /// Whether this shard's subscriptions take a vehicle's state: a ring neighbour it
    /// watches, or (under the horizon) one in a tile it reads. What a transport without
    /// Zenoh (lockstep) delivers by.
    pub fn shard_reads(&self, report: &VehicleReport) -> bool {
        let Some(p) = self.peers.as_ref() else {
            return false;
        };
        let i = usize::from(report.vehicle);
        if p.plan.is_watched(i) {
            return true;
        }
        let pos = nalgebra::Vector2::new(
            f64::from(report.pos_enu_m[0]),
            f64::from(report.pos_enu_m[1]),
        );
        !p.plan.is_local(i) && p.tiles.as_ref().is_some_and(|t| t.reads(pos))
    }
}
