//! Vehicle profiles: the physical numbers and controller gains of an emulated quadrotor.
//!
//! | profile | mass | thrust/weight | hover | motor lag | drag | used for |
//! |---|---|---|---|---|---|---|
//! | `ideal` | 1.0 kg | 5 | 0.2 | 3 ms | 0 | reproducing the paper: large margin, attitude fast enough (~40 rad/s) for the paper's gains |
//! | `x500` | 2.0 kg | 2 | 0.5 | 30 ms | 0.10 /s | a Holybro X500-class frame |
//!
//! The x500 inertia, arm and moment constant follow PX4's Gazebo x500 model
//! (`Ixx = Iyy = 0.0217`, `Izz = 0.040` kg·m², motors at ±0.174 m, moment constant
//! 0.016 m); its motor lag is the slower of Gazebo's up/down time constants.

use std::fmt;
use std::str::FromStr;

use nalgebra::Vector3;

/// Standard gravity (m/s²), shared with the other side through `ringswarm-wire`.
pub use ringswarm_wire::geo::GRAVITY_MPS2;

/// Gains of the PX4-like attitude and rate controllers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AttitudeGains {
    /// Attitude P (1/s) for roll/pitch and for yaw.
    pub attitude_p: Vector3<f64>,
    /// Rate P (1/s), applied to the rate error to give angular acceleration.
    pub rate_p: Vector3<f64>,
    /// Rate I (1/s²).
    pub rate_i: Vector3<f64>,
    /// Rate D (dimensionless), on the measured rate's derivative.
    pub rate_d: Vector3<f64>,
    /// Largest commanded body rate (rad/s).
    pub max_rate_rps: Vector3<f64>,
}

/// A vehicle profile.
#[derive(Debug, Clone, PartialEq)]
pub struct Profile {
    /// Name, as used in configs and on the command line.
    pub name: &'static str,
    /// Mass (kg).
    pub mass_kg: f64,
    /// Principal moments of inertia about body x, y, z (kg·m²).
    pub inertia_kg_m2: Vector3<f64>,
    /// Motor distance along body x and y from the centre (m), X configuration.
    pub motor_offset_m: f64,
    /// Thrust of one motor at full command (N).
    pub max_motor_thrust_n: f64,
    /// Yaw reaction moment per newton of thrust (m).
    pub moment_constant_m: f64,
    /// First-order motor time constant (s).
    pub motor_time_constant_s: f64,
    /// Linear drag: acceleration per m/s of airspeed (1/s).
    pub linear_drag_per_s: f64,
    /// Attitude and rate controller gains.
    pub gains: AttitudeGains,
}

impl Profile {
    /// Collective thrust at full command (N).
    pub fn max_thrust_n(&self) -> f64 {
        4.0 * self.max_motor_thrust_n
    }

    /// The normalised thrust that hovers (PX4's `MPC_THR_HOVER`).
    pub fn hover_throttle(&self) -> f64 {
        self.mass_kg * GRAVITY_MPS2 / self.max_thrust_n()
    }

    /// The `ideal` profile: thrust-to-weight 5, fast motors, no drag.
    pub fn ideal() -> Self {
        Self {
            name: "ideal",
            mass_kg: 1.0,
            inertia_kg_m2: Vector3::new(0.003, 0.003, 0.006),
            motor_offset_m: 0.15,
            max_motor_thrust_n: 5.0 * GRAVITY_MPS2 / 4.0,
            moment_constant_m: 0.016,
            motor_time_constant_s: 0.003,
            linear_drag_per_s: 0.0,
            gains: AttitudeGains {
                attitude_p: Vector3::new(40.0, 40.0, 8.0),
                rate_p: Vector3::new(160.0, 160.0, 40.0),
                rate_i: Vector3::new(40.0, 40.0, 10.0),
                rate_d: Vector3::new(0.0, 0.0, 0.0),
                max_rate_rps: Vector3::new(20.0, 20.0, 5.0),
            },
        }
    }

    /// The `x500` profile: about 2 kg, thrust-to-weight 2, 30 ms motors, mild drag.
    pub fn x500() -> Self {
        Self {
            name: "x500",
            mass_kg: 2.0,
            inertia_kg_m2: Vector3::new(0.0217, 0.0217, 0.040),
            motor_offset_m: 0.174,
            max_motor_thrust_n: 2.0 * 2.0 * GRAVITY_MPS2 / 4.0,
            moment_constant_m: 0.016,
            motor_time_constant_s: 0.03,
            linear_drag_per_s: 0.10,
            gains: AttitudeGains {
                attitude_p: Vector3::new(6.5, 6.5, 2.8),
                rate_p: Vector3::new(18.0, 18.0, 8.0),
                rate_i: Vector3::new(8.0, 8.0, 4.0),
                rate_d: Vector3::new(0.0, 0.0, 0.0),
                max_rate_rps: Vector3::new(3.8, 3.8, 3.5),
            },
        }
    }

    /// The `arducopter` profile: ArduPilot SITL's built-in quad (`SIM_Frame.cpp`: 3 kg,
    /// 0.35 m diagonal, hover throttle 0.39, inertia m·0.25·(d/2)² about x and y, twice
    /// that about z) with ArduCopter's attitude P gain (ATC_ANG_RLL_P 4.5). Its drag is
    /// the linear part only: the momentum drag at hover, 0.72 N/(m/s) for 3 kg = 0.24 1/s;
    /// SITL's quadratic part (0.101 N/(m/s)², 0.034 1/m per kg) is not modelled, so above
    /// about 7 m/s this airframe is slower to lose speed than ArduPilot's.
    pub fn arducopter() -> Self {
        let mass_kg = 3.0;
        let half_diagonal_m: f64 = 0.175;
        let ixx = mass_kg * 0.25 * half_diagonal_m * half_diagonal_m;
        Self {
            name: "arducopter",
            mass_kg,
            inertia_kg_m2: Vector3::new(ixx, ixx, 2.0 * ixx),
            motor_offset_m: half_diagonal_m,
            max_motor_thrust_n: mass_kg * GRAVITY_MPS2 / (4.0 * 0.39),
            moment_constant_m: 0.016,
            motor_time_constant_s: 0.03,
            linear_drag_per_s: 0.24,
            gains: AttitudeGains {
                attitude_p: Vector3::new(4.5, 4.5, 4.5),
                rate_p: Vector3::new(18.0, 18.0, 8.0),
                rate_i: Vector3::new(8.0, 8.0, 4.0),
                rate_d: Vector3::new(0.0, 0.0, 0.0),
                max_rate_rps: Vector3::new(3.8, 3.8, 3.5),
            },
        }
    }

    /// The same airframe with another true mass (kg), hover throttle (the motors' thrust
    /// for that mass) or linear drag (1/s); `None` keeps the profile's.
    ///
    /// # Errors
    /// The first value out of range, named (`mass_kg` in (0, 1000], `hover_throttle` in
    /// [0.01, 0.99], `drag_per_s` in [0, 10]).
    pub fn with_airframe(
        mut self,
        mass_kg: Option<f64>,
        hover_throttle: Option<f64>,
        drag_per_s: Option<f64>,
    ) -> Result<Self, String> {
        let hover = hover_throttle.unwrap_or(self.hover_throttle());
        if let Some(m) = mass_kg {
            if !(m.is_finite() && m > 0.0 && m <= 1000.0) {
                return Err(format!("mass_kg must be in (0, 1000] kg, got {m}"));
            }
            self.mass_kg = m;
        }
        if !(hover.is_finite() && (0.01..=0.99).contains(&hover)) {
            return Err(format!(
                "hover_throttle must be in [0.01, 0.99], got {hover}"
            ));
        }
        self.max_motor_thrust_n = self.mass_kg * GRAVITY_MPS2 / hover / 4.0;
        if let Some(d) = drag_per_s {
            if !(d.is_finite() && (0.0..=10.0).contains(&d)) {
                return Err(format!("drag_per_s must be in [0, 10] 1/s, got {d}"));
            }
            self.linear_drag_per_s = d;
        }
        Ok(self)
    }

    /// Every profile, for listings.
    pub fn all() -> [Self; 3] {
        [Self::ideal(), Self::x500(), Self::arducopter()]
    }
}

/// A profile name that is not known.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UnknownProfile(pub String);

impl fmt::Display for UnknownProfile {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let known: Vec<&str> = Profile::all().iter().map(|p| p.name).collect();
        write!(
            f,
            "unknown vehicle profile \"{}\" (known: {})",
            self.0,
            known.join(", ")
        )
    }
}

impl std::error::Error for UnknownProfile {}

impl FromStr for Profile {
    type Err = UnknownProfile;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Profile::all()
            .into_iter()
            .find(|p| p.name == s)
            .ok_or_else(|| UnknownProfile(s.to_owned()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn documented_numbers_hold() {
        let x = Profile::x500();
        assert!((x.max_thrust_n() / (x.mass_kg * GRAVITY_MPS2) - 2.0).abs() < 1e-12);
        assert!((x.hover_throttle() - 0.5).abs() < 1e-12);
        let i = Profile::ideal();
        assert!((i.hover_throttle() - 0.2).abs() < 1e-12);
        let a = Profile::arducopter();
        assert!((a.hover_throttle() - 0.39).abs() < 1e-12);
        // ArduPilot SITL's inertia: 3 kg · 0.25 · (0.35 m / 2)² = 0.0230 kg·m².
        assert!((a.inertia_kg_m2.x - 0.022_968_75).abs() < 1e-12);
        assert_eq!(
            "arducopter".parse::<Profile>().map(|p| p.name),
            Ok("arducopter")
        );
    }

    #[test]
    fn unknown_profile_names_the_known_ones() {
        let err = "x600".parse::<Profile>().unwrap_err();
        assert_eq!(
            err.to_string(),
            "unknown vehicle profile \"x600\" (known: ideal, x500, arducopter)"
        );
    }
}
