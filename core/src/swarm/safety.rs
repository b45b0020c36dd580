//! The safety filter in the control tick: each vehicle's state and envelope handed to
//! [`crate::safety::SafetyFilter`] between the law and the saturation, and what it did
//! counted for `summary.json` and logged.

use std::time::Duration;

use nalgebra::Vector2;
use ringswarm_wire::time::SimTime;

use super::VehicleIndex;
use super::slot::VehicleSlot;
use super::{BREACH_SHARE, BreachAction, SafetySetup, StopReason, Swarm, SwarmPhase};
use crate::safety::{Agent, Outcome, Settings, Side};
use crate::vehicle::VehicleLink;

/// The attitude response counted for a vehicle not measured yet (s): the emulated
/// x500's measured `L + T` is 0.18–0.20 s, PX4 SIH's 0.28–0.36 s (docs/math.md).
pub const UNMEASURED_RESPONSE_S: f64 = 0.3;

/// The lag counted inside an unmeasured response (s): the time constants fitted are
/// 0.08–0.15 s on the emulated x500, 0.16–0.18 s on PX4 SIH and 0.23–0.27 s on ArduCopter
/// SITL, each with a delay of 0.02–0.14 s (docs/math.md). Counting the whole response as a
/// delay would count the commands the vehicle already shows again
/// ([`crate::safety::Agent::lag_s`]).
pub const UNMEASURED_LAG_S: f64 = 0.2;

/// How long every filter call must have finished before a vehicle moves to or from the
/// jam layer (s): a climb takes seconds, and on a tick out of time the check brakes
/// horizontally and cannot stop a vertical move (docs/dense.md).
pub const LAYER_CALM_S: f64 = 2.0;

/// Whether the filter has kept up for [`LAYER_CALM_S`] at `now`, its last call out of time
/// or fallen back at `last_unfinished` (`None`: never).
fn calm(last_unfinished: Option<SimTime>, now: SimTime) -> bool {
    last_unfinished.is_none_or(|t| now.saturating_since(t).as_secs_f64() >= LAYER_CALM_S)
}

/// A vehicle's unseen speed is named in the events once it reaches this (m/s); any is
/// counted, and the largest is in the summary.
pub const UNSEEN_REPORTED_MPS: f64 = 0.2;

/// The longest measured attitude response counted (s); a longer fit is not trusted.
pub const MAX_RESPONSE_S: f64 = 1.0;

/// What the filter did over a flight.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SafetyStats {
    /// Ticks the filter ran on.
    pub ticks: u64,
    /// Ticks with at least one active barrier row.
    pub active_ticks: u64,
    /// Ticks it changed a command.
    pub filtered_ticks: u64,
    /// Ticks on which the weighted sum could not be kept (the filter solved without it).
    pub sum_released_ticks: u64,
    /// Ticks on which a barrier row could not be met inside the envelopes (met as nearly
    /// as they allow).
    pub relaxed_ticks: u64,
    /// Ticks on which it fell back to braking.
    pub fallbacks: u64,
    /// Ticks on which the time limit or the sweep limit ended a solve before its answer
    /// ([`Outcome::Unfinished`]).
    pub unfinished_ticks: u64,
    /// The most a barrier row was missed by on those ticks (m/s²).
    pub unfinished_missed_mps2: f64,
    /// Vehicles the stopping check turned to braking on those ticks, summed over them.
    pub unfinished_braked: u64,
    /// Pairs that conflicted even braking on those ticks, summed over them.
    pub unfinished_unresolved: u64,
    /// Ticks on which the stopping check turned a vehicle to braking (every tick is
    /// checked with the stopping rows, an unfinished one with the barrier's).
    pub check_braked_ticks: u64,
    /// Vehicles the stopping check turned to braking, summed over all ticks.
    pub check_braked: u64,
    /// Pairs the stopping check found in conflict even braking, summed over all ticks.
    pub check_unresolved: u64,
    /// Ticks on which the stopping check ran out of time and every vehicle braked.
    pub check_out_of_time_ticks: u64,
    /// How long each tick's filter call took (wall clock).
    pub filter_time: super::timing::Histogram,
    /// The age each tick's filter counted, by which every pair's separation grows: what
    /// is known of the oldest vehicle when the command acts (its state's age, how far
    /// behind its sockets the coordinator was, its response, a period).
    pub counted_age: super::timing::Histogram,
    /// The most vehicles in one piece solved together.
    pub largest_piece: usize,
    /// The most sweeps of the dual ascent in one tick.
    pub most_sweeps: usize,
    /// Times the fence made the swarm hold or land.
    pub fence_actions: u64,
    /// Times a pair the filter could not keep apart made the swarm hold or land.
    pub separation_actions: u64,
    /// Jams found (vehicles the filter held without progress, turned past each other):
    /// each time some vehicle was jammed while none was.
    pub jams: u64,
    /// Consensus ticks with a jammed vehicle.
    pub jam_ticks: u64,
    /// Times a vehicle left the formation's altitude for the jam layer.
    pub layer_climbs: u64,
    /// Vehicles that, told to land above another closer than the horizontal
    /// separation, first flew clear of it (`super::landing`).
    pub landing_moves: u64,
    /// Silences of a vehicle in the air kept as its stopping path (`super::lost`): once
    /// per last state, each named in the events.
    pub quiet_paths: u64,
    /// The largest unseen speed counted for a vehicle (m/s: its positions moving beyond
    /// its velocities, [`crate::control::UnseenMotion`]) and which (`None`: none counted).
    pub unseen_max: Option<(f64, usize)>,
    /// Vehicles whose unseen speed was reported (once each).
    unseen_reported: Vec<bool>,
    /// `safety.action = "continue"` was reported (once a flight).
    continue_reported: bool,
    /// The smallest ellipsoidal distance between two vehicles with a usable state seen on
    /// a control tick, with when, the swarm's phase then and the pair (`None` while never
    /// two): what a flight that lost its separation needs to be read.
    pub min_seen: Option<ClosestSeen>,
    /// Pairs within the separation now (to log each entry once).
    inside: Vec<(usize, usize)>,
}

/// Where and when the smallest distance of a flight was seen.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClosestSeen {
    /// The ellipsoidal distance (m, horizontal metres).
    pub distance_m: f64,
    /// The control tick's time.
    pub at: SimTime,
    /// The swarm's phase on that tick.
    pub phase: SwarmPhase,
    /// The two vehicles (indices into the swarm's links).
    pub pair: (usize, usize),
}

impl SafetyStats {
    /// Empty statistics.
    pub fn new() -> Self {
        Self::default()
    }
}

/// The safety filter and what it works with: its reused input buffers, its tallies and
/// the closest pair of the last tick.
#[derive(Debug, Clone)]
pub(super) struct SafetyWork {
    pub(super) filter: crate::safety::SafetyFilter,
    pub(super) agents: Vec<crate::safety::Agent>,
    pub(super) xy: Vec<Vector2<f64>>,
    pub(super) stats: SafetyStats,
    pub(super) closest_pair: Option<(usize, usize, f64)>,
    /// The jam watch and its buffers.
    pub(super) jams: JamWork,
    /// What was sent to each vehicle, for the path of one whose state stops arriving.
    pub(super) sent: super::lost::SentCommands,
}

/// The jam watch and what it reads each tick.
#[derive(Debug, Clone, Default)]
pub(super) struct JamWork {
    pub(super) watch: crate::safety::jam::JamWatch,
    /// Each vehicle's distance to its place (m).
    pub(super) errors: Vec<Option<f64>>,
    /// Each vehicle's offset from its place (m, ENU: where it is less where it should be).
    pub(super) offsets: Vec<Option<Vector2<f64>>>,
    /// Since when each vehicle has flown on the jam layer (`crate::safety::layers`;
    /// `None`: at the formation's altitude).
    pub(super) layered: Vec<Option<ringswarm_wire::time::SimTime>>,
    /// With shards: the layer as seen before this shard decided (another shard's vehicles
    /// keep it).
    pub(super) remote_layered: Vec<Option<ringswarm_wire::time::SimTime>>,
    /// Horizontal positions (m, ENU).
    pub(super) positions: Vec<Option<Vector2<f64>>>,
    /// Horizontal velocities (m/s, ENU).
    pub(super) velocities: Vec<Option<Vector2<f64>>>,
    /// Horizontal commands (m/s², ENU).
    pub(super) commands: Vec<Vector2<f64>>,
    /// Whether the last filter took at least the watch's share of each vehicle's command
    /// away.
    pub(super) restrained: Vec<bool>,
    /// Whether every filter call of the last [`LAYER_CALM_S`] finished (its solve and its
    /// check in time, no fallback): vehicles move to and from the jam layer only then.
    pub(super) filter_finished: bool,
    /// When a filter call last did not finish.
    pub(super) last_unfinished: Option<SimTime>,
}

impl JamWork {
    /// Each vehicle's horizontal position and velocity from its state (`None` without).
    pub(super) fn read_motions(&mut self, states: &[Option<super::CommonState>]) {
        self.positions.clear();
        self.positions
            .extend(states.iter().map(|s| s.map(|s| s.pos_enu_m.xy())));
        self.velocities.clear();
        self.velocities
            .extend(states.iter().map(|s| s.map(|s| s.vel_enu_mps.xy())));
    }
}

impl SafetyWork {
    pub(super) fn new(n: usize) -> Self {
        Self {
            filter: crate::safety::SafetyFilter::default(),
            agents: Vec::with_capacity(n),
            xy: Vec::with_capacity(n),
            stats: SafetyStats::new(),
            closest_pair: None,
            jams: JamWork::default(),
            sent: super::lost::SentCommands::new(n),
        }
    }
}

impl Swarm {
    /// The velocity the filter's stopping check brakes a vehicle to (m/s, ENU): the
    /// prediction in consensus (one for every shard), the w-weighted mean of the known
    /// velocities while the vehicles keep theirs (handshake, re-target stage), and rest
    /// once the swarm brakes and holds.
    fn common_velocity_mps(&self) -> Vector2<f64> {
        let keeping = matches!(
            self.phase,
            SwarmPhase::Handshake | SwarmPhase::Retargeting(_) | SwarmPhase::Consensus(_)
        );
        if !keeping {
            return Vector2::zeros();
        }
        let v = match (self.phase, self.predicted_final_velocity) {
            (SwarmPhase::Consensus(_), Some(v)) => v,
            _ => {
                let (mut sum, mut w_sum) = (Vector2::zeros(), 0.0);
                for (s, w) in self.law.states.iter().zip(&self.law.w) {
                    if let Some(s) = s {
                        sum += s.vel_enu_mps.xy() * *w;
                        w_sum += *w;
                    }
                }
                if w_sum > 0.0 {
                    sum / w_sum
                } else {
                    Vector2::zeros()
                }
            }
        };
        if v.iter().all(|x| x.is_finite()) && v.norm() <= super::MAX_SPEED_MPS {
            v
        } else {
            Vector2::zeros()
        }
    }

    /// Filters the horizontal commands of the vehicles flown on our commands, in place,
    /// when `[safety]` is on.
    pub(super) fn filter_for_safety(&mut self, now: SimTime) {
        let Some(setup) = self.setup.safety else {
            return;
        };
        let consensus = matches!(self.phase, SwarmPhase::Consensus(_));
        let period_s = self.setup.control_interval.as_secs_f64();
        let mut age_s: f64 = 0.0;
        // The vehicle whose age is counted, for the events.
        let mut oldest = None;
        for i in self.indices() {
            let age = if self.law.states[i].is_some() && self.ours_in_air(i) {
                self.command_age_s(i, now) - period_s
            } else if self.law.states[i].is_some()
                && let Some(at) = self.remote_measured(i)
            {
                // Another shard's vehicle: its state is as old as the hop made it, and it
                // answers its own shard's commands only after its attitude response
                // (not measured here: counted as unmeasured).
                let hop_s = now.saturating_since(at).as_secs_f64();
                hop_s + period_s + UNMEASURED_RESPONSE_S
            } else {
                continue;
            };
            if age > age_s {
                age_s = age;
                oldest = Some(i);
            }
        }
        // Each position put at one instant, the newest report's arrival: on a lossy or
        // jittery link the reports of two vehicles can differ in age by several periods,
        // and at the swarm's common speed that shifts the one against the other by metres
        // (14 m/s and 100 ms: 1.4 m), which the barrier's reach, grown by the pair's
        // relative speed over the age, does not cover.
        // Another shard's vehicle is already carried to now by its hop, and stays.
        self.count_unseen(now);
        let local = |i: VehicleIndex| self.slots[i].link().is_some();
        let newest = self
            .indices()
            .filter(|&i| self.law.states[i].is_some() && local(i))
            .filter_map(|i| self.state_time(i))
            .max();
        self.safety.agents.clear();
        self.safety.xy.clear();
        for i in self.indices() {
            // A remote vehicle flown through its own shard's copy of this filter is a
            // variable too: a pair split between shards is solved here as one process
            // solves it, and each shard flies only its own vehicle's part.
            let controlled =
                self.law.states[i].is_some() && (self.ours_in_air(i) || self.cooperating_remote(i));
            let model = &self.law.flown_models[i];
            let envelope = &self.setup.envelope;
            let u_z = envelope.limit_vertical(self.law.commands[i].z, model);
            let limit = envelope.horizontal_limit_mps2(u_z, model);
            let behind_s = if local(i) {
                self.state_behind_s(i, newest)
            } else {
                0.0
            };
            self.safety.agents.push(Agent {
                side: self.law.states[i].map(|s| Side {
                    pos_m: s.pos_enu_m + s.vel_enu_mps * behind_s,
                    vel_mps: s.vel_enu_mps,
                    accel_z_mps2: if controlled { self.slots[i].u_z } else { 0.0 },
                }),
                controlled,
                weight: if consensus { self.law.w[i] } else { 1.0 },
                // What the command holds besides the law's acceleration (the drag fed
                // forward less the disturbance taken off), from before the saturation.
                drift_mps2: self.law.law_commands[i].xy() - self.law.accel[i],
                limit_mps2: limit,
                braking_mps2: setup.braking_share * limit,
                lag_s: if local(i) { self.counted_lag_s(i) } else { 0.0 },
                spread_m: 0.0,
                // Another shard's vehicle's as its shard counts it.
                unseen_mps: self.slots[i].unseen_mps(),
            });
            self.safety.xy.push(self.law.commands[i].xy());
        }
        let measured = self.safety.agents.len();
        self.push_lost_vehicles(now);
        let settings = Settings {
            separation: setup.separation,
            age_s: age_s + period_s,
            period_s,
            keep_weighted_sum: consensus,
            time_limit_s: if setup.wall_clock_budget {
                setup.budget_share * period_s
            } else {
                f64::INFINITY
            },
            // A command moves the stopping rows' stop end by `h²/2 + hT/2` per m/s²
            // (about a centimetre at 50 Hz), so they hold only while the plan predicts
            // each vehicle that closely; flown with x500s they relax and the block loses
            // its separation (docs/dense.md, "The synchronised stop"). The swarm flies the
            // barrier rows.
            rows: crate::safety::Rows::Barrier,
            brake_to_mps: self.common_velocity_mps(),
        };
        let report = self.safety.filter.filter(
            &settings,
            &self.safety.agents,
            &mut self.safety.xy,
            self.setup.fence.as_ref().map(|f| (&f.fence, f.margin_m)),
        );
        let counted_age = Duration::try_from_secs_f64(settings.age_s).unwrap_or(Duration::MAX);
        let fell_back = matches!(report.outcome, Outcome::Fallback { .. });
        let work = &mut self.safety.jams;
        if fell_back
            || report.check_out_of_time
            || matches!(report.outcome, Outcome::Unfinished { .. })
        {
            work.last_unfinished = Some(now);
        }
        work.filter_finished = calm(work.last_unfinished, now);
        let stats = &mut self.safety.stats;
        stats.ticks += 1;
        stats.active_ticks += u64::from(report.active > 0);
        stats.filter_time.record(report.elapsed);
        stats.counted_age.record(counted_age);
        stats.largest_piece = stats.largest_piece.max(report.largest_piece);
        stats.most_sweeps = stats.most_sweeps.max(report.sweeps);
        if let Some((i, j, d)) = report.closest
            && d < stats.min_seen.map_or(f64::INFINITY, |c| c.distance_m)
        {
            stats.min_seen = Some(ClosestSeen {
                distance_m: d,
                at: now,
                phase: self.phase,
                pair: (i, j),
            });
        }
        stats.check_braked_ticks += u64::from(report.braked > 0);
        stats.check_braked += report.braked as u64;
        stats.check_unresolved += report.unresolved as u64;
        if report.check_out_of_time {
            stats.check_out_of_time_ticks += 1;
            if stats.check_out_of_time_ticks % 100 == 1 {
                self.log.push(
                    now,
                    true,
                    format!(
                        "safety filter: the stopping check ran out of time: every vehicle brakes this tick (tick {})",
                        stats.check_out_of_time_ticks
                    ),
                );
            }
        }
        self.safety.closest_pair = report.closest;
        match report.outcome {
            Outcome::Untouched => {}
            Outcome::Filtered { sum_kept, relaxed } => {
                stats.filtered_ticks += 1;
                if consensus && !sum_kept {
                    stats.sum_released_ticks += 1;
                }
                if relaxed {
                    stats.relaxed_ticks += 1;
                    if stats.relaxed_ticks % 100 == 1 {
                        self.log.push(
                            now,
                            true,
                            format!(
                                "safety filter: a pair closes faster than the envelopes can stop it inside the separation: braking as hard as they allow (relaxed tick {})",
                                stats.relaxed_ticks
                            ),
                        );
                    }
                }
            }
            Outcome::Unfinished {
                missed_mps2,
                braked,
                unresolved,
            } => {
                stats.filtered_ticks += 1;
                stats.unfinished_ticks += 1;
                stats.unfinished_missed_mps2 = stats.unfinished_missed_mps2.max(missed_mps2);
                stats.unfinished_braked += braked as u64;
                stats.unfinished_unresolved += unresolved as u64;
                if stats.unfinished_ticks % 100 == 1 {
                    let oldest = oldest
                        .map_or_else(|| "none".to_string(), |i| self.setup.links[i].file_label());
                    self.log.push(
                        now,
                        true,
                        format!(
                            "safety filter: its time ran out before the answer: the answer so far went out, {braked} vehicles braking where it and then braking would not keep the separation (unfinished tick {}; {} active rows, largest piece {}, {} sweeps; the age counted {:.0} ms, the oldest {oldest}; listening {:.0} ms behind)",
                            stats.unfinished_ticks,
                            report.active,
                            report.largest_piece,
                            report.sweeps,
                            counted_age.as_secs_f64() * 1e3,
                            self.listen_lag.as_secs_f64() * 1e3,
                        ),
                    );
                }
            }
            Outcome::Fallback { reason } => {
                stats.fallbacks += 1;
                // The first, then one in a hundred: a long fallback must not flood the log.
                if stats.fallbacks % 100 == 1 {
                    self.log.push(
                        now,
                        true,
                        format!(
                            "safety filter: no command keeps every pair apart ({reason}): the vehicles of the conflict brake (fallback {})",
                            stats.fallbacks
                        ),
                    );
                }
            }
        }
        // What the filter took of each command, for the jam watch: an active row holds a
        // vehicle only when it took a good share of the law's command away (read only with
        // this call's active rows, so not needed without one).
        if let Some(jams) = setup
            .jams
            .filter(|_| !self.safety.filter.active_rows().is_empty())
        {
            let work = &mut self.safety.jams;
            work.restrained.clear();
            work.restrained.extend(
                self.safety
                    .xy
                    .iter()
                    .zip(&self.law.commands)
                    .zip(&self.safety.agents)
                    .map(|((post, pre), a)| {
                        let taken = (pre.xy() - post).norm();
                        a.controlled
                            && taken > 0.0
                            && taken >= jams.restrained_share * pre.xy().norm()
                    }),
            );
        }
        for (i, xy) in self.safety.xy.iter().enumerate().take(measured) {
            if self.safety.agents[i].controlled && !self.is_remote(VehicleIndex(i)) {
                self.law.commands[i].x = xy.x;
                self.law.commands[i].y = xy.y;
            }
        }
        self.record_sent(now, measured);
        self.log_pairs_inside(now, setup.separation);
        self.act_on_breach(now, &setup, fell_back);
    }

    /// Applies `safety.action` when, while the swarm flies its law (the re-target stage
    /// or consensus), the filter did not keep a pair with a vehicle it commands apart: a
    /// pair closer than [`BREACH_SHARE`] of the separation, or a fallback.
    fn act_on_breach(&mut self, now: SimTime, setup: &SafetySetup, fell_back: bool) {
        if !matches!(
            self.phase,
            SwarmPhase::Consensus(_) | SwarmPhase::Retargeting(_)
        ) {
            return;
        }
        let limit_m = BREACH_SHARE * setup.separation.horizontal_m;
        let closest = self
            .safety
            .filter
            .close_pairs(limit_m)
            .min_by(|a, b| a.2.total_cmp(&b.2));
        let what = match closest {
            Some((i, j, d)) => format!(
                "vehicles {} and {} are {d:.2} m apart (states {} and {}), inside {:.0} % of the {} m separation",
                self.setup.links[i].file_label(),
                self.setup.links[j].file_label(),
                self.state_age_text(VehicleIndex(i), now),
                self.state_age_text(VehicleIndex(j), now),
                100.0 * BREACH_SHARE,
                setup.separation.horizontal_m
            ),
            None if fell_back => "no command keeps every pair apart".to_owned(),
            None => return,
        };
        match setup.action {
            BreachAction::Continue => {
                if !self.safety.stats.continue_reported {
                    self.safety.stats.continue_reported = true;
                    self.log.push(
                        now,
                        true,
                        format!(
                            "safety: {what}: the flight goes on (safety.action = \"continue\")"
                        ),
                    );
                }
            }
            BreachAction::Hold | BreachAction::Land => {
                let land = setup.action == BreachAction::Land;
                let verb = if land { "lands" } else { "holds" };
                self.safety.stats.separation_actions += 1;
                let text = format!("safety: {what}: the swarm {verb}");
                self.stop_law(now, StopReason::Separation, land, text);
            }
        }
    }

    /// How old vehicle `i`'s state is at `now` and where it came from ("12 ms old here",
    /// "40 ms old from another shard"; "none yet" before its first).
    fn state_age_text(&self, i: VehicleIndex, now: SimTime) -> String {
        let whence = if self.is_remote(i) {
            "from another shard"
        } else {
            "here"
        };
        self.state_time(i).map_or_else(
            || "none yet".to_owned(),
            |at| format!("{} ms old {whence}", now.saturating_since(at).as_millis()),
        )
    }

    /// Takes each vehicle's unseen speed into the stats, and names a vehicle the first
    /// time its unseen speed reaches [`UNSEEN_REPORTED_MPS`].
    fn count_unseen(&mut self, now: SimTime) {
        let n = self.vehicle_count();
        let stats = &mut self.safety.stats;
        stats.unseen_reported.resize(n, false);
        for i in 0..n {
            let unseen = self.slots[i]
                .link()
                .map_or(0.0, VehicleLink::unseen_speed_mps);
            if unseen <= 0.0 {
                continue;
            }
            if stats.unseen_max.is_none_or(|(m, _)| unseen > m) {
                stats.unseen_max = Some((unseen, i));
            }
            if !stats.unseen_reported[i] && unseen >= UNSEEN_REPORTED_MPS {
                stats.unseen_reported[i] = true;
                self.log.push_vehicle(
                    now,
                    &self.setup.links[i],
                    true,
                    format!(
                        "its reported positions move {unseen:.2} m/s beyond its reported velocity: every pair with it is kept apart as if closing that much faster"
                    ),
                );
            }
        }
    }

    /// How old what is known of vehicle `i` is by the time a command sent now acts (s):
    /// its state's age since it arrived, how far behind its sockets the coordinator is
    /// (what arrived may have waited that long unread), a control period, and the time
    /// from a command
    /// sent to a state that shows it: the measured attitude response (which holds the
    /// uplink and the downlink), but never less than the link's round trip (TIMESYNC);
    /// a fit beyond [`MAX_RESPONSE_S`] is not trusted, and then the round trip plus
    /// [`UNMEASURED_RESPONSE_S`] is counted.
    pub(super) fn command_age_s(&self, i: VehicleIndex, now: SimTime) -> f64 {
        let state = self
            .link(i)
            .and_then(|l| l.state().last_position)
            .map_or(0.0, |at| now.saturating_since(at).as_secs_f64());
        state
            + self.listen_lag.as_secs_f64()
            + self.setup.control_interval.as_secs_f64()
            + self.counted_response_s(i)
    }

    /// The time from a command sent to vehicle `i` to a state that shows it, as counted
    /// (s): its measured attitude response, never less than its round trip; the round
    /// trip and [`UNMEASURED_RESPONSE_S`] when the fit is missing or not trusted.
    pub(super) fn counted_response_s(&self, i: VehicleIndex) -> f64 {
        let round_trip = self
            .link(i)
            .and_then(VehicleLink::round_trip)
            .map_or(0.0, |rtt| rtt.as_secs_f64());
        // A fit beyond a second is no attitude loop a swarm flies with (the emulator's
        // ideal vehicles, which have none, fit 4.5 s): not counted.
        self.slots[i]
            .flown
            .attitude_response()
            .map(|r| r.response_s)
            .filter(|r| (0.0..=MAX_RESPONSE_S).contains(r))
            .map_or(round_trip + UNMEASURED_RESPONSE_S, |r| r.max(round_trip))
    }

    /// Vehicle `i`'s attitude response as counted, split into its delay and its lag (s):
    /// for another shard's vehicle, the unmeasured response's.
    pub(super) fn counted_delay_and_lag_s(&self, i: VehicleIndex) -> (f64, f64) {
        if self.is_remote(i) {
            return (UNMEASURED_RESPONSE_S - UNMEASURED_LAG_S, UNMEASURED_LAG_S);
        }
        let lag_s = self.counted_lag_s(i);
        ((self.counted_response_s(i) - lag_s).max(0.0), lag_s)
    }

    /// The lag of vehicle `i`'s attitude response counted inside its age (s): the
    /// fitted time constant when the fit is counted ([`Self::command_age_s`]), otherwise
    /// [`UNMEASURED_LAG_S`] of the unmeasured response.
    fn counted_lag_s(&self, i: VehicleIndex) -> f64 {
        self.slots[i]
            .flown
            .attitude_response()
            .filter(|r| (0.0..=MAX_RESPONSE_S).contains(&r.response_s))
            .map_or(UNMEASURED_LAG_S, |r| r.time_constant_s)
    }

    /// Logs every pair that came within the separation (once per entry).
    fn log_pairs_inside(&mut self, now: SimTime, sep: crate::safety::Separation) {
        let mut inside = std::mem::take(&mut self.safety.stats.inside);
        let mut entered: Vec<(usize, usize, f64)> = Vec::new();
        let mut still = Vec::with_capacity(inside.len());
        for (i, j, d) in self.safety.filter.close_pairs(sep.horizontal_m) {
            if !inside.contains(&(i, j)) {
                entered.push((i, j, d));
            }
            still.push((i, j));
        }
        inside.clear();
        inside.extend(still);
        self.safety.stats.inside = inside;
        for (i, j, d) in entered {
            // Named by network too when system ids repeat across networks.
            let (a, b) = (
                self.setup.links[i].file_label(),
                self.setup.links[j].file_label(),
            );
            self.log.push(
                now,
                true,
                format!(
                    "vehicles {a} and {b} came within the separation: {d:.2} m (ellipsoid {} m by {} m)",
                    sep.horizontal_m, sep.vertical_m
                ),
            );
        }
    }

    /// The safety filter's rows that bound on the last control tick (`(i, j)` vehicle
    /// indices; `i == j` against the fence); empty when it is off or changed nothing.
    pub fn safety_active_rows(&self) -> &[(usize, usize)] {
        if self.setup.safety.is_some() {
            self.safety.filter.active_rows()
        } else {
            &[]
        }
    }

    /// What the safety filter did so far.
    pub fn safety_stats(&self) -> &SafetyStats {
        &self.safety.stats
    }

    /// The closest pair on the last control tick (indices and ellipsoidal distance, m).
    pub fn closest_pair(&self) -> Option<(usize, usize, f64)> {
        self.safety.closest_pair
    }

    /// Vehicle `i`'s unseen speed as the filter counts it (m/s): its link's, or what its
    /// own shard reported last; 0 for an index out of range.
    pub fn unseen_speed_mps(&self, i: usize) -> f64 {
        self.slots.get(i).map_or(0.0, VehicleSlot::unseen_mps)
    }

    /// The separation the filter enforces (`None`: off).
    pub fn safety_enforced(&self) -> Option<crate::safety::Separation> {
        self.setup.safety.map(|s| s.separation)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_layer_waits_two_seconds_of_finished_filter_calls() {
        let at = SimTime::from_secs_f64;
        assert!(calm(None, at(0.0)));
        assert!(!calm(Some(at(10.0)), at(11.98)));
        assert!(calm(Some(at(10.0)), at(12.0)));
    }
}
