//! The consensus value: the common velocity the agents converge to.
//!
//! `w·v` is invariant under the law (because `w·L = 0`), so
//! `v_f = Σ wᵢ vᵢ(0) / Σ wᵢ = Σ (v_{2i−1}(0) + (1+k) v_{2i}(0)) / (m(2+k))`, per axis and
//! in any dimension. Formation offsets do not change it (`w·L·d = 0`). Pure: no I/O.

use nalgebra::SVector;

use super::graph::RingDigraph;
use crate::error::ConsensusError;

/// The predicted final velocity for initial velocities `v0` (one per agent, any frame,
/// m/s), valid when the closed loop is stable.
///
/// # Errors
/// [`ConsensusError::WrongLength`] when `v0` has not one entry per agent,
/// [`ConsensusError::NonFinite`] for a NaN or infinite component,
/// [`ConsensusError::DegenerateConsensus`] for `k = −2`.
pub fn predicted_final_velocity<const D: usize>(
    ring: &RingDigraph,
    v0: &[SVector<f64, D>],
) -> Result<SVector<f64, D>, ConsensusError> {
    if v0.len() != ring.agents() {
        return Err(ConsensusError::WrongLength {
            what: "initial velocities",
            expected: ring.agents(),
            got: v0.len(),
        });
    }
    if let Some(bad) = v0.iter().flat_map(|v| v.iter()).find(|x| !x.is_finite()) {
        return Err(ConsensusError::NonFinite {
            name: "initial velocity component",
            value: *bad,
        });
    }
    let w_sum = ring.w_sum();
    if w_sum.abs() < 1e-12 {
        return Err(ConsensusError::DegenerateConsensus { k: ring.k() });
    }
    let weighted = v0
        .iter()
        .enumerate()
        .fold(SVector::<f64, D>::zeros(), |acc, (i, v)| {
            acc + v * ring.w(i)
        });
    Ok(weighted / w_sum)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Vector1, Vector3};

    #[test]
    fn paper_first_simulation_final_velocity() {
        // k = 5, w = (1, 6, 1, 6, 1, 6), Σw = 21:
        // x: (9 + 18 − 8 + 6·(15 + 13 + 14)) / 21 = 271/21; y: (4 − 2 − 7 + 6·(8 + 1 + 18)) / 21 = 157/21.
        let ring = RingDigraph::new(3, 5.0).unwrap();
        let v0 = [
            Vector3::new(9.0, 4.0, 0.0),
            Vector3::new(15.0, 8.0, 7.0),
            Vector3::new(18.0, -2.0, 13.0),
            Vector3::new(13.0, 1.0, 7.0),
            Vector3::new(-8.0, -7.0, 6.0),
            Vector3::new(14.0, 18.0, -6.0),
        ];
        let vf = predicted_final_velocity(&ring, &v0).unwrap();
        assert!((vf.x - 271.0 / 21.0).abs() < 1e-12);
        assert!((vf.y - 157.0 / 21.0).abs() < 1e-12);
        // z: (0 + 13 + 6 + 6·(7 + 7 − 6)) / 21 = 67/21.
        assert!((vf.z - 67.0 / 21.0).abs() < 1e-12);
    }

    #[test]
    fn wrong_count_and_degenerate_gain_are_refused() {
        let ring = RingDigraph::new(2, 1.0).unwrap();
        assert!(matches!(
            predicted_final_velocity(&ring, &[Vector1::new(1.0)]),
            Err(ConsensusError::WrongLength {
                expected: 4,
                got: 1,
                ..
            })
        ));
        let ring = RingDigraph::new(1, -2.0).unwrap();
        assert!(matches!(
            predicted_final_velocity(&ring, &[Vector1::new(1.0), Vector1::new(2.0)]),
            Err(ConsensusError::DegenerateConsensus { .. })
        ));
    }
}
