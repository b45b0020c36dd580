//! The altitude loop: a PD law on height, z up, with a slow integral.
//!
//! `u_z = −k_pz·(z − z_cmd) − k_vz·v_z + k_iz·∫(z_cmd − z) dt`. The integral removes the
//! steady error a wrong thrust model or drag leaves; it only integrates within
//! [`INTEGRAL_BAND_M`] of the commanded height (a climb to altitude is flown by the PD
//! alone) and its term is kept within [`INTEGRAL_LIMIT_MPS2`]. With the integral the
//! closed loop is `s³ + k_vz·s² + k_pz·s + k_iz`, stable (Routh) iff `k_iz < k_pz·k_vz`. The paper prints `+k_pz(z − z_cmd) + k_vz·v_z`
//! with positive gains, which pushes a vehicle further from the commanded height: the
//! closed loop `z̈ = u_z` then has characteristic polynomial `s² − k_vz·s − k_pz`, with a
//! root in the right half-plane. With the sign corrected it is `s² + k_vz·s + k_pz`,
//! stable for any positive gains.

use crate::error::ControlError;

use super::vehicle::check_finite;

/// The integral only runs this close to the commanded height (m).
pub const INTEGRAL_BAND_M: f64 = 2.0;
/// Largest acceleration the integral term may add (m/s²).
pub const INTEGRAL_LIMIT_MPS2: f64 = 2.0;

/// Gains of the altitude loop.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AltitudeGains {
    k_pz: f64,
    k_vz: f64,
    k_iz: f64,
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
        Ok(Self {
            k_pz,
            k_vz,
            k_iz: 0.0,
        })
    }

    /// The same loop with the integral gain `k_iz` (1/s³), `0 ≤ k_iz < k_pz·k_vz`.
    ///
    /// # Errors
    /// [`ControlError`] for a non-finite or negative `k_iz`, or one that makes the loop
    /// unstable.
    pub fn with_integral(self, k_iz: f64) -> Result<Self, ControlError> {
        check_finite("k_iz", k_iz)?;
        if !(k_iz >= 0.0 && k_iz < self.k_pz * self.k_vz) {
            return Err(ControlError::OutOfRange {
                name: "k_iz",
                value: k_iz,
                expected: "in [0, k_pz·k_vz) (the Routh bound of s³ + k_vz·s² + k_pz·s + k_iz)",
            });
        }
        Ok(Self { k_iz, ..self })
    }

    /// The integral gain (1/s³).
    pub fn k_iz(&self) -> f64 {
        self.k_iz
    }

    /// The integral `∫(z_cmd − z) dt` (m·s) after `dt_s` more at height `z_m`: it grows
    /// only within `INTEGRAL_BAND_M` of the commanded height and while `hold` is false
    /// (the vertical command saturated), and its term stays within
    /// `INTEGRAL_LIMIT_MPS2`.
    pub fn integrate(&self, integral: f64, z_m: f64, z_cmd_m: f64, dt_s: f64, hold: bool) -> f64 {
        let error = z_cmd_m - z_m;
        if self.k_iz == 0.0 || hold || error.abs() > INTEGRAL_BAND_M || !dt_s.is_finite() {
            return integral;
        }
        let limit = INTEGRAL_LIMIT_MPS2 / self.k_iz;
        (integral + error * dt_s).clamp(-limit, limit)
    }

    /// The vertical acceleration command (m/s², z up) at height `z_m` and climb rate
    /// `vz_mps` (z up) for the commanded height `z_cmd_m`.
    pub fn acceleration(&self, z_m: f64, vz_mps: f64, z_cmd_m: f64) -> f64 {
        -self.k_pz * (z_m - z_cmd_m) - self.k_vz * vz_mps
    }

    /// The same with the integral term `k_iz·integral` (m/s², z up).
    pub fn acceleration_with(&self, z_m: f64, vz_mps: f64, z_cmd_m: f64, integral: f64) -> f64 {
        self.acceleration(z_m, vz_mps, z_cmd_m) + self.k_iz * integral
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
    fn the_integral_removes_a_constant_disturbance_and_is_bounded() {
        // A vehicle whose thrust model is 10 % weak: a constant −0.98 m/s² on its
        // acceleration. PD alone settles 0.98/k_pz = 0.98 m low; with k_iz = 0.1 (a
        // fortieth of the Routh bound 4) it returns within 1 cm in 120 s (slowest pole
        // of s³ + 4s² + s + 0.1 at −0.130 ± 0.099i: e^(−0.130·120) ≈ 2e−7).
        let gains = AltitudeGains::new(1.0, 4.0)
            .unwrap()
            .with_integral(0.1)
            .unwrap();
        let (mut z, mut vz, mut i) = (49.0, 0.0, 0.0);
        let dt = 1e-3;
        for _ in 0..120_000 {
            i = gains.integrate(i, z, 50.0, dt, false);
            let a = gains.acceleration_with(z, vz, 50.0, i) - 0.98;
            vz += a * dt;
            z += vz * dt;
        }
        assert!((z - 50.0).abs() < 0.01, "z = {z}");
        assert!(
            (gains.k_iz() * i - 0.98).abs() < 0.01,
            "term {}",
            gains.k_iz() * i
        );
        // Far from the commanded height, or held, it does not grow; and it is bounded.
        assert_eq!(gains.integrate(1.0, 40.0, 50.0, 1.0, false), 1.0);
        assert_eq!(gains.integrate(1.0, 49.5, 50.0, 1.0, true), 1.0);
        assert_eq!(gains.integrate(19.9, 49.0, 50.0, 1.0, false), 20.0);
        assert!(
            AltitudeGains::new(1.0, 4.0)
                .unwrap()
                .with_integral(4.0)
                .is_err()
        );
    }

    #[test]
    fn non_positive_gains_are_refused() {
        assert!(matches!(
            AltitudeGains::new(-1.0, 4.0),
            Err(ControlError::OutOfRange { name: "k_pz", .. })
        ));
    }
}
