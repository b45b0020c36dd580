//! From a desired acceleration to an attitude setpoint and normalised thrust.
//!
//! The paper's `T = m·|u + g·e₃|` with its roll/pitch formulas is the same thing as
//! aligning the body's thrust axis with the required specific force. That is how it is
//! computed here, in NED: the required specific force is `f = a_ned − g·e_down`, the
//! body z axis (FRD, pointing down) is `−f/|f|`, and the body x axis is the yaw heading
//! made orthogonal to it (ZYX Euler yaw exactly equals the requested yaw). Thrust is
//! `m·|f|`, normalised by the model's maximum. The result is guarded: a unit quaternion,
//! thrust clamped to `[0, 1]`, no NaN.

use nalgebra::{UnitQuaternion, Vector3};
use ringswarm_wire::attitude::body_z_to_attitude;

use super::frames::enu_to_ned;
use super::vehicle::{GRAVITY_MPS2, VehicleModel};

/// An attitude and thrust setpoint: what SET_ATTITUDE_TARGET carries (type_mask 7).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AttitudeThrust {
    /// Rotation from body FRD to NED (`v_ned = q·v_frd`), MAVLink's attitude quaternion.
    pub attitude_ned_frd: UnitQuaternion<f64>,
    /// Normalised collective thrust, `0..=1`.
    pub thrust_norm: f64,
    /// Collective thrust (N), before normalisation.
    pub thrust_n: f64,
}

/// The attitude and thrust that produce the acceleration `accel_enu_mps2` (paper frame,
/// z up) at NED yaw `yaw_ned_rad` (0 = nose north).
///
/// A command of free fall (no thrust needed) gives a level attitude with zero thrust. A
/// non-finite input is a bad number, not a wish to fall: it gives a level attitude at the
/// model's hover thrust, never a motor cut in the air.
pub fn attitude_thrust_from_acceleration(
    accel_enu_mps2: Vector3<f64>,
    yaw_ned_rad: f64,
    model: &VehicleModel,
) -> AttitudeThrust {
    let yaw = if yaw_ned_rad.is_finite() {
        yaw_ned_rad
    } else {
        0.0
    };
    if !accel_enu_mps2.iter().all(|x| x.is_finite()) {
        return AttitudeThrust {
            attitude_ned_frd: UnitQuaternion::from_euler_angles(0.0, 0.0, yaw),
            thrust_norm: model.hover_throttle(),
            thrust_n: model.mass_kg() * GRAVITY_MPS2,
        };
    }
    let specific_force_ned = enu_to_ned(accel_enu_mps2) - Vector3::new(0.0, 0.0, GRAVITY_MPS2);
    let magnitude = specific_force_ned.norm();
    if magnitude < 1e-9 {
        return AttitudeThrust {
            attitude_ned_frd: UnitQuaternion::from_euler_angles(0.0, 0.0, yaw),
            thrust_norm: 0.0,
            thrust_n: 0.0,
        };
    }
    // Body z against the specific force, nose toward the yaw: PX4's construction.
    let attitude_ned_frd = body_z_to_attitude(-specific_force_ned, yaw);
    let thrust_n = model.mass_kg() * magnitude;
    AttitudeThrust {
        attitude_ned_frd,
        thrust_norm: (thrust_n / model.max_thrust_n()).clamp(0.0, 1.0),
        thrust_n,
    }
}

/// The cosine of an attitude's tilt (the angle between the body z axis and the vertical):
/// the body z axis's vertical component, `1 − 2(x² + y²)` of the quaternion (no
/// trigonometry).
pub fn tilt_cos(attitude_ned_frd: &UnitQuaternion<f64>) -> f64 {
    let q = attitude_ned_frd.quaternion();
    (1.0 - 2.0 * (q.i * q.i + q.j * q.j)).clamp(-1.0, 1.0)
}

/// The direction the thrust of an attitude points in (unit vector, ENU: east, north, up):
/// the body's −z axis (FRD) turned into NED by the attitude, then into ENU.
pub fn thrust_direction_enu(attitude_ned_frd: &UnitQuaternion<f64>) -> Vector3<f64> {
    super::ned_to_enu(attitude_ned_frd * Vector3::new(0.0, 0.0, -1.0))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::frames::euler_ned_frd;
    use nalgebra::{Matrix3, Rotation3};
    use std::f64::consts::FRAC_PI_2;

    fn model() -> VehicleModel {
        VehicleModel::from_hover_throttle(1.5, 0.4).unwrap()
    }

    #[test]
    fn thrust_points_up_when_level_and_north_when_the_nose_is_down() {
        let level = thrust_direction_enu(&UnitQuaternion::identity());
        assert!((level - Vector3::new(0.0, 0.0, 1.0)).norm() < 1e-15);
        // Nose down by 0.3 rad (pitch −0.3 in FRD, heading north): the thrust tilts north.
        let nose_down = thrust_direction_enu(&UnitQuaternion::from_euler_angles(0.0, -0.3, 0.0));
        let expected = Vector3::new(0.0, 0.3f64.sin(), 0.3f64.cos());
        assert!((nose_down - expected).norm() < 1e-12, "{nose_down}");
        // Right wing down by 0.2 rad, heading east (yaw π/2): the thrust tilts south.
        let roll_east =
            thrust_direction_enu(&UnitQuaternion::from_euler_angles(0.2, 0.0, FRAC_PI_2));
        let expected = Vector3::new(0.0, -0.2f64.sin(), 0.2f64.cos());
        assert!((roll_east - expected).norm() < 1e-12, "{roll_east}");
        // Its vertical part is the tilt's cosine.
        let q = UnitQuaternion::from_euler_angles(0.3, -0.4, 1.0);
        assert!((thrust_direction_enu(&q).z - tilt_cos(&q)).abs() < 1e-12);
    }

    #[test]
    fn thrust_at_hover_equals_the_hover_throttle() {
        let sp = attitude_thrust_from_acceleration(Vector3::zeros(), 0.0, &model());
        assert!((sp.thrust_norm - 0.4).abs() < 1e-12);
        assert!((sp.thrust_n - 1.5 * GRAVITY_MPS2).abs() < 1e-12);
        assert!(sp.attitude_ned_frd.angle() < 1e-12);
    }

    #[test]
    fn accelerating_north_pitches_the_nose_down() {
        // North is +y in the paper's ENU frame.
        let sp = attitude_thrust_from_acceleration(Vector3::new(0.0, 2.0, 0.0), 0.0, &model());
        let (roll, pitch, yaw) = euler_ned_frd(&sp.attitude_ned_frd);
        assert!(pitch < 0.0, "pitch {pitch} must be negative (nose down)");
        assert!((pitch + (2.0 / GRAVITY_MPS2).atan()).abs() < 1e-12);
        assert!(roll.abs() < 1e-12 && yaw.abs() < 1e-12);
    }

    #[test]
    fn accelerating_east_rolls_right() {
        let sp = attitude_thrust_from_acceleration(Vector3::new(3.0, 0.0, 0.0), 0.0, &model());
        let (roll, pitch, _) = euler_ned_frd(&sp.attitude_ned_frd);
        // Roll right (positive in FRD) tilts the thrust towards east: sin φ = a_e / |f|.
        let expected = (3.0 / (9.0 + GRAVITY_MPS2 * GRAVITY_MPS2).sqrt()).asin();
        assert!((roll - expected).abs() < 1e-12 && pitch.abs() < 1e-12);
    }

    /// The paper's formulas in its own z-up frame (x east, y north, body x forward,
    /// z up), taken to NED/FRD by the two fixed frame rotations.
    fn paper_construction(u: Vector3<f64>, yaw_ned: f64, mass: f64) -> (UnitQuaternion<f64>, f64) {
        let g = GRAVITY_MPS2;
        let thrust = mass * (u.x * u.x + u.y * u.y + (u.z + g) * (u.z + g)).sqrt();
        let psi = FRAC_PI_2 - yaw_ned; // heading measured from east, counter-clockwise
        let phi = (mass / thrust * (u.x * psi.sin() - u.y * psi.cos())).asin();
        let theta = ((u.x * psi.cos() + u.y * psi.sin()) / (u.z + g)).atan();
        let r_enu_flu = Rotation3::from_euler_angles(phi, theta, psi);
        let enu_to_ned = Rotation3::from_matrix_unchecked(Matrix3::new(
            0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, -1.0,
        ));
        let frd_to_flu = Matrix3::from_diagonal(&Vector3::new(1.0, -1.0, -1.0));
        let r = enu_to_ned.matrix() * r_enu_flu.matrix() * frd_to_flu;
        let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
        (q, thrust)
    }

    #[test]
    fn quaternion_is_unit_and_matches_the_papers_euler_construction() {
        let m = model();
        let cases = [
            (Vector3::new(1.0, 2.0, 0.5), 0.0),
            (Vector3::new(-4.0, 0.5, -1.0), 0.0),
            (Vector3::new(3.0, -3.0, 2.0), 0.7),
            (Vector3::new(0.0, -6.0, 0.0), -2.5),
            (Vector3::new(7.5, 7.5, 4.0), 1.2),
        ];
        for (u, yaw) in cases {
            let sp = attitude_thrust_from_acceleration(u, yaw, &m);
            let q = sp.attitude_ned_frd;
            let norm = q.quaternion().norm();
            assert!((norm - 1.0).abs() < 1e-12);
            let (expected, thrust) = paper_construction(u, yaw, m.mass_kg());
            assert!(q.angle_to(&expected) < 1e-9, "u = {u:?}, yaw = {yaw}");
            assert!((sp.thrust_n - thrust).abs() < 1e-9);
            let (_, _, got_yaw) = euler_ned_frd(&q);
            assert!((got_yaw - yaw).abs() < 1e-9);
        }
    }

    #[test]
    fn free_fall_gives_zero_thrust_but_a_bad_number_gives_hover() {
        let sp =
            attitude_thrust_from_acceleration(Vector3::new(0.0, 0.0, -GRAVITY_MPS2), 0.0, &model());
        assert_eq!(sp.thrust_norm, 0.0);
        assert!(sp.attitude_ned_frd.angle() < 1e-12);
        for u in [
            Vector3::new(f64::NAN, 0.0, 0.0),
            Vector3::new(0.0, f64::INFINITY, 0.0),
            Vector3::new(0.0, 0.0, f64::NEG_INFINITY),
        ] {
            let sp = attitude_thrust_from_acceleration(u, 0.3, &model());
            // The model's hover throttle is 0.4, its weight 1.5·g.
            assert_eq!(sp.thrust_norm, 0.4, "u = {u:?}");
            assert!((sp.thrust_n - 1.5 * GRAVITY_MPS2).abs() < 1e-12);
            let (roll, pitch, yaw) = euler_ned_frd(&sp.attitude_ned_frd);
            assert!(roll.abs() < 1e-12 && pitch.abs() < 1e-12 && (yaw - 0.3).abs() < 1e-12);
        }
    }

    #[test]
    fn tilt_cosine_is_the_body_z_axis_vertical_component() {
        for (roll, pitch, yaw) in [
            (0.0, 0.0, 0.0),
            (0.3, -0.2, 2.0),
            (FRAC_PI_2, 0.0, 1.0),
            (2.5, 0.4, -3.0),
        ] {
            let q = UnitQuaternion::from_euler_angles(roll, pitch, yaw);
            // Roll then pitch about the rotated axes: cos(tilt) = cos(roll)·cos(pitch).
            let expected = f64::cos(roll) * f64::cos(pitch);
            assert!((tilt_cos(&q) - expected).abs() < 1e-12, "{roll} {pitch}");
            assert!((tilt_cos(&q) - (q * Vector3::z()).z).abs() < 1e-12);
        }
    }
}
