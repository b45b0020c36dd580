//! The emulated flight controller, shaped like PX4's multicopter stack:
//!
//! ```text
//! attitude setpoint (q, thrust) ──► attitude P ──► rate setpoint ──► rate PID ──► torques ──► mixer ──► motors
//!          ▲                              ▲
//!   offboard (SET_ATTITUDE_TARGET) or     offboard body rates
//!   the position controller (every other mode, `position_control`)
//! ```
//!
//! The attitude error is taken in the body frame, `q_e = q⁻¹·q_sp`, and the rate setpoint
//! is `2·K_att·sign(w_e)·vec(q_e)`, clamped to the profile's largest rates. The rate loop
//! gives an angular acceleration `K_p·e + K_i·∫e − K_d·ω̇`, turned into torque through the
//! inertia (plus the gyroscopic term). A yaw-rate feed-forward is added along the world's
//! vertical expressed in the body frame, as PX4's attitude controller does. Pure and
//! deterministic.

use nalgebra::{UnitQuaternion, Vector3, Vector4};

use crate::physics::{Airframe, BodyState};

/// An attitude and normalised thrust to track.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AttitudeSetpoint {
    /// Rotation from body FRD to NED.
    pub attitude: UnitQuaternion<f64>,
    /// Collective thrust, `0..1` of full thrust.
    pub thrust_norm: f64,
}

impl AttitudeSetpoint {
    /// Level at `yaw_rad` with zero thrust.
    pub fn idle(yaw_rad: f64) -> Self {
        Self {
            attitude: UnitQuaternion::from_euler_angles(0.0, 0.0, yaw_rad),
            thrust_norm: 0.0,
        }
    }
}

/// The attitude and rate controllers, with their integrator state.
#[derive(Debug, Clone, Default)]
pub struct AttitudeController {
    rate_integral: Vector3<f64>,
    last_rate: Option<Vector3<f64>>,
}

impl AttitudeController {
    /// Clears the integrator (on arming, disarming and on the ground).
    pub fn reset(&mut self) {
        self.rate_integral = Vector3::zeros();
        self.last_rate = None;
    }

    /// Motor thrust commands (N) that track `setpoint` from `state`, for a step of `dt_s`.
    pub fn update(
        &mut self,
        frame: &Airframe,
        state: &BodyState,
        setpoint: &AttitudeSetpoint,
        dt_s: f64,
    ) -> Vector4<f64> {
        let command = AttitudeCommand::Attitude {
            setpoint: *setpoint,
            yawspeed_ff_rps: 0.0,
        };
        self.update_command(frame, state, &command, dt_s)
    }

    /// Motor thrust commands (N) for an attitude (with a yaw-rate feed-forward) or a body
    /// rate command, for a step of `dt_s`.
    pub fn update_command(
        &mut self,
        frame: &Airframe,
        state: &BodyState,
        command: &AttitudeCommand,
        dt_s: f64,
    ) -> Vector4<f64> {
        let gains = &frame.profile().gains;
        let (rate_sp, thrust) = match *command {
            AttitudeCommand::Attitude {
                setpoint,
                yawspeed_ff_rps,
            } => {
                let error = state.attitude.inverse() * setpoint.attitude;
                let sign = if error.w < 0.0 { -1.0 } else { 1.0 };
                let mut rate_sp = (error.imag() * (2.0 * sign)).component_mul(&gains.attitude_p);
                if yawspeed_ff_rps.is_finite() {
                    // The world's yaw rate expressed in the body frame, as PX4 adds it.
                    rate_sp += state.attitude.inverse() * Vector3::z() * yawspeed_ff_rps;
                }
                (rate_sp, setpoint.thrust_norm)
            }
            AttitudeCommand::Rates {
                rates_frd_rps,
                thrust_norm,
            } => (rates_frd_rps, thrust_norm),
        };
        let rate_sp = rate_sp.zip_map(&gains.max_rate_rps, |r, max| r.clamp(-max, max));
        self.track_rates(frame, state, rate_sp, thrust, dt_s)
    }

    /// The rate PID and the mixer.
    fn track_rates(
        &mut self,
        frame: &Airframe,
        state: &BodyState,
        rate_sp: Vector3<f64>,
        thrust_norm: f64,
        dt_s: f64,
    ) -> Vector4<f64> {
        let gains = &frame.profile().gains;
        let rate = state.rate_frd_rps;
        let rate_error = rate_sp - rate;
        let rate_dot = self
            .last_rate
            .map_or(Vector3::zeros(), |last| (rate - last) / dt_s);
        self.last_rate = Some(rate);
        let thrust_norm = if thrust_norm.is_finite() {
            thrust_norm.clamp(0.0, 1.0)
        } else {
            0.0
        };
        // Integrate only with enough thrust to be flying, like PX4's landed gating.
        if thrust_norm > 0.05 {
            self.rate_integral += rate_error * dt_s;
            let limit = frame.rate_integral_scale();
            self.rate_integral = self
                .rate_integral
                .zip_map(&limit, |x, l| x.clamp(-l * 10.0, l * 10.0));
        }
        let angular_accel = rate_error.component_mul(&gains.rate_p)
            + self.rate_integral.component_mul(&gains.rate_i)
            - rate_dot.component_mul(&gains.rate_d);
        let inertia = frame.profile().inertia_kg_m2;
        let torque =
            inertia.component_mul(&angular_accel) + rate.cross(&inertia.component_mul(&rate));
        frame.mix(thrust_norm * frame.profile().max_thrust_n(), torque)
    }
}

/// What the attitude controller is asked to track.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum AttitudeCommand {
    /// An attitude and thrust, with a yaw-rate feed-forward (rad/s; NaN = none).
    Attitude {
        /// The attitude and thrust.
        setpoint: AttitudeSetpoint,
        /// World yaw-rate feed-forward (rad/s).
        yawspeed_ff_rps: f64,
    },
    /// Body rates (FRD, rad/s) and normalised thrust.
    Rates {
        /// Roll, pitch and yaw rate.
        rates_frd_rps: Vector3<f64>,
        /// Collective thrust `0..1`.
        thrust_norm: f64,
    },
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::Environment;
    use crate::profile::{GRAVITY_MPS2, Profile};

    const DT: f64 = 1e-3;

    /// Flies a roll step from level and returns (overshoot fraction, settling time to
    /// within 2 % of the step).
    fn roll_step(profile: Profile, step_rad: f64) -> (f64, f64) {
        let mut frame = Airframe::new(profile.clone());
        let hover = profile.hover_throttle();
        let mut state = BodyState::at_rest(Vector3::new(0.0, 0.0, -100.0));
        state.motor_thrust_n = Vector4::repeat(profile.mass_kg * GRAVITY_MPS2 / 4.0);
        let env = Environment {
            ground_z_ned_m: 0.0,
            ..Default::default()
        };
        let mut ctrl = AttitudeController::default();
        let sp = AttitudeSetpoint {
            attitude: UnitQuaternion::from_euler_angles(step_rad, 0.0, 0.0),
            thrust_norm: hover,
        };
        let (mut peak, mut settled_at) = (0.0_f64, 0.0);
        for i in 0..3000 {
            let cmd = ctrl.update(&frame, &state, &sp, DT);
            state = frame.step(&state, &cmd, &env, DT);
            let (roll, _, _) = state.attitude.euler_angles();
            peak = peak.max(roll);
            if (roll - step_rad).abs() > 0.02 * step_rad {
                settled_at = (i + 1) as f64 * DT;
            }
        }
        ((peak - step_rad) / step_rad, settled_at)
    }

    #[test]
    fn roll_step_of_20_degrees_settles_without_much_overshoot() {
        // Documented settling times (to 2 %): ideal 0.40 s, x500 0.80 s.
        for (profile, settle_s) in [(Profile::ideal(), 0.40), (Profile::x500(), 0.80)] {
            let name = profile.name;
            let (overshoot, settled) = roll_step(profile, 20f64.to_radians());
            assert!(overshoot <= 0.10, "{name}: overshoot {overshoot}");
            assert!(settled <= settle_s, "{name}: settled at {settled} s");
        }
    }
}
