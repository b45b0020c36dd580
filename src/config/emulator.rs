//! What a coordinator config means for the built-in emulator and the transport: the
//! emulated world and vehicles, the lockstep link faults, and each vehicle's UDP
//! endpoints.

use std::net::SocketAddr;
use std::time::Duration;

use nalgebra::Vector3;
use ringswarm_sitl::autopilot::{StartState, VehicleConfig};
use ringswarm_sitl::profile::Profile;
use ringswarm_sitl::time::SimTime;
use ringswarm_sitl::world::World;

use super::{Config, LockstepFaults};
use crate::control::enu_to_ned;

impl Config {
    /// The lockstep link faults of `[emulator]`.
    ///
    /// # Errors
    /// Every out-of-range value, one per line.
    pub fn lockstep_faults(&self) -> Result<LockstepFaults, String> {
        let e = &self.emulator;
        let mut problems = Vec::new();
        for (name, v) in [("latency_ms", e.latency_ms), ("jitter_ms", e.jitter_ms)] {
            if !(v.is_finite() && (0.0..=10_000.0).contains(&v)) {
                problems.push(format!("emulator.{name} must be in [0, 10000], got {v}"));
            }
        }
        if !(0.0..=100.0).contains(&e.loss_pct) {
            problems.push(format!(
                "emulator.loss_pct must be in [0, 100], got {}",
                e.loss_pct
            ));
        }
        let mut silences = Vec::new();
        for (j, s) in e.silence.iter().enumerate() {
            if s.vehicle == 0 || s.vehicle > self.vehicle.len() {
                problems.push(format!(
                    "emulator.silence[{j}].vehicle must be 1..={}, got {}",
                    self.vehicle.len(),
                    s.vehicle
                ));
            }
            if !(s.from_s.is_finite()
                && s.from_s >= 0.0
                && s.until_s.is_finite()
                && s.until_s > s.from_s)
            {
                problems.push(format!(
                    "emulator.silence[{j}] needs 0 <= from_s < until_s, got {} .. {}",
                    s.from_s, s.until_s
                ));
            } else {
                let t = |x: f64| SimTime::from_micros((x * 1e6).round() as u64);
                silences.push((s.vehicle.saturating_sub(1), t(s.from_s), t(s.until_s)));
            }
        }
        if !problems.is_empty() {
            return Err(problems.join("\n"));
        }
        let ms = |x: f64| Duration::from_secs_f64(x / 1000.0);
        Ok(LockstepFaults {
            conditions: crate::driver::lockstep::LinkConditions {
                latency: ms(e.latency_ms),
                jitter: ms(e.jitter_ms),
                loss: e.loss_pct / 100.0,
                seed: e.seed,
            },
            silences,
        })
    }

    /// Every vehicle's `(address, bind address)`, in order.
    ///
    /// # Errors
    /// A vehicle whose default port would pass 65535, named.
    pub fn all_udp_endpoints(&self) -> Result<Vec<(SocketAddr, SocketAddr)>, String> {
        (0..self.vehicle.len())
            .map(|i| {
                self.udp_endpoints(i)
                    .ok_or_else(|| format!("vehicle {}: no default port", i + 1))
            })
            .collect()
    }

    /// Vehicle `i`'s address and the coordinator's bind address for it (PX4 SITL
    /// defaults: the vehicle listens on 14580+i and sends to 14540+i).
    pub fn udp_endpoints(&self, i: usize) -> Option<(SocketAddr, SocketAddr)> {
        let v = self.vehicle.get(i)?;
        let port = |base: u16| u16::try_from(i).ok().and_then(|i| base.checked_add(i));
        let peer = match v.address {
            Some(a) => a,
            None => SocketAddr::from(([127, 0, 0, 1], port(14580)?)),
        };
        let bind = match v.bind {
            Some(a) => a,
            None => SocketAddr::from(([0, 0, 0, 0], port(14540)?)),
        };
        Some((peer, bind))
    }

    /// The built-in emulator's world and vehicles for this configuration: the world
    /// reference is the common frame's reference, the ground `ground_below_m` under it,
    /// and each vehicle starts where `start_enu_m` puts it (converted to NED).
    ///
    /// # Errors
    /// An unknown profile or a start state the emulator refuses, naming the vehicle.
    pub fn emulator(&self) -> Result<(World, Vec<VehicleConfig>), String> {
        let world = World {
            reference: ringswarm_sitl::world::Geodetic {
                lat_deg: self.frame.latitude_deg,
                lon_deg: self.frame.longitude_deg,
                alt_amsl_m: self.frame.altitude_amsl_m,
            },
            ground_down_m: self.emulator.ground_below_m,
        };
        let vehicles = self
            .vehicle
            .iter()
            .enumerate()
            .map(|(i, v)| {
                let profile = v
                    .profile
                    .parse::<Profile>()
                    .map_err(|e| format!("vehicle[{i}].profile: {e}"))?;
                let mut cfg = VehicleConfig::new(v.system_id, profile);
                cfg.start = StartState {
                    pos_world_ned_m: enu_to_ned(Vector3::from(v.start_enu_m)),
                    vel_ned_mps: enu_to_ned(Vector3::from(v.start_velocity_enu_mps)),
                    yaw_rad: 0.0,
                    in_air: v.in_air,
                };
                cfg.validate().map_err(|e| format!("vehicle[{i}]: {e}"))?;
                Ok(cfg)
            })
            .collect::<Result<Vec<_>, String>>()?;
        Ok((world, vehicles))
    }
}
