//! The bandwidth gate of a configuration: can its vehicles fly its gains at its control
//! rate? ([`crate::consensus::check_bandwidth`] has the rule and its calibration.)

use super::Config;
use crate::consensus::{
    BandwidthCheck, CouplingGains, RingDigraph, RingSpectrum, check_bandwidth_with_hop,
    fastest_mode_per_s,
};
use crate::swarm::SwarmSetup;

impl Config {
    /// The gate for the gains as flown (time scale applied), against the slowest
    /// vehicle's attitude bandwidth and the control rate. Call it on a validated config;
    /// [`Config::validate`] runs the same gate on the spectrum it already has and puts
    /// it in the setup.
    ///
    /// # Errors
    /// A vehicle without a bandwidth (an unknown profile and no
    /// `attitude_bandwidth_rps`), or gains the maths refuses.
    pub fn bandwidth_check(&self) -> Result<BandwidthCheck, String> {
        let g = &self.gains;
        let c = g.time_scale;
        let ring = RingDigraph::for_agents(self.vehicle.len(), g.k).map_err(|e| e.to_string())?;
        let gains = CouplingGains::new(g.alpha * c * c, g.beta * c).map_err(|e| e.to_string())?;
        self.bandwidth_from(&RingSpectrum::of(&ring), gains)
    }

    /// The gate from the Laplacian's spectrum and the gains as flown.
    ///
    /// # Errors
    /// A vehicle without a bandwidth, named.
    pub(super) fn bandwidth_from(
        &self,
        spectrum: &RingSpectrum,
        gains: CouplingGains,
    ) -> Result<BandwidthCheck, String> {
        let mu = spectrum.nonzero_up_to_conjugation();
        Ok(check_bandwidth_with_hop(
            fastest_mode_per_s(&mu, gains),
            self.slowest_attitude_bandwidth_rps()?,
            self.swarm.control_rate_hz,
            self.hop_s(),
        ))
    }

    /// The one-way delay between shards the gate allows for (s): `[distributed] hop_ms`
    /// when the swarm is split into two shards or more, else 0.
    fn hop_s(&self) -> f64 {
        match &self.distributed {
            Some(d) if self.shard.len() >= 2 && d.hop_ms.is_finite() && d.hop_ms > 0.0 => {
                d.hop_ms / 1000.0
            }
            _ => 0.0,
        }
    }

    /// The slowest vehicle's attitude bandwidth: `attitude_bandwidth_rps`, or its
    /// profile's attitude P gain.
    fn slowest_attitude_bandwidth_rps(&self) -> Result<f64, String> {
        let mut slowest = f64::INFINITY;
        for (i, v) in self.vehicle.iter().enumerate() {
            let bandwidth = match v.attitude_bandwidth_rps {
                Some(b) if b.is_finite() && b > 0.0 && b <= 1000.0 => b,
                Some(b) => {
                    return Err(format!(
                        "vehicle[{i}].attitude_bandwidth_rps must be a finite number in (0, 1000] rad/s, got {b}"
                    ));
                }
                None => profile_attitude_bandwidth_rps(&v.profile)
                    .map_err(|e| format!("vehicle[{i}]: no attitude_bandwidth_rps and {e}"))?,
            };
            slowest = slowest.min(bandwidth);
        }
        Ok(slowest)
    }
}

/// The attitude bandwidth of an emulator profile: its roll and pitch attitude P gain,
/// the slower of the two (rad/s).
#[cfg(feature = "emulator")]
fn profile_attitude_bandwidth_rps(profile: &str) -> Result<f64, String> {
    profile
        .parse::<ringswarm_sitl::profile::Profile>()
        .map(|p| p.gains.attitude_p.x.min(p.gains.attitude_p.y))
        .map_err(|e| e.to_string())
}

/// Without the emulator there are no profiles to read gains from.
#[cfg(not(feature = "emulator"))]
fn profile_attitude_bandwidth_rps(profile: &str) -> Result<f64, String> {
    Err(format!(
        "profile \"{profile}\" has no gains in a build without the emulator"
    ))
}

/// Warns (at `warn`, which is printed by default) when the gains of a validated setup are
/// too fast for the airframe, naming the time scale that fits (`time_scale` is the one
/// flown); a gate that could not run is said too.
pub fn warn_if_too_fast(setup: &SwarmSetup, time_scale: f64) {
    match &setup.bandwidth {
        Some(b) if !b.fits => {
            tracing::warn!("{}", crate::report::bandwidth_text(b, time_scale));
        }
        Some(_) => {}
        None => tracing::warn!("bandwidth gate not run: a vehicle has no attitude bandwidth"),
    }
}
