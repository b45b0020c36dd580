//! The emulator's TOML configuration (`ringswarm sitl --config FILE`).
//!
//! ```toml
//! [world]                      # one geodetic reference for every vehicle
//! latitude_deg = 47.397742
//! longitude_deg = 8.545594
//! altitude_amsl_m = 488.0
//! ground_down_m = 0.0          # the ground as a NED z offset from the reference (m)
//!
//! [faults]                     # every link, both directions
//! loss_pct = 0.0
//! latency_ms = 0.0
//! jitter_ms = 0.0
//! duplicate_pct = 0.0
//! seed = 1
//!
//! [[vehicle]]                  # one table per vehicle, in instance order (ports 14580+i …)
//! system_id = 1                # default: instance + 1
//! profile = "x500"             # "x500" (default), "ideal" or "arducopter"
//! autopilot = "px4"            # whose autopilot it plays on the wire: "px4" or "ardupilot"
//! ekf_settle_s = 5.0           # ardupilot: seconds after boot before its EKF has a position
//! start_ned_m = [0.0, 0.0, 0.0]    # NED offset from the reference; becomes its local origin
//! velocity_ned_mps = [0.0, 0.0, 0.0]
//! yaw_deg = 0.0
//! in_air = false               # true: armed, a pilot holds velocity_ned_mps until OFFBOARD
//! telemetry_rate_hz = 50.0
//! wind_ned_mps = [0.0, 0.0, 0.0]
//! gust_std_mps = 0.0
//! gust_tau_s = 2.0
//! mass_kg = 2.0                # the true airframe, where it differs from the profile
//! hover_throttle = 0.5         #   (sets the motors' thrust for that mass)
//! drag_per_s = 0.1
//! position_noise_m = 0.0       # what the estimator reports: white noise (1 sigma),
//! velocity_noise_mps = 0.0
//! drift_std_m = 0.0            #   a slow GPS-like horizontal drift and its correlation time,
//! drift_tau_s = 60.0
//! estimator_latency_ms = 0.0   #   and a delay
//! battery_sag = 0.0            # thrust lost when the battery is empty (0..0.5)
//! battery_capacity_mah = 5000.0    # default: the profile's BAT1_CAPACITY
//! ```
//!
//! Unknown keys are refused; every problem found after parsing is reported at once.

use nalgebra::Vector3;
use serde::Deserialize;

use std::time::Duration;

use crate::autopilot::estimator::EstimatorConfig;
use crate::autopilot::{BatteryConfig, Personality, StartState, VehicleConfig, WindConfig};
use crate::profile::Profile;
use crate::udp::LinkFaults;
use crate::world::{Geodetic, World};

/// A parsed and validated emulator configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct SitlConfig {
    /// The world.
    pub world: World,
    /// Faults on every link.
    pub faults: LinkFaults,
    /// Seed of the fault injection.
    pub fault_seed: u64,
    /// The vehicles, in instance order.
    pub vehicles: Vec<VehicleConfig>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawConfig {
    #[serde(default)]
    world: RawWorld,
    #[serde(default)]
    faults: RawFaults,
    #[serde(default)]
    vehicle: Vec<EmulatedVehicle>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct RawWorld {
    latitude_deg: f64,
    longitude_deg: f64,
    altitude_amsl_m: f64,
    ground_down_m: f64,
}

impl Default for RawWorld {
    fn default() -> Self {
        let w = World::default();
        Self {
            latitude_deg: w.reference.lat_deg,
            longitude_deg: w.reference.lon_deg,
            altitude_amsl_m: w.reference.alt_amsl_m,
            ground_down_m: w.ground_down_m,
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct RawFaults {
    loss_pct: f64,
    latency_ms: f64,
    jitter_ms: f64,
    duplicate_pct: f64,
    seed: u64,
}

impl Default for RawFaults {
    fn default() -> Self {
        Self {
            loss_pct: 0.0,
            latency_ms: 0.0,
            jitter_ms: 0.0,
            duplicate_pct: 0.0,
            seed: 1,
        }
    }
}

/// One emulated vehicle as the emulator's schema says it (the `[[vehicle]]` table of
/// `ringswarm sitl --config`, NED about the world's reference): the one description every
/// emulator configuration is read into, and built from by [`EmulatedVehicle::build`]. A
/// coordinator file's `[[vehicle]]` and `[emulator]` tables are translated into it.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EmulatedVehicle {
    /// MAVLink system id (default: instance + 1).
    pub system_id: Option<u8>,
    /// Profile: `x500` or `ideal`.
    #[serde(default = "default_profile")]
    pub profile: String,
    /// Start position: NED offset from the world's reference (m); becomes its origin.
    #[serde(default)]
    pub start_ned_m: [f64; 3],
    /// Start velocity (m/s, NED).
    #[serde(default)]
    pub velocity_ned_mps: [f64; 3],
    /// Start heading (deg).
    #[serde(default)]
    pub yaw_deg: f64,
    /// Started armed in the air, a pilot holding `velocity_ned_mps` until OFFBOARD.
    #[serde(default)]
    pub in_air: bool,
    /// Rate of the fast telemetry streams (Hz).
    #[serde(default = "default_rate")]
    pub telemetry_rate_hz: f64,
    /// Steady wind (m/s, NED).
    #[serde(default)]
    pub wind_ned_mps: [f64; 3],
    /// Gusts: standard deviation (m/s) and correlation time (s).
    #[serde(default)]
    pub gust_std_mps: f64,
    /// See `gust_std_mps`.
    #[serde(default = "default_gust_tau")]
    pub gust_tau_s: f64,
    /// The true airframe where it differs from the profile: mass (kg).
    pub mass_kg: Option<f64>,
    /// True hover throttle (0..1): sets the motors' thrust for the true mass.
    pub hover_throttle: Option<f64>,
    /// True linear drag (1/s).
    pub drag_per_s: Option<f64>,
    /// What its estimator reports: white noise on each position axis (m, 1 sigma).
    #[serde(default)]
    pub position_noise_m: f64,
    /// White noise on each velocity axis (m/s, 1 sigma).
    #[serde(default)]
    pub velocity_noise_mps: f64,
    /// A slow GPS-like horizontal drift (m, 1 sigma) and its correlation time (s).
    #[serde(default)]
    pub drift_std_m: f64,
    /// See `drift_std_m`.
    #[serde(default = "default_drift_tau")]
    pub drift_tau_s: f64,
    /// The age of what it reports (ms).
    #[serde(default)]
    pub estimator_latency_ms: f64,
    /// Thrust lost when the battery is empty (0..0.5).
    #[serde(default)]
    pub battery_sag: f64,
    /// Battery capacity (mAh; default the profile's BAT1_CAPACITY).
    pub battery_capacity_mah: Option<f64>,
    /// Whose autopilot it plays: `px4` (default; `auto` too) or `ardupilot`.
    #[serde(default = "default_autopilot")]
    pub autopilot: String,
    /// ArduPilot: seconds after boot before its EKF has a position and it may arm.
    #[serde(default = "default_ekf_settle")]
    pub ekf_settle_s: f64,
}

fn default_autopilot() -> String {
    "px4".to_owned()
}

/// ArduPilot SITL takes about 40 s; the emulator's default is shorter, as a test needs.
fn default_ekf_settle() -> f64 {
    5.0
}

impl Default for EmulatedVehicle {
    fn default() -> Self {
        Self {
            system_id: None,
            profile: default_profile(),
            start_ned_m: [0.0; 3],
            velocity_ned_mps: [0.0; 3],
            yaw_deg: 0.0,
            in_air: false,
            telemetry_rate_hz: default_rate(),
            wind_ned_mps: [0.0; 3],
            gust_std_mps: 0.0,
            gust_tau_s: default_gust_tau(),
            mass_kg: None,
            hover_throttle: None,
            drag_per_s: None,
            position_noise_m: 0.0,
            velocity_noise_mps: 0.0,
            drift_std_m: 0.0,
            drift_tau_s: default_drift_tau(),
            estimator_latency_ms: 0.0,
            battery_sag: 0.0,
            battery_capacity_mah: None,
            autopilot: default_autopilot(),
            ekf_settle_s: default_ekf_settle(),
        }
    }
}

/// How a configuration names the keys of an [`EmulatedVehicle`] in its messages: a
/// prefix for the vehicle's own keys, one for the true airframe's and one for the
/// estimator's and battery's (a sitl file: `vehicle[i].` for all three; a coordinator
/// file: `vehicle[i].`, `vehicle[i].airframe.` and `emulator.`).
#[derive(Debug, Clone, Copy)]
pub struct KeyNames<'a> {
    /// Before `profile`, and the vehicle named in a problem of its start or rates.
    pub vehicle: &'a str,
    /// Before `mass_kg`, `hover_throttle`, `drag_per_s`.
    pub airframe: &'a str,
    /// Before the estimator's and the battery's keys.
    pub estimator: &'a str,
}

impl EmulatedVehicle {
    /// The vehicle's configuration, as system `system_id`.
    ///
    /// # Errors
    /// Every problem, each naming its key as `names` says: an unknown profile, an
    /// airframe the profile cannot take, an estimator or battery number out of range,
    /// a start state or rate the vehicle refuses.
    pub fn build(&self, system_id: u8, names: &KeyNames<'_>) -> Result<VehicleConfig, Vec<String>> {
        let mut problems = Vec::new();
        let est = names.estimator;
        let mut within = |key: &str, value: f64, lo: f64, hi: f64, unit: &str| {
            let good = value.is_finite() && value >= lo && value <= hi;
            if !good {
                problems.push(format!(
                    "{est}{key} must be a finite number in [{lo}, {hi}]{unit}, got {value}"
                ));
            }
            good
        };
        within("position_noise_m", self.position_noise_m, 0.0, 100.0, " m");
        within(
            "velocity_noise_mps",
            self.velocity_noise_mps,
            0.0,
            10.0,
            " m/s",
        );
        within("drift_std_m", self.drift_std_m, 0.0, 100.0, " m");
        within(
            "estimator_latency_ms",
            self.estimator_latency_ms,
            0.0,
            2000.0,
            " ms",
        );
        within("battery_sag", self.battery_sag, 0.0, 0.5, "");
        if let Some(c) = self.battery_capacity_mah {
            within("battery_capacity_mah", c, 1.0, 1.0e6, " mAh");
        }
        if !(self.drift_tau_s.is_finite() && self.drift_tau_s > 0.0 && self.drift_tau_s <= 1.0e4) {
            problems.push(format!(
                "{est}drift_tau_s must be a finite number in (0, 10000] s, got {}",
                self.drift_tau_s
            ));
        }
        let rate = self.telemetry_rate_hz;
        if !(rate.is_finite() && rate > 0.0 && rate <= 1000.0) {
            problems.push(format!(
                "{est}telemetry_rate_hz must be a finite number in (0, 1000] Hz, got {rate}"
            ));
        }
        let profile = match self.profile.parse::<Profile>() {
            Ok(p) => match p.with_airframe(self.mass_kg, self.hover_throttle, self.drag_per_s) {
                Ok(p) => Some(p),
                Err(e) => {
                    problems.push(format!("{}{e}", names.airframe));
                    None
                }
            },
            Err(e) => {
                problems.push(format!("{}profile: {e}", names.vehicle));
                None
            }
        };
        let personality = match self.autopilot.as_str() {
            "px4" | "auto" => Some(Personality::Px4),
            "ardupilot" => {
                let settle = self.ekf_settle_s;
                if settle.is_finite() && (0.0..=600.0).contains(&settle) {
                    Some(Personality::ArduPilot {
                        ekf_settle: Duration::from_secs_f64(settle),
                    })
                } else {
                    problems.push(format!(
                        "{est}ekf_settle_s must be a finite number in [0, 600] s, got {settle}"
                    ));
                    None
                }
            }
            other => {
                problems.push(format!(
                    "{}autopilot = \"{other}\" is not one of \"px4\", \"ardupilot\" (\"auto\" plays PX4)",
                    names.vehicle
                ));
                None
            }
        };
        let (Some(profile), Some(personality)) =
            (profile.filter(|_| problems.is_empty()), personality)
        else {
            return Err(problems);
        };
        let cfg = VehicleConfig {
            system_id,
            profile,
            start: StartState {
                pos_world_ned_m: Vector3::from(self.start_ned_m),
                vel_ned_mps: Vector3::from(self.velocity_ned_mps),
                yaw_rad: self.yaw_deg.to_radians(),
                in_air: self.in_air,
            },
            fast_rate_hz: self.telemetry_rate_hz,
            wind: WindConfig {
                steady_ned_mps: Vector3::from(self.wind_ned_mps),
                gust_std_mps: self.gust_std_mps,
                gust_tau_s: self.gust_tau_s,
            },
            seed: u64::from(system_id),
            estimator: EstimatorConfig {
                position_noise_m: self.position_noise_m,
                velocity_noise_mps: self.velocity_noise_mps,
                drift_std_m: self.drift_std_m,
                drift_tau_s: self.drift_tau_s,
                latency: Duration::from_secs_f64(self.estimator_latency_ms / 1000.0),
                faults: Vec::new(),
            },
            battery: BatteryConfig {
                capacity_mah: self.battery_capacity_mah,
                sag: self.battery_sag,
            },
            signing: None,
            personality,
        };
        cfg.validate()
            .map_err(|e| vec![format!("{}: {e}", names.vehicle.trim_end_matches('.'))])?;
        Ok(cfg)
    }
}

fn default_drift_tau() -> f64 {
    60.0
}

fn default_profile() -> String {
    "x500".to_owned()
}

fn default_rate() -> f64 {
    50.0
}

fn default_gust_tau() -> f64 {
    2.0
}

impl SitlConfig {
    /// Parses and validates a configuration.
    ///
    /// # Errors
    /// A TOML or unknown-key error from the parser, or every validation problem, one per
    /// line, each naming the key and the value.
    pub fn from_toml(text: &str) -> Result<Self, String> {
        let raw: RawConfig = toml::from_str(text).map_err(|e| e.to_string())?;
        let mut problems = Vec::new();
        let w = &raw.world;
        if !(-89.0..=89.0).contains(&w.latitude_deg) {
            problems.push(format!(
                "world.latitude_deg must be within ±89°, got {}",
                w.latitude_deg
            ));
        }
        if !(-180.0..=180.0).contains(&w.longitude_deg) {
            problems.push(format!(
                "world.longitude_deg must be within ±180°, got {}",
                w.longitude_deg
            ));
        }
        for (key, v) in [
            ("world.altitude_amsl_m", w.altitude_amsl_m),
            ("world.ground_down_m", w.ground_down_m),
        ] {
            if !v.is_finite() {
                problems.push(format!("{key} must be a finite number, got {v}"));
            }
        }
        let f = &raw.faults;
        let faults = LinkFaults::from_percent_and_ms(
            f.loss_pct,
            f.latency_ms,
            f.jitter_ms,
            f.duplicate_pct,
            [
                "faults.loss_pct",
                "faults.latency_ms",
                "faults.jitter_ms",
                "faults.duplicate_pct",
            ],
        )
        .unwrap_or_else(|why| {
            problems.push(why);
            LinkFaults::default()
        });
        if raw.vehicle.is_empty() {
            problems.push("no [[vehicle]] table: at least one vehicle is needed".to_owned());
        }
        let world = World {
            reference: Geodetic {
                lat_deg: w.latitude_deg,
                lon_deg: w.longitude_deg,
                alt_amsl_m: w.altitude_amsl_m,
            },
            ground_down_m: w.ground_down_m,
        };
        let mut vehicles = Vec::new();
        let mut seen_ids = Vec::new();
        for (i, v) in raw.vehicle.iter().enumerate() {
            let system_id = v.system_id.unwrap_or((i + 1).min(255) as u8);
            if seen_ids.contains(&system_id) {
                problems.push(format!("vehicle[{i}].system_id {system_id} is used twice"));
            }
            seen_ids.push(system_id);
            let prefix = format!("vehicle[{i}].");
            let names = KeyNames {
                vehicle: &prefix,
                airframe: &prefix,
                estimator: &prefix,
            };
            let cfg = match v.build(system_id, &names) {
                Ok(cfg) => cfg,
                Err(found) => {
                    problems.extend(found);
                    continue;
                }
            };
            if v.start_ned_m[2] > w.ground_down_m {
                problems.push(format!(
                    "vehicle[{i}].start_ned_m is below the ground (z = {} > ground_down_m = {})",
                    v.start_ned_m[2], w.ground_down_m
                ));
            }
            vehicles.push(cfg);
        }
        if !problems.is_empty() {
            return Err(problems.join("\n"));
        }
        Ok(Self {
            world,
            faults,
            fault_seed: f.seed,
            vehicles,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn a_full_file_parses() {
        let cfg = SitlConfig::from_toml(
            r#"
            [world]
            ground_down_m = 20.0
            [faults]
            loss_pct = 20.0
            latency_ms = 20.0
            jitter_ms = 10.0
            [[vehicle]]
            profile = "ideal"
            start_ned_m = [20.0, 0.0, 0.0]
            velocity_ned_mps = [4.0, 9.0, 0.0]
            in_air = true
            [[vehicle]]
            system_id = 7
            "#,
        )
        .unwrap();
        assert_eq!(cfg.vehicles.len(), 2);
        assert_eq!(cfg.vehicles[0].system_id, 1);
        assert_eq!(cfg.vehicles[1].system_id, 7);
        assert_eq!(cfg.vehicles[0].profile.name, "ideal");
        assert!(cfg.vehicles[0].start.in_air);
        assert_eq!(cfg.world.ground_down_m, 20.0);
        assert!((cfg.faults.loss - 0.2).abs() < 1e-12);
        assert_eq!(cfg.faults.latency, Duration::from_millis(20));
    }

    #[test]
    fn the_reality_knobs_reach_the_vehicle() {
        let cfg = SitlConfig::from_toml(
            r#"
            [[vehicle]]
            mass_kg = 2.2
            hover_throttle = 0.55
            drag_per_s = 0.3
            position_noise_m = 0.2
            velocity_noise_mps = 0.05
            drift_std_m = 1.0
            drift_tau_s = 30.0
            estimator_latency_ms = 40.0
            battery_sag = 0.2
            battery_capacity_mah = 800.0
            "#,
        )
        .unwrap();
        let v = &cfg.vehicles[0];
        assert_eq!(v.profile.mass_kg, 2.2);
        assert!((v.profile.hover_throttle() - 0.55).abs() < 1e-12);
        assert_eq!(v.profile.linear_drag_per_s, 0.3);
        assert_eq!(v.estimator.position_noise_m, 0.2);
        assert_eq!(v.estimator.latency, Duration::from_millis(40));
        assert_eq!(v.battery.sag, 0.2);
        assert_eq!(v.battery.capacity_mah, Some(800.0));
        let err = SitlConfig::from_toml("[[vehicle]]\nhover_throttle = 1.5\nbattery_sag = 0.9\n")
            .unwrap_err();
        assert!(
            err.contains("vehicle[0].hover_throttle must be in [0.01, 0.99], got 1.5"),
            "{err}"
        );
    }

    #[test]
    fn unknown_keys_are_refused_with_their_name() {
        let err = SitlConfig::from_toml("[[vehicle]]\nprofil = \"x500\"\n").unwrap_err();
        assert!(err.contains("unknown field `profil`"), "{err}");
    }

    #[test]
    fn every_problem_is_reported_at_once() {
        let err = SitlConfig::from_toml(
            r#"
            [faults]
            loss_pct = 150.0
            [[vehicle]]
            profile = "x600"
            [[vehicle]]
            system_id = 2
            start_ned_m = [0.0, 0.0, 5.0]
            [[vehicle]]
            system_id = 2
            telemetry_rate_hz = 0.0
            "#,
        )
        .unwrap_err();
        let lines: Vec<&str> = err.lines().collect();
        assert_eq!(lines.len(), 5, "{err}");
        assert!(err.contains("faults.loss_pct"));
        assert!(err.contains("unknown vehicle profile \"x600\""));
        assert!(err.contains("below the ground"));
        assert!(err.contains("system_id 2 is used twice"));
        assert!(
            err.contains(
                "vehicle[2].telemetry_rate_hz must be a finite number in (0, 1000] Hz, got 0"
            ),
            "{err}"
        );
    }
}
