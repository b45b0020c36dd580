//! The altitude loop: a PD law on height, z up.
//!
//! `u_z = −k_pz·(z − z_cmd) − k_vz·v_z`. The paper prints `+k_pz(z − z_cmd) + k_vz·v_z`
//! with positive gains, which pushes a vehicle further from the commanded height: the
//! closed loop `z̈ = u_z` then has characteristic polynomial `s² − k_vz·s − k_pz`, with a
//! root in the right half-plane. With the sign corrected it is `s² + k_vz·s + k_pz`,
//! stable for any positive gains.

use crate::error::ControlError;

use super::vehicle::check_finite;

/// Gains of the altitude PD loop.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AltitudeGains {
    k_pz: f64,
    k_vz: f64,
}

impl AltitudeGains {
    /// Validates `k_pz > 0` (1/s²) and `k_vz > 0` (1/s).
    ///
    /// # Errors
    /// [`ControlError`] naming the gain that is not finite or not positive.
    pub fn new(k_pz: f64, k_vz: f64) -> Result<Self, ControlError> {
        for (name, value) in [("k_pz", k_pz), ("k_vz", k_vz)] {
            check_finite(name, value)?;
            if value <= 0.0 {
                return Err(ControlError::OutOfRange {
                    name,
                    value,
                    expected: "greater than zero",
                });
            }
        }
        Ok(Self { k_pz, k_vz })
    }

    /// The vertical acceleration command (m/s², z up) at height `z_m` and climb rate
    /// `vz_mps` (z up) for the commanded height `z_cmd_m`.
    pub fn acceleration(&self, z_m: f64, vz_mps: f64, z_cmd_m: f64) -> f64 {
        -self.k_pz * (z_m - z_cmd_m) - self.k_vz * vz_mps
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Integrates z̈ = u_z with a small explicit step and returns the final height.
    fn fly(law: impl Fn(f64, f64) -> f64, z0: f64, vz0: f64, seconds: f64) -> f64 {
        let dt = 1e-3;
        let (mut z, mut vz) = (z0, vz0);
        for _ in 0..(seconds / dt) as usize {
            let a = law(z, vz);
            vz += a * dt;
            z += vz * dt;
        }
        z
    }

    #[test]
    fn corrected_sign_converges_to_the_commanded_height() {
        let gains = AltitudeGains::new(1.0, 4.0).unwrap();
        let z = fly(|z, vz| gains.acceleration(z, vz, 50.0), 0.0, 7.0, 60.0);
        // Slowest pole of s² + 4s + 1 is −2 + √3 ≈ −0.268: after 60 s the error is
        // below 50·e^(−16) ≈ 6e−6 m (times a modest modal factor).
        assert!((z - 50.0).abs() < 1e-3, "z = {z}");
    }

    #[test]
    fn printed_sign_diverges() {
        let z = fly(|z, vz| 1.0 * (z - 50.0) + 4.0 * vz, 0.0, 7.0, 5.0);
        assert!((z - 50.0).abs() > 1e3, "z = {z}");
    }

    #[test]
    fn non_positive_gains_are_refused() {
        assert!(matches!(
            AltitudeGains::new(-1.0, 4.0),
            Err(ControlError::OutOfRange { name: "k_pz", .. })
        ));
    }
}
