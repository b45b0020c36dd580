//! The bandwidth gate of a configuration: can its vehicles fly its gains at its control
//! rate? ([`crate::consensus::check_bandwidth`] has the rule and its calibration.)

use ringswarm_sitl::profile::Profile;

use super::Config;
use crate::consensus::{
    BandwidthCheck, CouplingGains, RingDigraph, check_bandwidth, eigenvalues, fastest_mode_per_s,
    nonzero_eigenvalues,
};

impl Config {
    /// The gate for the gains as flown (time scale applied), against the slowest
    /// vehicle's attitude bandwidth and the control rate. Call it on a validated config.
    ///
    /// # Errors
    /// A vehicle without a bandwidth (an unknown profile and no
    /// `attitude_bandwidth_rps`), or gains the maths refuses.
    pub fn bandwidth_check(&self) -> Result<BandwidthCheck, String> {
        let g = &self.gains;
        let c = g.time_scale;
        let ring = RingDigraph::for_agents(self.vehicle.len(), g.k).map_err(|e| e.to_string())?;
        let gains = CouplingGains::new(g.alpha * c * c, g.beta * c).map_err(|e| e.to_string())?;
        let mu = nonzero_eigenvalues(&eigenvalues(ring.laplacian()).map_err(|e| e.to_string())?);
        let mut slowest = f64::INFINITY;
        for (i, v) in self.vehicle.iter().enumerate() {
            let bandwidth = match v.attitude_bandwidth_rps {
                Some(b) if b.is_finite() && b > 0.0 && b <= 1000.0 => b,
                Some(b) => {
                    return Err(format!(
                        "vehicle[{i}].attitude_bandwidth_rps must be a finite number in (0, 1000] rad/s, got {b}"
                    ));
                }
                None => v
                    .profile
                    .parse::<Profile>()
                    .map(|p| p.gains.attitude_p.x.min(p.gains.attitude_p.y))
                    .map_err(|e| format!("vehicle[{i}]: no attitude_bandwidth_rps and {e}"))?,
            };
            slowest = slowest.min(bandwidth);
        }
        Ok(check_bandwidth(
            fastest_mode_per_s(&mu, gains),
            slowest,
            self.swarm.control_rate_hz,
        ))
    }
}

/// Warns (at `warn`, which is printed by default) when the gains are too fast for the
/// airframe, naming the time scale that fits; a gate that cannot run is said too.
pub fn warn_if_too_fast(config: &Config) {
    match config.bandwidth_check() {
        Ok(b) if !b.fits => tracing::warn!(
            "{}",
            crate::report::bandwidth_text(&b, config.gains.time_scale)
        ),
        Ok(_) => {}
        Err(e) => tracing::warn!("bandwidth gate not run: {e}"),
    }
}
