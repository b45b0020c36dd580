//! One control tick, as named stages in order:
//!
//! ```text
//!  gather_states ─► (horizon, phase transition, shard prediction) ─► observe_models
//!  ─► fill_law_inputs ─► (divergence guard, fence) ─► horizontal_law (laws.rs)
//!  ─► compose_commands (altitude loop, drag, disturbance) ─► isolate_non_finite
//!  ─► saturate ─► filter_for_safety (safety.rs) ─► isolate_non_finite
//!  ─► integrate_altitude ─► stream_setpoints ─► publish (shards)
//! ```
//!
//! Each stage reads what the ones before wrote into the law's arrays; the per-vehicle
//! arithmetic is in pure functions ([`compose_command`], [`command_to_fly`]).

use nalgebra::Vector3;
use ringswarm_wire::time::SimTime;

use super::VehicleIndex;
use super::model::HorizontalDrive;
use super::slot::{Member, VehicleSlot};
use super::{Swarm, SwarmPhase};
use crate::consensus::HorizontalState;
use crate::control::{
    attitude_thrust_from_acceleration, enu_to_ned, saturate_with, thrust_direction_enu, tilt_cos,
};
use crate::swarm::SetpointKind;
use crate::vehicle::{Phase, Setpoint};

impl Swarm {
    /// One control tick. The law and the saturation allocate nothing in consensus (every
    /// buffer was sized at construction); each link encodes its setpoint into a new frame.
    ///
    /// Only fresh states are flown on. A vehicle whose command comes out non-finite is
    /// isolated before the swarm-wide saturation sees it: its command becomes level at
    /// its hover thrust and it is handed to its own Hold; the swarm applies its loss
    /// policy on the next tick.
    pub(super) fn control(&mut self, now: SimTime) {
        self.control_ticks += 1;
        self.gather_states(now);
        self.update_horizon(now);
        self.transition(now);
        self.land_when_clear(now);
        self.shard_prediction(now);
        self.assign_places_in_shards(now);
        self.observe_models(now);
        self.fill_law_inputs();
        self.watch_divergence(now);
        self.watch_fence(now);
        let saturation = self.horizontal_law(now);
        self.compose_commands();
        self.isolate_non_finite(now, "the law's command");
        self.law.law_commands.copy_from_slice(&self.law.commands);
        self.break_jams(now);
        self.saturate(saturation);
        // On the saturated commands, inside the same envelope: the saturation after it
        // would change nothing.
        self.filter_for_safety(now);
        self.isolate_non_finite(now, "the saturated command");
        self.integrate_altitude();
        self.stream_setpoints(now);
        self.publish(now);
        // The links' events are drained by `handle_timeout` right after.
    }

    /// Each vehicle's state in the common frame, `None` unless fresh: its link's, or
    /// its shard's report carried to `now`. The ages flown on are timed.
    fn gather_states(&mut self, now: SimTime) {
        for i in self.indices() {
            let Some(link) = self.slots[i].link() else {
                self.law.states[i] = self.remote_fresh_state(i, now);
                if self.law.states[i].is_some()
                    && let Some(at) = self.remote_measured(i)
                {
                    self.timing.remote_state_age(at, now);
                }
                continue;
            };
            if link.phase() == Phase::Flying
                && let Some(at) = link.state().last_position
            {
                self.timing.state_age(at, now);
            }
            self.law.states[i] = if link.state_fresh(now) {
                self.common_state(i)
            } else {
                None
            };
        }
    }

    /// The horizontal law's inputs: each state's x/y (zero when unknown) and offset.
    fn fill_law_inputs(&mut self) {
        for (i, state) in self.law.states.iter().enumerate() {
            let s = state.unwrap_or_default();
            self.law.horizontal[i] = HorizontalState {
                pos_m: s.pos_enu_m.xy(),
                vel_mps: s.vel_enu_mps.xy(),
                offset_m: self.slots[i].place_m,
            };
        }
    }

    /// Each vehicle's command from the horizontal law's output, its altitude loop, the
    /// drag fed forward and the disturbance estimate.
    fn compose_commands(&mut self) {
        for (i, state) in self.law.states.iter().enumerate() {
            let s = state.unwrap_or_default();
            let altitude_m = self.altitude_target_m(i);
            let slot = &mut self.slots[i];
            let u_z = self.setup.altitude_gains.acceleration_with(
                s.pos_enu_m.z,
                s.vel_enu_mps.z,
                altitude_m,
                slot.altitude_integral,
            );
            slot.u_z = u_z;
            self.law.commands[i] = compose_command(
                self.law.accel[i],
                u_z,
                s.vel_enu_mps,
                slot.flown.drag_fed_forward_per_s(),
                slot.flown.disturbance_mps2(),
            );
        }
    }

    /// The swarm-wide saturation (`conserve` keeps `Σ wᵢuᵢ`; in a shard, over the
    /// commands it computes), counted on consensus ticks.
    fn saturate(&mut self, saturation: crate::control::SaturationMode) {
        if self.peers.is_some() {
            // A vehicle whose command cannot be computed here (its state or a neighbour's
            // is not read) has none to saturate with.
            for i in self.indices() {
                if !self.computable_now(i) {
                    self.law.commands[i] = Vector3::zeros();
                }
            }
        }
        let weights = self
            .peers
            .as_ref()
            .map_or(&self.law.w, |p| &p.saturation_weights);
        if let Ok(summary) = saturate_with(
            saturation,
            &self.setup.envelope,
            &self.law.flown_models,
            weights,
            &mut self.law.commands,
            &mut self.law.boxes,
        ) && matches!(self.phase, SwarmPhase::Consensus(_))
        {
            self.consensus_ticks += 1;
            self.saturated_ticks +=
                u64::from(summary.horizontal_limited + summary.vertical_limited > 0);
        }
    }

    /// Each link flown here gets its setpoint (level at hover thrust without a usable
    /// state, never a motor cut), and its flown model what was commanded.
    fn stream_setpoints(&mut self, now: SimTime) {
        for i in self.indices() {
            let VehicleSlot {
                member: Member::Local(link),
                flown,
                isolated,
                ..
            } = &mut self.slots[i]
            else {
                continue;
            };
            let isolated = *isolated;
            let state_known = self.law.states[i].is_some();
            let command = command_to_fly(self.law.commands[i], state_known, isolated);
            let sp = attitude_thrust_from_acceleration(command, 0.0, &self.law.flown_models[i]);
            self.law.setpoints[i] = sp;
            let usable = self.setup.setpoint == SetpointKind::Attitude
                && link.phase() == Phase::Flying
                && !link.state().landed
                && !isolated
                && state_known;
            flown.attitude_tick(
                now.as_secs_f64(),
                &sp.attitude_ned_frd,
                link.state().attitude,
                usable,
            );
            if state_known || link.phase() == Phase::Flying {
                match self.setup.setpoint {
                    SetpointKind::Attitude => link.set_setpoint(now, sp),
                    SetpointKind::Acceleration => {
                        link.set_setpoint(now, Setpoint::Acceleration(enu_to_ned(command)))
                    }
                }
            }
            if link.phase() == Phase::Flying
                && let Some(q) = link.state().attitude
            {
                // The thrust along the reported tilt: the vehicle's attitude may lag the
                // command, its motors hardly. An acceleration setpoint is the vehicle's
                // own to turn into thrust: only its tilt is known.
                let direction = thrust_direction_enu(&q);
                let horizontal = match self.setup.setpoint {
                    SetpointKind::Attitude => {
                        let specific =
                            sp.thrust_norm * self.law.flown_models[i].max_specific_thrust_mps2();
                        HorizontalDrive::Acceleration(specific * direction.xy())
                    }
                    SetpointKind::Acceleration => {
                        HorizontalDrive::TiltPerVertical(direction.xy() / direction.z.max(0.1))
                    }
                };
                flown.commanded(sp.thrust_norm * tilt_cos(&q), horizontal);
            }
        }
    }

    /// Whether vehicle `i` flies on our commands in the air now.
    pub(super) fn ours_in_air(&self, i: VehicleIndex) -> bool {
        let Some(link) = self.slots[i].link() else {
            return false;
        };
        link.phase() == Phase::Flying && !link.state().landed && !self.slots[i].isolated
    }

    /// Feeds each vehicle's hover thrust estimator with its latest report and takes the
    /// model to fly this tick.
    fn observe_models(&mut self, now: SimTime) {
        for i in self.indices() {
            if self.is_remote(i) {
                continue;
            }
            let ours = self.ours_in_air(i);
            let trusted = self.slots[i].flown.trusted();
            let drag_trusted = self.slots[i].flown.drag_trusted();
            let position_at = self.slots[i].link().and_then(|l| l.state().last_position);
            if let (Some(s), Some(at)) = (self.law.states[i], position_at) {
                self.slots[i].flown.observe(at, s.vel_enu_mps, ours);
            }
            if !drag_trusted && self.slots[i].flown.drag_trusted() {
                let (drag, std) = self.slots[i].flown.drag_estimate();
                self.log.push_vehicle(
                    now,
                    &self.setup.links[i],
                    true,
                    format!(
                        "drag estimated at {drag:.3} ± {std:.3} 1/s, not the configured {:.3}: flying the estimate",
                        self.setup.drag_per_s[i]
                    ),
                );
            }
            if !trusted && self.slots[i].flown.trusted() {
                let (hover, std) = self.slots[i].flown.hover_estimate();
                self.log.push_vehicle(
                    now,
                    &self.setup.links[i],
                    true,
                    format!(
                        "hover thrust estimated at {hover:.3} ± {std:.3}, not the {:.3} it started from: flying the estimate",
                        self.slots[i].flown.start_hover()
                    ),
                );
            }
            self.law.flown_models[i] = self.slots[i].flown.model();
        }
    }

    /// The altitude integrals, for the vehicles flown on our commands in the air (not
    /// while landing), frozen while a vertical command is saturated.
    fn integrate_altitude(&mut self) {
        if matches!(self.phase, SwarmPhase::Landing(_)) {
            return;
        }
        let dt = self.setup.control_interval.as_secs_f64();
        for i in self.indices() {
            let Some(s) = self.law.states[i] else {
                continue;
            };
            if !self.ours_in_air(i) {
                continue;
            }
            let drag = self.slots[i].flown.drag_fed_forward_per_s();
            let saturated =
                (self.law.commands[i].z - self.slots[i].u_z - s.vel_enu_mps.z * drag).abs() > 1e-9;
            self.slots[i].altitude_integral = self.setup.altitude_gains.integrate(
                self.slots[i].altitude_integral,
                s.pos_enu_m.z,
                self.altitude_target_m(i.0),
                dt,
                saturated,
            );
        }
    }

    /// Isolates every vehicle whose command is not finite: zero acceleration (level at
    /// hover thrust) and its own Hold, for good.
    fn isolate_non_finite(&mut self, now: SimTime, what: &str) {
        for i in self.indices() {
            if self.law.commands[i].iter().all(|x| x.is_finite()) {
                continue;
            }
            self.law.commands[i] = Vector3::zeros();
            if !self.slots[i].isolated && !self.is_remote(i) {
                self.slots[i].isolated = true;
                let reason = format!("{what} is not a finite number: isolated");
                self.log
                    .push_vehicle(now, &self.setup.links[i], true, reason.clone());
                if let Some(link) = self.slots[i].link_mut() {
                    link.hold_on_own(now, &reason);
                }
            }
        }
    }
}

/// A vehicle's command (m/s², ENU, z up): the horizontal law's `accel` less the
/// disturbance estimate `disturbance`, the altitude loop's `u_z`, plus the drag fed
/// forward (`drag_per_s` times the velocity, on every axis).
pub(super) fn compose_command(
    accel: nalgebra::Vector2<f64>,
    u_z: f64,
    vel_enu_mps: Vector3<f64>,
    drag_per_s: f64,
    disturbance: nalgebra::Vector2<f64>,
) -> Vector3<f64> {
    Vector3::new(accel.x - disturbance.x, accel.y - disturbance.y, u_z) + vel_enu_mps * drag_per_s
}

/// What a vehicle is flown on: its command, or none (level at hover thrust) when its
/// state is unknown or it is isolated.
pub(super) fn command_to_fly(
    command: Vector3<f64>,
    state_known: bool,
    isolated: bool,
) -> Vector3<f64> {
    if state_known && !isolated {
        command
    } else {
        Vector3::zeros()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector2;

    #[test]
    fn a_command_is_the_law_less_the_disturbance_with_the_drag_fed_forward() {
        // accel (1, −2), disturbance (0.5, 0.25), u_z 0.3, v (2, 4, −1) at 0.1 1/s:
        // x 1 − 0.5 + 0.2 = 0.7; y −2 − 0.25 + 0.4 = −1.85; z 0.3 − 0.1 = 0.2.
        let u = compose_command(
            Vector2::new(1.0, -2.0),
            0.3,
            Vector3::new(2.0, 4.0, -1.0),
            0.1,
            Vector2::new(0.5, 0.25),
        );
        assert!((u - Vector3::new(0.7, -1.85, 0.2)).norm() < 1e-15, "{u}");
    }

    #[test]
    fn without_a_state_or_once_isolated_the_vehicle_flies_level() {
        let u = Vector3::new(1.0, 2.0, 3.0);
        assert_eq!(command_to_fly(u, true, false), u);
        assert_eq!(command_to_fly(u, false, false), Vector3::zeros());
        assert_eq!(command_to_fly(u, true, true), Vector3::zeros());
    }
}
