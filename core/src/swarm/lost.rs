//! A vehicle whose state stopped arriving, kept in the safety filter as its stopping path
//! ([`crate::safety::lost`]): which vehicles, what is known of each, and what was sent to
//! them before.

use std::collections::VecDeque;
use std::time::Duration;

use nalgebra::Vector2;
use ringswarm_wire::time::SimTime;

use super::{Swarm, VehicleIndex};
use crate::link::Autopilot;
use crate::safety::Agent;
use crate::safety::lost::{HOLD_BRAKING_MPS2, HOLD_ONSET_S, LostVehicle, StoppingPath};
use crate::vehicle::Phase;

/// How long what was sent to a vehicle is kept (s): longer than the longest response
/// counted (a second) and a state timeout.
const KEEP_S: f64 = 3.0;

/// What was sent to each vehicle the filter commanded: each tick's net horizontal
/// acceleration times the period it held for (m/s, ENU), with when it was sent.
#[derive(Debug, Clone, Default)]
pub(super) struct SentCommands {
    per_vehicle: Vec<VecDeque<(SimTime, Vector2<f64>)>>,
    /// The last state of each vehicle kept as a path, once named in the events.
    named: Vec<Option<SimTime>>,
    /// For a vehicle another shard flies: when the first report that its shard had
    /// handed it to its Hold (or lost it) was sent, while it is quiet.
    handed_over: Vec<Option<SimTime>>,
    /// Each vehicle's stopping path as the filter kept clear of it on the last tick.
    paths: Vec<Option<StoppingPath>>,
}

impl SentCommands {
    pub(super) fn new(n: usize) -> Self {
        Self {
            per_vehicle: vec![VecDeque::new(); n],
            named: vec![None; n],
            handed_over: vec![None; n],
            paths: vec![None; n],
        }
    }

    /// Vehicle `i` was sent a net horizontal acceleration `net_mps2` for `period_s`.
    fn record(&mut self, i: usize, now: SimTime, net_mps2: Vector2<f64>, period_s: f64) {
        let Some(sent) = self.per_vehicle.get_mut(i) else {
            return;
        };
        let dv = if net_mps2.iter().all(|x| x.is_finite()) {
            net_mps2 * period_s
        } else {
            Vector2::zeros()
        };
        sent.push_back((now, dv));
        while sent
            .front()
            .is_some_and(|f| now.saturating_since(f.0).as_secs_f64() > KEEP_S)
        {
            sent.pop_front();
        }
    }

    /// What the last net acceleration sent to vehicle `i` can add to its speed if it
    /// is flown until `held_until` (m/s): its size times the time from when it was sent,
    /// less the period it is already counted for. (Through the vehicle's attitude lag a
    /// command adds, in all, its size times how long it is the input: the lag delays
    /// that, it adds nothing.) Nothing when none was sent.
    fn held_margin_mps(&self, i: usize, period_s: f64, held_until: SimTime) -> f64 {
        let Some((sent_at, dv)) = self.per_vehicle.get(i).and_then(|sent| sent.back()) else {
            return 0.0;
        };
        if period_s <= 0.0 {
            return 0.0;
        }
        let held_s = held_until.saturating_since(*sent_at).as_secs_f64();
        dv.norm() / period_s * (held_s - period_s).max(0.0)
    }

    /// What the commands sent to vehicle `i` can still add to its speed from its last
    /// state at `last` on (m/s), its acceleration following them after a delay
    /// `delay_s` through a first-order lag `lag_s`: a command sent after `last − delay`
    /// acts wholly after `last`, an older one by `e^(−(last − delay − t)/lag)` of it.
    /// The first are summed as vectors (their sum is what they add), the others by size.
    fn speed_margin_mps(&self, i: usize, last: SimTime, delay_s: f64, lag_s: f64) -> f64 {
        let Some(sent) = self.per_vehicle.get(i) else {
            return 0.0;
        };
        let delay_us = (delay_s.clamp(0.0, KEEP_S) * 1e6) as u64;
        let cut = SimTime::from_micros(last.as_micros().saturating_sub(delay_us));
        let (mut whole, mut tail) = (Vector2::zeros(), 0.0);
        for (t, dv) in sent {
            if *t >= cut {
                whole += dv;
            } else if lag_s > 0.0 {
                tail += dv.norm() * (-cut.saturating_since(*t).as_secs_f64() / lag_s).exp();
            }
        }
        whole.norm() + tail
    }
}

impl Swarm {
    /// Records what the filter's answer sends to each vehicle it commands here.
    pub(super) fn record_sent(&mut self, now: SimTime, measured: usize) {
        let period_s = self.setup.control_interval.as_secs_f64();
        for i in 0..measured.min(self.slots.len()) {
            let a = &self.safety.agents[i];
            // A remote vehicle's answer here is what its own shard's filter answers too
            // while the two cooperate (`Swarm::cooperating_remote`).
            if !a.controlled {
                continue;
            }
            let net = self.safety.xy[i] - a.drift_mps2;
            self.safety.sent.record(i, now, net, period_s);
        }
    }

    /// Each vehicle flown here that is in the air without a fresh state joins the filter
    /// as the chain of points of its stopping path: uncontrolled agents at rest, each
    /// with the spread of its stretch. Named in the events once per silence.
    pub(super) fn push_lost_vehicles(&mut self, now: SimTime) {
        for i in self.indices() {
            if let Some(kept) = self.safety.sent.paths.get_mut(i.0) {
                *kept = None;
            }
            let Some(lost) = self.lost_vehicle(i, now) else {
                continue;
            };
            let Some(path) = lost.path() else {
                continue;
            };
            if let Some(kept) = self.safety.sent.paths.get_mut(i.0) {
                *kept = Some(path);
            }
            for (pos_m, spread_m) in path.points() {
                self.safety.agents.push(Agent::bound(pos_m, spread_m));
                self.safety.xy.push(Vector2::zeros());
            }
            let last = self.state_time(i);
            if self.safety.sent.named.get(i.0).copied().flatten() != last {
                if let Some(named) = self.safety.sent.named.get_mut(i.0) {
                    *named = last;
                }
                self.safety.stats.quiet_paths += 1;
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

    /// Vehicle `i`'s stopping path as the filter kept the others clear of it on the last
    /// tick (`None`: it had a fresh state, or nothing bounds where it is).
    pub fn stopping_path(&self, i: VehicleIndex) -> Option<StoppingPath> {
        self.safety.sent.paths.get(i.0).copied().flatten()
    }

    /// What is known of vehicle `i` when it is in the air (as last known) without a fresh
    /// state: flying on our commands, handed to its own Hold, or silent; flown here or,
    /// as its shard reports it, by another shard. `None` otherwise (a vehicle landing,
    /// or flown by someone else, is not bounded).
    fn lost_vehicle(&mut self, i: VehicleIndex, now: SimTime) -> Option<LostVehicle> {
        if self.is_remote(i) {
            return self.lost_remote(i, now);
        }
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
        let dialect = link.state().dialect();
        let held_s = link.setpoint_held_s();
        let (delay_s, lag_s) = self.counted_delay_and_lag_s(i);
        // If its uplink is down too, an ArduCopter flies the last target that reached it
        // until GUID_TIMEOUT after it arrived (3 s, and nothing brakes it after); a
        // confirmed BRAKE ends it sooner (the uplink works, and the vehicle left GUIDED).
        // Later level setpoints may not have reached it. (PX4 holds its last setpoint for
        // COM_OF_LOSS_T, 1 s, then brakes in its failsafe: not counted here, see
        // docs/dense.md.)
        let period_s = self.setup.control_interval.as_secs_f64();
        // When an ArduCopter's GUID_TIMEOUT runs out after its last setpoint arrived.
        let levels_at = link
            .last_setpoint_sent()
            .filter(|_| dialect.levels_after_setpoint_loss())
            .map(|sent| sent + Duration::from_secs_f64(held_s + delay_s));
        let held_mps = levels_at
            .map(|t| link.hold_confirmed_at().map_or(t, |c| c.min(t)))
            .map_or(0.0, |until| {
                self.safety.sent.held_margin_mps(i.0, period_s, until)
            });
        let speed_margin_mps =
            self.safety.sent.speed_margin_mps(i.0, last, delay_s, lag_s) + held_mps;
        let since_last = |t: SimTime| t.saturating_since(last).as_secs_f64() + HOLD_ONSET_S;
        // It brakes once its Hold is confirmed, or its own failsafe took over after the
        // last setpoint; until either, it may still coast (a bound that grows with now).
        let failsafe = dialect
            .setpoint_loss_brakes_after_s()
            .zip(link.last_setpoint_sent())
            .map(|(after_s, sent)| sent + Duration::from_secs_f64(after_s + delay_s));
        let braking_from = [link.hold_confirmed_at(), failsafe]
            .into_iter()
            .flatten()
            .min()
            .unwrap_or(now);
        let braked = LostVehicle {
            pos_m: state.pos_enu_m,
            vel_mps: state.vel_enu_mps.xy(),
            coast_s: since_last(braking_from),
            speed_margin_mps,
            braking_mps2: HOLD_BRAKING_MPS2,
        };
        // An ArduPilot vehicle levels once its setpoints stopped for GUID_TIMEOUT and
        // then drifts, slowed by its drag alone: from speed V at rate k it goes V/k
        // further, what braking at V·k/2 gives.
        let drift_drag_per_s = self.slots[i].flown.drift_drag_per_s();
        let drifted = levels_at
            .filter(|_| drift_drag_per_s > 0.0)
            .map(|levels_at| {
                let top_mps = state.vel_enu_mps.xy().norm() + speed_margin_mps;
                LostVehicle {
                    coast_s: since_last(levels_at),
                    braking_mps2: top_mps * drift_drag_per_s / 2.0,
                    ..braked
                }
            });
        // Both bound where it may be: the shorter is kept.
        let length = |v: &LostVehicle| v.path().map_or(f64::INFINITY, |p| p.length_m);
        Some(match drifted {
            Some(d) if length(&d) < length(&braked) => d,
            _ => braked,
        })
    }

    /// [`Self::lost_vehicle`] for a vehicle another shard flies, from its shard's last
    /// report: its last state, once its shard reports it lost (handed to its own Hold,
    /// or silent). Its shard handed it over no later than the first report that says so
    /// was sent (its last setpoint went before that); whether the Hold was confirmed is
    /// not reported, so only its autopilot's own failsafe (when the file names the
    /// autopilot) bounds the coasting. What it was sent is what this shard's filter
    /// answered for it while it cooperated.
    fn lost_remote(&mut self, i: VehicleIndex, now: SimTime) -> Option<LostVehicle> {
        let r = self.slots[i].remote()?;
        let (phase, landed, measured, sent, state) =
            (r.phase, r.landed, r.measured, r.sent, r.state);
        // Reported flying, a remote vehicle without a fresh state is one whose shard went
        // silent: it may fly on with its shard (a partition), and nothing bounds where;
        // the swarm holds for a silent shard.
        let quiet = self.law.states[i].is_none()
            && !landed
            && matches!(phase, Phase::VehicleHold | Phase::Lost);
        let handed = self.safety.sent.handed_over.get_mut(i.0)?;
        if !quiet {
            *handed = None;
            return None;
        }
        let handed = *handed.get_or_insert(sent);
        let autopilot = match self.setup.links[i].autopilot {
            crate::link::AutopilotChoice::Only(a) => Some(a),
            crate::link::AutopilotChoice::Auto => None,
        };
        let (delay_s, lag_s) = self.counted_delay_and_lag_s(i);
        let failsafe = autopilot
            .and_then(|a| a.setpoint_loss_brakes_after_s())
            .map(|after_s| handed + Duration::from_secs_f64(after_s + delay_s));
        // An ArduCopter (or an autopilot not named) may fly its last target until
        // GUID_TIMEOUT (the default here: its own shard read the vehicle's).
        let held_mps = if autopilot.is_none_or(Autopilot::levels_after_setpoint_loss) {
            let held_s = Autopilot::ArduPilot.setpoint_held_s(|_| None);
            let until = handed + Duration::from_secs_f64(held_s + delay_s);
            let period_s = self.setup.control_interval.as_secs_f64();
            self.safety.sent.held_margin_mps(i.0, period_s, until)
        } else {
            0.0
        };
        Some(LostVehicle {
            pos_m: state.pos_enu_m,
            vel_mps: state.vel_enu_mps.xy(),
            coast_s: failsafe
                .unwrap_or(now)
                .saturating_since(measured)
                .as_secs_f64()
                + HOLD_ONSET_S,
            speed_margin_mps: self
                .safety
                .sent
                .speed_margin_mps(i.0, measured, delay_s, lag_s)
                + held_mps,
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
    fn the_speed_margin_sums_what_still_acts_after_the_last_state() {
        let mut sent = SentCommands::new(2);
        let east = Vector2::new(1.0, 0.0);
        // 2 m/s² east for 20 ms periods at 0, 20 and 40 ms; 1 m/s² west at 60 ms.
        for (t, a) in [(0, 2.0), (20, 2.0), (40, 2.0), (60, -1.0)] {
            sent.record(0, at(t), east * a, 0.02);
        }
        // No delay, no lag: what was sent from the last state on, as one vector:
        // 3·0.04 − 0.02 = 0.10 from 0 ms, 0.04 − 0.02 = 0.02 from 30 ms.
        assert!((sent.speed_margin_mps(0, at(0), 0.0, 0.0) - 0.10).abs() < 1e-12);
        assert!((sent.speed_margin_mps(0, at(30), 0.0, 0.0) - 0.02).abs() < 1e-12);
        assert_eq!(sent.speed_margin_mps(0, at(61), 0.0, 0.0), 0.0);
        // A 30 ms delay reaches back to the commands of 20 ms and later (0.06 in all).
        assert!((sent.speed_margin_mps(0, at(50), 0.03, 0.0) - 0.06).abs() < 1e-12);
        // A 0.1 s lag adds what is left of older ones: at 50 ms with no delay, the 0, 20
        // and 40 ms commands by e^(−0.5), e^(−0.3) and e^(−0.1), after the vector of
        // 60 ms (0.02).
        let left: f64 = [-0.5f64, -0.3, -0.1].iter().map(|x| x.exp()).sum();
        let expected = 0.02 + 0.04 * left;
        let got = sent.speed_margin_mps(0, at(50), 0.0, 0.1);
        assert!((got - expected).abs() < 1e-12, "{got} vs {expected}");
        assert_eq!(
            sent.speed_margin_mps(1, at(0), 0.0, 0.0),
            0.0,
            "nothing sent"
        );
        assert_eq!(
            sent.speed_margin_mps(5, at(0), 0.0, 0.0),
            0.0,
            "no such vehicle"
        );
        // Old entries go; a number that is not finite adds nothing.
        sent.record(0, at(4000), east * 3.0, 0.02);
        sent.record(0, at(4020), Vector2::new(f64::NAN, 0.0), 0.02);
        assert!((sent.speed_margin_mps(0, at(0), 0.0, 0.0) - 0.06).abs() < 1e-12);
    }

    #[test]
    fn the_last_command_held_adds_its_size_for_as_long_as_it_may_be_flown_beyond_its_period() {
        let mut sent = SentCommands::new(2);
        // 1 m/s² north at 0 ms, then 3 m/s² along (0.6, 0.8) at 20 ms, 20 ms periods.
        sent.record(0, at(0), Vector2::new(0.0, 1.0), 0.02);
        sent.record(0, at(20), Vector2::new(1.8, 2.4), 0.02);
        // Flown until 3.02 s (ArduPilot's GUID_TIMEOUT after it): 3 m/s² for 3 s less
        // the 20 ms already counted, 8.94 m/s.
        let held = sent.held_margin_mps(0, 0.02, at(3020));
        assert!((held - 8.94).abs() < 1e-9, "{held}");
        // Until its own period's end: nothing beyond what is counted.
        assert_eq!(sent.held_margin_mps(0, 0.02, at(40)), 0.0);
        // Ended before it was sent (a Hold confirmed earlier): nothing.
        assert_eq!(sent.held_margin_mps(0, 0.02, at(10)), 0.0);
        assert_eq!(sent.held_margin_mps(1, 0.02, at(3000)), 0.0, "nothing sent");
    }
}
