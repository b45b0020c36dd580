//! Offboard setpoints as PX4's MAVLink receiver reads them (`mavlink_receiver.cpp`):
//! SET_POSITION_TARGET_LOCAL_NED, SET_POSITION_TARGET_GLOBAL_INT and SET_ATTITUDE_TARGET
//! become one [`OffboardTarget`], and each says whether it is *proof of life* for the
//! offboard signal (PX4's `offboard_control_mode`, which keeps OFFBOARD available for
//! `COM_OF_LOSS_T`).
//!
//! Local NED (`type_mask` bits: 1/2/4 ignore x/y/z, 8/16/32 vx/vy/vz, 64/128/256
//! ax/ay/az, 512 force, 1024 yaw, 2048 yaw rate):
//! - `LOCAL_NED` (1): every axis on its own, NaN where ignored.
//! - `BODY_NED` (8): no position; velocity (all three or none) rotated by the heading,
//!   acceleration (all three or none) rotated by the full attitude; yaw stays absolute.
//! - `LOCAL_OFFSET_NED` (7), `BODY_OFFSET_NED` (9) and any other frame: refused, as
//!   current PX4 does ("coordinate frame unsupported"): nothing is flown and the message
//!   is no proof of life.
//! - Acceleration with the force bit: refused ("force not supported").
//! - Neither position, velocity nor acceleration: refused (yaw alone is not a setpoint).
//!
//! Global (frames `GLOBAL_INT` 5, `GLOBAL_RELATIVE_ALT_INT` 6): position only when none
//! of x/y/z is ignored, projected around the vehicle's origin; velocity and acceleration
//! per axis in NED; other frames with a position are refused.
//!
//! Attitude: attitude (bit 128 clear) or body rates (bits 1 and 2 clear), with thrust
//! (bit 64 clear). Yaw rate alone, or no thrust, is nothing. With the attitude, the body
//! yaw rate (bit 4 clear) is a feed-forward.
//!
//! Beyond PX4, which passes them on to its controllers, non-finite numbers and a
//! quaternion that is not of unit length are refused here: a refused setpoint is never
//! flown and never keeps OFFBOARD alive.

use nalgebra::{Quaternion, UnitQuaternion, Vector3};

use crate::position_control::TrajectorySetpoint;

/// What OFFBOARD flies.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum OffboardTarget {
    /// Position, velocity and acceleration (NaN = not set) through the position
    /// controller.
    Trajectory(TrajectorySetpoint),
    /// An attitude (body FRD → NED) with normalised thrust and a yaw-rate feed-forward
    /// (rad/s; NaN = none).
    Attitude {
        /// Attitude.
        attitude: UnitQuaternion<f64>,
        /// Normalised collective thrust `0..1`.
        thrust: f64,
        /// Yaw-rate feed-forward (rad/s), NaN when not given.
        yawspeed_ff_rps: f64,
    },
    /// An attitude with a climb rate (ArduPilot's guided angle mode reads the thrust
    /// field so by default): the thrust is the vehicle's own, to make the climb.
    AttitudeClimb {
        /// Attitude.
        attitude: UnitQuaternion<f64>,
        /// Climb rate (m/s, up).
        climb_up_mps: f64,
        /// Yaw-rate feed-forward (rad/s), NaN when not given.
        yawspeed_ff_rps: f64,
    },
    /// Body rates (FRD, rad/s; NaN yaw = 0) with normalised thrust.
    Rates {
        /// Roll, pitch, yaw rate.
        rates_frd_rps: Vector3<f64>,
        /// Normalised collective thrust `0..1`.
        thrust: f64,
    },
}

/// Why a setpoint was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refusal {
    /// The coordinate frame is not one PX4 flies for this message.
    UnsupportedFrame(u8),
    /// The force bit with an acceleration.
    ForceNotSupported,
    /// Nothing to fly (only yaw, only a yaw rate, or no thrust).
    NothingSet,
    /// A non-finite value, a quaternion not of unit length, or thrust outside `0..=1`.
    BadValue,
    /// A global position while the vehicle has no global origin.
    NoGlobalOrigin,
}

/// How far a setpoint quaternion's norm may be from 1.
const UNIT_QUATERNION_TOLERANCE: f64 = 1e-3;

/// SET_POSITION_TARGET_* type_mask bits.
pub mod mask {
    /// Ignore x, y, z position.
    pub const POS: [u16; 3] = [1, 2, 4];
    /// Ignore vx, vy, vz.
    pub const VEL: [u16; 3] = [8, 16, 32];
    /// Ignore ax, ay, az.
    pub const ACC: [u16; 3] = [64, 128, 256];
    /// The acceleration is a force.
    pub const FORCE: u16 = 512;
    /// Ignore yaw.
    pub const YAW: u16 = 1024;
    /// Ignore yaw rate.
    pub const YAW_RATE: u16 = 2048;
}

/// MAV_FRAME values PX4 flies.
pub mod frame {
    /// MAV_FRAME_LOCAL_NED.
    pub const LOCAL_NED: u8 = 1;
    /// MAV_FRAME_GLOBAL_INT.
    pub const GLOBAL_INT: u8 = 5;
    /// MAV_FRAME_GLOBAL_RELATIVE_ALT_INT.
    pub const GLOBAL_RELATIVE_ALT_INT: u8 = 6;
    /// MAV_FRAME_LOCAL_OFFSET_NED.
    pub const LOCAL_OFFSET_NED: u8 = 7;
    /// MAV_FRAME_BODY_NED.
    pub const BODY_NED: u8 = 8;
    /// MAV_FRAME_BODY_OFFSET_NED.
    pub const BODY_OFFSET_NED: u8 = 9;
}

/// The fields of a SET_POSITION_TARGET_LOCAL_NED or _GLOBAL_INT in plain numbers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PositionTarget {
    /// MAV_FRAME.
    pub frame: u8,
    /// type_mask.
    pub type_mask: u16,
    /// x, y, z (m) for local frames; lat, lon (deg) and alt (m) for global ones.
    pub position: [f64; 3],
    /// vx, vy, vz (m/s).
    pub velocity: [f64; 3],
    /// afx, afy, afz (m/s²).
    pub acceleration: [f64; 3],
    /// Yaw (rad).
    pub yaw_rad: f64,
    /// Yaw rate (rad/s).
    pub yaw_rate_rps: f64,
}

/// The vehicle's geodetic frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GlobalFrame {
    /// The world the vehicle lives in.
    pub world: crate::world::World,
    /// The vehicle's local origin as a NED offset from the world's reference (m).
    pub origin_world_ned_m: Vector3<f64>,
    /// Home altitude AMSL (m), the zero of relative altitudes.
    pub home_alt_amsl_m: f64,
}

impl GlobalFrame {
    /// The local NED position of a geodetic position.
    pub fn to_local(&self, lat_deg: f64, lon_deg: f64, alt_amsl_m: f64) -> Vector3<f64> {
        let geo = crate::world::Geodetic {
            lat_deg,
            lon_deg,
            alt_amsl_m,
        };
        self.world.to_offset_ned(&geo) - self.origin_world_ned_m
    }
}

fn masked(mask: u16, bits: [u16; 3], values: [f64; 3]) -> Vector3<f64> {
    Vector3::from_fn(|i, _| {
        if mask & bits[i] != 0 {
            f64::NAN
        } else {
            values[i]
        }
    })
}

fn all_or_nothing(mask: u16, bits: [u16; 3], values: [f64; 3]) -> Option<Vector3<f64>> {
    (bits.iter().all(|b| mask & b == 0)).then(|| Vector3::from(values))
}

/// Whether every set component is finite (NaN marks "not set" and is fine; ±∞ is not).
fn no_infinities(v: &Vector3<f64>) -> bool {
    v.iter().all(|x| x.is_nan() || x.is_finite())
}

/// Reads a SET_POSITION_TARGET_LOCAL_NED.
///
/// # Errors
/// The [`Refusal`] PX4 (or the emulator's stricter value check) would apply.
pub fn local_ned(
    t: &PositionTarget,
    attitude: &UnitQuaternion<f64>,
) -> Result<OffboardTarget, Refusal> {
    let m = t.type_mask;
    let (pos, vel, acc) = match t.frame {
        frame::LOCAL_NED => (
            masked(m, mask::POS, t.position),
            masked(m, mask::VEL, t.velocity),
            masked(m, mask::ACC, t.acceleration),
        ),
        frame::BODY_NED => {
            let yaw = attitude.euler_angles().2;
            let heading = UnitQuaternion::from_euler_angles(0.0, 0.0, yaw);
            let vel = all_or_nothing(m, mask::VEL, t.velocity)
                .map_or(Vector3::repeat(f64::NAN), |v| heading * v);
            let acc = all_or_nothing(m, mask::ACC, t.acceleration)
                .map_or(Vector3::repeat(f64::NAN), |a| attitude * a);
            (Vector3::repeat(f64::NAN), vel, acc)
        }
        other => return Err(Refusal::UnsupportedFrame(other)),
    };
    trajectory(m, pos, vel, acc, t)
}

/// Reads a SET_POSITION_TARGET_GLOBAL_INT (`position` is lat, lon in degrees and the
/// altitude in metres) in the vehicle's geodetic `frame`.
///
/// # Errors
/// The [`Refusal`] PX4 (or the emulator's stricter value check) would apply.
pub fn global_int(t: &PositionTarget, frame: &GlobalFrame) -> Result<OffboardTarget, Refusal> {
    let m = t.type_mask;
    let pos = if mask::POS.iter().any(|b| m & b != 0) {
        Vector3::repeat(f64::NAN)
    } else {
        let [lat, lon, alt] = t.position;
        if !(lat.is_finite() && lon.is_finite() && alt.is_finite()) {
            return Err(Refusal::BadValue);
        }
        let alt_amsl = match t.frame {
            frame::GLOBAL_INT => alt,
            frame::GLOBAL_RELATIVE_ALT_INT => frame.home_alt_amsl_m + alt,
            other => return Err(Refusal::UnsupportedFrame(other)),
        };
        frame.to_local(lat, lon, alt_amsl)
    };
    let vel = masked(m, mask::VEL, t.velocity);
    let acc = masked(m, mask::ACC, t.acceleration);
    trajectory(m, pos, vel, acc, t)
}

fn trajectory(
    m: u16,
    pos: Vector3<f64>,
    vel: Vector3<f64>,
    acc: Vector3<f64>,
    t: &PositionTarget,
) -> Result<OffboardTarget, Refusal> {
    let any = |v: &Vector3<f64>| v.iter().any(|x| !x.is_nan());
    if any(&acc) && m & mask::FORCE != 0 {
        return Err(Refusal::ForceNotSupported);
    }
    if !(any(&pos) || any(&vel) || any(&acc)) {
        return Err(Refusal::NothingSet);
    }
    let yaw = if m & mask::YAW != 0 {
        f64::NAN
    } else {
        t.yaw_rad
    };
    let yawspeed = if m & mask::YAW_RATE != 0 {
        f64::NAN
    } else {
        t.yaw_rate_rps
    };
    let finite_or_nan = |x: f64| x.is_nan() || x.is_finite();
    if !(no_infinities(&pos)
        && no_infinities(&vel)
        && no_infinities(&acc)
        && finite_or_nan(yaw)
        && finite_or_nan(yawspeed))
    {
        return Err(Refusal::BadValue);
    }
    // PX4 flies x and y as a pair: half a horizontal position or velocity is no
    // setpoint for that pair.
    let pair = |v: Vector3<f64>| {
        if v.x.is_nan() != v.y.is_nan() {
            Vector3::new(f64::NAN, f64::NAN, v.z)
        } else {
            v
        }
    };
    Ok(OffboardTarget::Trajectory(TrajectorySetpoint {
        pos_ned_m: pair(pos),
        vel_ned_mps: pair(vel),
        acc_ned_mps2: pair(acc),
        yaw_rad: yaw,
        yawspeed_rps: yawspeed,
    }))
}

/// SET_ATTITUDE_TARGET type_mask bits.
pub mod att_mask {
    /// Ignore the body roll rate.
    pub const ROLL_RATE: u8 = 1;
    /// Ignore the body pitch rate.
    pub const PITCH_RATE: u8 = 2;
    /// Ignore the body yaw rate.
    pub const YAW_RATE: u8 = 4;
    /// `thrust_body` is set.
    pub const THRUST_BODY: u8 = 32;
    /// Ignore thrust.
    pub const THROTTLE: u8 = 64;
    /// Ignore the attitude.
    pub const ATTITUDE: u8 = 128;
}

/// The fields of a SET_ATTITUDE_TARGET in plain numbers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AttitudeTarget {
    /// type_mask.
    pub type_mask: u8,
    /// Quaternion `[w, x, y, z]`, body FRD → NED.
    pub q: [f64; 4],
    /// Body roll, pitch, yaw rates (rad/s).
    pub body_rates_rps: [f64; 3],
    /// Normalised thrust.
    pub thrust: f64,
    /// The thrust vector in body FRD (normalised; used with bit 32).
    pub thrust_body: [f64; 3],
}

/// Reads a SET_ATTITUDE_TARGET.
///
/// # Errors
/// [`Refusal::NothingSet`] without thrust or with neither attitude nor roll and pitch
/// rates; [`Refusal::BadValue`] for non-finite numbers, a quaternion not of unit length
/// or thrust outside `0..=1`.
pub fn attitude_target(t: &AttitudeTarget) -> Result<OffboardTarget, Refusal> {
    let m = t.type_mask;
    let use_attitude = m & att_mask::ATTITUDE == 0;
    let use_rates = m & att_mask::ROLL_RATE == 0 && m & att_mask::PITCH_RATE == 0;
    let thrust = if m & att_mask::THRUST_BODY != 0 {
        // A multicopter's collective thrust is along body −z.
        Some(-t.thrust_body[2])
    } else if m & att_mask::THROTTLE == 0 {
        Some(t.thrust)
    } else {
        None
    };
    let Some(thrust) = thrust else {
        return Err(Refusal::NothingSet);
    };
    if !(use_attitude || use_rates) {
        return Err(Refusal::NothingSet);
    }
    if !(thrust.is_finite() && (0.0..=1.0).contains(&thrust)) {
        return Err(Refusal::BadValue);
    }
    let yaw_rate = if m & att_mask::YAW_RATE != 0 {
        f64::NAN
    } else {
        t.body_rates_rps[2]
    };
    if use_attitude {
        let q = Quaternion::new(t.q[0], t.q[1], t.q[2], t.q[3]);
        let unit = q.coords.iter().all(|x| x.is_finite())
            && (q.norm() - 1.0).abs() <= UNIT_QUATERNION_TOLERANCE;
        if !unit || !(yaw_rate.is_nan() || yaw_rate.is_finite()) {
            return Err(Refusal::BadValue);
        }
        return Ok(OffboardTarget::Attitude {
            attitude: UnitQuaternion::new_normalize(q),
            thrust,
            yawspeed_ff_rps: yaw_rate,
        });
    }
    let rates = Vector3::new(
        t.body_rates_rps[0],
        t.body_rates_rps[1],
        if yaw_rate.is_nan() { 0.0 } else { yaw_rate },
    );
    if !rates.iter().all(|x| x.is_finite()) {
        return Err(Refusal::BadValue);
    }
    Ok(OffboardTarget::Rates {
        rates_frd_rps: rates,
        thrust,
    })
}

#[cfg(test)]
mod tests;
