//! [`Config::validate`]: every number of the file is checked where it enters, against a
//! range a flight can use (docs/configuration.md lists them), and every problem is reported
//! at once, one per line, naming the key and the value. Nothing non-finite or absurd gets
//! past this point into a setpoint.

use std::time::Duration;

use super::Config;
use super::problems::Problems;
use crate::consensus::{CouplingGains, RingDigraph, analyze};
use crate::control::{AltitudeGains, Envelope, VehicleModel};
use crate::frame::{CommonFrame, Geodetic};
use crate::swarm::SetpointKind;
use crate::swarm::SwarmSetup;
use crate::vehicle::{Autopilot, AutopilotChoice, LinkConfig};

/// Longest flight (s): about eleven days. `Duration` cannot hold 1e20 s, and no battery
/// lasts a day.
pub const MAX_DURATION_S: f64 = 1.0e6;
/// Largest distance (m) an offset, radius, spacing or start position may have: 10 km, far
/// beyond any formation flown over one radio link.
pub const MAX_DISTANCE_M: f64 = 1.0e4;
/// Largest speed (m/s) a start velocity or target velocity may have.
pub use crate::swarm::MAX_SPEED_MPS;
/// Largest gain any coupling (`k`, `alpha`, `beta`, `k_pz`, `k_vz`) may have.
pub const MAX_GAIN: f64 = 1.0e4;

/// Whether gains the stability analysis calls unstable are refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stability {
    /// Refused (every flight, and anything that may fly real vehicles).
    Required,
    /// Flown: an experiment on emulated vehicles that asks where the swarm stops
    /// converging (`ringswarm sweep`); the divergence guard still ends a runaway.
    Unchecked,
}

impl Config {
    /// Checks everything and builds the swarm's setup; every problem is reported, one per
    /// line.
    ///
    /// # Errors
    /// All problems found, each naming the key and the value.
    pub fn validate(&self) -> Result<SwarmSetup, String> {
        self.validate_with(Stability::Required)
    }

    /// [`Self::validate`], unstable gains refused or not as `stability` says.
    ///
    /// # Errors
    /// As [`Self::validate`].
    pub fn validate_with(&self, stability: Stability) -> Result<SwarmSetup, String> {
        let mut p = Problems::default();
        if let Err(split) = self.shard_layout() {
            split.lines().for_each(|l| p.push(l.to_owned()));
        }
        let n = self.vehicle.len();
        let autopilots = self.autopilots(&mut p);
        let law = self.law_gains(n, stability, &mut p);
        let offsets = self.offsets(n, &mut p);
        let assign_places = self.assign_places(&mut p);
        p.within(
            "formation.altitude_m",
            self.formation.altitude_m,
            -MAX_DISTANCE_M,
            MAX_DISTANCE_M,
            " m",
        );
        let envelope = self.envelope_checked(&mut p);
        self.check_frame(&mut p);
        let timing = self.check_swarm(&mut p);
        let target = self.target(&mut p);
        let models = self.models(envelope.as_ref(), &mut p);
        let guard = self.guard(&mut p);
        let safety = self.safety(offsets.as_deref(), &mut p);
        let fence = self.fence(&mut p);
        self.transport(&mut p);
        if !p.0.is_empty() {
            return Err(p.0.join("\n"));
        }
        let LawGains {
            ring,
            gains,
            altitude_gains,
            bandwidth,
        } = law;
        let (
            Some(ring),
            Some(gains),
            Some(altitude_gains),
            Some(offsets),
            Some(envelope),
            Some(timing),
        ) = (ring, gains, altitude_gains, offsets, envelope, timing)
        else {
            return Err("invalid configuration".to_owned());
        };
        let f = &self.frame;
        let frame = CommonFrame::new(Geodetic {
            lat_deg: f.latitude_deg,
            lon_deg: f.longitude_deg,
            alt_amsl_m: f.altitude_amsl_m,
        });
        let fence_plan = match (&fence, &self.fence) {
            (Some(setup), Some(section)) if section.upload => Some(std::sync::Arc::new(
                crate::vehicle::FencePlan::new(&setup.fence, &frame)?,
            )),
            _ => None,
        };
        Ok(SwarmSetup {
            ring,
            gains,
            altitude_gains,
            altitude_m: self.formation.altitude_m,
            offsets_m: offsets,
            assign_places,
            assign_off_tick: false,
            models,
            drag_per_s: self.vehicle.iter().map(|v| v.drag_per_s).collect(),
            envelope,
            saturation: self.envelope.saturation,
            control_interval: timing.control_interval,
            frame,
            links: self.link_configs(&autopilots, &timing, fence_plan),
            duration: Some(timing.duration),
            handshake_timeout: timing.handshake_timeout,
            estimate_hover: self.swarm.estimate_hover,
            estimate_drag: self.swarm.estimate_drag,
            disturbance_time_constant_s: self.swarm.disturbance_time_constant_s,
            mean_velocity_gain: self.gains.k_vmean,
            setpoint: self.swarm.setpoint,
            bandwidth,
            end_action: self.swarm.end,
            loss_policy: self.swarm.on_link_loss,
            target,
            guard,
            safety,
            fence,
        })
    }

    /// `[gains]`: the ring, the coupling gains (stable, within Theorem 1 and Yu's bound),
    /// the bandwidth gate's check and the altitude loop's gains.
    fn law_gains(&self, n: usize, stability: Stability, p: &mut Problems) -> LawGains {
        let g = &self.gains;
        p.within("gains.k_vmean", g.k_vmean, 0.0, 10.0, " 1/s");
        let gains_ok = p.within("gains.k", g.k, -2.0, MAX_GAIN, "")
            & p.positive("gains.alpha", g.alpha, MAX_GAIN, " 1/s²")
            & p.positive("gains.beta", g.beta, MAX_GAIN, " 1/s")
            & p.positive("gains.time_scale", g.time_scale, 10.0, "");
        let altitude_ok = p.positive("gains.k_pz", g.k_pz, MAX_GAIN, " 1/s²")
            & p.positive("gains.k_vz", g.k_vz, MAX_GAIN, " 1/s");
        let ring = RingDigraph::for_agents(n, g.k)
            .map_err(|e| p.push(format!("vehicle count / gains.k: {e}")))
            .ok();
        let c = g.time_scale;
        let gains = gains_ok
            .then(|| {
                CouplingGains::new(g.alpha * c * c, g.beta * c)
                    .map_err(|e| p.push(format!("gains: {e}")))
                    .ok()
            })
            .flatten();
        let mut bandwidth = None;
        if let (Some(ring), Some(gains)) = (&ring, gains) {
            let analysis = analyze(ring, Some(gains));
            if let Ok(report) = &analysis {
                bandwidth = self.bandwidth_from(&report.spectrum, gains).ok();
            }
            match analysis {
                Ok(report) if !report.stable && stability == Stability::Required => p.push(format!(
                    "gains are unstable: k = {} (bound k > {:.6}, margin {:+.6}), beta^2/alpha = {:.6} vs Yu's bound {}",
                    g.k,
                    report.k_min,
                    report.k_margin,
                    gains.ratio(),
                    report.yu_bound.map_or("none (k below the bound)".to_owned(), |b| format!("{b:.6}"))
                )),
                Ok(_) => {}
                Err(e) => p.push(format!("gains: {e}")),
            }
        }
        let k_iz = g.k_iz.unwrap_or(g.k_pz * g.k_vz / 40.0);
        let altitude_gains = altitude_ok
            .then(|| {
                AltitudeGains::new(g.k_pz, g.k_vz)
                    .and_then(|a| a.with_integral(k_iz))
                    .map_err(|e| p.push(format!("gains: {e}")))
                    .ok()
            })
            .flatten();
        LawGains {
            ring,
            gains,
            altitude_gains,
            bandwidth,
        }
    }

    /// `[envelope]`: tilt, thrust limits and the horizontal margin.
    fn envelope_checked(&self, p: &mut Problems) -> Option<Envelope> {
        let e = &self.envelope;
        let envelope_ok = p.positive("envelope.max_tilt_deg", e.max_tilt_deg, 80.0, " deg")
            & p.within("envelope.min_thrust", e.min_thrust, 0.0, 1.0, "")
            & p.within("envelope.max_thrust", e.max_thrust, 0.0, 1.0, "")
            & p.within("envelope.xy_margin", e.xy_margin, 0.0, 1.0, "");
        envelope_ok
            .then(|| {
                Envelope::new(e.max_tilt_deg.to_radians(), e.min_thrust, e.max_thrust)
                    .and_then(|env| env.with_xy_margin(e.xy_margin))
                    .map_err(|err| p.push(format!("envelope: {err}")))
                    .ok()
            })
            .flatten()
    }

    /// `[frame]`'s reference and the emulator's ground.
    fn check_frame(&self, p: &mut Problems) {
        let f = &self.frame;
        p.within("frame.latitude_deg", f.latitude_deg, -85.0, 85.0, " deg");
        p.within(
            "frame.longitude_deg",
            f.longitude_deg,
            -180.0,
            180.0,
            " deg",
        );
        p.within(
            "frame.altitude_amsl_m",
            f.altitude_amsl_m,
            -500.0,
            1.0e4,
            " m",
        );
        p.within(
            "emulator.ground_below_m",
            self.emulator.ground_below_m,
            -MAX_DISTANCE_M,
            MAX_DISTANCE_M,
            " m",
        );
    }

    /// Each vehicle's link configuration.
    fn link_configs(
        &self,
        autopilots: &[AutopilotChoice],
        timing: &Timing,
        fence_plan: Option<std::sync::Arc<crate::vehicle::FencePlan>>,
    ) -> Vec<LinkConfig> {
        let s = &self.swarm;
        self.vehicle
            .iter()
            .zip(autopilots)
            .map(|(v, autopilot)| LinkConfig {
                autopilot: *autopilot,
                setpoint_interval: timing.control_interval,
                telemetry_interval: timing.control_interval,
                attitude_interval: timing.attitude_interval,
                link_timeout: timing.link_timeout,
                max_attempts: s.command_attempts,
                own_ids: (s.gcs_system_id, s.gcs_component_id),
                retake_offboard: s.retake_offboard,
                state_timeout: timing.state_timeout,
                network: v.network.clone(),
                fence: fence_plan.clone(),
                ..LinkConfig::new(v.system_id)
            })
            .collect()
    }

    /// Each `[[vehicle]] autopilot`, by name; ArduPilot is flown with attitude setpoints
    /// only.
    fn autopilots(&self, p: &mut Problems) -> Vec<AutopilotChoice> {
        self.vehicle
            .iter()
            .enumerate()
            .map(|(i, v)| match AutopilotChoice::parse(&v.autopilot) {
                Ok(choice) => {
                    let ardupilot = choice == AutopilotChoice::Only(Autopilot::ArduPilot);
                    if ardupilot && self.swarm.setpoint == SetpointKind::Acceleration {
                        p.push(format!(
                            "vehicle[{i}].autopilot = \"ardupilot\" is flown with attitude setpoints only: swarm.setpoint = \"acceleration\" is PX4's"
                        ));
                    }
                    choice
                }
                Err(e) => {
                    p.push(format!("vehicle[{i}].{e}"));
                    AutopilotChoice::Auto
                }
            })
            .collect()
    }

    /// `[swarm]`: rates, durations and timeouts, and the coordinator's own ids.
    fn check_swarm(&self, p: &mut Problems) -> Option<Timing> {
        let s = &self.swarm;
        let rate_ok = p.within(
            "swarm.control_rate_hz",
            s.control_rate_hz,
            1.0,
            250.0,
            " Hz",
        );
        let duration_ok = p.positive("swarm.duration_s", s.duration_s, MAX_DURATION_S, " s");
        let link_ok = p.within(
            "swarm.link_timeout_ms",
            s.link_timeout_ms as f64,
            100.0,
            60_000.0,
            " ms",
        );
        p.within(
            "swarm.command_attempts",
            f64::from(s.command_attempts),
            1.0,
            50.0,
            " (sends of a command before its link fails)",
        );
        let handshake_ok = p.within(
            "swarm.handshake_timeout_s",
            s.handshake_timeout_s,
            1.0,
            3600.0,
            " s",
        );
        // The state must be allowed to miss a couple of telemetry samples (streamed at the
        // control rate), and a stale state must be noticed before the link itself is lost.
        let period_ms = if rate_ok {
            1000.0 / s.control_rate_hz
        } else {
            20.0
        };
        let state_lo = (3.0 * period_ms).ceil();
        let state_ok = p.within(
            "swarm.state_timeout_ms",
            s.state_timeout_ms as f64,
            state_lo,
            s.link_timeout_ms as f64,
            " ms (three control periods up to swarm.link_timeout_ms)",
        );
        // 0 turns the observer off; above a minute it would follow nothing a flight shows.
        p.within(
            "swarm.disturbance_time_constant_s",
            s.disturbance_time_constant_s,
            0.0,
            60.0,
            " s (0 turns the disturbance observer off)",
        );
        if s.gcs_system_id == 0 {
            p.push("swarm.gcs_system_id must be 1..=255, got 0".to_owned());
        }
        let attitude_ok = match s.attitude_rate_hz {
            Some(hz) => p.within(
                "swarm.attitude_rate_hz",
                hz,
                1.0,
                if rate_ok { s.control_rate_hz } else { 250.0 },
                " Hz (1 Hz up to swarm.control_rate_hz)",
            ),
            None => true,
        };
        let attitude_hz = s.attitude_rate_hz.unwrap_or(s.control_rate_hz);
        (rate_ok && duration_ok && link_ok && handshake_ok && state_ok && attitude_ok).then(|| {
            Timing {
                control_interval: Duration::from_secs_f64(1.0 / s.control_rate_hz),
                attitude_interval: Duration::from_secs_f64(1.0 / attitude_hz),
                duration: Duration::from_secs_f64(s.duration_s),
                link_timeout: Duration::from_millis(s.link_timeout_ms),
                handshake_timeout: Duration::from_secs_f64(s.handshake_timeout_s),
                state_timeout: Duration::from_millis(s.state_timeout_ms),
            }
        })
    }

    /// `[[vehicle]]`: models and start states (ids: `transport`).
    fn models(&self, envelope: Option<&Envelope>, p: &mut Problems) -> Vec<VehicleModel> {
        let mut models = Vec::new();
        for (i, v) in self.vehicle.iter().enumerate() {
            let key = |name: &str| format!("vehicle[{i}].{name}");
            let mass_ok = p.positive(&key("mass_kg"), v.mass_kg, 1000.0, " kg");
            let hover_ok = p.within(&key("hover_throttle"), v.hover_throttle, 0.01, 0.99, "");
            if mass_ok && hover_ok {
                match VehicleModel::from_hover_throttle(v.mass_kg, v.hover_throttle) {
                    Ok(m) => {
                        if let Some(env) = envelope
                            && let Err(err) = env.check_hover(&m)
                        {
                            p.push(format!("vehicle[{i}]: {err}"));
                        }
                        models.push(m);
                    }
                    Err(err) => p.push(format!("vehicle[{i}]: {err}")),
                }
            }
            p.within(&key("drag_per_s"), v.drag_per_s, 0.0, 10.0, " 1/s");
            if let Some(b) = v.attitude_bandwidth_rps {
                p.positive(&key("attitude_bandwidth_rps"), b, 1000.0, " rad/s");
            }
            p.vector(&key("start_enu_m"), &v.start_enu_m, MAX_DISTANCE_M, " m");
            p.vector(
                &key("start_velocity_enu_mps"),
                &v.start_velocity_enu_mps,
                MAX_SPEED_MPS,
                " m/s",
            );
        }
        models
    }
}

/// The validated times of `[swarm]`.
struct Timing {
    control_interval: Duration,
    attitude_interval: Duration,
    duration: Duration,
    link_timeout: Duration,
    handshake_timeout: Duration,
    state_timeout: Duration,
}

/// What `[gains]` gives when it is valid.
struct LawGains {
    ring: Option<RingDigraph>,
    gains: Option<CouplingGains>,
    altitude_gains: Option<AltitudeGains>,
    bandwidth: Option<crate::consensus::BandwidthCheck>,
}
