//! The vehicle model the law needs: mass and how normalised thrust maps to newtons.
//!
//! Thrust is taken as proportional to the normalised command (PX4's default thrust
//! model), so `thrust_norm = T / T_max` and hover is at `m·g / T_max`.

use crate::error::ControlError;

/// Standard gravity (m/s²), shared with the other side through `ringswarm-wire`.
pub use ringswarm_wire::geo::GRAVITY_MPS2;

/// Mass and thrust authority of one vehicle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VehicleModel {
    mass_kg: f64,
    max_thrust_n: f64,
}

impl VehicleModel {
    /// A model from mass and the normalised thrust that hovers (PX4's `MPC_THR_HOVER`).
    ///
    /// # Errors
    /// [`ControlError`] for a non-finite or non-positive mass, or a hover throttle outside
    /// `(0, 1)`.
    pub fn from_hover_throttle(mass_kg: f64, hover_throttle: f64) -> Result<Self, ControlError> {
        check_mass(mass_kg)?;
        check_finite("hover_throttle", hover_throttle)?;
        if !(hover_throttle > 0.0 && hover_throttle < 1.0) {
            return Err(ControlError::OutOfRange {
                name: "hover_throttle",
                value: hover_throttle,
                expected: "strictly between 0 and 1",
            });
        }
        Ok(Self {
            mass_kg,
            max_thrust_n: mass_kg * GRAVITY_MPS2 / hover_throttle,
        })
    }

    /// A model from mass and the total thrust at full throttle.
    ///
    /// # Errors
    /// [`ControlError`] for a non-finite or non-positive mass, or a maximum thrust that
    /// cannot lift the vehicle.
    pub fn from_max_thrust(mass_kg: f64, max_thrust_n: f64) -> Result<Self, ControlError> {
        check_mass(mass_kg)?;
        check_finite("max_thrust_n", max_thrust_n)?;
        if max_thrust_n <= mass_kg * GRAVITY_MPS2 {
            return Err(ControlError::OutOfRange {
                name: "max_thrust_n",
                value: max_thrust_n,
                expected: "greater than the weight m·g",
            });
        }
        Ok(Self {
            mass_kg,
            max_thrust_n,
        })
    }

    /// Mass (kg).
    pub fn mass_kg(&self) -> f64 {
        self.mass_kg
    }

    /// Total thrust at full throttle (N).
    pub fn max_thrust_n(&self) -> f64 {
        self.max_thrust_n
    }

    /// Normalised thrust that hovers.
    pub fn hover_throttle(&self) -> f64 {
        self.mass_kg * GRAVITY_MPS2 / self.max_thrust_n
    }

    /// Largest specific thrust (thrust / mass) the motors can give (m/s²).
    pub fn max_specific_thrust_mps2(&self) -> f64 {
        self.max_thrust_n / self.mass_kg
    }
}

fn check_mass(mass_kg: f64) -> Result<(), ControlError> {
    check_finite("mass_kg", mass_kg)?;
    if mass_kg <= 0.0 {
        return Err(ControlError::OutOfRange {
            name: "mass_kg",
            value: mass_kg,
            expected: "greater than zero",
        });
    }
    Ok(())
}

pub(crate) fn check_finite(name: &'static str, value: f64) -> Result<(), ControlError> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(ControlError::NonFinite { name, value })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn both_constructors_agree() {
        let a = VehicleModel::from_hover_throttle(2.0, 0.5).unwrap();
        let b = VehicleModel::from_max_thrust(2.0, 4.0 * GRAVITY_MPS2).unwrap();
        assert!((a.max_thrust_n() - b.max_thrust_n()).abs() < 1e-12);
        assert!((b.hover_throttle() - 0.5).abs() < 1e-15);
    }

    #[test]
    fn impossible_models_are_refused() {
        assert!(matches!(
            VehicleModel::from_hover_throttle(2.0, 1.0),
            Err(ControlError::OutOfRange {
                name: "hover_throttle",
                ..
            })
        ));
        assert!(matches!(
            VehicleModel::from_max_thrust(2.0, 10.0),
            Err(ControlError::OutOfRange {
                name: "max_thrust_n",
                ..
            })
        ));
        assert!(matches!(
            VehicleModel::from_hover_throttle(f64::NAN, 0.5),
            Err(ControlError::NonFinite {
                name: "mass_kg",
                ..
            })
        ));
    }
}
