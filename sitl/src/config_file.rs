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
//! profile = "x500"             # "x500" (default) or "ideal"
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
use crate::autopilot::{BatteryConfig, StartState, VehicleConfig, WindConfig};
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
    vehicle: Vec<RawVehicle>,
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

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawVehicle {
    system_id: Option<u8>,
    #[serde(default = "default_profile")]
    profile: String,
    #[serde(default)]
    start_ned_m: [f64; 3],
    #[serde(default)]
    velocity_ned_mps: [f64; 3],
    #[serde(default)]
    yaw_deg: f64,
    #[serde(default)]
    in_air: bool,
    #[serde(default = "default_rate")]
    telemetry_rate_hz: f64,
    #[serde(default)]
    wind_ned_mps: [f64; 3],
    #[serde(default)]
    gust_std_mps: f64,
    #[serde(default = "default_gust_tau")]
    gust_tau_s: f64,
    mass_kg: Option<f64>,
    hover_throttle: Option<f64>,
    drag_per_s: Option<f64>,
    #[serde(default)]
    position_noise_m: f64,
    #[serde(default)]
    velocity_noise_mps: f64,
    #[serde(default)]
    drift_std_m: f64,
    #[serde(default = "default_drift_tau")]
    drift_tau_s: f64,
    #[serde(default)]
    estimator_latency_ms: f64,
    #[serde(default)]
    battery_sag: f64,
    battery_capacity_mah: Option<f64>,
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
            let profile = match v.profile.parse::<Profile>() {
                Ok(p) => p,
                Err(e) => {
                    problems.push(format!("vehicle[{i}].profile: {e}"));
                    continue;
                }
            };
            let profile = match profile.with_airframe(v.mass_kg, v.hover_throttle, v.drag_per_s) {
                Ok(p) => p,
                Err(e) => {
                    problems.push(format!("vehicle[{i}].{e}"));
                    continue;
                }
            };
            let latency_ms = v.estimator_latency_ms;
            if !(latency_ms.is_finite() && (0.0..=2000.0).contains(&latency_ms)) {
                problems.push(format!(
                    "vehicle[{i}].estimator_latency_ms must be in [0, 2000] ms, got {latency_ms}"
                ));
                continue;
            }
            let cfg = VehicleConfig {
                system_id,
                profile,
                start: StartState {
                    pos_world_ned_m: Vector3::from(v.start_ned_m),
                    vel_ned_mps: Vector3::from(v.velocity_ned_mps),
                    yaw_rad: v.yaw_deg.to_radians(),
                    in_air: v.in_air,
                },
                fast_rate_hz: v.telemetry_rate_hz,
                wind: WindConfig {
                    steady_ned_mps: Vector3::from(v.wind_ned_mps),
                    gust_std_mps: v.gust_std_mps,
                    gust_tau_s: v.gust_tau_s,
                },
                seed: u64::from(system_id),
                estimator: EstimatorConfig {
                    position_noise_m: v.position_noise_m,
                    velocity_noise_mps: v.velocity_noise_mps,
                    drift_std_m: v.drift_std_m,
                    drift_tau_s: v.drift_tau_s,
                    latency: Duration::from_secs_f64(latency_ms / 1000.0),
                    faults: Vec::new(),
                },
                battery: BatteryConfig {
                    capacity_mah: v.battery_capacity_mah,
                    sag: v.battery_sag,
                },
                signing: None,
            };
            if let Err(e) = cfg.validate() {
                problems.push(format!("vehicle[{i}]: {e}"));
            }
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
        assert!(err.contains("telemetry rate"));
    }
}
