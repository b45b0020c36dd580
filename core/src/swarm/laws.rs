//! The horizontal law of each phase. Every phase that holds a velocity holds it with
//! velocity feedback, never by feed-forward alone (a vehicle whose drag or thrust is not
//! the model's would otherwise drift):
//!
//! - **Handshake:** each flying vehicle keeps the velocity it had when it was first seen
//!   flying: `u = K_KEEP·(v_keep − v)`; one that took off under the swarm (seen on the
//!   ground first) holds where it was first seen in the air, with the hold law below, so
//!   that it does not drift while the swarm waits for the others (ArduPilot's EKF keeps a
//!   vehicle on the ground for about 40 s after boot). A vehicle met in the air keeps its
//!   velocity, however slow.
//! - **Retargeting:** each re-targeted agent goes to its planned velocity
//!   (`RETARGET_K_V`), the others keep the velocity they had at the plan.
//! - **Consensus:** the ring law `u = −αL(p − d) − βLv`, plus, unless `k_vmean = 0`, a
//!   uniform PI correction `−k·e − (k²/2)·∫e`, `e = v̄_w − v_f`, `k = k_vmean`, that drives
//!   the w-weighted mean velocity
//!   `v̄_w = Σwᵢvᵢ / Σwᵢ` to the predicted final velocity `v_f`. The correction is the same
//!   for every vehicle, so it leaves the formation dynamics (`L·1 = 0`) untouched; for a
//!   vehicle that is the model, `v̄_w = v_f` already (the law keeps `w·v`) and it is zero.
//!   With model error (a wrong hover thrust, drag, PX4's own loops) it stops the drift
//!   the pure law cannot see. A documented deviation from the paper.
//! - **Holding, Stopped, Ended, Landing:** each vehicle brakes on its own and holds where it
//!   stopped: `u = −HOLD_K_V·v + HOLD_K_P·(p_hold − p)`.

use nalgebra::Vector2;
use ringswarm_wire::time::SimTime;

use super::{PlanDecision, Swarm, SwarmPhase};
use crate::consensus::ring_accelerations;
use crate::control::SaturationMode;

/// Braking law gains: velocity (1/s) and position (1/s²), about critically damped.
const HOLD_K_V: f64 = 2.5;
const HOLD_K_P: f64 = 1.5;
/// Below this speed (m/s) a braking vehicle takes its hold point.
const HOLD_CAPTURE_MPS: f64 = 1.0;
/// Stage 1 velocity gain (1/s): the re-targeted agent's acceleration per m/s of error.
const RETARGET_K_V: f64 = 2.0;
/// Velocity keeping gain (1/s) of the handshake and of the others during stage 1.
const KEEP_K_V: f64 = 1.0;
/// Largest acceleration the mean-velocity integral may add (m/s²).
pub const MEAN_INTEGRAL_LIMIT_MPS2: f64 = 1.0;

impl Swarm {
    /// The horizontal accelerations of this phase into `accel`; the saturation to use.
    pub(super) fn horizontal_law(&mut self, now: SimTime) -> SaturationMode {
        let dt_s = self.setup.control_interval.as_secs_f64();
        match self.phase {
            SwarmPhase::Consensus(_) => {
                ring_accelerations(
                    &self.setup.ring,
                    self.setup.gains,
                    &self.law.horizontal,
                    &mut self.law.accel,
                );
                if let Some(correction) = self.mean_velocity_correction(now, dt_s) {
                    self.law.accel.iter_mut().for_each(|a| *a += correction);
                }
                self.setup.saturation
            }
            SwarmPhase::Holding(_)
            | SwarmPhase::Ended(_)
            | SwarmPhase::Landing(_)
            | SwarmPhase::Stopped(_) => {
                for ((a, h), slot) in self
                    .law
                    .accel
                    .iter_mut()
                    .zip(&self.law.horizontal)
                    .zip(&mut self.slots)
                {
                    let hold = &mut slot.hold_point;
                    if hold.is_none() && h.vel_mps.norm() < HOLD_CAPTURE_MPS {
                        *hold = Some(h.pos_m);
                    }
                    *a = hold_acceleration(h.vel_mps, h.pos_m, *hold);
                }
                SaturationMode::Clip
            }
            SwarmPhase::Handshake => {
                for i in self.indices() {
                    let in_air = self.ours_in_air(i);
                    let slot = &mut self.slots[i];
                    let on_ground = slot.link().is_some_and(|l| l.state().landed);
                    if slot.keep_velocity.is_none() && on_ground {
                        slot.started_on_ground = true;
                    }
                    if slot.keep_velocity.is_none() && self.law.states[i].is_some() && in_air {
                        let h = self.law.horizontal[i];
                        slot.keep_velocity = Some(h.vel_mps);
                        if slot.started_on_ground {
                            slot.keep_point = Some(h.pos_m);
                        }
                    }
                }
                self.keep_velocities();
                for ((a, h), slot) in self
                    .law
                    .accel
                    .iter_mut()
                    .zip(&self.law.horizontal)
                    .zip(&self.slots)
                {
                    if slot.keep_point.is_some() {
                        *a = hold_acceleration(h.vel_mps, h.pos_m, slot.keep_point);
                    }
                }
                self.setup.saturation
            }
            SwarmPhase::Retargeting(_) => {
                self.keep_velocities();
                if let Some(PlanDecision::Planned { retarget, .. }) = &self.plan {
                    for &(agent, v) in retarget {
                        self.law.accel[agent] =
                            RETARGET_K_V * (v - self.law.horizontal[agent].vel_mps);
                    }
                }
                SaturationMode::Clip
            }
        }
    }

    /// `u = K_KEEP·(v_keep − v)` for every vehicle with a velocity to keep, zero for the
    /// others.
    fn keep_velocities(&mut self) {
        for ((a, h), slot) in self
            .law
            .accel
            .iter_mut()
            .zip(&self.law.horizontal)
            .zip(&self.slots)
        {
            *a = keep_acceleration(h.vel_mps, slot.keep_velocity);
        }
    }

    /// The w-weighted mean velocity `Σwᵢvᵢ / Σwᵢ` of the states flown on this tick (m/s,
    /// ENU); `None` when the weights sum to zero.
    pub(super) fn weighted_mean_velocity(&self) -> Option<Vector2<f64>> {
        if self.peers.is_some() {
            return self.shard_mean_velocity();
        }
        let total: f64 = self.law.w.iter().sum();
        if total.abs() < 1e-12 {
            return None;
        }
        let sum = self
            .law
            .w
            .iter()
            .zip(&self.law.horizontal)
            .map(|(w, h)| *w * h.vel_mps)
            .sum::<Vector2<f64>>();
        Some(sum / total)
    }

    /// The uniform correction of the w-weighted mean velocity, if it is on: a PI loop on
    /// `e = v̄_w − v_f`, `−k·e − (k²/2)·∫e` (damping 0.707), the integral kept within
    /// [`MEAN_INTEGRAL_LIMIT_MPS2`] and reset when consensus (re)starts.
    fn mean_velocity_correction(&mut self, now: SimTime, dt_s: f64) -> Option<Vector2<f64>> {
        let k = self.setup.mean_velocity_gain;
        let target = self.predicted_final_velocity?;
        if k == 0.0 {
            return None;
        }
        let mean = self.weighted_mean_velocity()?;
        let error = mean - target;
        let k_i = 0.5 * k * k;
        let limit = MEAN_INTEGRAL_LIMIT_MPS2 / k_i;
        self.mean_velocity_integral = match self.shard_mean_integral(now) {
            // With shards, the state the sum integrates to (shard.rs); held within the
            // same limit.
            Some(integral) => integral.map(|x| x.clamp(-limit, limit)),
            None if self.peers.is_some() => Vector2::zeros(),
            None => (self.mean_velocity_integral + error * dt_s).map(|x| x.clamp(-limit, limit)),
        };
        Some(-k * error - k_i * self.mean_velocity_integral)
    }
}

/// The braking and holding law: `u = −HOLD_K_V·v + HOLD_K_P·(p_hold − p)` (m/s², ENU),
/// the position term only once a hold point is taken.
pub(super) fn hold_acceleration(
    vel_mps: Vector2<f64>,
    pos_m: Vector2<f64>,
    hold_point: Option<Vector2<f64>>,
) -> Vector2<f64> {
    -HOLD_K_V * vel_mps + hold_point.map_or(Vector2::zeros(), |p| HOLD_K_P * (p - pos_m))
}

/// Velocity keeping: `u = K_KEEP·(v_keep − v)`, zero without a velocity to keep.
pub(super) fn keep_acceleration(vel_mps: Vector2<f64>, keep: Option<Vector2<f64>>) -> Vector2<f64> {
    keep.map_or(Vector2::zeros(), |v| KEEP_K_V * (v - vel_mps))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_braking_vehicle_without_a_hold_point_only_damps_its_velocity() {
        let u = hold_acceleration(Vector2::new(2.0, -1.0), Vector2::new(5.0, 5.0), None);
        assert_eq!(u, Vector2::new(-2.0 * HOLD_K_V, HOLD_K_V));
    }

    #[test]
    fn a_holding_vehicle_is_pulled_back_to_its_point() {
        // At rest 2 m east and 1 m south of its point: pulled west and north.
        let u = hold_acceleration(
            Vector2::zeros(),
            Vector2::new(2.0, -1.0),
            Some(Vector2::zeros()),
        );
        assert_eq!(u, Vector2::new(-2.0 * HOLD_K_P, HOLD_K_P));
        // About critically damped: K_V² ≈ 4·K_P.
        assert!((HOLD_K_V * HOLD_K_V / (4.0 * HOLD_K_P) - 1.0).abs() < 0.05);
    }

    #[test]
    fn velocity_keeping_pushes_towards_the_kept_velocity() {
        let u = keep_acceleration(Vector2::new(1.0, 1.0), Some(Vector2::new(3.0, 0.5)));
        assert_eq!(u, KEEP_K_V * Vector2::new(2.0, -0.5));
        assert_eq!(
            keep_acceleration(Vector2::new(1.0, 1.0), None),
            Vector2::zeros()
        );
    }
}
