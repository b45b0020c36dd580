//! The multicopter position controller, shaped like PX4's `mc_pos_control`: one
//! controller flies every mode that is not a raw attitude or rate setpoint (offboard
//! position/velocity/acceleration, Takeoff, Hold, Land, goto, Return, Mission).
//!
//! ```text
//!  trajectory setpoint (pos, vel, acc, yaw, yawspeed; NaN = not set, per axis)
//!     │
//!     ├─ position P: vel_sp = P_pos·(pos_sp − pos) + vel_ff   (MPC_XY_P, MPC_Z_P)
//!     │     horizontal speed ≤ MPC_XY_VEL_MAX, keeping the position part first;
//!     │     vertical −MPC_Z_VEL_MAX_UP ≤ vz ≤ MPC_Z_VEL_MAX_DN
//!     ├─ velocity PID: acc_sp = P·e + I·∫e − D·v̇ + acc_ff  (MPC_*_VEL_{P,I,D}_ACC)
//!     ├─ acceleration → thrust direction: body z along (−ax, −ay, g), tilt ≤ MPC_TILTMAX_AIR;
//!     │     vertical thrust = (az − g)·MPC_THR_HOVER/g projected on body z,
//!     │     |thrust| ≥ MPC_THR_MIN
//!     ├─ saturation: vertical first within MPC_THR_MAX keeping MPC_THR_XY_MARG for the
//!     │     horizontal; horizontal integrator with tracking anti-windup (gain 2/P)
//!     └─ thrust vector + yaw → attitude quaternion (body FRD → NED) and normalised thrust
//! ```
//!
//! A position axis that is NaN is not controlled; a velocity that is NaN where its
//! position is set is only the position loop's; an axis with neither follows its
//! acceleration setpoint (or none). A NaN yaw means the current heading (a yaw speed is
//! then only a feed-forward that turns the vehicle). Frames: NED, metres, seconds,
//! radians. Pure and deterministic: state is the integrator and the filtered velocity
//! derivative.

use nalgebra::{Vector2, Vector3};

use crate::control::AttitudeSetpoint;
use crate::profile::GRAVITY_MPS2;

/// The controller's parameters (PX4's names, PX4's units: m/s, m/s², fractions).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MpcParams {
    /// MPC_XY_P (1/s).
    pub xy_p: f64,
    /// MPC_Z_P (1/s).
    pub z_p: f64,
    /// MPC_XY_VEL_P_ACC, MPC_XY_VEL_I_ACC, MPC_XY_VEL_D_ACC.
    pub xy_vel_pid: [f64; 3],
    /// MPC_Z_VEL_P_ACC, MPC_Z_VEL_I_ACC, MPC_Z_VEL_D_ACC.
    pub z_vel_pid: [f64; 3],
    /// MPC_XY_VEL_MAX (m/s).
    pub xy_vel_max_mps: f64,
    /// MPC_Z_VEL_MAX_UP (m/s).
    pub z_vel_max_up_mps: f64,
    /// MPC_Z_VEL_MAX_DN (m/s).
    pub z_vel_max_dn_mps: f64,
    /// MPC_TILTMAX_AIR (rad).
    pub tilt_max_rad: f64,
    /// MPC_THR_MIN.
    pub thr_min: f64,
    /// MPC_THR_MAX.
    pub thr_max: f64,
    /// MPC_THR_HOVER.
    pub thr_hover: f64,
    /// MPC_THR_XY_MARG.
    pub thr_xy_margin: f64,
}

impl MpcParams {
    /// PX4's defaults for a vehicle hovering at `thr_hover`.
    pub fn px4_defaults(thr_hover: f64) -> Self {
        Self {
            xy_p: 0.95,
            z_p: 1.0,
            xy_vel_pid: [1.8, 0.4, 0.2],
            z_vel_pid: [4.0, 2.0, 0.0],
            xy_vel_max_mps: 12.0,
            z_vel_max_up_mps: 3.0,
            z_vel_max_dn_mps: 1.5,
            tilt_max_rad: 45f64.to_radians(),
            thr_min: 0.12,
            thr_max: 1.0,
            thr_hover,
            thr_xy_margin: 0.3,
        }
    }
}

/// What the controller tracks (PX4's `trajectory_setpoint`): NaN marks an axis not set.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrajectorySetpoint {
    /// Position, local NED (m).
    pub pos_ned_m: Vector3<f64>,
    /// Velocity (feed-forward when the position is set), NED (m/s).
    pub vel_ned_mps: Vector3<f64>,
    /// Acceleration (feed-forward), NED (m/s²).
    pub acc_ned_mps2: Vector3<f64>,
    /// Heading (rad, from north, clockwise).
    pub yaw_rad: f64,
    /// Heading rate (rad/s).
    pub yawspeed_rps: f64,
}

impl TrajectorySetpoint {
    /// Nothing set.
    pub const UNSET: Self = Self {
        pos_ned_m: Vector3::new(f64::NAN, f64::NAN, f64::NAN),
        vel_ned_mps: Vector3::new(f64::NAN, f64::NAN, f64::NAN),
        acc_ned_mps2: Vector3::new(f64::NAN, f64::NAN, f64::NAN),
        yaw_rad: f64::NAN,
        yawspeed_rps: f64::NAN,
    };

    /// Hold `pos_ned_m` at `yaw_rad`.
    pub fn hold(pos_ned_m: Vector3<f64>, yaw_rad: f64) -> Self {
        Self {
            pos_ned_m,
            yaw_rad,
            ..Self::UNSET
        }
    }

    /// Whether any axis of position, velocity or acceleration is set.
    pub fn controls_anything(&self) -> bool {
        self.pos_ned_m
            .iter()
            .chain(self.vel_ned_mps.iter())
            .chain(self.acc_ned_mps2.iter())
            .any(|x| x.is_finite())
    }
}

/// What the controller measures.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Kinematics {
    /// Position, local NED (m).
    pub pos_ned_m: Vector3<f64>,
    /// Velocity, NED (m/s).
    pub vel_ned_mps: Vector3<f64>,
    /// Heading (rad).
    pub yaw_rad: f64,
}

/// The controller's output.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ControlOutput {
    /// Attitude and normalised thrust for the attitude controller.
    pub attitude: AttitudeSetpoint,
    /// Yaw rate feed-forward (rad/s).
    pub yawspeed_ff_rps: f64,
    /// The velocity setpoint after the position loop and limits (NED, m/s).
    pub vel_sp_ned_mps: Vector3<f64>,
    /// The thrust vector (NED, normalised).
    pub thrust_ned: Vector3<f64>,
}

/// Cut-off of the velocity-derivative filter (PX4's MPC_VELD_LP, Hz).
const VEL_DERIVATIVE_CUTOFF_HZ: f64 = 5.0;

/// The controller's state.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PositionController {
    vel_int: Vector3<f64>,
    vel_dot: Vector3<f64>,
    last_vel: Option<Vector3<f64>>,
}

impl PositionController {
    /// Forgets the integrator and the derivative (on arming, on the ground, when another
    /// controller took over).
    pub fn reset(&mut self) {
        *self = Self::default();
    }

    /// One step of `dt_s` seconds.
    pub fn update(
        &mut self,
        p: &MpcParams,
        sp: &TrajectorySetpoint,
        kin: &Kinematics,
        dt_s: f64,
    ) -> ControlOutput {
        self.update_vel_dot(kin.vel_ned_mps, dt_s);
        let vel_sp = velocity_setpoint(p, sp, kin);
        let thrust = self.velocity_control(p, sp, kin, &vel_sp, dt_s);
        let (yaw_sp, yawspeed_ff) = Self::yaw_setpoint(sp, kin);
        ControlOutput {
            attitude: thrust_to_attitude(&thrust, yaw_sp),
            yawspeed_ff_rps: yawspeed_ff,
            vel_sp_ned_mps: vel_sp,
            thrust_ned: thrust,
        }
    }

    fn update_vel_dot(&mut self, vel: Vector3<f64>, dt_s: f64) {
        if let Some(last) = self.last_vel {
            let raw = (vel - last) / dt_s;
            let rc = 1.0 / (2.0 * std::f64::consts::PI * VEL_DERIVATIVE_CUTOFF_HZ);
            let a = dt_s / (rc + dt_s);
            self.vel_dot += (raw - self.vel_dot) * a;
        }
        self.last_vel = Some(vel);
    }

    /// PX4's `_velocityControl` and `_accelerationControl`: the thrust vector (NED,
    /// normalised) and the integrator update with its anti-windup.
    fn velocity_control(
        &mut self,
        p: &MpcParams,
        sp: &TrajectorySetpoint,
        kin: &Kinematics,
        vel_sp: &Vector3<f64>,
        dt_s: f64,
    ) -> Vector3<f64> {
        let gain_p = Vector3::new(p.xy_vel_pid[0], p.xy_vel_pid[0], p.z_vel_pid[0]);
        let gain_i = Vector3::new(p.xy_vel_pid[1], p.xy_vel_pid[1], p.z_vel_pid[1]);
        let gain_d = Vector3::new(p.xy_vel_pid[2], p.xy_vel_pid[2], p.z_vel_pid[2]);
        self.vel_int.z = self.vel_int.z.clamp(-GRAVITY_MPS2, GRAVITY_MPS2);
        let mut vel_error = vel_sp - kin.vel_ned_mps;
        let acc_from_vel =
            vel_error.component_mul(&gain_p) + self.vel_int - self.vel_dot.component_mul(&gain_d);
        // An axis with no velocity setpoint has no velocity loop; NaN never reaches the
        // integrator.
        let acc_sp = Vector3::from_fn(|i, _| {
            let ff = sp.acc_ned_mps2[i];
            let fb = acc_from_vel[i];
            match (ff.is_finite(), fb.is_finite()) {
                (true, true) => ff + fb,
                (true, false) => ff,
                (false, true) => fb,
                (false, false) => 0.0,
            }
        });
        let mut thrust = acceleration_to_thrust(p, &acc_sp);
        // Vertical anti-windup: stop integrating into a saturated direction.
        if (thrust.z >= -p.thr_min && vel_error.z >= 0.0)
            || (thrust.z <= -p.thr_max && vel_error.z <= 0.0)
        {
            vel_error.z = 0.0;
        }
        saturate_thrust(p, &mut thrust);
        // Horizontal tracking anti-windup (Rundqwist): unwind by what was not produced.
        let produced_xy = thrust.xy() * (GRAVITY_MPS2 / p.thr_hover);
        let wanted_xy = acc_sp.xy();
        let limited_xy = if wanted_xy.norm_squared() > produced_xy.norm_squared() {
            produced_xy
        } else {
            wanted_xy
        };
        let arw_gain = 2.0 / gain_p.x.max(1e-6);
        let xy = vel_error.xy() - (wanted_xy - limited_xy) * arw_gain;
        vel_error.x = xy.x;
        vel_error.y = xy.y;
        let vel_error = vel_error.map(|x| if x.is_finite() { x } else { 0.0 });
        self.vel_int += vel_error.component_mul(&gain_i) * dt_s;
        thrust
    }

    /// PX4's yaw: the setpoint's heading, or the current one when it has none (a yaw
    /// speed alone then turns the vehicle by its feed-forward).
    fn yaw_setpoint(sp: &TrajectorySetpoint, kin: &Kinematics) -> (f64, f64) {
        let yawspeed = if sp.yawspeed_rps.is_finite() {
            sp.yawspeed_rps
        } else {
            0.0
        };
        let yaw = if sp.yaw_rad.is_finite() {
            sp.yaw_rad
        } else {
            kin.yaw_rad
        };
        (yaw, yawspeed)
    }
}

/// PX4's `_positionControl`: the velocity setpoint from the position error plus the
/// velocity feed-forward, horizontally limited with the position part first.
fn velocity_setpoint(p: &MpcParams, sp: &TrajectorySetpoint, kin: &Kinematics) -> Vector3<f64> {
    let gain = Vector3::new(p.xy_p, p.xy_p, p.z_p);
    let from_pos = (sp.pos_ned_m - kin.pos_ned_m).component_mul(&gain);
    let mut vel = Vector3::from_fn(|i, _| {
        let (fb, ff) = (from_pos[i], sp.vel_ned_mps[i]);
        match (fb.is_finite(), ff.is_finite()) {
            (true, true) => fb + ff,
            (true, false) => fb,
            (false, true) => ff,
            (false, false) => f64::NAN,
        }
    });
    let pos_part = from_pos.map(|x| if x.is_finite() { x } else { 0.0 });
    if vel.x.is_finite() && vel.y.is_finite() {
        let xy = constrain_xy(pos_part.xy(), vel.xy() - pos_part.xy(), p.xy_vel_max_mps);
        vel.x = xy.x;
        vel.y = xy.y;
    }
    if vel.z.is_finite() {
        vel.z = vel.z.clamp(-p.z_vel_max_up_mps, p.z_vel_max_dn_mps);
    }
    vel
}

/// PX4's `ControlMath::constrainXY`: `v0 + v1` limited to `max`, keeping as much of `v0`
/// (the position part) as fits and then the part of `v1` along it.
pub fn constrain_xy(v0: Vector2<f64>, v1: Vector2<f64>, max: f64) -> Vector2<f64> {
    let sum = v0 + v1;
    if sum.norm() <= max {
        return sum;
    }
    if v0.norm() >= max {
        return v0.normalize() * max;
    }
    if (v0 - v1).norm() < 1e-3 {
        return sum.normalize() * max;
    }
    if v0.norm() < 1e-3 {
        return v1.normalize() * max;
    }
    // Find s ≥ 0 with |v0 + s·u1| = max, u1 the unit of v1.
    let u1 = v1.normalize();
    let m = u1.dot(&v0);
    let c = v0.norm_squared() - max * max;
    let s = -m + (m * m - c).max(0.0).sqrt();
    v0 + u1 * s
}

/// PX4's `_accelerationControl` with horizontal and vertical decoupled (MPC_ACC_DECOUPLE
/// 1): tilt from the horizontal acceleration against gravity, collective thrust from the
/// vertical acceleration scaled by the hover thrust.
fn acceleration_to_thrust(p: &MpcParams, acc_sp: &Vector3<f64>) -> Vector3<f64> {
    let mut body_z = Vector3::new(-acc_sp.x, -acc_sp.y, GRAVITY_MPS2).normalize();
    limit_tilt(&mut body_z, p.tilt_max_rad);
    let thrust_ned_z = acc_sp.z * (p.thr_hover / GRAVITY_MPS2) - p.thr_hover;
    let cos_tilt = body_z.z;
    let collective = (thrust_ned_z / cos_tilt).min(-p.thr_min);
    body_z * collective
}

/// PX4's `ControlMath::limitTilt` against the world's up axis.
fn limit_tilt(body_up: &mut Vector3<f64>, max_rad: f64) {
    let up = Vector3::z();
    let dot = body_up.dot(&up).clamp(-1.0, 1.0);
    let angle = dot.acos().min(max_rad);
    let mut rejection = *body_up - up * dot;
    if rejection.norm_squared() < 1e-12 {
        rejection = Vector3::x();
    }
    *body_up = up * angle.cos() + rejection.normalize() * angle.sin();
}

/// Vertical thrust first, leaving `MPC_THR_XY_MARG` for the horizontal, then the
/// horizontal within what is left of `MPC_THR_MAX`.
fn saturate_thrust(p: &MpcParams, thrust: &mut Vector3<f64>) {
    let xy_norm = thrust.xy().norm();
    let max_sq = p.thr_max * p.thr_max;
    let allocated_xy = xy_norm.min(p.thr_xy_margin);
    let z_max_sq = max_sq - allocated_xy * allocated_xy;
    thrust.z = thrust.z.max(-z_max_sq.max(0.0).sqrt());
    let xy_max_sq = max_sq - thrust.z * thrust.z;
    let xy_max = if xy_max_sq > 0.0 {
        xy_max_sq.sqrt()
    } else {
        0.0
    };
    if xy_norm > xy_max {
        let scale = xy_max / xy_norm;
        thrust.x *= scale;
        thrust.y *= scale;
    }
}

/// PX4's `ControlMath::thrustToAttitude`: body z against the thrust, body x toward the
/// heading; normalised thrust is the vector's length.
pub fn thrust_to_attitude(thrust_ned: &Vector3<f64>, yaw_rad: f64) -> AttitudeSetpoint {
    AttitudeSetpoint {
        attitude: ringswarm_wire::attitude::body_z_to_attitude(-*thrust_ned, yaw_rad),
        thrust_norm: thrust_ned.norm().clamp(0.0, 1.0),
    }
}

/// An angle wrapped into `(−π, π]`.
pub fn wrap_pi(angle_rad: f64) -> f64 {
    let two_pi = 2.0 * std::f64::consts::PI;
    let a = (angle_rad + std::f64::consts::PI).rem_euclid(two_pi) - std::f64::consts::PI;
    if a <= -std::f64::consts::PI {
        a + two_pi
    } else {
        a
    }
}

#[cfg(test)]
mod tests;
