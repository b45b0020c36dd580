//! What a coordinator config means for the built-in emulator: the emulated world and
//! vehicles, and the lockstep link faults (built with the `emulator` feature only).

use std::net::{IpAddr, SocketAddr};
use std::path::PathBuf;

use nalgebra::Vector3;
use ringswarm_sitl::autopilot::VehicleConfig;
use ringswarm_sitl::autopilot::estimator::{FaultKind, TelemetryFault};
use ringswarm_sitl::config_file::{EmulatedVehicle, KeyNames};
use ringswarm_sitl::udp::{Placement, PortLayout};
use ringswarm_sitl::world::World;
use ringswarm_wire::px4;
use ringswarm_wire::time::SimTime;

use super::problems::Problems;
use super::{Config, FaultKindName, LockstepFaults};
use crate::control::enu_to_ned;
use crate::link::router::Endpoint;

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
        let e = &self.emulator;
        let mut vehicles = Vec::new();
        for (i, v) in self.vehicle.iter().enumerate() {
            // The coordinator's tables in the emulator's one schema: ENU made NED, the
            // shared estimator and battery of `[emulator]`, the true airframe's overrides.
            let airframe = v.airframe.unwrap_or_default();
            let emulated = EmulatedVehicle {
                system_id: Some(v.system_id),
                profile: v.profile.clone(),
                start_ned_m: enu_to_ned(Vector3::from(v.start_enu_m)).into(),
                velocity_ned_mps: enu_to_ned(Vector3::from(v.start_velocity_enu_mps)).into(),
                in_air: v.in_air,
                mass_kg: airframe.mass_kg,
                hover_throttle: airframe.hover_throttle,
                drag_per_s: airframe.drag_per_s,
                position_noise_m: e.position_noise_m,
                velocity_noise_mps: e.velocity_noise_mps,
                drift_std_m: e.drift_std_m,
                drift_tau_s: e.drift_tau_s,
                estimator_latency_ms: e.estimator_latency_ms,
                battery_sag: e.battery_sag,
                battery_capacity_mah: e.battery_capacity_mah,
                autopilot: v.autopilot.clone(),
                ekf_settle_s: e.ekf_settle_s,
                telemetry_rate_hz: e.telemetry_rate_hz,
                ..EmulatedVehicle::default()
            };
            let (vehicle, airframe_key) =
                (format!("vehicle[{i}]."), format!("vehicle[{i}].airframe."));
            let names = KeyNames {
                vehicle: &vehicle,
                airframe: &airframe_key,
                estimator: "emulator.",
            };
            match emulated.build(v.system_id, &names) {
                Ok(mut cfg) => {
                    cfg.estimator.faults = self.faults_of(i, &mut p);
                    vehicles.push(cfg);
                }
                // `[emulator]`'s problems are every vehicle's: said once.
                Err(found) => {
                    for problem in found {
                        if !p.0.contains(&problem) {
                            p.push(problem);
                        }
                    }
                }
            }
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
    /// The transport's problems ([`Config::transport_layout`]).
    pub fn emulator_placements(&self) -> Result<Vec<Placement>, String> {
        let plan = self.transport_layout()?;
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
            let coordinator = match &socket.endpoint {
                Endpoint::Udp(bind) => reach(*bind),
                Endpoint::Serial { device, .. } => {
                    out.push(Placement::Serial {
                        device: PathBuf::from(device),
                    });
                    continue;
                }
            };
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
                    Placement::Ports(PortLayout {
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
