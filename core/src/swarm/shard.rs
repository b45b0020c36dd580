//! The swarm machine as one shard of several ([`crate::distributed`]): it flies its own
//! vehicles' links and takes the other vehicles from the other shards' messages.
//!
//! - **Remote vehicles.** A remote vehicle the plan watches is known by its
//!   [`VehicleReport`]s: its link phase and its state, fresh while the position is
//!   younger than the state timeout (the hop between shards counts in that age). It is
//!   never commanded here: for the law it is a neighbour, for the safety filter a
//!   vehicle this shard does not control.
//! - **Every vehicle flying, a vehicle lost.** As in one process, over the vehicles
//!   known here; the others through their shard's [`ShardReport`]: every shard heard
//!   within the link timeout, each with all its vehicles flying on fresh states. A shard
//!   silent for the link timeout, or one with a vehicle not flying, is a lost vehicle:
//!   the loss policy applies (hold, or land).
//! - **One start for all.** A shard that sees every vehicle flying proposes to start
//!   consensus [`ShardPlan::start_lead`] later; the swarm adopts the earliest proposal
//!   of the round (a round starts with the flight, and again with each hold). A shard
//!   reports the start it adopts only while it sees every vehicle flying itself, and
//!   starts only once every other shard reports that same start: a shard that cannot
//!   hear a third one (a broken mesh), or sees a vehicle down, holds every shard back,
//!   so no shard flies consensus while another does not. A start acknowledged late is
//!   started late, at the first tick after the last acknowledgement. Each
//!   shard takes its own vehicles' `Σ wᵢ vᵢ` at the first control tick at or after the
//!   adopted instant and publishes it; once every shard's sum for that instant is in,
//!   each adds them in shard order: the same prediction, bit for bit, in every shard.
//!   The flight ends the configured duration after that instant, in every shard.
//! - **The mean velocity** (the correction and the guard) is the sum of this shard's
//!   own `Σ wᵢ vᵢ` now and the others' latest.
//! - **Nearby vehicles** ([`crate::distributed::Watch::Horizon`]): the states of other
//!   shards' vehicles within the safety filter's horizon, by tile (horizon.rs). They
//!   are known to the safety filter only, never to the swarm-wide checks.

use std::time::Duration;

use nalgebra::{Vector2, Vector3};
use ringswarm_wire::time::SimTime;

use super::VehicleIndex;
use super::agreement::Heard;
use super::slot::{Member, RemoteVehicle};
use super::{CommonState, Swarm, SwarmPhase};
use crate::distributed::{
    MemberPhase, PlanVelocities, ShardMessage, ShardPlan, ShardReport, VehicleReport, WeightedSum,
};
use crate::vehicle::{Phase, VehicleLink};

/// What another shard is told of a link's phase.
pub(super) fn member_phase(phase: Phase) -> MemberPhase {
    match phase {
        Phase::Discovering | Phase::Streaming(_) | Phase::Arming | Phase::Offboarding => {
            MemberPhase::Waiting
        }
        Phase::Flying => MemberPhase::Flying,
        Phase::Lost | Phase::Overridden | Phase::VehicleHold => MemberPhase::Lost,
        Phase::Landing | Phase::Disarming | Phase::Done => MemberPhase::Landing,
        Phase::Failed => MemberPhase::Failed,
    }
}

/// The link phase a remote vehicle is taken to be in.
fn link_phase(phase: MemberPhase) -> Phase {
    match phase {
        MemberPhase::Waiting => Phase::Discovering,
        MemberPhase::Flying => Phase::Flying,
        MemberPhase::Lost => Phase::Lost,
        MemberPhase::Landing => Phase::Landing,
        MemberPhase::Failed => Phase::Failed,
    }
}

fn to_f32(v: Vector3<f64>) -> [f32; 3] {
    [v.x as f32, v.y as f32, v.z as f32]
}

fn from_f32(v: [f32; 3]) -> Vector3<f64> {
    Vector3::new(f64::from(v[0]), f64::from(v[1]), f64::from(v[2]))
}

impl Swarm {
    /// Whether vehicle `i` is flown by another shard.
    pub(super) fn is_remote(&self, i: VehicleIndex) -> bool {
        self.slots
            .get(i.0)
            .is_some_and(super::slot::VehicleSlot::is_remote)
    }

    /// Whether vehicle `i`'s state is known here: flown here, or a watched remote one.
    pub(super) fn is_known(&self, i: VehicleIndex) -> bool {
        self.peers
            .as_ref()
            .is_none_or(|p| p.plan.is_local(i.0) || p.plan.is_watched(i.0))
    }

    /// Vehicle `i`'s link phase as this shard knows it: its own link's, or, for a
    /// vehicle another shard flies, that shard's report of it (`discovering` until one
    /// comes). What a run directory and the live view show.
    pub fn vehicle_phase(&self, i: VehicleIndex) -> Phase {
        self.slots[i].phase()
    }

    /// Whether vehicle `i` is flown by this process (always, without shards).
    pub fn is_flown_here(&self, i: VehicleIndex) -> bool {
        !self.is_remote(i)
    }

    /// A remote vehicle's state, when fresh, carried forward to `now` at its velocity:
    /// the hop between shards (since its shard's control tick sent it) makes it older
    /// than the states of this shard's own vehicles, and in a swarm moving at `v` a hop
    /// `τ` would otherwise put it `v·τ` behind them for the law (a steady formation
    /// error: 0.3 m at 15 m/s and 20 ms). Its age at that tick is kept, as this shard's
    /// own vehicles' ages are.
    pub(super) fn remote_fresh_state(&self, i: VehicleIndex, now: SimTime) -> Option<CommonState> {
        let r = self.slots.get(i.0)?.remote()?;
        let age = now.saturating_since(r.measured);
        let hop = now.saturating_since(r.sent).as_secs_f64();
        (age <= self.setup.links[i].state_timeout).then(|| CommonState {
            pos_enu_m: r.state.pos_enu_m + r.state.vel_enu_mps * hop,
            vel_enu_mps: r.state.vel_enu_mps,
        })
    }

    /// Whether remote vehicle `i` flies on its shard's commands, through that shard's
    /// safety filter, on a law command this shard computes too (its ring in-neighbours
    /// are known here): this shard's filter then solves a pair with it as one process
    /// would, and each shard flies its own vehicle's part of the same answer. Braking
    /// alone against a partner taken to fly its law command unfiltered, the two
    /// shards' answers chatter and the pair closes inside the separation (measured:
    /// 2.76 m of 3 m on a head-on swap, 3.14 m in one process).
    pub(super) fn cooperating_remote(&self, i: VehicleIndex) -> bool {
        let Some(p) = self.peers.as_ref() else {
            return false;
        };
        !p.plan.is_local(i.0)
            && self.computable_now(i)
            && self.slots[i]
                .remote()
                .is_some_and(|r| r.phase == Phase::Flying && !r.landed)
    }

    /// Whether vehicle `i`'s law command is computed here on this tick: always in one
    /// process; in a shard, when the plan reads its state and its ring in-neighbours',
    /// or (under the horizon, which reads more as vehicles come near) when all of these
    /// states are in on this tick.
    pub(super) fn computable_now(&self, i: VehicleIndex) -> bool {
        let Some(p) = self.peers.as_ref() else {
            return true;
        };
        p.plan.is_computable(i.0)
            || (p.tiles.is_some()
                && self.law.states[i].is_some()
                && self
                    .setup
                    .ring
                    .neighbours(i.0)
                    .iter()
                    .all(|e| self.law.states[e.from].is_some()))
    }

    /// When a remote vehicle's position was measured.
    pub(super) fn remote_measured(&self, i: VehicleIndex) -> Option<SimTime> {
        self.slots.get(i.0)?.remote().map(|r| r.measured)
    }

    /// Takes a message from another shard.
    pub fn handle_shard_message(&mut self, now: SimTime, message: &ShardMessage) {
        let Some(p) = self.peers.as_mut() else {
            return;
        };
        match message {
            ShardMessage::Vehicle(v) => {
                let i = usize::from(v.vehicle);
                // A nearby vehicle's tile may have been left since the state was sent:
                // any remote vehicle's state is taken under the horizon.
                let nearby = p.tiles.is_some() && i < self.slots.len() && !p.plan.is_local(i);
                if !(p.plan.is_watched(i) || nearby) {
                    p.refused += 1;
                    return;
                }
                let sent = p.local_time_of(v.sent_us);
                let measured =
                    SimTime::from_micros(sent.as_micros().saturating_sub(u64::from(v.age_us)));
                let Some(Member::Remote(known)) = self.slots.get_mut(i).map(|s| &mut s.member)
                else {
                    p.refused += 1;
                    return;
                };
                if known.is_some_and(|r| r.sent > sent) {
                    p.refused += 1;
                    return;
                }
                let state = CommonState {
                    pos_enu_m: from_f32(v.pos_enu_m),
                    vel_enu_mps: from_f32(v.vel_enu_mps),
                };
                let unseen_mps = f64::from(v.unseen_mps);
                let finite =
                    (state.pos_enu_m.iter().chain(state.vel_enu_mps.iter())).all(|x| x.is_finite());
                if !finite || !(0.0..=f64::MAX).contains(&unseen_mps) {
                    p.refused += 1;
                    return;
                }
                *known = Some(RemoteVehicle {
                    phase: link_phase(v.phase),
                    landed: v.landed,
                    measured,
                    sent,
                    state,
                    unseen_mps,
                });
            }
            ShardMessage::Shard(r) => {
                let s = usize::from(r.shard);
                let expected = p.plan.vehicles_of(s);
                if s == p.plan.this()
                    || s >= p.plan.shards()
                    || usize::from(r.vehicles) != expected
                    || p.reports[s]
                        .as_ref()
                        .is_some_and(|(_, old)| old.sent_us > r.sent_us)
                {
                    p.refused += 1;
                    return;
                }
                p.reports[s] = Some((now, r.clone()));
            }
        }
    }

    /// The next message for the other shards.
    pub fn poll_shard_message(&mut self) -> Option<ShardMessage> {
        self.peers.as_mut()?.outbox.pop_front()
    }

    /// Messages from other shards refused, and messages lost because they were not
    /// polled.
    pub fn shard_message_counts(&self) -> (u64, u64) {
        self.peers
            .as_ref()
            .map_or((0, 0), |p| (p.refused, p.dropped))
    }

    /// Sets the swarm clock (µs since the Unix epoch on a real deployment) at this
    /// shard's time zero: the driver calls it when its clock starts.
    pub fn set_swarm_epoch_us(&mut self, epoch_us: u64) {
        if let Some(p) = self.peers.as_mut() {
            p.plan = p.plan.clone().with_epoch_us(epoch_us);
        }
    }

    /// `t` on the swarm clock (µs), when the swarm is one shard of several.
    pub fn swarm_clock_us(&self, t: SimTime) -> Option<u64> {
        self.peers.as_ref().map(|p| p.to_swarm_us(t))
    }

    /// The shard's plan, when the swarm is one shard of several.
    pub fn shard_plan(&self) -> Option<&ShardPlan> {
        self.peers.as_ref().map(|p| &p.plan)
    }

    /// The other shards: all flying (true without shards).
    pub(super) fn others_flying(&self, now: SimTime) -> bool {
        let timeout = self.link_timeout();
        self.peers
            .as_ref()
            .is_none_or(|p| p.others_flying(now, timeout))
    }

    /// Another shard silent, or with a vehicle not flying: why.
    pub(super) fn others_lost(&self, now: SimTime) -> Option<String> {
        let timeout = self.link_timeout();
        self.peers.as_ref()?.others_lost(now, timeout)
    }

    pub(super) fn link_timeout(&self) -> Duration {
        self.setup
            .links
            .first()
            .map_or(Duration::from_millis(1500), |l| l.link_timeout)
    }

    /// A new round of the start agreement (a hold began).
    pub(super) fn new_round(&mut self, now: SimTime) {
        if let Some(p) = self.peers.as_mut() {
            p.agreement.new_round(now);
        }
    }

    /// With every vehicle flying: whether consensus starts on this tick. Without shards,
    /// at once; with them, at the adopted instant (this shard proposes one first).
    pub(super) fn start_due(&mut self, now: SimTime) -> bool {
        let Some(p) = self.peers.as_mut() else {
            return true;
        };
        let clock = p.clock();
        p.agreement.due(
            now,
            Heard {
                reports: &p.reports,
                clock,
            },
        )
    }

    /// Starts consensus now (one process) or at the instant every shard adopts.
    pub(super) fn start_when_agreed(&mut self, now: SimTime) {
        if self.start_due(now) {
            self.start_consensus(now);
        }
    }

    /// Whether this shard has proposed a start in the current round (always false in one
    /// process, which starts at once).
    pub(super) fn start_proposed(&self) -> bool {
        self.peers.as_ref().is_some_and(|p| p.agreement.proposed())
    }

    /// Not every vehicle flies in this shard's view: it vouches for no start (its
    /// proposal stays, for when they fly again).
    pub(super) fn withdraw_start(&mut self) {
        if let Some(p) = self.peers.as_mut() {
            p.agreement.withdraw();
        }
    }

    /// Consensus starts on this tick: this shard's sum at the adopted instant, and the
    /// prediction once every shard's is in. Without shards, `None`: the caller predicts
    /// from every state.
    pub(super) fn shard_start(&mut self, now: SimTime) -> Option<SimTime> {
        let own = self.local_sum();
        let p = self.peers.as_mut()?;
        let clock = p.clock();
        Some(p.agreement.start(
            now,
            own,
            Heard {
                reports: &p.reports,
                clock,
            },
        ))
    }

    /// This shard's `Σ wᵢ vᵢ` over its own vehicles' states flown on this tick.
    fn local_sum(&self) -> WeightedSum {
        let mut sum = WeightedSum::default();
        for i in self.indices() {
            if self.is_remote(i) {
                continue;
            }
            let w = self.law.w[i];
            let h = &self.law.horizontal[i];
            let v = h.vel_mps;
            sum.wp_m[0] += w * h.pos_m.x;
            sum.wp_m[1] += w * h.pos_m.y;
            sum.wv_mps[0] += w * v.x;
            sum.wv_mps[1] += w * v.y;
            sum.w += w;
        }
        sum
    }

    /// The prediction of this round, once every shard's sum at the start is in.
    pub(super) fn shard_prediction(&mut self, now: SimTime) {
        let Some(p) = self.peers.as_ref() else {
            return;
        };
        let Some((start, own)) = p.agreement.awaits_prediction() else {
            return;
        };
        if let Some(v) = p.prediction(start, own) {
            if let Some(p) = self.peers.as_mut() {
                p.agreement.set_predicted();
            }
            self.predicted_final_velocity = Some(v);
            self.log.push(
                now,
                false,
                format!(
                    "every shard's sum at the start is in: predicted final velocity ({:.3}, {:.3}) m/s",
                    v.x, v.y
                ),
            );
        }
    }

    /// The swarm's w-weighted mean velocity from this shard's vehicles now and the other
    /// shards' latest sums.
    pub(super) fn shard_mean_velocity(&self) -> Option<Vector2<f64>> {
        self.shard_means(SimTime::ZERO).map(|(_, v)| v)
    }

    /// The swarm's w-weighted mean position and velocity now: this shard's own sums,
    /// and the others' latest, their positions carried forward by the hop (from when
    /// they were sent to `now`; with `now` zero, not carried).
    fn shard_means(&self, now: SimTime) -> Option<(Vector2<f64>, Vector2<f64>)> {
        let p = self.peers.as_ref()?;
        let own = self.local_sum();
        let mut wp = Vector2::new(own.wp_m[0], own.wp_m[1]);
        let mut wv = Vector2::new(own.wv_mps[0], own.wv_mps[1]);
        let mut w = own.w;
        for (s, r) in p.reports.iter().enumerate() {
            if s == p.plan.this() {
                continue;
            }
            let (_, r) = r.as_ref()?;
            let v = Vector2::new(r.now_sum.wv_mps[0], r.now_sum.wv_mps[1]);
            let hop = if now == SimTime::ZERO {
                0.0
            } else {
                now.saturating_since(p.local_time_of(r.sent_us))
                    .as_secs_f64()
            };
            wp += Vector2::new(r.now_sum.wp_m[0], r.now_sum.wp_m[1]) + v * hop;
            wv += v;
            w += r.now_sum.w;
        }
        (w.abs() > 1e-12).then(|| (wp / w, wv / w))
    }

    /// With shards, the mean-velocity correction's integral `∫(v̄_w − v_f) dt` since the
    /// start, as the state it integrates to: `p̄_w(now) − p̄_w(t₀) − v_f·(now − t₀)`, from
    /// every shard's sums at the start (the same in every shard) and now. A sum of
    /// errors kept by each shard would hold, for good, whatever the hop's delays made
    /// them differ by: a steady acceleration of one shard against another, which the
    /// formation pays for with a steady error. `None` without shards, or before the
    /// prediction.
    pub(super) fn shard_mean_integral(&self, now: SimTime) -> Option<Vector2<f64>> {
        let p = self.peers.as_ref()?;
        let (start, own) = p.agreement.started()?;
        let target = self.predicted_final_velocity?;
        let (mean_at_start, _) = p.start_means(start, own)?;
        let (mean_now, _) = self.shard_means(now)?;
        let elapsed = now.saturating_since(start).as_secs_f64();
        Some(mean_now - mean_at_start - target * elapsed)
    }

    /// After a control tick: this shard's vehicles' states others read, then its report.
    pub(super) fn publish(&mut self, now: SimTime) {
        if self.peers.is_none() {
            return;
        }
        let mut vehicles = 0u16;
        let mut flying = 0u16;
        let mut lost = 0u16;
        let mut messages = Vec::new();
        for i in self.indices() {
            if self.is_remote(i) {
                continue;
            }
            vehicles = vehicles.saturating_add(1);
            let Some(link) = self.slots[i].link() else {
                continue;
            };
            let phase = link.phase();
            let fresh = self.law.states[i].is_some();
            if phase == Phase::Flying && fresh && !self.slots[i].isolated {
                flying = flying.saturating_add(1);
            }
            let member = if self.slots[i].isolated {
                MemberPhase::Lost
            } else {
                member_phase(phase)
            };
            if member == MemberPhase::Lost {
                lost = lost.saturating_add(1);
            }
            let read = self
                .peers
                .as_ref()
                .is_some_and(|p| p.plan.is_read_elsewhere(i.0));
            if let (true, Some(s), Some(at)) =
                (read, self.common_state(i), link.state().last_position)
            {
                messages.push((i, s, at, member));
            }
        }
        let own = self.local_sum();
        let top_speed = self.own_top_speed_mps() as f32;
        let phase = self.phase;
        let ended = self.stop == Some(super::StopReason::DurationOver);
        let Some(p) = self.peers.as_mut() else {
            return;
        };
        p.now_sum = own;
        for (i, s, at, member) in messages {
            let age_us = now.saturating_since(at).as_micros();
            let link = self.slots[i].link();
            let landed = link.is_some_and(|l| l.state().landed);
            let unseen_mps = link.map_or(0.0, VehicleLink::unseen_speed_mps);
            let report = VehicleReport {
                vehicle: u16::try_from(i.get()).unwrap_or(u16::MAX),
                sent_us: p.to_swarm_us(now),
                age_us: u32::try_from(age_us).unwrap_or(u32::MAX),
                phase: member,
                landed,
                pos_enu_m: to_f32(s.pos_enu_m),
                vel_enu_mps: to_f32(s.vel_enu_mps),
                unseen_mps: unseen_mps as f32,
            };
            p.push(ShardMessage::Vehicle(report));
        }
        let in_round = matches!(
            phase,
            SwarmPhase::Handshake
                | SwarmPhase::Retargeting(_)
                | SwarmPhase::Holding(_)
                | SwarmPhase::Consensus(_)
        );
        let start = p.agreement.vouched();
        let report =
            ShardReport {
                shard: u16::try_from(p.plan.this()).unwrap_or(u16::MAX),
                sent_us: p.to_swarm_us(now),
                vehicles,
                flying,
                lost,
                ended,
                start_us: start.filter(|_| in_round).map(|t| p.to_swarm_us(t)),
                start_sum: p.agreement.started().map(|(_, s)| s).filter(|_| in_round),
                now_sum: own,
                top_speed_mps: top_speed,
                planned: p.agreement.planned(),
                plan_velocities: p.plan_own.as_ref().filter(|_| !p.others_planned()).map(
                    |(at, v)| PlanVelocities {
                        at_us: p.to_swarm_us(*at),
                        vel_mps: v.iter().map(|(v, _)| [v.x, v.y]).collect(),
                        limit_mps: v.iter().map(|(_, l)| *l).collect(),
                    },
                ),
                places_assigned: p.places_assigned,
                start_positions: p
                    .places_own
                    .as_ref()
                    .filter(|_| in_round && !p.others_assigned())
                    .map(|(at, pos)| crate::distributed::StartPositions {
                        at_us: p.to_swarm_us(*at),
                        pos_m: pos.iter().map(|v| [v.x, v.y]).collect(),
                    }),
            };
        p.push(ShardMessage::Shard(report));
    }
}
