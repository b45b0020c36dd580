//! What a coordinator config means for the built-in emulator: the emulated world and
//! vehicles, and the lockstep link faults (built with the `emulator` feature only).

use std::net::{IpAddr, SocketAddr};
use std::time::Duration;

use nalgebra::Vector3;
use ringswarm_sitl::autopilot::estimator::{EstimatorConfig, FaultKind, TelemetryFault};
use ringswarm_sitl::autopilot::{BatteryConfig, StartState, VehicleConfig};
use ringswarm_sitl::profile::Profile;
use ringswarm_sitl::udp::{Placement, PortPlan};
use ringswarm_sitl::world::World;
use ringswarm_wire::px4;
use ringswarm_wire::time::SimTime;

use super::validate::Problems;
use super::{Config, FaultKindName, LockstepFaults};
use crate::control::enu_to_ned;

/// How `[emulator]`'s link faults are named in messages (loss, latency, jitter, and the
/// duplication it does not offer).
pub const EMULATOR_FAULT_NAMES: [&str; 4] = [
    "emulator.loss_pct",
    "emulator.latency_ms",
    "emulator.jitter_ms",
    "emulator.duplicate_pct",
];

impl Config {
    /// The link faults of `[emulator]` (loss, latency, jitter), for every driver of the
    /// emulator: the lockstep's and `demo --realtime`'s.
    ///
    /// # Errors
    /// Every out-of-range value, one per line, named as in the file.
    pub fn link_faults(&self) -> Result<ringswarm_sitl::link_faults::LinkFaults, String> {
        let e = &self.emulator;
        ringswarm_sitl::link_faults::LinkFaults::from_percent_and_ms(
            e.loss_pct,
            e.latency_ms,
            e.jitter_ms,
            0.0,
            EMULATOR_FAULT_NAMES,
        )
    }

    /// The lockstep link faults of `[emulator]`.
    ///
    /// # Errors
    /// Every out-of-range value, one per line.
    pub fn lockstep_faults(&self) -> Result<LockstepFaults, String> {
        let e = &self.emulator;
        let mut problems = Vec::new();
        let faults = self.link_faults().unwrap_or_else(|why| {
            problems.push(why);
            Default::default()
        });
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
        Ok(LockstepFaults {
            conditions: ringswarm_sitl::link_faults::LinkConditions {
                faults,
                seed: e.seed,
            },
            silences,
        })
    }

    /// The built-in emulator's world and vehicles for this configuration: the world
    /// reference is the common frame's reference, the ground `ground_below_m` under it,
    /// and each vehicle starts where `start_enu_m` puts it (converted to NED).
    ///
    /// # Errors
    /// An unknown profile or a start state the emulator refuses, naming the vehicle.
    pub fn emulator(&self) -> Result<(World, Vec<VehicleConfig>), String> {
        let world = World {
            reference: crate::frame::Geodetic {
                lat_deg: self.frame.latitude_deg,
                lon_deg: self.frame.longitude_deg,
                alt_amsl_m: self.frame.altitude_amsl_m,
            },
            ground_down_m: self.emulator.ground_below_m,
        };
        let mut p = Problems::default();
        let estimator = self.estimator(&mut p);
        let battery = self.battery(&mut p);
        let mut vehicles = Vec::new();
        for (i, v) in self.vehicle.iter().enumerate() {
            let mut profile: Profile = match v.profile.parse::<Profile>() {
                Ok(profile) => profile,
                Err(e) => {
                    p.push(format!("vehicle[{i}].profile: {e}"));
                    continue;
                }
            };
            if let Some(a) = &v.airframe {
                match profile
                    .clone()
                    .with_airframe(a.mass_kg, a.hover_throttle, a.drag_per_s)
                {
                    Ok(changed) => profile = changed,
                    Err(e) => p.push(format!("vehicle[{i}].airframe.{e}")),
                }
            }
            let mut cfg = VehicleConfig::new(v.system_id, profile);
            cfg.start = StartState {
                pos_world_ned_m: enu_to_ned(Vector3::from(v.start_enu_m)),
                vel_ned_mps: enu_to_ned(Vector3::from(v.start_velocity_enu_mps)),
                yaw_rad: 0.0,
                in_air: v.in_air,
            };
            cfg.estimator = estimator.clone();
            cfg.battery = battery;
            cfg.estimator.faults = self.faults_of(i, &mut p);
            if let Err(e) = cfg.validate() {
                p.push(format!("vehicle[{i}]: {e}"));
            }
            vehicles.push(cfg);
        }
        if !p.0.is_empty() {
            return Err(p.0.join("\n"));
        }
        Ok((world, vehicles))
    }

    /// Where the built-in emulator puts each vehicle so that `fly` with this config
    /// reaches it: a vehicle with its own socket listens where the config says (PX4's
    /// 14580+i by default), sends to the coordinator's socket for it and has a GCS link
    /// on PX4's 18570+i; a vehicle on a network listens at its `address` (any free port
    /// without one) and sends to the network's socket. A `0.0.0.0` bind is reached on
    /// 127.0.0.1.
    ///
    /// # Errors
    /// The transport's problems ([`Config::transport_plan`]).
    pub fn emulator_placements(&self) -> Result<Vec<Placement>, String> {
        let plan = self.transport_plan()?;
        let reach = |a: SocketAddr| {
            if a.ip().is_unspecified() {
                SocketAddr::new(IpAddr::from([127, 0, 0, 1]), a.port())
            } else {
                a
            }
        };
        let mut out = Vec::with_capacity(plan.routes.len());
        for (i, route) in plan.routes.iter().enumerate() {
            let Some(socket) = plan.sockets.get(route.socket) else {
                return Err(format!("vehicle[{i}]: no coordinator socket"));
            };
            let coordinator = reach(socket.bind);
            out.push(match (&socket.network, route.address) {
                (Some(_), address) => Placement::Network {
                    bind: address.unwrap_or(SocketAddr::new(coordinator.ip(), 0)),
                    peer: coordinator,
                },
                (None, Some(address)) => {
                    let gcs = u16::try_from(i)
                        .ok()
                        .and_then(|i| px4::GCS_LISTEN_PORT.checked_add(i))
                        .ok_or_else(|| format!("vehicle[{i}]: no GCS port for instance {i}"))?;
                    Placement::Ports(PortPlan {
                        offboard_bind: address,
                        offboard_peer: coordinator,
                        gcs_bind: SocketAddr::new(address.ip(), gcs),
                        gcs_peer: SocketAddr::new(address.ip(), px4::GCS_PEER_PORT),
                    })
                }
                (None, None) => return Err(format!("vehicle[{i}]: no address")),
            });
        }
        Ok(out)
    }

    /// The estimate's errors of `[emulator]`, the same for every vehicle (each draws its
    /// own numbers).
    fn estimator(&self, p: &mut Problems) -> EstimatorConfig {
        let e = &self.emulator;
        p.within(
            "emulator.position_noise_m",
            e.position_noise_m,
            0.0,
            100.0,
            " m",
        );
        p.within(
            "emulator.velocity_noise_mps",
            e.velocity_noise_mps,
            0.0,
            10.0,
            " m/s",
        );
        p.within("emulator.drift_std_m", e.drift_std_m, 0.0, 100.0, " m");
        p.positive("emulator.drift_tau_s", e.drift_tau_s, 1.0e4, " s");
        let latency_ok = p.within(
            "emulator.estimator_latency_ms",
            e.estimator_latency_ms,
            0.0,
            2000.0,
            " ms",
        );
        EstimatorConfig {
            position_noise_m: e.position_noise_m,
            velocity_noise_mps: e.velocity_noise_mps,
            drift_std_m: e.drift_std_m,
            drift_tau_s: e.drift_tau_s,
            latency: if latency_ok {
                Duration::from_secs_f64(e.estimator_latency_ms / 1000.0)
            } else {
                Duration::ZERO
            },
            faults: Vec::new(),
        }
    }

    /// The battery of `[emulator]`, the same for every vehicle.
    fn battery(&self, p: &mut Problems) -> BatteryConfig {
        let e = &self.emulator;
        p.within("emulator.battery_sag", e.battery_sag, 0.0, 0.5, "");
        if let Some(c) = e.battery_capacity_mah {
            p.within("emulator.battery_capacity_mah", c, 1.0, 1.0e6, " mAh");
        }
        BatteryConfig {
            capacity_mah: e.battery_capacity_mah,
            sag: e.battery_sag,
        }
    }

    /// The `[[emulator.fault]]` tables of vehicle `i` (0-based).
    fn faults_of(&self, i: usize, p: &mut Problems) -> Vec<TelemetryFault> {
        let n = self.vehicle.len();
        let mut faults = Vec::new();
        for (j, f) in self.emulator.fault.iter().enumerate() {
            if i == 0 && (f.vehicle == 0 || f.vehicle > n) {
                p.push(format!(
                    "emulator.fault[{j}].vehicle must be 1..={n}, got {}",
                    f.vehicle
                ));
            }
            if f.vehicle != i + 1 {
                continue;
            }
            let key = format!("emulator.fault[{j}]");
            let times_ok = p.within(
                &format!("{key}.from_s"),
                f.from_s,
                0.0,
                super::MAX_DURATION_S,
                " s",
            ) & p.within(
                &format!("{key}.until_s"),
                f.until_s,
                0.0,
                super::MAX_DURATION_S,
                " s",
            );
            if times_ok && f.until_s <= f.from_s {
                p.push(format!(
                    "{key} needs from_s < until_s, got {} .. {}",
                    f.from_s, f.until_s
                ));
                continue;
            }
            let kind = match f.kind {
                FaultKindName::NanPosition => FaultKind::NanPosition,
                FaultKindName::NoPosition => FaultKind::NoPosition,
                FaultKindName::PositionLost => FaultKind::PositionLost,
                FaultKindName::OriginShift => {
                    let Some(shift) = f.shift_ned_m else {
                        p.push(format!(
                            "{key}.shift_ned_m is required for kind = \"origin_shift\""
                        ));
                        continue;
                    };
                    if !p.vector(&format!("{key}.shift_ned_m"), &shift, 1.0e5, " m") {
                        continue;
                    }
                    FaultKind::OriginShift {
                        shift_ned_m: Vector3::from(shift),
                        positions_follow: f.positions_follow,
                    }
                }
            };
            if times_ok {
                let t = |x: f64| SimTime::from_micros((x * 1e6).round() as u64);
                faults.push(TelemetryFault {
                    from: t(f.from_s),
                    until: t(f.until_s),
                    kind,
                });
            }
        }
        faults
    }
}
