//! The other shards as this one knows them ([`Peers`]): each one's latest report, the
//! start agreement with them, the messages waiting for the driver, and what follows from
//! the reports alone (whether they all fly, which one is lost, the swarm's sums at the
//! start and now, the planner's inputs). The swarm machine's shard side (shard.rs)
//! reads and writes it.

use std::collections::VecDeque;
use std::time::Duration;

use nalgebra::Vector2;
use ringswarm_wire::time::SimTime;

use super::agreement::{Heard, StartAgreement, SwarmClock};
use crate::distributed::{ShardMessage, ShardPlan, ShardReport, TileInterest, Watch, WeightedSum};

/// Messages kept for the driver at most: one that does not poll loses the oldest.
const OUTBOX_CAPACITY: usize = 1 << 16;

/// The shard's side of the swarm.
#[derive(Debug, Clone)]
pub(super) struct Peers {
    pub(super) plan: ShardPlan,
    /// The ring's weights for the vehicles whose commands are computed here (every one
    /// when every state is watched), zero for the others: the saturation's `conserve`
    /// keeps their `Σ wᵢuᵢ` with one shift, as one process does for the whole swarm.
    pub(super) saturation_weights: Vec<f64>,
    /// Each shard's latest report and when it came (this shard's own slot stays empty).
    pub(super) reports: Vec<Option<(SimTime, ShardReport)>>,
    /// The tiles read for the safety filter (`Watch::Horizon` only).
    pub(super) tiles: Option<TileInterest>,
    /// The agreement on one start (and plan) instant with the other shards.
    pub(super) agreement: StartAgreement,
    /// This shard's `Σ wᵢ vᵢ` on the last control tick.
    pub(super) now_sum: WeightedSum,
    /// With a `[target]`: the adopted plan instant and this shard's vehicles' velocities
    /// and top speeds then (ring order), once taken.
    pub(super) plan_own: Option<(SimTime, Vec<OwnPlanInput>)>,
    /// With interchangeable places: the adopted start and this shard's vehicles'
    /// horizontal positions then (ring order), and whether the places are assigned for
    /// it.
    pub(super) places_own: Option<(SimTime, Vec<Vector2<f64>>)>,
    pub(super) places_assigned: bool,
    pub(super) outbox: VecDeque<ShardMessage>,
    /// Messages refused: from this shard's own index, out of range, or older than the
    /// one kept.
    pub(super) refused: u64,
    /// Messages lost because the driver did not take them.
    pub(super) dropped: u64,
}

impl Peers {
    pub(super) fn new(plan: ShardPlan, w: &[f64]) -> Self {
        let shards = plan.shards();
        let saturation_weights = saturation_weights(&plan, w);
        let tiles = (plan.watch() == Watch::Horizon).then(|| TileInterest::new(plan.tile_m()));
        let agreement = StartAgreement::new(plan.this(), plan.start_lead());
        Self {
            plan,
            saturation_weights,
            reports: vec![None; shards],
            tiles,
            agreement,
            now_sum: WeightedSum::default(),
            plan_own: None,
            places_own: None,
            places_assigned: false,
            outbox: VecDeque::new(),
            refused: 0,
            dropped: 0,
        }
    }

    pub(super) fn clock(&self) -> SwarmClock {
        SwarmClock {
            epoch_us: self.plan.epoch_us(),
        }
    }

    pub(super) fn heard(&self) -> Heard<'_> {
        Heard {
            reports: &self.reports,
            clock: self.clock(),
        }
    }

    pub(super) fn to_swarm_us(&self, t: SimTime) -> u64 {
        self.clock().to_swarm_us(t)
    }

    pub(super) fn local_time_of(&self, us: u64) -> SimTime {
        self.clock().local_time_of(us)
    }

    pub(super) fn push(&mut self, message: ShardMessage) {
        if self.outbox.len() >= OUTBOX_CAPACITY {
            self.outbox.pop_front();
            self.dropped += 1;
        }
        self.outbox.push_back(message);
    }

    /// The other shards, each heard within `timeout` and flying all its vehicles.
    pub(super) fn others_flying(&self, now: SimTime, timeout: Duration) -> bool {
        self.reports.iter().enumerate().all(|(s, r)| {
            s == self.plan.this()
                || r.as_ref().is_some_and(|(at, r)| {
                    now.saturating_since(*at) <= timeout && r.flying == r.vehicles
                })
        })
    }

    /// Another shard silent for `timeout`, or with a vehicle not flying while its flight
    /// is not over.
    pub(super) fn others_lost(&self, now: SimTime, timeout: Duration) -> Option<String> {
        self.reports.iter().enumerate().find_map(|(s, r)| {
            if s == self.plan.this() {
                return None;
            }
            match r {
                None => Some(format!("shard {s} never heard")),
                Some((at, _)) if now.saturating_since(*at) > timeout => Some(format!(
                    "shard {s} silent for {:.0} ms",
                    now.saturating_since(*at).as_secs_f64() * 1e3
                )),
                Some((_, r)) if r.flying < r.vehicles && !r.ended => Some(format!(
                    "shard {s} flies {} of its {} vehicles",
                    r.flying, r.vehicles
                )),
                Some((_, r)) if self.agreement.started_without(r, self.clock()) => Some(format!(
                    "shard {s} did not start consensus at the adopted instant"
                )),
                _ => None,
            }
        })
    }

    /// The earliest start proposed in this round, this shard's own included.
    pub(super) fn adopted_start(&self) -> Option<SimTime> {
        self.agreement.adopted(self.heard())
    }

    /// One item per vehicle in ring order, once every other shard's list is in: this
    /// shard's vehicles' from `own` (in ring order), another shard's from the list
    /// `list_of` finds in its report (`None`: not in, or not for this instant).
    fn in_ring_order<'a, T, I: Iterator<Item = T>>(
        &'a self,
        mut own: impl Iterator<Item = T>,
        list_of: impl Fn(usize, &'a ShardReport) -> Option<I>,
    ) -> Option<Vec<T>> {
        let mut lists = Vec::with_capacity(self.reports.len());
        for (s, r) in self.reports.iter().enumerate() {
            if s == self.plan.this() {
                lists.push(None);
                continue;
            }
            lists.push(Some(list_of(s, &r.as_ref()?.1)?));
        }
        (0..self.plan.vehicle_count())
            .map(|i| {
                let s = self.plan.owner(i)?;
                if s == self.plan.this() {
                    own.next()
                } else {
                    lists.get_mut(s)?.as_mut()?.next()
                }
            })
            .collect()
    }

    /// With a `[target]`: every vehicle's velocity at the adopted plan instant and its
    /// top speed for the planner, in ring order, once every shard's are in (this shard's
    /// own from `plan_own`).
    pub(super) fn plan_inputs(&self) -> Option<PlanInputs> {
        let (at, own) = self.plan_own.as_ref()?;
        let at_us = self.to_swarm_us(*at);
        let merged = self.in_ring_order(own.iter().copied(), |s, r| {
            let v = r.plan_velocities.as_ref()?;
            let count = self.plan.vehicles_of(s);
            if v.at_us != at_us || v.vel_mps.len() != count || v.limit_mps.len() != count {
                return None;
            }
            Some(
                v.vel_mps
                    .iter()
                    .zip(&v.limit_mps)
                    .map(|(&[x, y], &limit)| (Vector2::new(x, y), limit)),
            )
        })?;
        let (velocities_mps, limits_mps) = merged.into_iter().unzip();
        Some(PlanInputs {
            velocities_mps,
            limits_mps,
        })
    }

    /// With interchangeable places: every vehicle's horizontal position at the adopted
    /// start, in ring order, once every shard's are in (this shard's own from
    /// `places_own`).
    pub(super) fn place_inputs(&self) -> Option<Vec<Vector2<f64>>> {
        let (at, own) = self.places_own.as_ref()?;
        let at_us = self.to_swarm_us(*at);
        self.in_ring_order(own.iter().copied(), |s, r| {
            let p = r.start_positions.as_ref()?;
            if p.at_us != at_us || p.pos_m.len() != self.plan.vehicles_of(s) {
                return None;
            }
            Some(p.pos_m.iter().map(|&[x, y]| Vector2::new(x, y)))
        })
    }

    /// Whether every other shard reports its places assigned: this shard's start
    /// positions are needed no more.
    pub(super) fn others_assigned(&self) -> bool {
        self.reports.iter().enumerate().all(|(s, r)| {
            s == self.plan.this() || r.as_ref().is_some_and(|(_, r)| r.places_assigned)
        })
    }

    /// Whether every other shard reports its plan made: this shard's plan velocities
    /// are needed no more.
    pub(super) fn others_planned(&self) -> bool {
        self.reports
            .iter()
            .enumerate()
            .all(|(s, r)| s == self.plan.this() || r.as_ref().is_some_and(|(_, r)| r.planned))
    }

    /// The weights changed (a plan's `k`): the saturation's weights follow.
    pub(super) fn reweigh(&mut self, w: &[f64]) {
        self.saturation_weights = saturation_weights(&self.plan, w);
    }

    /// The swarm's w-weighted mean position and velocity at `start`, from every shard's
    /// sums at that instant added in shard order (this shard's own is `own`), once all
    /// are in.
    pub(super) fn start_means(
        &self,
        start: SimTime,
        own: WeightedSum,
    ) -> Option<(Vector2<f64>, Vector2<f64>)> {
        let start_us = self.to_swarm_us(start);
        let mut wp = Vector2::zeros();
        let mut wv = Vector2::zeros();
        let mut w = 0.0;
        for (s, r) in self.reports.iter().enumerate() {
            let sum = if s == self.plan.this() {
                own
            } else {
                let (_, r) = r.as_ref()?;
                if r.start_us != Some(start_us) {
                    return None;
                }
                r.start_sum?
            };
            wp += Vector2::new(sum.wp_m[0], sum.wp_m[1]);
            wv += Vector2::new(sum.wv_mps[0], sum.wv_mps[1]);
            w += sum.w;
        }
        (w.abs() > 1e-12).then(|| (wp / w, wv / w))
    }

    /// The prediction `Σ wᵢvᵢ / Σ wᵢ` at `start`, once every shard's sum is in.
    pub(super) fn prediction(&self, start: SimTime, own: WeightedSum) -> Option<Vector2<f64>> {
        self.start_means(start, own).map(|(_, v)| v)
    }
}

/// The ring's weights `w` for the vehicles whose commands `plan` computes here, zero for
/// the others.
fn saturation_weights(plan: &ShardPlan, w: &[f64]) -> Vec<f64> {
    w.iter()
        .enumerate()
        .map(|(i, w)| if plan.is_computable(i) { *w } else { 0.0 })
        .collect()
}

/// One of this shard's vehicles at the plan instant: its velocity (m/s, ENU) and its top
/// speed for the planner (m/s, if any).
pub(super) type OwnPlanInput = (Vector2<f64>, Option<f64>);

/// What every shard plans from: each vehicle's velocity at the plan instant and its top
/// speed for the planner, in ring order.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct PlanInputs {
    /// Velocities (m/s, ENU).
    pub(super) velocities_mps: Vec<Vector2<f64>>,
    /// Top speeds (m/s), `None` where there is none.
    pub(super) limits_mps: Vec<Option<f64>>,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::consensus::RingDigraph;

    /// Shard 0 of two, each flying one macro-vertex of a ring of four.
    fn peers() -> Peers {
        let ring = RingDigraph::new(2, 2.0).expect("ring");
        let plan = ShardPlan::new(0, 2, vec![0, 0, 1, 1], &ring, Watch::All).expect("plan");
        let w: Vec<f64> = (0..4).map(|i| ring.w(i)).collect();
        Peers::new(plan, &w)
    }

    fn report(flying: u16, start_us: Option<u64>, start_sum: Option<WeightedSum>) -> ShardReport {
        ShardReport {
            shard: 1,
            sent_us: 0,
            vehicles: 2,
            flying,
            lost: 0,
            ended: false,
            start_us,
            start_sum,
            now_sum: WeightedSum::default(),
            top_speed_mps: 0.0,
            planned: false,
            plan_velocities: None,
            places_assigned: false,
            start_positions: None,
        }
    }

    #[test]
    fn a_lost_shard_is_named_with_why() {
        let timeout = Duration::from_millis(1500);
        let mut p = peers();
        let now = SimTime::from_millis(2000);
        assert_eq!(
            p.others_lost(now, timeout).as_deref(),
            Some("shard 1 never heard")
        );
        p.reports[1] = Some((SimTime::ZERO, report(2, None, None)));
        assert_eq!(
            p.others_lost(now, timeout).as_deref(),
            Some("shard 1 silent for 2000 ms")
        );
        assert!(!p.others_flying(now, timeout));
        p.reports[1] = Some((now, report(1, None, None)));
        assert_eq!(
            p.others_lost(now, timeout).as_deref(),
            Some("shard 1 flies 1 of its 2 vehicles")
        );
        p.reports[1] = Some((now, report(2, None, None)));
        assert_eq!(p.others_lost(now, timeout), None);
        assert!(p.others_flying(now, timeout));
    }

    #[test]
    fn the_swarm_means_at_the_start_add_every_shards_sums() {
        let mut p = peers();
        let start = SimTime::from_millis(1000);
        let own = WeightedSum {
            wp_m: [2.0, 4.0],
            wv_mps: [1.0, 0.0],
            w: 1.0,
        };
        let theirs = WeightedSum {
            wp_m: [6.0, 0.0],
            wv_mps: [3.0, 2.0],
            w: 3.0,
        };
        // Shard 1's sum for another instant does not count.
        let other_instant = p.to_swarm_us(start + Duration::from_millis(4));
        p.reports[1] = Some((start, report(2, Some(other_instant), Some(theirs))));
        assert_eq!(p.start_means(start, own), None);
        p.reports[1] = Some((start, report(2, Some(p.to_swarm_us(start)), Some(theirs))));
        // (2 + 6, 4 + 0) / 4 and (1 + 3, 0 + 2) / 4.
        let (pos, vel) = p.start_means(start, own).expect("every sum in");
        assert_eq!((pos, vel), (Vector2::new(2.0, 1.0), Vector2::new(1.0, 0.5)));
        assert_eq!(p.prediction(start, own), Some(Vector2::new(1.0, 0.5)));
    }

    #[test]
    fn only_the_vehicles_computed_here_weigh_in_the_saturation() {
        let p = peers();
        // Watching every state, each shard computes every command.
        assert!(p.saturation_weights.iter().all(|w| *w != 0.0));
        let ring = RingDigraph::new(2, 2.0).expect("ring");
        let plan = ShardPlan::new(0, 2, vec![0, 0, 1, 1], &ring, Watch::Neighbours).expect("plan");
        let w: Vec<f64> = (0..4).map(|i| ring.w(i)).collect();
        let computable: Vec<bool> = (0..4).map(|i| plan.is_computable(i)).collect();
        let weights = saturation_weights(&plan, &w);
        for i in 0..4 {
            assert_eq!(
                weights[i],
                if computable[i] { w[i] } else { 0.0 },
                "vehicle {i}"
            );
        }
        assert!(
            computable.iter().any(|c| !c),
            "a neighbours-only shard computes fewer"
        );
    }
}
