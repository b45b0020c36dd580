//! Figures of a flight, computed from the coordinator's view of the swarm (common frame,
//! ENU, metres): pure functions and a tracker fed once per control tick.

use nalgebra::{Vector2, Vector3};
use ringswarm_wire::time::SimTime;
use serde::Serialize;

use super::growth::GrowthFit;
use crate::swarm::VehicleIndex;
use crate::swarm::timing::TimingReport;
use crate::swarm::{Swarm, SwarmPhase};

/// Largest horizontal distance of any `pᵢ − dᵢ` from their mean (m): zero when the
/// vehicles are exactly in formation (the formation may sit anywhere).
pub fn formation_error_m(pos_m: &[Vector2<f64>], offsets_m: &[Vector2<f64>]) -> f64 {
    crate::consensus::formation_error_m(pos_m.iter().zip(offsets_m).map(|(p, d)| p - d))
}

/// Largest `|zᵢ − altitude|` (m).
pub fn altitude_error_m(z_m: &[f64], altitude_m: f64) -> f64 {
    z_m.iter()
        .map(|z| (z - altitude_m).abs())
        .fold(0.0, f64::max)
}

/// Smallest distance between two vehicles (m); infinite with fewer than two.
pub fn min_separation_m(pos_m: &[Vector3<f64>]) -> f64 {
    min_separation_in_place(&mut pos_m.to_vec())
}

/// Up to this many vehicles every pair is measured: fewer operations than sorting.
const EVERY_PAIR_UP_TO: usize = 12;

/// [`min_separation_m`] of `pos_m`, which it may reorder: a sweep along the axis of widest
/// spread, sorted, comparing each point only with those closer along that axis than the
/// best distance so far (O(N log N) for a spread-out swarm, not N²/2 distances); every
/// pair for a handful of vehicles.
pub fn min_separation_in_place(pos_m: &mut [Vector3<f64>]) -> f64 {
    if pos_m.len() <= EVERY_PAIR_UP_TO {
        // The square root is monotonic and correctly rounded: taken once, of the least
        // squared distance, it is the least distance exactly (NaNs are ignored either way).
        let mut least = f64::INFINITY;
        for (i, a) in pos_m.iter().enumerate() {
            for b in &pos_m[i + 1..] {
                least = least.min((a - b).norm_squared());
            }
        }
        return least.sqrt();
    }
    let spread = |axis: usize| {
        let (lo, hi) = pos_m
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
                (lo.min(p[axis]), hi.max(p[axis]))
            });
        hi - lo
    };
    let axis = (0..3)
        .max_by(|a, b| spread(*a).total_cmp(&spread(*b)))
        .unwrap_or(0);
    pos_m.sort_unstable_by(|a, b| a[axis].total_cmp(&b[axis]));
    let mut min = f64::INFINITY;
    for (i, a) in pos_m.iter().enumerate() {
        for b in &pos_m[i + 1..] {
            // Sorted: every later point is at least this far along the axis (a NaN
            // compares false and is measured, and its NaN distance is ignored by min).
            if b[axis] - a[axis] >= min {
                break;
            }
            min = min.min((a - b).norm());
        }
    }
    min
}

/// The swarm's figures at one instant.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Snapshot {
    /// When (s since start).
    pub t_s: f64,
    /// Mean horizontal velocity (m/s, ENU).
    pub mean_velocity_mps: [f64; 2],
    /// See [`formation_error_m`].
    pub formation_error_m: f64,
    /// See [`altitude_error_m`].
    pub altitude_error_m: f64,
}

/// Follows a flight tick by tick: the smallest separation seen and the last snapshot taken
/// during consensus (the flight's result, before any landing).
#[derive(Debug, Clone)]
pub struct RunTracker {
    min_separation_m: f64,
    last_consensus: Option<Snapshot>,
    latest: Option<Snapshot>,
    pos: Vec<Vector3<f64>>,
    xy: Vec<Vector2<f64>>,
    /// Each vehicle's formation place (as configured, or assigned).
    places: Vec<Vector2<f64>>,
    z: Vec<f64>,
    /// The positions carried to one instant, for the separation sweep (which reorders
    /// them).
    sweep: Vec<Vector3<f64>>,
    /// The formation error's growth over the last consensus.
    growth: GrowthFit,
}

impl RunTracker {
    /// A tracker for `n` vehicles.
    pub fn new(n: usize) -> Self {
        Self {
            min_separation_m: f64::INFINITY,
            last_consensus: None,
            latest: None,
            pos: Vec::with_capacity(n),
            xy: Vec::with_capacity(n),
            places: Vec::with_capacity(n),
            z: Vec::with_capacity(n),
            sweep: Vec::with_capacity(n),
            growth: GrowthFit::default(),
        }
    }

    /// Takes the swarm's state at `now`. Vehicles whose origin is not known yet make the
    /// snapshot incomplete and it is skipped.
    pub fn observe(&mut self, swarm: &Swarm, now: SimTime) {
        let n = swarm.vehicle_count();
        self.pos.clear();
        // The separation is measured between positions carried to the newest report's
        // arrival by their velocities, as the safety filter puts them: reports of
        // different ages (a lossy or jittery link) would otherwise show the pair where it
        // never was.
        let newest = swarm.indices().filter_map(|i| swarm.state_time(i)).max();
        self.sweep.clear();
        let mut vel = Vector2::zeros();
        for i in swarm.indices() {
            let Some(s) = swarm.common_state(i) else {
                return;
            };
            self.pos.push(s.pos_enu_m);
            self.sweep
                .push(s.pos_enu_m + s.vel_enu_mps * swarm.state_behind_s(i, newest));
            vel += s.vel_enu_mps.xy() / n as f64;
        }
        self.xy.clear();
        self.xy.extend(self.pos.iter().map(|p| p.xy()));
        self.z.clear();
        self.z.extend(self.pos.iter().map(|p| p.z));
        let setup = swarm.setup();
        let airborne = !matches!(swarm.phase(), SwarmPhase::Landing(_));
        if airborne {
            let min = min_separation_in_place(&mut self.sweep);
            self.min_separation_m = self.min_separation_m.min(min);
        }
        self.places.clear();
        self.places.extend(swarm.places_m());
        let snapshot = Snapshot {
            t_s: now.as_secs_f64(),
            mean_velocity_mps: [vel.x, vel.y],
            formation_error_m: formation_error_m(&self.xy, &self.places),
            altitude_error_m: altitude_error_m(&self.z, setup.altitude_m),
        };
        self.latest = Some(snapshot);
        if let SwarmPhase::Consensus(since) = swarm.phase() {
            self.last_consensus = Some(snapshot);
            self.growth.observe(
                since.as_secs_f64(),
                snapshot.t_s,
                snapshot.formation_error_m,
            );
        }
    }

    /// The smallest separation seen while flying (not landing).
    pub fn min_separation_m(&self) -> f64 {
        self.min_separation_m
    }

    /// The last snapshot taken during consensus.
    pub fn last_consensus(&self) -> Option<Snapshot> {
        self.last_consensus
    }

    /// The latest snapshot.
    pub fn latest(&self) -> Option<Snapshot> {
        self.latest
    }

    /// The formation error's growth rate over the last consensus (1/s; see
    /// [`super::growth`]).
    pub fn formation_growth_per_s(&self) -> Option<f64> {
        self.growth.rate_per_s()
    }
}

/// What a traffic mirror carried (`summary.json`'s `mirrors`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MirrorReport {
    /// Where it sent (`host:port`).
    pub address: String,
    /// Datagrams forwarded (every one the coordinator sent or received).
    pub forwarded_datagrams: u64,
    /// Datagrams the kernel did not take at once (never waited for).
    pub not_sent_datagrams: u64,
    /// Datagrams that came back from the mirror: read and dropped.
    pub dropped_inbound_datagrams: u64,
}

/// `summary.json`.
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    /// Number of vehicles.
    pub vehicles: usize,
    /// Control rate (Hz).
    pub control_rate_hz: f64,
    /// The final velocity predicted at the (last) start of consensus (m/s, ENU).
    pub predicted_final_velocity: Option<[f64; 2]>,
    /// The mean velocity at the end of consensus (m/s, ENU).
    pub achieved_final_velocity: Option<[f64; 2]>,
    /// `|achieved − predicted| / |predicted|`.
    pub velocity_error_fraction: Option<f64>,
    /// Formation error at the end of consensus (m).
    pub formation_error_m: Option<f64>,
    /// How fast the formation error grew over the later half of the last consensus
    /// (1/s, the slope of its logarithm until it fell below 0.01 m): negative when the
    /// formation closes; for a ring within its envelopes, the closed loop's spectral
    /// abscissa (`analyze`). `null` with less than a second of it above 0.01 m.
    pub formation_growth_per_s: Option<f64>,
    /// Altitude error at the end of consensus (m).
    pub altitude_error_m: Option<f64>,
    /// Smallest separation while flying (m); `null` if never known. The distance between
    /// the states the coordinator holds, each carried to the newest one's arrival by its
    /// velocity (on a lossy link their ages differ).
    pub min_separation_m: Option<f64>,
    /// Smallest distance between two emulated vehicles' true positions while flying (m),
    /// when the emulator is in the same process (`sweep`); absent otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub true_min_separation_m: Option<f64>,
    /// Fraction of consensus ticks with a saturated command.
    pub saturated_fraction: f64,
    /// When consensus first started (s).
    pub consensus_started_s: Option<f64>,
    /// When consensus last ran (s).
    pub consensus_ended_s: Option<f64>,
    /// Simulated (or, over UDP, flown) seconds.
    pub sim_seconds: f64,
    /// Wall-clock seconds.
    pub wall_seconds: f64,
    /// The swarm's final phase (`landing`, `ended`, …).
    pub final_phase: String,
    /// Why the swarm gave up before its flight, if it did.
    pub failure: Option<String>,
    /// Why the flight stopped: `duration`, `guard`, `handshake`, `link_loss` or
    /// `requested`; `null` while it has not.
    pub stop_reason: Option<String>,
    /// What the divergence guard saw when it ended the consensus, if it did.
    pub guard: Option<String>,
    /// The vehicles the landing stopped waiting for, lost 30 s after it was ordered and
    /// left to their own failsafes (`vehicle 3`, `vehicle 3 on n1`); `fly` and `demo`
    /// exit 7 when there are any.
    pub left_lost: Vec<String>,
    /// What the coordinator learnt about each vehicle, at the end.
    pub models: Vec<ModelReport>,
    /// Warnings in `events.csv`.
    pub warnings: usize,
    /// A vehicle's warnings left out of `events.csv` as repeats of one of the same kind
    /// logged less than a second before (the next one logged counts them).
    pub warnings_repeated: u64,
    /// The control loop's punctuality (in lockstep every tick is on time).
    pub timing: TimingReport,
    /// What the safety filter enforced and did (`null` when `[safety]` is off).
    pub safety: Option<SafetyReport>,
    /// What each traffic mirror (`--mirror`) carried; absent without one.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub mirrors: Vec<MirrorReport>,
}

impl Summary {
    /// The summary of a flight.
    pub fn new(swarm: &Swarm, tracker: &RunTracker, now: SimTime, wall_seconds: f64) -> Self {
        let predicted = swarm.predicted_final_velocity();
        let end = tracker.last_consensus();
        let achieved = end.map(|s| Vector2::from(s.mean_velocity_mps));
        let velocity_error_fraction = predicted
            .zip(achieved)
            .filter(|(p, _)| p.norm() > 0.0)
            .map(|(p, a)| (a - p).norm() / p.norm());
        Self {
            vehicles: swarm.vehicle_count(),
            control_rate_hz: 1.0 / swarm.setup().control_interval.as_secs_f64(),
            predicted_final_velocity: predicted.map(|v| [v.x, v.y]),
            achieved_final_velocity: achieved.map(|v| [v.x, v.y]),
            velocity_error_fraction,
            formation_error_m: end.map(|s| s.formation_error_m),
            formation_growth_per_s: tracker.formation_growth_per_s(),
            altitude_error_m: end.map(|s| s.altitude_error_m),
            min_separation_m: Some(tracker.min_separation_m()).filter(|m| m.is_finite()),
            true_min_separation_m: None,
            saturated_fraction: swarm.saturated_fraction(),
            consensus_started_s: swarm.consensus_started().map(SimTime::as_secs_f64),
            consensus_ended_s: end.map(|s| s.t_s),
            sim_seconds: now.as_secs_f64(),
            wall_seconds,
            final_phase: swarm.phase().name().to_owned(),
            failure: swarm.failure().map(ToString::to_string),
            stop_reason: swarm.stop_reason().map(|r| r.name().to_owned()),
            guard: swarm.guard_trip().map(|t| t.to_string()),
            left_lost: swarm.left_lost().to_vec(),
            models: ModelReport::of(swarm),
            warnings: swarm.events().iter().filter(|e| e.warning).count(),
            warnings_repeated: swarm.repeated_warnings(),
            timing: swarm.timing(),
            safety: SafetyReport::of(swarm),
            mirrors: Vec::new(),
        }
    }
}

/// What the safety filter enforced and did (`summary.json`'s `safety`).
#[derive(Debug, Clone, Serialize)]
pub struct SafetyReport {
    /// The horizontal separation enforced, centre to centre (m).
    pub min_separation_m: f64,
    /// The vertical separation enforced (m).
    pub vertical_separation_m: f64,
    /// The smallest ellipsoidal distance between two vehicles seen on a control tick
    /// (m, horizontal metres; `null` while never two had a usable state).
    pub min_separation_seen_m: Option<f64>,
    /// When it was seen (s of swarm time, as in `events.csv`).
    pub min_separation_seen_at_s: Option<f64>,
    /// The swarm's phase then (`handshake`, `consensus`, `ended`, ...).
    pub min_separation_seen_phase: Option<&'static str>,
    /// The two vehicles, named as in the events (`n2-10` for a vehicle on a network,
    /// its system id otherwise).
    pub min_separation_seen_pair: Option<[String; 2]>,
    /// The fraction of control ticks with at least one active barrier constraint.
    pub active_fraction: f64,
    /// Control ticks on which the filter changed a command.
    pub filtered_ticks: u64,
    /// Consensus ticks on which `Σ wᵢuᵢ` could not be kept with the envelopes.
    pub sum_released_ticks: u64,
    /// Control ticks on which a pair closed faster than the envelopes could stop it
    /// inside the separation (the filter braked as hard as they allow).
    pub relaxed_ticks: u64,
    /// Control ticks on which the solver failed and the filter fell back to braking.
    pub fallbacks: u64,
    /// Times the fence made the swarm hold or land.
    pub fence_actions: u64,
    /// Times a pair the filter could not keep apart made the swarm hold or land
    /// (`safety.action`).
    pub separation_actions: u64,
    /// Jams found: vehicles the filter held without progress, turned past each other
    /// (each time some vehicle was jammed while none was).
    pub jams: u64,
    /// Consensus ticks with a jammed vehicle.
    pub jam_ticks: u64,
    /// Times a vehicle left the formation's altitude for the jam layer.
    pub layer_climbs: u64,
    /// Vehicles that, told to land above another closer than the horizontal
    /// separation, first flew clear of every other vehicle's way down.
    pub landing_moves: u64,
    /// Silences of a vehicle in the air kept as its stopping path: its neighbours kept
    /// clear of where it may be until its own Hold stops it.
    pub quiet_paths: u64,
    /// Ticks on which the time limit (`budget_share`, in real time) ended a solve before
    /// its answer: the dual ascent's answer so far went out, secured by the stopping
    /// check.
    pub unfinished_ticks: u64,
    /// The most a barrier row of the ascent's answer was missed by on those ticks (m/s²).
    pub unfinished_missed_mps2: f64,
    /// Vehicles the stopping check turned to braking, summed over those ticks.
    pub unfinished_braked: u64,
    /// Pairs that conflicted even braking, summed over those ticks.
    pub unfinished_unresolved: u64,
    /// Ticks on which the stopping check (run on the ticks whose solve the time limit
    /// ended) turned a vehicle to braking.
    pub check_braked_ticks: u64,
    /// Vehicles the stopping check turned to braking, summed over all ticks.
    pub check_braked: u64,
    /// Pairs the stopping check found in conflict even braking, summed over all ticks.
    pub check_unresolved: u64,
    /// Ticks on which the stopping check ran out of time and every vehicle braked.
    pub check_out_of_time_ticks: u64,
    /// The filter's time per control tick (wall clock; the sweep for pairs and the
    /// solve): median, 99th percentile and longest.
    pub filter_time: crate::swarm::timing::Quantiles,
    /// The age the filter counted each tick, by which every pair's separation grows:
    /// what is known of the oldest vehicle when the command acts (its state's age, how
    /// far behind its sockets the coordinator was, its response, a control period).
    pub counted_age: crate::swarm::timing::Quantiles,
    /// The most vehicles whose commands were solved together in one piece.
    pub largest_piece: usize,
    /// The most sweeps of the filter's dual ascent in one tick.
    pub most_sweeps: usize,
    /// The largest unseen speed counted for a vehicle (m/s): how fast its reported
    /// positions moved beyond its reported velocities, less a deadband; every pair with
    /// it is kept apart as if closing that much faster. 0 when none was.
    pub unseen_speed_max_mps: f64,
    /// The vehicle it was counted for, named as in the events (`null` when none).
    pub unseen_speed_max_vehicle: Option<String>,
}

impl SafetyReport {
    /// The report of a swarm whose filter is on.
    pub fn of(swarm: &Swarm) -> Option<Self> {
        let sep = swarm.safety_enforced()?;
        let s = swarm.safety_stats();
        Some(Self {
            min_separation_m: sep.horizontal_m,
            vertical_separation_m: sep.vertical_m,
            min_separation_seen_m: s.min_seen.map(|c| c.distance_m),
            min_separation_seen_at_s: s.min_seen.map(|c| c.at.as_secs_f64()),
            min_separation_seen_phase: s.min_seen.map(|c| c.phase.name()),
            min_separation_seen_pair: s.min_seen.map(|c| {
                let label = |i: usize| swarm.setup().links[i].file_label();
                [label(c.pair.0), label(c.pair.1)]
            }),
            active_fraction: if s.ticks > 0 {
                s.active_ticks as f64 / s.ticks as f64
            } else {
                0.0
            },
            filtered_ticks: s.filtered_ticks,
            sum_released_ticks: s.sum_released_ticks,
            relaxed_ticks: s.relaxed_ticks,
            fallbacks: s.fallbacks,
            fence_actions: s.fence_actions,
            separation_actions: s.separation_actions,
            jams: s.jams,
            jam_ticks: s.jam_ticks,
            layer_climbs: s.layer_climbs,
            landing_moves: s.landing_moves,
            quiet_paths: s.quiet_paths,
            unfinished_ticks: s.unfinished_ticks,
            unfinished_missed_mps2: s.unfinished_missed_mps2,
            unfinished_braked: s.unfinished_braked,
            unfinished_unresolved: s.unfinished_unresolved,
            check_braked_ticks: s.check_braked_ticks,
            check_braked: s.check_braked,
            check_unresolved: s.check_unresolved,
            check_out_of_time_ticks: s.check_out_of_time_ticks,
            filter_time: s.filter_time.quantiles(),
            counted_age: s.counted_age.quantiles(),
            largest_piece: s.largest_piece,
            most_sweeps: s.most_sweeps,
            unseen_speed_max_mps: s.unseen_max.map_or(0.0, |(v, _)| v),
            unseen_speed_max_vehicle: s
                .unseen_max
                .map(|(_, i)| swarm.setup().links[i].file_label()),
        })
    }
}

/// What the coordinator learnt about one vehicle in flight (`summary.json`'s `models`).
#[derive(Debug, Clone, Serialize)]
pub struct ModelReport {
    /// The vehicle's MAVLink system id.
    pub system_id: u8,
    /// The autopilot its heartbeat named (`px4`, `ardupilot`; `null` if never heard).
    pub autopilot: Option<&'static str>,
    /// Hover thrust estimate (normalised) and its standard deviation.
    pub hover_throttle: f64,
    /// See `hover_throttle`.
    pub hover_throttle_std: f64,
    /// Linear drag estimate (1/s) and its standard deviation.
    pub drag_per_s: f64,
    /// See `drag_per_s`.
    pub drag_std_per_s: f64,
    /// The drag fed forward at the end (1/s).
    pub drag_fed_forward_per_s: f64,
    /// The disturbance observer's last estimate in the air (m/s², east and north).
    pub disturbance_enu_mps2: [f64; 2],
    /// The attitude response measured in flight (`null` before enough motion, or with
    /// acceleration setpoints).
    pub attitude_response: Option<crate::control::AttitudeResponse>,
}

impl ModelReport {
    /// One report per vehicle of `swarm`.
    pub fn of(swarm: &Swarm) -> Vec<Self> {
        swarm
            .setup()
            .links
            .iter()
            .enumerate()
            .filter_map(|(i, link)| {
                let i = VehicleIndex(i);
                let (hover, hover_std) = swarm.hover_estimate(i)?;
                let (drag, drag_std, fed) = swarm.drag_estimate(i)?;
                let b = swarm.disturbance_estimate_mps2(i)?;
                let autopilot = swarm
                    .link(i)
                    .and_then(|l| l.state().autopilot)
                    .map(|a| a.key());
                Some(Self {
                    system_id: link.system_id,
                    autopilot,
                    hover_throttle: hover,
                    hover_throttle_std: hover_std,
                    drag_per_s: drag,
                    drag_std_per_s: drag_std,
                    drag_fed_forward_per_s: fed,
                    disturbance_enu_mps2: [b.x, b.y],
                    attitude_response: swarm.attitude_response(i),
                })
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn formation_error_ignores_where_the_formation_is() {
        let d = [Vector2::new(1.0, 0.0), Vector2::new(-1.0, 0.0)];
        let shifted = [Vector2::new(11.0, 5.0), Vector2::new(9.0, 5.0)];
        assert_eq!(formation_error_m(&shifted, &d), 0.0);
        // One vehicle 2 m east of its slot: p − d = (2, 0) and (0, 0), mean (1, 0), so
        // each is 1 m from the mean.
        let off = [Vector2::new(3.0, 0.0), Vector2::new(-1.0, 0.0)];
        assert!((formation_error_m(&off, &d) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn separation_and_altitude() {
        let p = [
            Vector3::new(0.0, 0.0, 50.0),
            Vector3::new(3.0, 4.0, 50.0),
            Vector3::new(0.0, 0.0, 62.0),
        ];
        assert_eq!(min_separation_m(&p), 5.0);
        assert_eq!(min_separation_m(&p[..1]), f64::INFINITY);
        assert_eq!(altitude_error_m(&[49.0, 50.5, 47.5], 50.0), 2.5);
    }

    #[test]
    fn the_sweep_finds_the_same_separation_as_every_pair() {
        use rand::{Rng, SeedableRng};
        let brute = |p: &[Vector3<f64>]| {
            let mut min = f64::INFINITY;
            for (i, a) in p.iter().enumerate() {
                for b in &p[i + 1..] {
                    min = min.min((a - b).norm());
                }
            }
            min
        };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        // Both ways: every pair (up to EVERY_PAIR_UP_TO) and the sweep (above).
        for n in [2, 3, 10, EVERY_PAIR_UP_TO, EVERY_PAIR_UP_TO + 1, 200] {
            for spread in [1.0, 1000.0] {
                let p: Vec<Vector3<f64>> = (0..n)
                    .map(|_| {
                        Vector3::new(
                            rng.random_range(-spread..spread),
                            rng.random_range(-spread..spread),
                            rng.random_range(40.0..60.0),
                        )
                    })
                    .collect();
                assert_eq!(min_separation_m(&p), brute(&p), "n {n}, spread {spread}");
                // Every point on one line along y (x and z equal): the sweep goes along y.
                let line: Vec<Vector3<f64>> =
                    p.iter().map(|q| Vector3::new(1.0, q.y, 50.0)).collect();
                assert_eq!(min_separation_m(&line), brute(&line));
            }
        }
        // Two vehicles at the same point.
        let same = [Vector3::new(1.0, 2.0, 3.0); 2];
        assert_eq!(min_separation_m(&same), 0.0);
    }
}
