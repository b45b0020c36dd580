//! A distributed swarm seen from outside: what `ringswarm view --zenoh` shows, built from
//! the shards' messages alone (no vehicle is flown or commanded). Pure: the driver hands
//! it each message with the Unix time it came, and asks for the [`ViewState`] at an
//! instant.
//!
//! - Each vehicle is its newest [`VehicleReport`]: position and velocity, its shard's
//!   link phase, and its age (the age at its shard's tick plus the hop since).
//! - The phase is the shards': `handshake` until every shard reports the same start,
//!   `consensus` once every shard took its sums at it, `holding` when a shard reports a
//!   lost vehicle, `ended` when every shard's flight is over.
//! - The prediction is what every shard computes: the start sums added in shard order.
//! - The mean velocity is every shard's latest `Σ wᵢvᵢ` over `Σ wᵢ`.
//! - The places, with interchangeable places, are the shards': once every shard has sent
//!   its vehicles' positions at one start, the watch assigns from all of them as each
//!   shard does, so the formation error is measured against the places flown.

use nalgebra::Vector2;

use crate::assignment::assign_places;
use crate::distributed::{ShardMessage, ShardReport, StartPositions, VehicleReport};
use crate::swarm::SwarmSetup;
use crate::view::state::{EventView, PairView, VehicleView, ViewState, formation_targets};

/// A shard silent this long (µs) is reported as such once.
const SILENT_AFTER_US: u64 = 1_500_000;

/// What is known of a distributed swarm.
#[derive(Debug, Clone)]
pub struct SwarmWatch {
    sysids: Vec<u8>,
    networks: Vec<Option<String>>,
    /// The configured places, in ring order (m, ENU, from the formation's centre).
    offsets_m: Vec<Vector2<f64>>,
    /// The places flown: the configured ones, or the ones assigned at the last start.
    places_m: Vec<Vector2<f64>>,
    /// Whether the places are assigned at each start of consensus.
    assign: bool,
    /// Each vehicle's shard (index into the names), in ring order.
    owner: Vec<usize>,
    /// Each shard's newest positions at a start of consensus.
    start_positions: Vec<Option<StartPositions>>,
    /// The start the places were last assigned at (µs, swarm clock).
    assigned_at_us: Option<u64>,
    w: Vec<f64>,
    altitude_m: f64,
    shard_names: Vec<String>,
    /// Each vehicle's newest report and when it came (Unix µs).
    vehicles: Vec<Option<(u64, VehicleReport)>>,
    /// Each shard's newest report and when it came (Unix µs).
    reports: Vec<Option<(u64, ShardReport)>>,
    /// Whether each shard was last said to be silent.
    silent: Vec<bool>,
    /// The start last logged (swarm clock µs).
    logged_start: Option<u64>,
    /// The first message's arrival (Unix µs): the view's time zero.
    first_us: Option<u64>,
    events: Vec<EventView>,
    refused: u64,
}

impl SwarmWatch {
    /// A watch of the swarm `setup` describes, split into the shards `shard_names`, each
    /// vehicle flown by its `owner` (index into the names, in ring order).
    pub fn new(setup: &SwarmSetup, shard_names: Vec<String>, owner: Vec<usize>) -> Self {
        let n = setup.links.len();
        let shards = shard_names.len();
        Self {
            sysids: setup.links.iter().map(|l| l.system_id).collect(),
            networks: setup.links.iter().map(|l| l.network.clone()).collect(),
            offsets_m: setup.offsets_m.clone(),
            places_m: setup.offsets_m.clone(),
            assign: setup.assign_places,
            owner,
            start_positions: vec![None; shards],
            assigned_at_us: None,
            w: (0..n).map(|i| setup.ring.w(i)).collect(),
            altitude_m: setup.altitude_m,
            shard_names,
            vehicles: vec![None; n],
            reports: vec![None; shards],
            silent: vec![false; shards],
            logged_start: None,
            first_us: None,
            events: Vec::new(),
            refused: 0,
        }
    }

    /// Messages refused: a vehicle or shard index out of range.
    pub fn refused(&self) -> u64 {
        self.refused
    }

    fn t_s(&self, us: u64) -> f64 {
        us.saturating_sub(self.first_us.unwrap_or(us)) as f64 * 1e-6
    }

    fn log(&mut self, now_us: u64, warning: bool, text: String) {
        self.events.push(EventView {
            t_s: self.t_s(now_us),
            sysid: None,
            network: None,
            warning,
            text,
        });
    }

    /// A message that came at `now_us` (Unix µs).
    pub fn handle(&mut self, now_us: u64, message: &ShardMessage) {
        self.first_us.get_or_insert(now_us);
        match message {
            ShardMessage::Vehicle(v) => match self.vehicles.get_mut(usize::from(v.vehicle)) {
                Some(slot) => {
                    if slot
                        .as_ref()
                        .is_none_or(|(_, old)| old.sent_us <= v.sent_us)
                    {
                        *slot = Some((now_us, *v));
                    }
                }
                None => self.refused += 1,
            },
            ShardMessage::Shard(r) => {
                let s = usize::from(r.shard);
                let Some(slot) = self.reports.get_mut(s) else {
                    self.refused += 1;
                    return;
                };
                let first = slot.is_none();
                if slot
                    .as_ref()
                    .is_some_and(|(_, old)| old.sent_us > r.sent_us)
                {
                    return;
                }
                *slot = Some((now_us, r.clone()));
                if let Some(p) = &r.start_positions {
                    self.start_positions[s] = Some(p.clone());
                    self.assign_places(now_us);
                }
                let name = self.shard_names[s].clone();
                if first || self.silent[s] {
                    self.silent[s] = false;
                    self.log(now_us, false, format!("shard \"{name}\" heard"));
                }
                if let Some(start) = self.agreed_start()
                    && self.logged_start != Some(start)
                {
                    self.logged_start = Some(start);
                    self.log(
                        now_us,
                        false,
                        format!("every shard adopts the start at swarm clock {start} µs"),
                    );
                }
            }
        }
    }

    /// With interchangeable places, once every shard has sent its vehicles' positions at
    /// one start not yet assigned: the places every shard assigns from them.
    fn assign_places(&mut self, now_us: u64) {
        if !self.assign {
            return;
        }
        let Some(Some(first)) = self.start_positions.first() else {
            return;
        };
        let at_us = first.at_us;
        if self.assigned_at_us == Some(at_us) {
            return;
        }
        let mut lists = Vec::with_capacity(self.start_positions.len());
        for (s, p) in self.start_positions.iter().enumerate() {
            let Some(p) = p.as_ref().filter(|p| p.at_us == at_us) else {
                return;
            };
            if p.pos_m.len() != self.owner.iter().filter(|&&o| o == s).count() {
                return;
            }
            lists.push(p.pos_m.iter());
        }
        let positions: Option<Vec<Vector2<f64>>> = self
            .owner
            .iter()
            .map(|&s| lists.get_mut(s)?.next().map(|&[x, y]| Vector2::new(x, y)))
            .collect();
        let Some(positions) = positions else {
            return;
        };
        self.assigned_at_us = Some(at_us);
        match assign_places(&positions, &self.offsets_m) {
            Ok(a) => {
                self.places_m = a.place_of.iter().map(|&p| self.offsets_m[p]).collect();
                self.log(now_us, false, a.event_text());
            }
            Err(e) => self.log(now_us, true, format!("places not assigned: {e}")),
        }
    }

    /// Notes shards silent for [`SILENT_AFTER_US`] at `now_us`, once each time.
    pub fn tick(&mut self, now_us: u64) {
        for s in 0..self.reports.len() {
            let silent = self.reports[s]
                .as_ref()
                .is_some_and(|(at, r)| !r.ended && now_us.saturating_sub(*at) > SILENT_AFTER_US);
            if silent && !self.silent[s] {
                self.silent[s] = true;
                let name = self.shard_names[s].clone();
                self.log(now_us, true, format!("shard \"{name}\" silent"));
            }
        }
    }

    /// The start every shard reports, when they all report one.
    fn agreed_start(&self) -> Option<u64> {
        let mut starts = self
            .reports
            .iter()
            .map(|r| r.as_ref().and_then(|(_, r)| r.start_us));
        let first = starts.next()??;
        starts.all(|s| s == Some(first)).then_some(first)
    }

    /// `Σ wᵢvᵢ / Σ wᵢ` of every shard's sums at the agreed start, added in shard order
    /// (as every shard adds them).
    fn prediction(&self) -> Option<Vector2<f64>> {
        let start = self.agreed_start()?;
        let mut wv = Vector2::zeros();
        let mut w = 0.0;
        for r in &self.reports {
            let (_, r) = r.as_ref()?;
            if r.start_us != Some(start) {
                return None;
            }
            let sum = r.start_sum?;
            wv += Vector2::new(sum.wv_mps[0], sum.wv_mps[1]);
            w += sum.w;
        }
        (w.abs() > 1e-12).then(|| wv / w)
    }

    fn mean_velocity(&self) -> Option<Vector2<f64>> {
        let mut wv = Vector2::zeros();
        let mut w = 0.0;
        for r in &self.reports {
            let (_, r) = r.as_ref()?;
            wv += Vector2::new(r.now_sum.wv_mps[0], r.now_sum.wv_mps[1]);
            w += r.now_sum.w;
        }
        (w.abs() > 1e-12).then(|| wv / w)
    }

    fn phase(&self) -> &'static str {
        let reports: Vec<&ShardReport> = self.reports.iter().flatten().map(|(_, r)| r).collect();
        if reports.len() < self.reports.len() {
            return "handshake";
        }
        if reports.iter().all(|r| r.ended) {
            "ended"
        } else if reports.iter().any(|r| r.lost > 0) {
            "holding"
        } else if self.prediction().is_some() {
            "consensus"
        } else {
            "handshake"
        }
    }

    /// The swarm as known at `now_us` (Unix µs).
    pub fn state(&self, now_us: u64) -> ViewState {
        let xy: Vec<Option<Vector2<f64>>> = self
            .vehicles
            .iter()
            .map(|v| {
                v.map(|(_, r)| Vector2::new(f64::from(r.pos_enu_m[0]), f64::from(r.pos_enu_m[1])))
            })
            .collect();
        let targets = formation_targets(&xy, &self.places_m, &self.w);
        let formation_error_m = targets.as_ref().and_then(|(_, t)| {
            xy.iter()
                .zip(t)
                .map(|(p, t)| p.map(|p| (p - t).norm()))
                .collect::<Option<Vec<f64>>>()
                .map(|e| e.into_iter().fold(0.0, f64::max))
        });
        let altitude_error_m = self
            .vehicles
            .iter()
            .map(|v| v.map(|(_, r)| (f64::from(r.pos_enu_m[2]) - self.altitude_m).abs()))
            .collect::<Option<Vec<f64>>>()
            .map(|e| e.into_iter().fold(0.0, f64::max));
        let predicted = self.prediction();
        let mean = self.mean_velocity();
        let vehicles = self
            .vehicles
            .iter()
            .enumerate()
            .map(|(i, v)| {
                let f3 = |a: [f32; 3]| a.map(f64::from);
                let report = v.map(|(_, r)| r);
                VehicleView {
                    sysid: self.sysids[i],
                    network: self.networks[i].clone(),
                    position_enu_m: report.map(|r| f3(r.pos_enu_m)),
                    velocity_enu_mps: report.map(|r| f3(r.vel_enu_mps)),
                    target_enu_m: targets.as_ref().map(|(_, t)| t[i].into()),
                    link_phase: report.map_or("unknown", |r| r.phase.name()).to_owned(),
                    mode: None,
                    armed: None,
                    telemetry_age_ms: report.map(|r| {
                        (now_us.saturating_sub(r.sent_us) + u64::from(r.age_us)) as f64 * 1e-3
                    }),
                    speed_mps: report.map(|r| {
                        Vector2::new(f64::from(r.vel_enu_mps[0]), f64::from(r.vel_enu_mps[1]))
                            .norm()
                    }),
                    saturated: None,
                    constrained: None,
                }
            })
            .collect();
        ViewState {
            t_s: self.t_s(now_us),
            phase: self.phase().to_owned(),
            predicted_final_velocity: predicted.map(Into::into),
            mean_velocity_enu_mps: mean.map(Into::into),
            velocity_error_mps: mean.zip(predicted).map(|(m, p)| (m - p).norm()),
            formation_error_m,
            altitude_error_m,
            altitude_target_m: self.altitude_m,
            formation_centre_enu_m: targets.as_ref().map(|(c, _)| (*c).into()),
            closest_pair: closest_pair(&xy).map(|(i, j, d)| PairView {
                vehicles: [i, j],
                sysids: [self.sysids[i], self.sysids[j]],
                distance_m: d,
            }),
            active_pairs: Vec::new(),
            vehicles,
            events: self.events[self
                .events
                .len()
                .saturating_sub(crate::view::state::RECENT_EVENTS)..]
                .to_vec(),
            events_total: self.events.len(),
        }
    }
}

/// The two known vehicles closest to each other horizontally (m).
fn closest_pair(xy: &[Option<Vector2<f64>>]) -> Option<(usize, usize, f64)> {
    let mut best: Option<(usize, usize, f64)> = None;
    for (i, a) in xy.iter().enumerate() {
        for (j, b) in xy.iter().enumerate().skip(i + 1) {
            if let (Some(a), Some(b)) = (a, b) {
                let d = (a - b).norm();
                if best.is_none_or(|(_, _, bd)| d < bd) {
                    best = Some((i, j, d));
                }
            }
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::distributed::{MemberPhase, WeightedSum};

    fn setup() -> SwarmSetup {
        let text = std::fs::read_to_string(
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/paper-sim1.toml"),
        )
        .expect("paper-sim1.toml");
        crate::config::Config::from_toml(&text)
            .expect("parses")
            .validate()
            .expect("validates")
    }

    fn vehicle(i: u16, sent_us: u64, pos: [f32; 3], vel: [f32; 3]) -> ShardMessage {
        ShardMessage::Vehicle(VehicleReport {
            vehicle: i,
            sent_us,
            age_us: 10_000,
            phase: MemberPhase::Flying,
            landed: false,
            pos_enu_m: pos,
            vel_enu_mps: vel,
            unseen_mps: 0.0,
        })
    }

    fn report(
        shard: u16,
        sent_us: u64,
        start: Option<(u64, WeightedSum)>,
        now: WeightedSum,
    ) -> ShardMessage {
        ShardMessage::Shard(ShardReport {
            shard,
            sent_us,
            vehicles: 2,
            flying: 2,
            lost: 0,
            ended: false,
            start_us: start.map(|(t, _)| t),
            start_sum: start.map(|(_, s)| s),
            now_sum: now,
            top_speed_mps: 10.0,
            planned: false,
            plan_velocities: None,
            places_assigned: false,
            start_positions: None,
        })
    }

    #[test]
    fn the_prediction_is_the_start_sums_in_shard_order_and_the_phase_follows_the_shards() {
        let setup = setup();
        let names = ["a", "b", "c"].map(str::to_owned).to_vec();
        let mut watch = SwarmWatch::new(&setup, names, vec![0, 0, 1, 1, 2, 2]);
        let sum = |wv: [f64; 2], w: f64| WeightedSum {
            wp_m: [0.0, 0.0],
            wv_mps: wv,
            w,
        };
        let t0 = 1_000_000_000;
        // Before every shard is heard: handshake, nothing predicted.
        watch.handle(t0, &report(0, t0, None, sum([1.0, 0.0], 1.0)));
        assert_eq!(watch.state(t0).phase, "handshake");
        // Every shard with its sums at one start: (1·1 + 4·2 + 0) / (1 + 2 + 3) etc.
        let start = Some(t0 + 200_000);
        for (s, (wv, w)) in [([1.0, 0.0], 1.0), ([4.0, 2.0], 2.0), ([0.0, 4.0], 3.0)]
            .into_iter()
            .enumerate()
        {
            let at = t0 + 300_000 + s as u64;
            watch.handle(
                at,
                &report(s as u16, at, start.map(|t| (t, sum(wv, w))), sum(wv, w)),
            );
        }
        let state = watch.state(t0 + 400_000);
        assert_eq!(state.phase, "consensus");
        let p = state.predicted_final_velocity.expect("predicted");
        assert_eq!(p, [5.0 / 6.0, 6.0 / 6.0]);
        assert_eq!(state.mean_velocity_enu_mps, Some(p));
        assert_eq!(state.velocity_error_mps, Some(0.0));
        assert!(
            state
                .events
                .iter()
                .any(|e| e.text.contains("adopts the start"))
        );
        // A shard silent for 1.5 s is said so, once.
        watch.tick(t0 + 2_000_000);
        watch.tick(t0 + 2_100_000);
        assert_eq!(
            watch
                .state(t0 + 2_100_000)
                .events
                .iter()
                .filter(|e| e.warning)
                .count(),
            3
        );
    }

    #[test]
    fn vehicles_take_their_newest_report_and_their_age_counts_the_hop() {
        let setup = setup();
        let mut watch = SwarmWatch::new(
            &setup,
            ["a", "b", "c"].map(str::to_owned).to_vec(),
            vec![0, 0, 1, 1, 2, 2],
        );
        let t0 = 5_000_000;
        watch.handle(
            t0 + 30_000,
            &vehicle(1, t0 + 20_000, [3.0, 4.0, 50.0], [1.0, 0.0, 0.0]),
        );
        // An older report that comes late changes nothing.
        watch.handle(
            t0 + 31_000,
            &vehicle(1, t0, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]),
        );
        watch.handle(t0, &vehicle(99, t0, [0.0; 3], [0.0; 3]));
        let state = watch.state(t0 + 50_000);
        let v = &state.vehicles[1];
        assert_eq!(v.sysid, setup.links[1].system_id);
        assert_eq!(v.position_enu_m, Some([3.0, 4.0, 50.0]));
        assert_eq!(v.link_phase, "flying");
        // 30 ms since its shard sent it, plus 10 ms old at its shard's tick.
        assert_eq!(v.telemetry_age_ms, Some(40.0));
        assert_eq!(v.speed_mps, Some(1.0));
        assert!(state.vehicles[0].position_enu_m.is_none());
        assert_eq!(state.formation_error_m, None, "not every vehicle known");
        assert_eq!(watch.refused(), 1);
    }

    #[test]
    fn interchangeable_places_are_assigned_from_every_shard_s_start_positions() {
        let text = std::fs::read_to_string(
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/paper-sim1.toml"),
        )
        .expect("paper-sim1.toml");
        let mut config = crate::config::Config::from_toml(&text).expect("parses");
        config.formation.assign = Some("optimal".into());
        let setup = config.validate().expect("validates");
        let d = setup.offsets_m.clone();
        // Vehicle i starts exactly at place σ(i) about (100, 50): the assignment that
        // costs nothing is σ, and no other does (the six places are distinct).
        let sigma = [3, 4, 5, 0, 1, 2];
        let centre = Vector2::new(100.0, 50.0);
        let start: Vec<Vector2<f64>> = sigma.iter().map(|&p| centre + d[p]).collect();
        let owner = vec![0, 0, 1, 1, 2, 2];
        let names = ["a", "b", "c"].map(str::to_owned).to_vec();
        let mut watch = SwarmWatch::new(&setup, names, owner);
        let t0 = 2_000_000_000;
        for (i, p) in start.iter().enumerate() {
            watch.handle(
                t0,
                &vehicle(i as u16, t0, [p.x as f32, p.y as f32, 50.0], [0.0; 3]),
            );
        }
        let configured_error = watch.state(t0).formation_error_m.expect("all known");
        assert!(configured_error > 1.0, "{configured_error}");
        let with_positions = |shard: u16, at_us: u64| {
            let mut m = report(shard, t0 + 1_000, None, WeightedSum::default());
            if let ShardMessage::Shard(r) = &mut m {
                let k = usize::from(shard) * 2;
                r.start_positions = Some(StartPositions {
                    at_us,
                    pos_m: start[k..k + 2].iter().map(|p| [p.x, p.y]).collect(),
                });
            }
            m
        };
        // Two shards at one start, the third at another: nothing assigned yet.
        watch.handle(t0 + 1_000, &with_positions(0, 7));
        watch.handle(t0 + 1_000, &with_positions(1, 7));
        watch.handle(t0 + 1_000, &with_positions(2, 8));
        assert_eq!(watch.places_m, d);
        // The third at the same start: the places are σ's, and the formation error
        // against them is the float rounding of the reported positions.
        watch.handle(t0 + 2_000, &with_positions(2, 7));
        let expected: Vec<Vector2<f64>> = sigma.iter().map(|&p| d[p]).collect();
        assert_eq!(watch.places_m, expected);
        let error = watch
            .state(t0 + 2_000)
            .formation_error_m
            .expect("all known");
        assert!(error < 1e-4, "{error}");
        let events = watch.state(t0 + 2_000).events;
        assert_eq!(
            events
                .iter()
                .filter(|e| e.text.starts_with("places assigned: 6 of 6 vehicles away"))
                .count(),
            1,
            "{events:?}"
        );
        // The same start again assigns nothing more.
        watch.handle(t0 + 3_000, &with_positions(0, 7));
        let again = watch.state(t0 + 3_000).events;
        assert_eq!(
            again
                .iter()
                .filter(|e| e.text.starts_with("places assigned"))
                .count(),
            1
        );
    }
}
