//! PX4's construction of an attitude from a thrust direction and a yaw
//! (`ControlMath::bodyzToAttitude`): the one both the coordinator (acceleration →
//! attitude setpoint) and the emulator (PX4's position controller) use, so that an
//! acceleration means the same attitude on both sides.
//!
//! Frames: NED world, FRD body; `body_z_ned` is where the body z axis (down through the
//! floor of the airframe) should point, i.e. against the thrust.

use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};

/// The attitude whose body z axis points along `body_z_ned` and whose nose points as
/// close to yaw `yaw_rad` (0 = north, clockwise seen from above) as that allows. As PX4:
/// a zero vector means level; upside down the nose is kept to the front; a body z in the
/// horizontal plane (no vertical component) takes body x straight down.
pub fn body_z_to_attitude(body_z_ned: Vector3<f64>, yaw_rad: f64) -> UnitQuaternion<f64> {
    let mut body_z = body_z_ned;
    if body_z.norm_squared() < f64::from(f32::EPSILON) {
        body_z.z = 1.0;
    }
    let body_z = body_z.normalize();
    // At yaw zero (the swarm's setpoints) sine and cosine are exact without the library:
    // sin ±0 = ±0, cos ±0 = 1.
    let (sin, cos) = if yaw_rad == 0.0 {
        (yaw_rad, 1.0)
    } else {
        yaw_rad.sin_cos()
    };
    let y_c = Vector3::new(-sin, cos, 0.0);
    let mut body_x = y_c.cross(&body_z);
    if body_z.z < 0.0 {
        body_x = -body_x;
    }
    if body_z.z.abs() < 1e-6 {
        body_x = Vector3::z();
    }
    let body_x = body_x.normalize();
    let body_y = body_z.cross(&body_x);
    let rotation =
        Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[body_x, body_y, body_z]));
    UnitQuaternion::from_rotation_matrix(&rotation)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: Vector3<f64>, b: Vector3<f64>) -> bool {
        (a - b).norm() < 1e-12
    }

    #[test]
    fn axes_follow_the_thrust_and_the_heading() {
        // Straight up thrust (body z down), yaw 90° (east): nose east, right wing south.
        let q = body_z_to_attitude(Vector3::z(), std::f64::consts::FRAC_PI_2);
        assert!(close(q * Vector3::x(), Vector3::new(0.0, 1.0, 0.0)));
        assert!(close(q * Vector3::y(), Vector3::new(-1.0, 0.0, 0.0)));
        // Thrust tilted north by 30°: body z = (-sin 30°, 0, cos 30°), yaw 0: the nose
        // pitches down by 30° toward north: body x = (cos 30°, 0, sin 30°).
        let (s, c) = (0.5_f64, 3.0_f64.sqrt() / 2.0);
        let q = body_z_to_attitude(Vector3::new(-s, 0.0, c), 0.0);
        assert!(close(q * Vector3::z(), Vector3::new(-s, 0.0, c)));
        assert!(close(q * Vector3::x(), Vector3::new(c, 0.0, s)));
    }

    #[test]
    fn px4s_corner_cases() {
        // No direction: level.
        let q = body_z_to_attitude(Vector3::zeros(), 0.0);
        assert!(q.angle() < 1e-12);
        // Horizontal body z: body x straight down.
        let q = body_z_to_attitude(Vector3::new(1.0, 0.0, 0.0), 0.3);
        assert!(close(q * Vector3::x(), Vector3::z()));
        // Upside down (body z up), yaw 0: the nose stays north.
        let q = body_z_to_attitude(-Vector3::z(), 0.0);
        assert!(close(q * Vector3::x(), Vector3::x()));
    }
}
