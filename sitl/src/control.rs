//! The emulated flight controller, shaped like PX4's multicopter stack:
//!
//! ```text
//! attitude setpoint (q, thrust) ──► attitude P ──► rate setpoint ──► rate PID ──► torques ──► mixer ──► motors
//!          ▲
//!   offboard (SET_ATTITUDE_TARGET) or the position/velocity controller (Hold, Land, pilot)
//! ```
//!
//! The attitude error is taken in the body frame, `q_e = q⁻¹·q_sp`, and the rate setpoint
//! is `2·K_att·sign(w_e)·vec(q_e)`, clamped to the profile's largest rates. The rate loop
//! gives an angular acceleration `K_p·e + K_i·∫e − K_d·ω̇`, turned into torque through the
//! inertia (plus the gyroscopic term). The position/velocity controller turns a desired
//! acceleration into an attitude and thrust the same way the coordinator does.
//! Pure and deterministic.

use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3, Vector4};

use crate::physics::{Airframe, BodyState};
use crate::profile::GRAVITY_MPS2;

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
        let gains = &frame.profile().gains;
        let error = state.attitude.inverse() * setpoint.attitude;
        let sign = if error.w < 0.0 { -1.0 } else { 1.0 };
        let rate_sp = (error.imag() * (2.0 * sign))
            .component_mul(&gains.attitude_p)
            .zip_map(&gains.max_rate_rps, |r, max| r.clamp(-max, max));
        let rate = state.rate_frd_rps;
        let rate_error = rate_sp - rate;
        let rate_dot = self
            .last_rate
            .map_or(Vector3::zeros(), |last| (rate - last) / dt_s);
        self.last_rate = Some(rate);
        let thrust_norm = if setpoint.thrust_norm.is_finite() {
            setpoint.thrust_norm.clamp(0.0, 1.0)
        } else {
            0.0
        };
        // Integrate only with enough thrust to be flying, like PX4's landed gating.
        if thrust_norm > 0.05 {
            self.rate_integral += rate_error * dt_s;
            let limit = Vector3::repeat(0.3).component_div(&gains.rate_i.map(|g| g.max(1e-9)));
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

/// The attitude and normalised thrust that give the NED acceleration `accel_ned_mps2` at
/// NED yaw `yaw_rad`, for a vehicle whose hover throttle is `hover_throttle`. The tilt is
/// limited to `max_tilt_rad`.
pub fn attitude_from_acceleration(
    accel_ned_mps2: Vector3<f64>,
    yaw_rad: f64,
    hover_throttle: f64,
    max_tilt_rad: f64,
) -> AttitudeSetpoint {
    let mut force = accel_ned_mps2 - Vector3::new(0.0, 0.0, GRAVITY_MPS2);
    // Never ask for downward thrust; limit the tilt by shrinking the horizontal part.
    force.z = force.z.min(-0.1 * GRAVITY_MPS2);
    let horizontal = force.xy().norm();
    let max_horizontal = -force.z * max_tilt_rad.tan();
    if horizontal > max_horizontal {
        let scale = max_horizontal / horizontal;
        force.x *= scale;
        force.y *= scale;
    }
    let body_z = -force.normalize();
    let heading_y = Vector3::new(-yaw_rad.sin(), yaw_rad.cos(), 0.0);
    let body_x = heading_y.cross(&body_z).normalize();
    let body_y = body_z.cross(&body_x);
    let rotation =
        Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[body_x, body_y, body_z]));
    AttitudeSetpoint {
        attitude: UnitQuaternion::from_rotation_matrix(&rotation),
        thrust_norm: (force.norm() / GRAVITY_MPS2 * hover_throttle).clamp(0.0, 1.0),
    }
}

/// Gains and limits of the simple position/velocity controller used by Hold, Land and
/// the pilot of a vehicle started in the air.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PositionGains {
    /// Position P (1/s): velocity per metre of error.
    pub pos_p: f64,
    /// Velocity P (1/s): acceleration per m/s of error.
    pub vel_p: f64,
    /// Largest horizontal speed asked by the position loop (m/s).
    pub max_speed_mps: f64,
    /// Largest tilt (rad).
    pub max_tilt_rad: f64,
}

impl Default for PositionGains {
    fn default() -> Self {
        // PX4's MPC_XY_P 0.95, MPC_XY_VEL_P_ACC 1.8, MPC_TILTMAX_AIR 45°, a 12 m/s cap.
        Self {
            pos_p: 0.95,
            vel_p: 1.8,
            max_speed_mps: 12.0,
            max_tilt_rad: 45f64.to_radians(),
        }
    }
}

/// What the position/velocity controller should hold.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Guidance {
    /// Hold a position (NED, m).
    Position(Vector3<f64>),
    /// Hold a velocity (NED, m/s).
    Velocity(Vector3<f64>),
    /// Hold a horizontal position and descend at a speed (m/s, positive down).
    Descend {
        /// Horizontal position to hold (NED x, y).
        xy_m: nalgebra::Vector2<f64>,
        /// Descent speed (m/s).
        speed_mps: f64,
    },
}

/// The attitude setpoint for a guidance target.
pub fn guide(
    gains: &PositionGains,
    target: &Guidance,
    state: &BodyState,
    hover_throttle: f64,
    yaw_rad: f64,
) -> AttitudeSetpoint {
    let clamp_xy = |v: Vector3<f64>| {
        let n = v.xy().norm();
        if n > gains.max_speed_mps {
            Vector3::new(
                v.x * gains.max_speed_mps / n,
                v.y * gains.max_speed_mps / n,
                v.z,
            )
        } else {
            v
        }
    };
    let vel_sp = match *target {
        Guidance::Position(p) => clamp_xy((p - state.pos_ned_m) * gains.pos_p),
        Guidance::Velocity(v) => v,
        Guidance::Descend { xy_m, speed_mps } => {
            let xy = (xy_m - state.pos_ned_m.xy()) * gains.pos_p;
            clamp_xy(Vector3::new(xy.x, xy.y, speed_mps))
        }
    };
    let accel = (vel_sp - state.vel_ned_mps) * gains.vel_p;
    attitude_from_acceleration(accel, yaw_rad, hover_throttle, gains.max_tilt_rad)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::Environment;
    use crate::profile::Profile;

    const DT: f64 = 1e-3;

    /// Flies a roll step from level and returns (overshoot fraction, settling time to
    /// within 2 % of the step).
    fn roll_step(profile: Profile, step_rad: f64) -> (f64, f64) {
        let frame = Airframe::new(profile.clone());
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

    #[test]
    fn acceleration_north_pitches_nose_down_and_hover_is_hover_throttle() {
        let sp = attitude_from_acceleration(Vector3::zeros(), 0.0, 0.5, 0.7);
        assert!((sp.thrust_norm - 0.5).abs() < 1e-12 && sp.attitude.angle() < 1e-12);
        let sp = attitude_from_acceleration(Vector3::new(2.0, 0.0, 0.0), 0.0, 0.5, 0.7);
        let (_, pitch, _) = sp.attitude.euler_angles();
        assert!(pitch < 0.0);
    }
}
