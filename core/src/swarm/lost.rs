//! A vehicle whose state stopped arriving, kept in the safety filter as its stopping path
//! ([`crate::safety::lost`]): which vehicles, what is known of each, and what was sent to
//! them before.

use std::collections::VecDeque;

use nalgebra::{Vector2, Vector3};
use ringswarm_wire::time::SimTime;

use super::{Swarm, VehicleIndex};
use crate::safety::lost::{HOLD_BRAKING_MPS2, HOLD_ONSET_S, LostVehicle};
use crate::safety::{Agent, Side};
use crate::vehicle::Phase;

/// How long what was sent to a vehicle is kept (s): longer than the longest response
/// counted ([`super::safety::MAX_RESPONSE_S`]) and a state timeout.
const KEEP_S: f64 = 3.0;

/// What was sent to each vehicle the filter commanded: each tick's net horizontal
/// acceleration times the period it held for, with when it was sent.
#[derive(Debug, Clone, Default)]
pub(super) struct SentCommands {
    /// Per vehicle: when each tick's command was sent and the sum of all sent before it
    /// (m/s), and the sum of all (m/s).
    per_vehicle: Vec<(VecDeque<(SimTime, f64)>, f64)>,
    /// The last state of each vehicle kept as a path, once named in the events.
    named: Vec<Option<SimTime>>,
}

impl SentCommands {
    pub(super) fn new(n: usize) -> Self {
        Self {
            per_vehicle: vec![(VecDeque::new(), 0.0); n],
            named: vec![None; n],
        }
    }

    /// Vehicle `i` was sent a net horizontal acceleration `net_mps2` for `period_s`.
    fn record(&mut self, i: usize, now: SimTime, net_mps2: f64, period_s: f64) {
        let Some((sent, total)) = self.per_vehicle.get_mut(i) else {
            return;
        };
        sent.push_back((now, *total));
        if net_mps2.is_finite() {
            *total += net_mps2.abs() * period_s;
        }
        while sent
            .front()
            .is_some_and(|f| now.saturating_since(f.0).as_secs_f64() > KEEP_S)
        {
            sent.pop_front();
        }
    }

    /// What the commands sent to vehicle `i` from `from` on can add to its speed (m/s):
    /// each acted for its period.
    fn speed_margin_mps(&self, i: usize, from: SimTime) -> f64 {
        let Some((sent, total)) = self.per_vehicle.get(i) else {
            return 0.0;
        };
        let first = sent.partition_point(|s| s.0 < from);
        sent.get(first).map_or(0.0, |s| (total - s.1).max(0.0))
    }
}

impl Swarm {
    /// Records what the filter's answer sends to each vehicle it commands here.
    pub(super) fn record_sent(&mut self, now: SimTime, measured: usize) {
        let period_s = self.setup.control_interval.as_secs_f64();
        for i in 0..measured.min(self.slots.len()) {
            let a = &self.safety.agents[i];
            if !a.controlled || self.is_remote(VehicleIndex(i)) {
                continue;
            }
            let net = (self.safety.xy[i] - a.drift_mps2).norm();
            self.safety.sent.record(i, now, net, period_s);
        }
    }

    /// Each vehicle flown here that is in the air without a fresh state joins the filter
    /// as the chain of points of its stopping path: uncontrolled agents at rest, each
    /// with the spread of its stretch. Named in the events once per silence.
    pub(super) fn push_lost_vehicles(&mut self, now: SimTime) {
        for i in self.indices() {
            let Some(lost) = self.lost_vehicle(i, now) else {
                continue;
            };
            let Some(path) = lost.path() else {
                continue;
            };
            for (pos_m, spread_m) in path.points() {
                self.safety.agents.push(Agent {
                    side: Some(Side {
                        pos_m,
                        vel_mps: Vector3::zeros(),
                        accel_z_mps2: 0.0,
                    }),
                    controlled: false,
                    weight: 1.0,
                    drift_mps2: Vector2::zeros(),
                    limit_mps2: 0.0,
                    braking_mps2: 0.0,
                    lag_s: 0.0,
                    spread_m,
                });
                self.safety.xy.push(Vector2::zeros());
            }
            let last = self.state_time(i);
            if self.safety.sent.named.get(i.0).copied().flatten() != last {
                if let Some(named) = self.safety.sent.named.get_mut(i.0) {
                    *named = last;
                }
                self.log.push_vehicle(
                    now,
                    &self.setup.links[i],
                    true,
                    format!(
                        "no fresh state: the others keep clear of where it may be until its Hold stops it ({:.1} m along its last velocity, {:.2} m either side)",
                        path.length_m, path.radius_m
                    ),
                );
            }
        }
    }

    /// What is known of vehicle `i` when it is flown here, in the air (as last known),
    /// and without a fresh state: flying on our commands, handed to its own Hold, or
    /// silent. `None` otherwise (a vehicle landing, or flown by someone else, is not
    /// bounded).
    fn lost_vehicle(&self, i: VehicleIndex, now: SimTime) -> Option<LostVehicle> {
        let link = self.slots[i].link()?;
        if self.law.states[i].is_some() || link.state().landed {
            return None;
        }
        if !matches!(
            link.phase(),
            Phase::Flying | Phase::VehicleHold | Phase::Lost
        ) {
            return None;
        }
        let state = self.common_state(i)?;
        let last = link.state().last_position?;
        let braking_from = link.hold_confirmed_at().unwrap_or(now);
        let response_s = self.counted_response_s(i).min(KEEP_S);
        let since =
            SimTime::from_micros(last.as_micros().saturating_sub((response_s * 1e6) as u64));
        Some(LostVehicle {
            pos_m: state.pos_enu_m,
            vel_mps: state.vel_enu_mps.xy(),
            coast_s: braking_from.saturating_since(last).as_secs_f64() + HOLD_ONSET_S,
            speed_margin_mps: self.safety.sent.speed_margin_mps(i.0, since),
            braking_mps2: HOLD_BRAKING_MPS2,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(ms: u64) -> SimTime {
        SimTime::from_micros(ms * 1000)
    }

    #[test]
    fn the_speed_margin_sums_what_was_sent_from_then_on() {
        let mut sent = SentCommands::new(2);
        // 2 m/s² for 20 ms periods at 0, 20, 40 ms; 1 m/s² at 60 ms.
        for (t, a) in [(0, 2.0), (20, 2.0), (40, 2.0), (60, 1.0)] {
            sent.record(0, at(t), a, 0.02);
        }
        assert!((sent.speed_margin_mps(0, at(0)) - 0.14).abs() < 1e-12);
        assert!((sent.speed_margin_mps(0, at(30)) - 0.06).abs() < 1e-12);
        assert!((sent.speed_margin_mps(0, at(60)) - 0.02).abs() < 1e-12);
        assert_eq!(sent.speed_margin_mps(0, at(61)), 0.0);
        assert_eq!(sent.speed_margin_mps(1, at(0)), 0.0, "nothing sent");
        assert_eq!(sent.speed_margin_mps(5, at(0)), 0.0, "no such vehicle");
        // Old entries go; what they held stays out of the sum from a later time.
        sent.record(0, at(4000), 3.0, 0.02);
        assert!((sent.speed_margin_mps(0, at(3000)) - 0.06).abs() < 1e-12);
        // A number that is not finite adds nothing.
        sent.record(0, at(4020), f64::NAN, 0.02);
        assert!((sent.speed_margin_mps(0, at(3000)) - 0.06).abs() < 1e-12);
    }
}
