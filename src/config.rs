//! The coordinator's TOML configuration: serde structs with `deny_unknown_fields`, and
//! [`Config::validate`], which reports every problem at once and produces the typed
//! [`SwarmSetup`] (unstable gains are refused here, before anything is sent).
//!
//! Frames: vehicle start states and formation offsets are in the paper's ENU frame (x
//! east, y north, z up, metres) about the common reference point.

use std::f64::consts::PI;
use std::net::SocketAddr;
use std::time::Duration;

use nalgebra::{Vector2, Vector3};
use serde::Deserialize;

use ringswarm_sitl::autopilot::{StartState, VehicleConfig};
use ringswarm_sitl::profile::Profile;
use ringswarm_sitl::time::SimTime;
use ringswarm_sitl::world::World;

use crate::consensus::{CouplingGains, RingDigraph, analyze};
use crate::control::{AltitudeGains, Envelope, SaturationMode, VehicleModel, enu_to_ned};
use crate::frame::{CommonFrame, Geodetic};
use crate::swarm::{EndAction, LossPolicy, SwarmSetup, TargetVelocity};
use crate::vehicle::LinkConfig;

/// The whole file.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    /// Rates, duration and end of flight.
    #[serde(default)]
    pub swarm: SwarmSection,
    /// Consensus and altitude gains.
    pub gains: GainsSection,
    /// The formation and its altitude.
    pub formation: FormationSection,
    /// Tilt and thrust limits.
    #[serde(default)]
    pub envelope: EnvelopeSection,
    /// The common frame's reference point.
    #[serde(default)]
    pub frame: FrameSection,
    /// The world of the built-in emulator.
    #[serde(default)]
    pub emulator: EmulatorSection,
    /// One table per vehicle, in ring order.
    #[serde(default)]
    pub vehicle: Vec<VehicleSection>,
    /// A final velocity to reach with the planner (optional).
    pub target: Option<TargetSection>,
}

/// `[target]`: the planner chooses `k` (and re-targets one agent if needed) so that the
/// swarm's consensus velocity is `velocity_enu_mps`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TargetSection {
    /// The final velocity (ENU, m/s).
    pub velocity_enu_mps: [f64; 2],
    /// `k ≥ k_min + k_margin` (default 0.1).
    #[serde(default = "default_k_margin")]
    pub k_margin: f64,
    /// `k ≤ k_max` (default 10).
    #[serde(default = "default_k_max")]
    pub k_max: f64,
    /// Largest speed a re-targeted agent may be asked for (m/s).
    pub max_speed_mps: Option<f64>,
    /// Stage 1 ends when the re-targeted agent is this close to its velocity (default
    /// 0.05 m/s).
    #[serde(default = "default_tolerance")]
    pub tolerance_mps: f64,
}

fn default_k_margin() -> f64 {
    0.1
}

fn default_k_max() -> f64 {
    10.0
}

fn default_tolerance() -> f64 {
    0.05
}

/// The coordinator's default system id: not QGroundControl's 255, not MAVSDK's 245.
pub const DEFAULT_GCS_SYSTEM_ID: u8 = 253;
/// The coordinator's default component id (MAV_COMP_ID_MISSIONPLANNER).
pub const DEFAULT_GCS_COMPONENT_ID: u8 = 190;

/// `[swarm]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SwarmSection {
    /// Control (and setpoint stream) rate, 1..=250 Hz.
    pub control_rate_hz: f64,
    /// Flight duration after consensus starts (s).
    pub duration_s: f64,
    /// Silence after which a vehicle is lost (ms).
    pub link_timeout_ms: u64,
    /// At the end of the duration: `land` (default) or `hold`.
    pub end: EndAction,
    /// When a vehicle is lost during consensus: `hold` (default) or `land`.
    pub on_link_loss: LossPolicy,
    /// The coordinator's own MAVLink system id, in its 1 Hz ground-station heartbeat and
    /// every frame it sends (default 253: neither QGroundControl's 255 nor MAVSDK's 245,
    /// so either can watch the same vehicles).
    pub gcs_system_id: u8,
    /// The coordinator's own MAVLink component id (default 190, MAV_COMP_ID_MISSIONPLANNER).
    pub gcs_component_id: u8,
}

impl Default for SwarmSection {
    fn default() -> Self {
        Self {
            control_rate_hz: 50.0,
            duration_s: 60.0,
            link_timeout_ms: 1500,
            end: EndAction::Land,
            on_link_loss: LossPolicy::Hold,
            gcs_system_id: DEFAULT_GCS_SYSTEM_ID,
            gcs_component_id: DEFAULT_GCS_COMPONENT_ID,
        }
    }
}

/// `[gains]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GainsSection {
    /// Ring gain k.
    pub k: f64,
    /// Position coupling α (1/s²).
    pub alpha: f64,
    /// Velocity coupling β (1/s).
    pub beta: f64,
    /// Altitude P (1/s²).
    pub k_pz: f64,
    /// Altitude D (1/s).
    pub k_vz: f64,
    /// Time scale `c` of the horizontal law: flies `α·c²` and `β·c`, which slows every
    /// mode by `c` and keeps the final velocity and stability (default 1).
    #[serde(default = "default_time_scale")]
    pub time_scale: f64,
}

fn default_time_scale() -> f64 {
    1.0
}

/// `[formation]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FormationSection {
    /// `polygon` (radius_m), `line` (spacing_m) or `offsets` (offsets_m).
    pub kind: String,
    /// Polygon radius (m).
    pub radius_m: Option<f64>,
    /// Line spacing (m).
    pub spacing_m: Option<f64>,
    /// Explicit ENU offsets (m), one per vehicle.
    pub offsets_m: Option<Vec<[f64; 2]>>,
    /// Commanded altitude in the common frame (m, z up).
    pub altitude_m: f64,
}

/// `[envelope]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EnvelopeSection {
    /// Largest tilt (deg).
    pub max_tilt_deg: f64,
    /// Thrust limits, normalised 0..1.
    pub min_thrust: f64,
    /// Upper thrust limit, normalised.
    pub max_thrust: f64,
    /// `conserve` (default) or `clip`.
    pub saturation: SaturationMode,
    /// Thrust kept for horizontal control when the vertical command saturates
    /// (normalised, like PX4's MPC_THR_XY_MARG; default 0.3).
    pub xy_margin: f64,
}

impl Default for EnvelopeSection {
    fn default() -> Self {
        Self {
            max_tilt_deg: 35.0,
            min_thrust: 0.1,
            max_thrust: 0.9,
            saturation: SaturationMode::Conserve,
            xy_margin: 0.3,
        }
    }
}

/// `[frame]`: the common reference point.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FrameSection {
    /// Latitude (deg).
    pub latitude_deg: f64,
    /// Longitude (deg).
    pub longitude_deg: f64,
    /// Altitude AMSL (m).
    pub altitude_amsl_m: f64,
}

impl Default for FrameSection {
    fn default() -> Self {
        Self {
            latitude_deg: 47.397742,
            longitude_deg: 8.545594,
            altitude_amsl_m: 488.0,
        }
    }
}

/// `[emulator]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EmulatorSection {
    /// Height of the paper's z = 0 above the ground (m).
    pub ground_below_m: f64,
    /// Lockstep links (`demo`, tests): one-way latency (ms).
    pub latency_ms: f64,
    /// Lockstep links: uniform extra latency `0..jitter` (ms).
    pub jitter_ms: f64,
    /// Lockstep links: datagrams lost, each direction (%).
    pub loss_pct: f64,
    /// Seed of the loss and jitter draws.
    pub seed: u64,
    /// Lockstep links silenced for a while: `[[emulator.silence]]`.
    pub silence: Vec<SilenceSection>,
}

impl Default for EmulatorSection {
    fn default() -> Self {
        Self {
            ground_below_m: 0.0,
            latency_ms: 0.0,
            jitter_ms: 0.0,
            loss_pct: 0.0,
            seed: 1,
            silence: Vec::new(),
        }
    }
}

/// `[[emulator.silence]]`: vehicle `vehicle` (1-based, in table order) neither sends nor
/// receives between `from_s` and `until_s` (simulated seconds).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SilenceSection {
    /// Which vehicle (1-based position in the `[[vehicle]]` list).
    pub vehicle: usize,
    /// Start (s).
    pub from_s: f64,
    /// End (s).
    pub until_s: f64,
}

/// Link faults of a lockstep run.
#[derive(Debug, Clone, PartialEq)]
pub struct LockstepFaults {
    /// Latency, jitter, loss and seed on every link.
    pub conditions: crate::driver::lockstep::LinkConditions,
    /// `(vehicle index, from, until)`.
    pub silences: Vec<(usize, SimTime, SimTime)>,
}

/// `[[vehicle]]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VehicleSection {
    /// MAVLink system id.
    pub system_id: u8,
    /// Where its offboard link listens (default PX4's 127.0.0.1:14580+i).
    pub address: Option<SocketAddr>,
    /// Where the coordinator's socket for it is bound (default 0.0.0.0:14540+i, the
    /// port PX4 SITL sends its offboard link to).
    pub bind: Option<SocketAddr>,
    /// Emulator profile (`ideal`, `x500`).
    #[serde(default = "default_profile")]
    pub profile: String,
    /// Mass (kg) for the law's thrust.
    pub mass_kg: f64,
    /// Hover throttle (0..1).
    pub hover_throttle: f64,
    /// Linear drag fed forward (1/s).
    #[serde(default)]
    pub drag_per_s: f64,
    /// Start position (ENU, m) for the emulator.
    #[serde(default)]
    pub start_enu_m: [f64; 3],
    /// Start velocity (ENU, m/s) for the emulator.
    #[serde(default)]
    pub start_velocity_enu_mps: [f64; 3],
    /// Started in the air (armed, a pilot holds the start velocity).
    #[serde(default)]
    pub in_air: bool,
}

fn default_profile() -> String {
    "x500".to_owned()
}

impl Config {
    /// Parses a TOML text.
    ///
    /// # Errors
    /// The parser's message (syntax, unknown keys, wrong types).
    pub fn from_toml(text: &str) -> Result<Self, String> {
        toml::from_str(text).map_err(|e| e.to_string())
    }

    /// Checks everything and builds the swarm's setup; every problem is reported, one per
    /// line.
    ///
    /// # Errors
    /// All problems found, each naming the key and the value.
    pub fn validate(&self) -> Result<SwarmSetup, String> {
        let mut problems = Vec::new();
        let n = self.vehicle.len();
        let ring = match RingDigraph::for_agents(n, self.gains.k) {
            Ok(r) => Some(r),
            Err(e) => {
                problems.push(format!("vehicle count / gains.k: {e}"));
                None
            }
        };
        let c = self.gains.time_scale;
        if !(c.is_finite() && c > 0.0 && c <= 10.0) {
            problems.push(format!("gains.time_scale must be in (0, 10], got {c}"));
        }
        let gains = CouplingGains::new(self.gains.alpha * c * c, self.gains.beta * c)
            .map_err(|e| problems.push(format!("gains: {e}")))
            .ok();
        if let (Some(ring), Some(gains)) = (&ring, gains) {
            match analyze(ring, Some(gains)) {
                Ok(report) if !report.stable => problems.push(format!(
                    "gains are unstable: k = {} (bound k > {:.6}, margin {:+.6}), beta^2/alpha = {:.6} vs Yu's bound {}",
                    self.gains.k,
                    report.k_min,
                    report.k_margin,
                    gains.ratio(),
                    report.yu_bound.map_or("none (k below the bound)".to_owned(), |b| format!("{b:.6}"))
                )),
                Ok(_) => {}
                Err(e) => problems.push(format!("gains: {e}")),
            }
        }
        let altitude_gains = AltitudeGains::new(self.gains.k_pz, self.gains.k_vz)
            .map_err(|e| problems.push(format!("gains: {e}")))
            .ok();
        let offsets = self.offsets(n).map_err(|e| problems.push(e)).ok();
        if !self.formation.altitude_m.is_finite() {
            problems.push(format!(
                "formation.altitude_m must be finite, got {}",
                self.formation.altitude_m
            ));
        }
        let e = &self.envelope;
        let envelope = Envelope::new(e.max_tilt_deg.to_radians(), e.min_thrust, e.max_thrust)
            .and_then(|env| env.with_xy_margin(e.xy_margin))
            .map_err(|err| problems.push(format!("envelope: {err}")))
            .ok();
        let s = &self.swarm;
        if !(s.control_rate_hz >= 1.0 && s.control_rate_hz <= 250.0) {
            problems.push(format!(
                "swarm.control_rate_hz must be in [1, 250], got {}",
                s.control_rate_hz
            ));
        }
        if s.gcs_system_id == 0 {
            problems.push("swarm.gcs_system_id must be 1..=255, got 0".to_owned());
        }
        if !(s.duration_s.is_finite() && s.duration_s > 0.0) {
            problems.push(format!(
                "swarm.duration_s must be positive, got {}",
                s.duration_s
            ));
        }
        let target = self.target.as_ref().and_then(|t| {
            let mut ok = true;
            let mut check = |what: &str, good: bool, value: String| {
                if !good {
                    problems.push(format!("target.{what}, got {value}"));
                    ok = false;
                }
            };
            check(
                "velocity_enu_mps must be finite",
                t.velocity_enu_mps.iter().all(|v| v.is_finite()),
                format!("{:?}", t.velocity_enu_mps),
            );
            check(
                "k_margin must be finite and at least 0",
                t.k_margin.is_finite() && t.k_margin >= 0.0,
                t.k_margin.to_string(),
            );
            check(
                "k_max must be finite",
                t.k_max.is_finite(),
                t.k_max.to_string(),
            );
            check(
                "tolerance_mps must be positive",
                t.tolerance_mps.is_finite() && t.tolerance_mps > 0.0,
                t.tolerance_mps.to_string(),
            );
            if let Some(max) = t.max_speed_mps {
                check(
                    "max_speed_mps must be positive",
                    max.is_finite() && max > 0.0,
                    max.to_string(),
                );
            }
            ok.then(|| TargetVelocity {
                velocity_mps: Vector2::from(t.velocity_enu_mps),
                k_margin: t.k_margin,
                k_max: t.k_max,
                max_speed_mps: t.max_speed_mps,
                tolerance_mps: t.tolerance_mps,
            })
        });
        let mut models = Vec::new();
        let mut ids = Vec::new();
        for (i, v) in self.vehicle.iter().enumerate() {
            if v.system_id == 0 || v.system_id > 250 {
                problems.push(format!(
                    "vehicle[{i}].system_id must be 1..=250, got {}",
                    v.system_id
                ));
            }
            if ids.contains(&v.system_id) {
                problems.push(format!(
                    "vehicle[{i}].system_id {} is used twice",
                    v.system_id
                ));
            }
            ids.push(v.system_id);
            if v.system_id == s.gcs_system_id {
                problems.push(format!(
                    "vehicle[{i}].system_id {} is the coordinator's own swarm.gcs_system_id",
                    v.system_id
                ));
            }
            match VehicleModel::from_hover_throttle(v.mass_kg, v.hover_throttle) {
                Ok(m) => {
                    if let Some(env) = &envelope
                        && let Err(err) = env.check_hover(&m)
                    {
                        problems.push(format!("vehicle[{i}]: {err}"));
                    }
                    models.push(m);
                }
                Err(err) => problems.push(format!("vehicle[{i}]: {err}")),
            }
            let finite = v
                .start_enu_m
                .iter()
                .chain(&v.start_velocity_enu_mps)
                .chain([&v.drag_per_s])
                .all(|x| x.is_finite());
            if !finite || v.drag_per_s < 0.0 {
                problems.push(format!(
                    "vehicle[{i}]: start state and drag_per_s must be finite (drag ≥ 0)"
                ));
            }
        }
        if !problems.is_empty() {
            return Err(problems.join("\n"));
        }
        let (Some(ring), Some(gains), Some(altitude_gains), Some(offsets), Some(envelope)) =
            (ring, gains, altitude_gains, offsets, envelope)
        else {
            return Err("invalid configuration".to_owned());
        };
        let interval = Duration::from_secs_f64(1.0 / s.control_rate_hz);
        Ok(SwarmSetup {
            ring,
            gains,
            altitude_gains,
            altitude_m: self.formation.altitude_m,
            offsets_m: offsets,
            models,
            drag_per_s: self.vehicle.iter().map(|v| v.drag_per_s).collect(),
            envelope,
            saturation: e.saturation,
            control_interval: interval,
            frame: CommonFrame::new(Geodetic {
                lat_deg: self.frame.latitude_deg,
                lon_deg: self.frame.longitude_deg,
                alt_amsl_m: self.frame.altitude_amsl_m,
            }),
            links: self
                .vehicle
                .iter()
                .map(|v| LinkConfig {
                    setpoint_interval: interval,
                    telemetry_interval: interval,
                    link_timeout: Duration::from_millis(s.link_timeout_ms),
                    own_ids: (s.gcs_system_id, s.gcs_component_id),
                    ..LinkConfig::new(v.system_id)
                })
                .collect(),
            duration: Some(Duration::from_secs_f64(s.duration_s)),
            end_action: s.end,
            loss_policy: s.on_link_loss,
            target,
        })
    }

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

    /// The formation offsets `dᵢ` (ENU, m).
    fn offsets(&self, n: usize) -> Result<Vec<Vector2<f64>>, String> {
        let f = &self.formation;
        match f.kind.as_str() {
            "polygon" => {
                let r = f
                    .radius_m
                    .filter(|r| r.is_finite() && *r > 0.0)
                    .ok_or("formation.radius_m must be a positive number for a polygon")?;
                Ok((0..n)
                    .map(|l| {
                        Vector2::new(
                            (2.0 * PI * l as f64 / n as f64).cos(),
                            (2.0 * PI * l as f64 / n as f64).sin(),
                        ) * r
                    })
                    .collect())
            }
            "line" => {
                let d = f
                    .spacing_m
                    .filter(|d| d.is_finite() && *d > 0.0)
                    .ok_or("formation.spacing_m must be a positive number for a line")?;
                Ok((0..n).map(|i| Vector2::new(d * i as f64, 0.0)).collect())
            }
            "offsets" => {
                let list = f
                    .offsets_m
                    .as_ref()
                    .ok_or("formation.offsets_m is required for kind = \"offsets\"")?;
                if list.len() != n {
                    return Err(format!(
                        "formation.offsets_m has {} entries for {n} vehicles",
                        list.len()
                    ));
                }
                Ok(list.iter().map(|o| Vector2::new(o[0], o[1])).collect())
            }
            other => Err(format!(
                "formation.kind \"{other}\" is not one of polygon, line, offsets"
            )),
        }
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
