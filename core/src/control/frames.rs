//! Frame conversions between the paper's world frame and MAVLink's.
//!
//! - **World (paper), ENU:** x east, y north, z up (m, m/s, m/s²). The consensus and
//!   altitude laws run here, so the paper's equations hold as printed (with the corrected
//!   altitude sign).
//! - **World (MAVLink), NED:** x north, y east, z down.
//! - **Body:** FRD (x forward, y right, z down). Attitudes are rotations that take
//!   body-FRD vectors to NED (`v_ned = q · v_frd`), which is what MAVLink's
//!   quaternion `[w, x, y, z]` encodes.
//!
//! ENU ↔ NED swaps x and y and negates z; the map is its own inverse.

use nalgebra::{UnitQuaternion, Vector3};

/// Converts a vector from ENU (x east, y north, z up) to NED (x north, y east, z down).
pub fn enu_to_ned(v_enu: Vector3<f64>) -> Vector3<f64> {
    Vector3::new(v_enu.y, v_enu.x, -v_enu.z)
}

/// Converts a vector from NED to ENU.
pub fn ned_to_enu(v_ned: Vector3<f64>) -> Vector3<f64> {
    Vector3::new(v_ned.y, v_ned.x, -v_ned.z)
}

/// A NED→FRD attitude quaternion in MAVLink order `[w, x, y, z]`.
pub fn quaternion_to_wxyz(q: &UnitQuaternion<f64>) -> [f64; 4] {
    [q.w, q.i, q.j, q.k]
}

/// Roll, pitch and yaw (rad, ZYX Euler, NED/FRD as in MAVLink's ATTITUDE message).
pub fn euler_ned_frd(q: &UnitQuaternion<f64>) -> (f64, f64, f64) {
    q.euler_angles()
}

/// Roll and pitch (rad) of [`euler_ned_frd`], to the last bit, without the yaw: only the
/// rotation matrix's third row (and, at ±90° pitch, the first row's two entries) is
/// formed, as nalgebra forms it, and one `atan2` is saved. The attitude response fit
/// converts two attitudes per vehicle on every control tick.
pub fn roll_pitch_ned_frd(q: &UnitQuaternion<f64>) -> (f64, f64) {
    let (i, j, k, w) = (q.i, q.j, q.k, q.w);
    let (ww, ii, jj, kk) = (w * w, i * i, j * j, k * k);
    let wj = w * j * 2.0;
    let ik = i * k * 2.0;
    let wi = w * i * 2.0;
    let jk = j * k * 2.0;
    let m20 = ik - wj;
    if m20.abs() < 1.0 {
        let pitch = -m20.asin();
        let cos = pitch.cos();
        let roll = ((wi + jk) / cos).atan2((ww - ii - jj + kk) / cos);
        return (roll, pitch);
    }
    let (ij, wk) = (i * j * 2.0, w * k * 2.0);
    let (m01, m02) = (ij - wk, wj + ik);
    if m20 <= -1.0 {
        (m01.atan2(m02), std::f64::consts::FRAC_PI_2)
    } else {
        (-m01.atan2(-m02), -std::f64::consts::FRAC_PI_2)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roll_and_pitch_alone_are_eulers_to_the_bit() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let mut attitudes: Vec<UnitQuaternion<f64>> = (0..100_000)
            .map(|_| {
                UnitQuaternion::from_euler_angles(
                    rng.random_range(-3.2..3.2),
                    rng.random_range(-1.6..1.6),
                    rng.random_range(-3.2..3.2),
                )
            })
            .collect();
        // Straight up and straight down (the matrix entry reaches ±1) and level.
        for pitch in [
            std::f64::consts::FRAC_PI_2,
            -std::f64::consts::FRAC_PI_2,
            0.0,
        ] {
            for roll in [0.0, 0.4, -2.0] {
                attitudes.push(UnitQuaternion::from_euler_angles(roll, pitch, 0.7));
            }
        }
        for q in attitudes {
            let (roll, pitch, _) = euler_ned_frd(&q);
            assert_eq!(roll_pitch_ned_frd(&q), (roll, pitch), "{:?}", q.coords);
        }
    }

    #[test]
    fn north_is_positive_x_in_ned() {
        let north_enu = Vector3::new(0.0, 1.0, 0.0);
        assert_eq!(enu_to_ned(north_enu), Vector3::new(1.0, 0.0, 0.0));
    }

    #[test]
    fn east_is_positive_y_in_ned_and_up_is_negative_z() {
        assert_eq!(
            enu_to_ned(Vector3::new(1.0, 0.0, 0.0)),
            Vector3::new(0.0, 1.0, 0.0)
        );
        assert_eq!(
            enu_to_ned(Vector3::new(0.0, 0.0, 1.0)),
            Vector3::new(0.0, 0.0, -1.0)
        );
    }

    #[test]
    fn conversion_is_its_own_inverse() {
        let v = Vector3::new(1.5, -2.0, 7.25);
        assert_eq!(ned_to_enu(enu_to_ned(v)), v);
        assert_eq!(enu_to_ned(ned_to_enu(v)), v);
    }

    #[test]
    fn mavlink_quaternion_order_is_w_first() {
        // 90° yaw: nose east. w = cos 45°, z = sin 45°.
        let q = UnitQuaternion::from_euler_angles(0.0, 0.0, std::f64::consts::FRAC_PI_2);
        let [w, x, y, z] = quaternion_to_wxyz(&q);
        let h = std::f64::consts::FRAC_1_SQRT_2;
        assert!(
            (w - h).abs() < 1e-15 && x.abs() < 1e-15 && y.abs() < 1e-15 && (z - h).abs() < 1e-15
        );
        // The body x axis (nose) points east in NED.
        let nose = q * Vector3::x();
        assert!((nose - Vector3::new(0.0, 1.0, 0.0)).norm() < 1e-15);
    }
}
