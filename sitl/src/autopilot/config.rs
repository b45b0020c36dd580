//! What one emulated vehicle is made of: identity, profile, start state, telemetry rates,
//! wind. Validated once, when the vehicle is built.

use nalgebra::Vector3;

use super::estimator::EstimatorConfig;
use crate::profile::Profile;

/// Where and how a vehicle starts.
#[derive(Debug, Clone, PartialEq)]
pub struct StartState {
    /// Start position as a NED offset from the world reference (m). It becomes the
    /// vehicle's local origin.
    pub pos_world_ned_m: Vector3<f64>,
    /// Start velocity in NED (m/s); only used in the air.
    pub vel_ned_mps: Vector3<f64>,
    /// Heading (rad, NED yaw, 0 = north).
    pub yaw_rad: f64,
    /// On the ground and disarmed (false), or in the air, armed, with a pilot holding the
    /// start velocity until OFFBOARD (true).
    pub in_air: bool,
}

/// Whose autopilot the vehicle plays on the wire.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Personality {
    /// PX4 (the default).
    #[default]
    Px4,
    /// ArduPilot's ArduCopter ([`super::ardupilot`]); its EKF has a position
    /// `ekf_settle` after boot (arming is refused before).
    ArduPilot {
        /// How long after boot the EKF has a position.
        ekf_settle: std::time::Duration,
    },
}

/// Steady wind plus seeded gusts (a first-order Gauss–Markov process per axis).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WindConfig {
    /// Steady wind in NED (m/s).
    pub steady_ned_mps: Vector3<f64>,
    /// Standard deviation of the gusts (m/s); 0 disables them.
    pub gust_std_mps: f64,
    /// Correlation time of the gusts (s).
    pub gust_tau_s: f64,
}

impl Default for WindConfig {
    fn default() -> Self {
        Self {
            steady_ned_mps: Vector3::zeros(),
            gust_std_mps: 0.0,
            gust_tau_s: 2.0,
        }
    }
}

/// One vehicle.
#[derive(Debug, Clone, PartialEq)]
pub struct VehicleConfig {
    /// MAVLink system id (1..=250); component id is always 1.
    pub system_id: u8,
    /// The airframe.
    pub profile: Profile,
    /// The start state.
    pub start: StartState,
    /// Default rate of the high-rate streams ATTITUDE, ATTITUDE_QUATERNION,
    /// LOCAL_POSITION_NED and GLOBAL_POSITION_INT (Hz).
    pub fast_rate_hz: f64,
    /// Wind.
    pub wind: WindConfig,
    /// Seed of the vehicle's random numbers (gusts, and the estimate's errors).
    pub seed: u64,
    /// How the reported estimate differs from the truth (noise, drift, latency, faults).
    pub estimator: EstimatorConfig,
    /// The battery.
    pub battery: BatteryConfig,
    /// The MAVLink 2 signing key it boots with (from its key store or the command line);
    /// `None` accepts everything unsigned, as PX4 without a key does.
    pub signing: Option<crate::keystore::StoredKey>,
    /// Whose autopilot it plays (default PX4).
    pub personality: Personality,
}

/// The battery: its capacity and how much thrust its voltage sag costs.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BatteryConfig {
    /// Capacity (mAh); `None` keeps the profile's (BAT1_CAPACITY).
    pub capacity_mah: Option<f64>,
    /// Fraction of the motors' thrust lost when the battery is empty, linear in the
    /// charge used (0 = no sag; a real pack loses 15–25 % between full and empty when
    /// nothing compensates its voltage).
    pub sag: f64,
}

impl VehicleConfig {
    /// A vehicle on the ground at the world reference, `x500`, 50 Hz telemetry.
    pub fn new(system_id: u8, profile: Profile) -> Self {
        Self {
            system_id,
            profile,
            start: StartState {
                pos_world_ned_m: Vector3::zeros(),
                vel_ned_mps: Vector3::zeros(),
                yaw_rad: 0.0,
                in_air: false,
            },
            fast_rate_hz: 50.0,
            wind: WindConfig::default(),
            seed: u64::from(system_id),
            estimator: EstimatorConfig::default(),
            battery: BatteryConfig::default(),
            signing: None,
            personality: Personality::Px4,
        }
    }

    /// Checks the numbers a vehicle cannot fly with.
    ///
    /// # Errors
    /// A message naming the field and its value.
    pub fn validate(&self) -> Result<(), String> {
        if self.system_id == 0 || self.system_id > 250 {
            return Err(format!("system_id must be 1..=250, got {}", self.system_id));
        }
        let finite = |v: &Vector3<f64>| v.iter().all(|x| x.is_finite());
        if !finite(&self.start.pos_world_ned_m)
            || !finite(&self.start.vel_ned_mps)
            || !self.start.yaw_rad.is_finite()
        {
            return Err(format!(
                "vehicle {}: start state must be finite numbers",
                self.system_id
            ));
        }
        if !(self.fast_rate_hz > 0.0 && self.fast_rate_hz <= 1000.0) {
            return Err(format!(
                "vehicle {}: telemetry rate must be in (0, 1000] Hz, got {}",
                self.system_id, self.fast_rate_hz
            ));
        }
        let w = &self.wind;
        let gusts_ok = w.gust_std_mps >= 0.0 && w.gust_tau_s > 0.0;
        if !finite(&w.steady_ned_mps) || !gusts_ok {
            return Err(format!(
                "vehicle {}: wind needs finite steady wind, gust_std ≥ 0 and gust_tau > 0",
                self.system_id
            ));
        }
        let b = &self.battery;
        if !(b.sag.is_finite() && (0.0..=0.5).contains(&b.sag)) {
            return Err(format!(
                "vehicle {}: battery sag must be in [0, 0.5], got {}",
                self.system_id, b.sag
            ));
        }
        if let Some(c) = b.capacity_mah
            && !(c.is_finite() && (1.0..=1.0e6).contains(&c))
        {
            return Err(format!(
                "vehicle {}: battery capacity must be in [1, 1000000] mAh, got {c}",
                self.system_id
            ));
        }
        if let Personality::ArduPilot { ekf_settle } = self.personality
            && ekf_settle > std::time::Duration::from_secs(600)
        {
            return Err(format!(
                "vehicle {}: the ArduPilot EKF settle must be at most 600 s, got {} s",
                self.system_id,
                ekf_settle.as_secs_f64()
            ));
        }
        self.estimator
            .validate()
            .map_err(|e| format!("vehicle {}: estimator {e}", self.system_id))?;
        Ok(())
    }
}
