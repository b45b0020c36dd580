//! What the live view and the replay show: the swarm at one instant, as the page and
//! `GET /api/state` see it. Positions and velocities are ENU in the common frame (metres,
//! m/s), as in the run directory's CSVs. Pure: built from a [`Swarm`] or from a run
//! directory's rows, serialised by the server.

use nalgebra::{Vector2, Vector3};
use ringswarm_wire::time::SimTime;
use serde::{Deserialize, Serialize};

use crate::record::metrics::Snapshot;
use crate::swarm::{Swarm, SwarmEvent};

/// How many of the newest events a state carries (the page keeps its own history, and
/// `events_total` tells it how many there were in all).
pub const RECENT_EVENTS: usize = 50;

/// The swarm at one instant.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ViewState {
    /// Seconds since the flight started.
    pub t_s: f64,
    /// The swarm's phase (`handshake`, `consensus`, `holding`, `ended`, `landing`, …).
    pub phase: String,
    /// The velocity the law takes the swarm to, predicted when consensus (last) started
    /// (m/s, ENU x/y); `null` before.
    pub predicted_final_velocity: Option<[f64; 2]>,
    /// The vehicles' mean horizontal velocity (m/s, ENU); `null` until every vehicle's
    /// position is known.
    pub mean_velocity_enu_mps: Option<[f64; 2]>,
    /// `|mean velocity − predicted final velocity|` (m/s).
    pub velocity_error_mps: Option<f64>,
    /// Largest horizontal distance of a vehicle from its place in the formation (m).
    pub formation_error_m: Option<f64>,
    /// Largest distance from the altitude the swarm holds (m).
    pub altitude_error_m: Option<f64>,
    /// The altitude the swarm holds (m, up).
    pub altitude_target_m: f64,
    /// Where the formation's reference point is heading for: the consensus value of
    /// `pᵢ − dᵢ`, the ring's left-null-vector average, which the law does not move but at
    /// the swarm's mean velocity (m, ENU x/y).
    pub formation_centre_enu_m: Option<[f64; 2]>,
    /// One entry per vehicle, in the config's order.
    pub vehicles: Vec<VehicleView>,
    /// The two vehicles closest to each other (ellipsoidal distance, horizontal metres),
    /// among pairs near enough to matter to the safety filter (live), or among all
    /// (replay); `null` when there is none.
    pub closest_pair: Option<PairView>,
    /// Pairs whose separation constraint bound the commands on the last control tick
    /// (indices into `vehicles`); empty in a replay.
    pub active_pairs: Vec<[usize; 2]>,
    /// The newest events (at most [`RECENT_EVENTS`]), oldest first.
    pub events: Vec<EventView>,
    /// How many events there have been.
    pub events_total: usize,
}

/// One vehicle.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VehicleView {
    /// MAVLink system id.
    pub sysid: u8,
    /// Its MAVLink network (`null` on a socket of its own).
    pub network: Option<String>,
    /// Position (m, ENU, common frame); `null` until its origin is known.
    pub position_enu_m: Option<[f64; 3]>,
    /// Velocity (m/s, ENU).
    pub velocity_enu_mps: Option<[f64; 3]>,
    /// Its place in the formation the law is taking the swarm to (m, ENU x/y).
    pub target_enu_m: Option<[f64; 2]>,
    /// The coordinator's link phase (`discovering`, `flying`, `lost`, …).
    pub link_phase: String,
    /// PX4's flight mode from the last heartbeat (`null` before one, or in a replay).
    pub mode: Option<String>,
    /// Armed, from the last heartbeat (`null` before one, or in a replay).
    pub armed: Option<bool>,
    /// Age of the newest frame from the vehicle (ms).
    pub telemetry_age_ms: Option<f64>,
    /// Horizontal speed (m/s).
    pub speed_mps: Option<f64>,
    /// Whether the envelope limited its last command (`null` in a replay).
    pub saturated: Option<bool>,
    /// Whether a safety constraint (a pair or the fence) bound its last command (`null`
    /// in a replay).
    pub constrained: Option<bool>,
}

/// Two vehicles and their distance.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PairView {
    /// Indices into `vehicles`.
    pub vehicles: [usize; 2],
    /// Their system ids.
    pub sysids: [u8; 2],
    /// Their ellipsoidal distance (m, horizontal metres: the vertical offset divided by
    /// the vertical-to-horizontal ratio of the separation).
    pub distance_m: f64,
}

/// An event (lost link, failsafe, refused command, timeout, …).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EventView {
    /// When (s since start).
    pub t_s: f64,
    /// The vehicle, or `null` for the swarm.
    pub sysid: Option<u8>,
    /// The vehicle's network.
    pub network: Option<String>,
    /// Whether an operator must see it.
    pub warning: bool,
    /// What happened.
    pub text: String,
}

impl From<&SwarmEvent> for EventView {
    fn from(e: &SwarmEvent) -> Self {
        Self {
            t_s: e.t.as_secs_f64(),
            sysid: e.system_id,
            network: e.network.clone(),
            warning: e.warning,
            text: e.text.clone(),
        }
    }
}

/// The consensus value of `pᵢ − dᵢ` over the vehicles whose position is known, weighted
/// by the ring's left null vector `w` (the average the double-integrator law conserves up
/// to the drift at the mean velocity), and each vehicle's place `centre + dᵢ` around it.
/// `None` when no position is known or the known weights sum to zero.
pub fn formation_targets(
    pos_m: &[Option<Vector2<f64>>],
    offsets_m: &[Vector2<f64>],
    w: &[f64],
) -> Option<(Vector2<f64>, Vec<Vector2<f64>>)> {
    let (sum, w_sum) = pos_m
        .iter()
        .zip(offsets_m)
        .zip(w)
        .filter_map(|((p, d), w)| p.map(|p| ((p - d) * *w, *w)))
        .fold((Vector2::zeros(), 0.0), |(s, ws), (x, w)| (s + x, ws + w));
    if w_sum.abs() < 1e-12 || !sum.iter().all(|x| x.is_finite()) {
        return None;
    }
    let centre = sum / w_sum;
    Some((centre, offsets_m.iter().map(|d| centre + d).collect()))
}

/// The closest two of `positions` (m, ENU; `None`: unknown) by the separation's
/// ellipsoidal distance: the vertical offset divided by `vertical_per_horizontal`.
/// All pairs: for a replay's state, not for a control tick.
pub fn closest_pair(
    positions: &[Option<Vector3<f64>>],
    vertical_per_horizontal: f64,
) -> Option<(usize, usize, f64)> {
    let scale = Vector3::new(1.0, 1.0, 1.0 / vertical_per_horizontal);
    let mut best: Option<(usize, usize, f64)> = None;
    for (i, a) in positions.iter().enumerate() {
        let Some(a) = a else { continue };
        for (j, b) in positions.iter().enumerate().skip(i + 1) {
            let Some(b) = b else { continue };
            let d = (a - b).component_mul(&scale).norm();
            if d.is_finite() && best.is_none_or(|(_, _, m)| d < m) {
                best = Some((i, j, d));
            }
        }
    }
    best
}

impl ViewState {
    /// The live swarm at `now`; `figures` is the run's latest snapshot of its figures.
    pub fn of_swarm(swarm: &Swarm, now: SimTime, figures: Option<Snapshot>) -> Self {
        let setup = swarm.setup();
        let n = swarm.vehicle_count();
        let states: Vec<_> = swarm.indices().map(|i| swarm.common_state(i)).collect();
        let xy: Vec<_> = states.iter().map(|s| s.map(|s| s.pos_enu_m.xy())).collect();
        let w: Vec<f64> = (0..n).map(|i| setup.ring.w(i)).collect();
        let places: Vec<_> = swarm.places_m().collect();
        let targets = formation_targets(&xy, &places, &w);
        let predicted = swarm.predicted_final_velocity();
        let active = swarm.safety_active_rows();
        let vehicles = swarm
            .indices()
            .map(|i| {
                // Another shard's vehicle has no link here: what its shard reports.
                let state = swarm.link(i).map(|l| l.state());
                let heard = state.is_some_and(|s| s.last_heartbeat.is_some());
                VehicleView {
                    sysid: setup.links[i].system_id,
                    network: setup.links[i].network.clone(),
                    position_enu_m: states[i].map(|s| s.pos_enu_m.into()),
                    velocity_enu_mps: states[i].map(|s| s.vel_enu_mps.into()),
                    target_enu_m: targets.as_ref().map(|(_, t)| t[i].into()),
                    link_phase: swarm.vehicle_phase(i).name().to_owned(),
                    mode: state.filter(|_| heard).map(|s| s.mode_name()),
                    armed: state.filter(|_| heard).map(|s| s.armed),
                    telemetry_age_ms: state
                        .and_then(|s| s.last_heard)
                        .map(|t| now.saturating_since(t).as_secs_f64() * 1e3),
                    speed_mps: states[i].map(|s| s.vel_enu_mps.xy().norm()),
                    saturated: Some(swarm.command_limited(i)),
                    constrained: Some(active.iter().any(|&(a, b)| a == i.get() || b == i.get())),
                }
            })
            .collect();
        let events = swarm.events();
        let mean = figures.map(|f| Vector2::from(f.mean_velocity_mps));
        Self {
            t_s: now.as_secs_f64(),
            phase: swarm.phase().name().to_owned(),
            predicted_final_velocity: predicted.map(Into::into),
            mean_velocity_enu_mps: mean.map(Into::into),
            velocity_error_mps: mean.zip(predicted).map(|(m, p)| (m - p).norm()),
            formation_error_m: figures.map(|f| f.formation_error_m),
            altitude_error_m: figures.map(|f| f.altitude_error_m),
            altitude_target_m: setup.altitude_m,
            formation_centre_enu_m: targets.map(|(c, _)| c.into()),
            closest_pair: swarm.closest_pair().map(|(i, j, d)| PairView {
                vehicles: [i, j],
                sysids: [setup.links[i].system_id, setup.links[j].system_id],
                distance_m: d,
            }),
            active_pairs: active
                .iter()
                .filter(|(a, b)| a != b)
                .map(|&(a, b)| [a, b])
                .collect(),
            vehicles,
            events: events[events.len().saturating_sub(RECENT_EVENTS)..]
                .iter()
                .map(EventView::from)
                .collect(),
            events_total: events.len(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn targets_are_the_weighted_consensus_value_plus_each_offset() {
        let d = [Vector2::new(1.0, 0.0), Vector2::new(-1.0, 0.0)];
        // In formation around (10, 5): every vehicle is at its target.
        let p = [Some(Vector2::new(11.0, 5.0)), Some(Vector2::new(9.0, 5.0))];
        let (c, t) = formation_targets(&p, &d, &[1.0, 3.0]).expect("targets");
        assert_eq!(c, Vector2::new(10.0, 5.0));
        assert_eq!(t, vec![Vector2::new(11.0, 5.0), Vector2::new(9.0, 5.0)]);
        // Out of formation: p − d = (0, 0) and (4, 0), weights 1 and 3 → centre (3, 0).
        let p = [Some(Vector2::new(1.0, 0.0)), Some(Vector2::new(3.0, 0.0))];
        let (c, t) = formation_targets(&p, &d, &[1.0, 3.0]).expect("targets");
        assert_eq!(c, Vector2::new(3.0, 0.0));
        assert_eq!(t, vec![Vector2::new(4.0, 0.0), Vector2::new(2.0, 0.0)]);
        // A vehicle not known yet is left out of the average; none known: no targets.
        let p = [None, Some(Vector2::new(3.0, 0.0))];
        assert_eq!(
            formation_targets(&p, &d, &[1.0, 3.0]).map(|x| x.0),
            Some(Vector2::new(4.0, 0.0))
        );
        assert_eq!(formation_targets(&[None, None], &d, &[1.0, 3.0]), None);
    }
}
