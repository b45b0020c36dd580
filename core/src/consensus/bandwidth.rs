//! Whether an airframe can fly the law: the bandwidth gate.
//!
//! The law's closed-loop modes are the roots `s` of `s² + βμ·s + αμ = 0` over the non-zero
//! eigenvalues `μ` of `L`; the fastest, `ω = max |s|`, is (for the usual `β²/α` above Yu's
//! bound) the velocity coupling's real pole near `−β·μ_max`. The law assumes the vehicle
//! produces the commanded acceleration at once, but a multicopter tilts to it through its
//! attitude loop (bandwidth about its attitude P gain, PX4's MC_ROLL_P / MC_PITCH_P) and
//! the command is only refreshed at the control rate. Two limits follow:
//!
//! - **Attitude:** `ω ≤ ρ·ω_att` with `ρ =` [`ATTITUDE_RATIO`]. Measured in lockstep on
//!   the x500 (attitude P 6.5 rad/s) flying the paper's gains (`ω = 34.8 1/s`) at 50 Hz:
//!   time scale 0.30 (`ω = 1.61·ω_att`) flies, 0.33 (`1.77·ω_att`) limit-cycles (body
//!   rates of 3 rad/s that never die out); `ρ = 1.5` keeps about 10 % below the onset.
//! - **Control rate:** `ω·T ≤` [`SAMPLING_PRODUCT`] (`T` the control period). Measured on
//!   the ideal frame with the paper's gains: 60 Hz (`ω·T = 0.58`) flies, 50 Hz (`0.70`)
//!   limit-cycles; 0.5 keeps about 15 % below the onset.
//!
//! - **Hop between shards** (a swarm split into shards, docs/distributed.md): `ω·τ ≤`
//!   [`HOP_PRODUCT`] (`τ` the one-way delay between shards). The neighbour states that
//!   cross it are carried forward by their age, which keeps much of the delay's phase
//!   lag out of the loop; what is left was measured in lockstep on paper-sim1 split in
//!   three (`ω = 34.8 1/s`, tests/integration/lockstep_shards.rs), safety filter on: up to
//!   `ω·τ = 4.2` (120 ms) the formation closes to 5 mm, with 30 % jitter and 5 % loss
//!   too; from 4.5 (130 ms, with jitter) or 4.9 (140 ms, without) the safety filter,
//!   which counts the hop and the remote vehicle's response in the age of what it knows,
//!   brakes so much that the shards' answers part and the divergence guard stops the
//!   swarm. 3.5 keeps about 20 % below the onset.
//!
//! Scaling time by `c` (`α·c²`, `β·c`) scales every mode by `c` and keeps stability and the
//! final velocity, so the gate recommends the largest `c ≤ 1` that meets every limit.

use nalgebra::Complex;
use serde::Serialize;

use super::stability::{CouplingGains, closed_loop_eigenvalues};

/// Largest ratio of the law's fastest mode to the attitude bandwidth.
pub const ATTITUDE_RATIO: f64 = 1.5;
/// Largest product of the fastest mode and the control period.
pub const SAMPLING_PRODUCT: f64 = 0.5;
/// Largest product of the fastest mode and the one-way delay between shards.
pub const HOP_PRODUCT: f64 = 3.5;

/// `max |s|` over the closed-loop eigenvalues of the non-zero `μ` (1/s).
pub fn fastest_mode_per_s(nonzero_eigs: &[Complex<f64>], gains: CouplingGains) -> f64 {
    closed_loop_eigenvalues(nonzero_eigs, gains)
        .iter()
        .map(|s| s.norm())
        .fold(0.0, f64::max)
}

/// What the gate found.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct BandwidthCheck {
    /// The fastest mode of the gains as flown (1/s).
    pub fastest_mode_per_s: f64,
    /// The attitude bandwidth it was compared with (rad/s).
    pub attitude_bandwidth_rps: f64,
    /// The control rate it was compared with (Hz).
    pub control_rate_hz: f64,
    /// The one-way delay between shards it was compared with (s; 0 for one process).
    pub hop_s: f64,
    /// The largest fastest mode the airframe and rate allow (1/s).
    pub allowed_per_s: f64,
    /// Which limit that is: `"attitude"`, `"control rate"` or `"hop between shards"`.
    pub limited_by: &'static str,
    /// The largest time scale, relative to the one flown, that fits (≤ 1 keeps it).
    pub scale_that_fits: f64,
    /// Whether the gains as flown fit.
    pub fits: bool,
}

/// Checks gains whose fastest mode is `fastest_mode_per_s` against an attitude bandwidth
/// (rad/s) and a control rate (Hz), in one process.
pub fn check_bandwidth(
    fastest_mode_per_s: f64,
    attitude_bandwidth_rps: f64,
    control_rate_hz: f64,
) -> BandwidthCheck {
    check_bandwidth_with_hop(
        fastest_mode_per_s,
        attitude_bandwidth_rps,
        control_rate_hz,
        0.0,
    )
}

/// As [`check_bandwidth`], for a swarm split into shards `hop_s` apart (one way; 0: no
/// hop limit).
pub fn check_bandwidth_with_hop(
    fastest_mode_per_s: f64,
    attitude_bandwidth_rps: f64,
    control_rate_hz: f64,
    hop_s: f64,
) -> BandwidthCheck {
    let attitude = ATTITUDE_RATIO * attitude_bandwidth_rps;
    let rate = SAMPLING_PRODUCT * control_rate_hz;
    let hop = if hop_s > 0.0 {
        HOP_PRODUCT / hop_s
    } else {
        f64::INFINITY
    };
    let (allowed, limited_by) = [
        (attitude, "attitude"),
        (rate, "control rate"),
        (hop, "hop between shards"),
    ]
    .into_iter()
    .fold((f64::INFINITY, "attitude"), |best, l| {
        if l.0 < best.0 { l } else { best }
    });
    let scale = if fastest_mode_per_s > 0.0 {
        allowed / fastest_mode_per_s
    } else {
        f64::INFINITY
    };
    BandwidthCheck {
        fastest_mode_per_s,
        attitude_bandwidth_rps,
        control_rate_hz,
        hop_s,
        allowed_per_s: allowed,
        limited_by,
        scale_that_fits: scale,
        fits: fastest_mode_per_s <= allowed * (1.0 + 1e-9),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::consensus::{RingDigraph, eigenvalues, nonzero_eigenvalues};

    fn paper_fastest(alpha: f64, beta: f64) -> f64 {
        let ring = RingDigraph::new(3, 5.0).unwrap();
        let mu = nonzero_eigenvalues(&eigenvalues(ring.laplacian()).unwrap());
        fastest_mode_per_s(&mu, CouplingGains::new(alpha, beta).unwrap())
    }

    #[test]
    fn the_fastest_mode_is_the_velocity_pole_and_scales_with_time() {
        // m = 3, k = 5: the largest eigenvalue of L is μ = 7 = 2 + k (the dense solve gives
        // 0, 0.219 ± 0.132i, 6.781 ± 0.132i, 7), so the velocity pole of s² + 5μs + μ = 0
        // sits at (−35 − √(35² − 28))/2 = −34.80.
        let omega = paper_fastest(1.0, 5.0);
        assert!((omega - 34.8).abs() < 0.3, "{omega}");
        // Scaled by c = 0.3: α·c², β·c, every mode ×0.3.
        let scaled = paper_fastest(0.09, 1.5);
        assert!((scaled - 0.3 * omega).abs() < 1e-9, "{scaled}");
    }

    #[test]
    fn the_x500_needs_about_a_third_of_the_papers_speed_and_the_ideal_frame_none() {
        let omega = paper_fastest(1.0, 5.0);
        // x500: attitude P 6.5 rad/s, 50 Hz: attitude limits, 1.5·6.5/34.8 = 0.28.
        let x500 = check_bandwidth(omega, 6.5, 50.0);
        assert!(!x500.fits && x500.limited_by == "attitude");
        assert!((x500.scale_that_fits - 9.75 / omega).abs() < 1e-12);
        assert!((0.27..0.29).contains(&x500.scale_that_fits), "{x500:?}");
        // The ideal frame (attitude P 40 rad/s) at 250 Hz: 60 vs 125 1/s, fits.
        let ideal = check_bandwidth(omega, 40.0, 250.0);
        assert!(ideal.fits && ideal.limited_by == "attitude", "{ideal:?}");
        // The same at 50 Hz: the rate limits (25 1/s), 0.72 of the speed.
        let slow = check_bandwidth(omega, 40.0, 50.0);
        assert!(!slow.fits && slow.limited_by == "control rate");
        assert!((slow.scale_that_fits - 25.0 / omega).abs() < 1e-12);
    }

    #[test]
    fn a_hop_between_shards_limits_the_speed_when_it_is_the_tightest() {
        let omega = paper_fastest(1.0, 5.0);
        // The ideal frame at 250 Hz (limits 60 and 125 1/s): 20 ms between shards allows
        // 3.5 / 0.02 = 175 1/s, not tighter than the attitude's 60: fits.
        let lan = check_bandwidth_with_hop(omega, 40.0, 250.0, 0.020);
        assert!(lan.fits && lan.limited_by == "attitude", "{lan:?}");
        // 140 ms (a radio mesh): 25 1/s, the tightest; the scale that fits is 25/ω.
        let radio = check_bandwidth_with_hop(omega, 40.0, 250.0, 0.140);
        assert!(
            !radio.fits && radio.limited_by == "hop between shards",
            "{radio:?}"
        );
        assert!((radio.scale_that_fits - 25.0 / omega).abs() < 1e-12);
        assert_eq!(radio.hop_s, 0.14);
        // No hop: as in one process.
        assert_eq!(
            check_bandwidth_with_hop(omega, 6.5, 50.0, 0.0),
            check_bandwidth(omega, 6.5, 50.0)
        );
    }
}
