//! The per-agent horizontal consensus law with formation offsets:
//!
//! `uᵢ = −α Σⱼ aᵢⱼ ((pᵢ − pⱼ) − (dᵢ − dⱼ)) − β Σⱼ aᵢⱼ (vᵢ − vⱼ)`
//!
//! Each agent uses only its own state and its neighbours' (the edges of
//! [`RingDigraph::neighbours`]). Positions, offsets and velocities are horizontal vectors
//! in the paper's world frame (x east, y north; see `docs/frames-and-units.md`); the
//! result is an acceleration in m/s². Pure: no I/O, no allocation.

use nalgebra::Vector2;

use super::graph::RingDigraph;
use super::stability::CouplingGains;

/// One agent's horizontal state and formation offset.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct HorizontalState {
    /// Position (m).
    pub pos_m: Vector2<f64>,
    /// Velocity (m/s).
    pub vel_mps: Vector2<f64>,
    /// Formation offset `dᵢ` (m): the agent's place in the formation.
    pub offset_m: Vector2<f64>,
}

/// Largest horizontal distance of any `pᵢ − dᵢ` from their mean (m), given the
/// `pᵢ − dᵢ`: zero when the vehicles are exactly in formation (the formation may sit
/// anywhere).
pub fn formation_error_m<I>(relative_m: I) -> f64
where
    I: Iterator<Item = Vector2<f64>> + Clone,
{
    let (sum, n) = relative_m
        .clone()
        .fold((Vector2::zeros(), 0usize), |(s, n), r| (s + r, n + 1));
    if n == 0 {
        return 0.0;
    }
    let centre = sum / n as f64;
    relative_m.map(|r| (r - centre).norm()).fold(0.0, f64::max)
}

/// The consensus acceleration of one agent from its own state and its weighted
/// neighbours `(aᵢⱼ, state of j)`.
pub fn consensus_acceleration<'a>(
    gains: CouplingGains,
    own: &HorizontalState,
    neighbours: impl IntoIterator<Item = (f64, &'a HorizontalState)>,
) -> Vector2<f64> {
    neighbours
        .into_iter()
        .fold(Vector2::zeros(), |acc, (weight, other)| {
            let position_error = (own.pos_m - other.pos_m) - (own.offset_m - other.offset_m);
            let velocity_error = own.vel_mps - other.vel_mps;
            acc - (position_error * gains.alpha + velocity_error * gains.beta) * weight
        })
}

/// The consensus acceleration of every agent of the ring, written into `out`
/// (`out[i]` for agent `i`; both slices hold one entry per agent).
///
/// # Panics
/// If `states` or `out` do not have one entry per agent (sizes are fixed when the swarm
/// is built).
pub fn ring_accelerations(
    ring: &RingDigraph,
    gains: CouplingGains,
    states: &[HorizontalState],
    out: &mut [Vector2<f64>],
) {
    assert_eq!(states.len(), ring.agents(), "one state per agent");
    assert_eq!(out.len(), ring.agents(), "one output per agent");
    for (i, slot) in out.iter_mut().enumerate() {
        let edges = ring.neighbours(i);
        *slot = consensus_acceleration(
            gains,
            &states[i],
            edges.iter().map(|e| (e.weight, &states[e.from])),
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DVector;

    #[test]
    fn per_agent_law_equals_the_laplacian_form() {
        // u = −α L (p − d) − β L v, axis by axis.
        let ring = RingDigraph::new(3, 0.8).unwrap();
        let gains = CouplingGains::new(1.5, 2.5).unwrap();
        let states: Vec<HorizontalState> = (0..6)
            .map(|i| {
                let f = i as f64;
                HorizontalState {
                    pos_m: Vector2::new(f * 3.0 - 2.0, 7.0 - f * f),
                    vel_mps: Vector2::new(f.sin(), f.cos() * 2.0),
                    offset_m: Vector2::new(f * 0.5, -f),
                }
            })
            .collect();
        let mut out = vec![Vector2::zeros(); 6];
        ring_accelerations(&ring, gains, &states, &mut out);
        let l = ring.laplacian();
        for axis in 0..2 {
            let p = DVector::from_fn(6, |i, _| states[i].pos_m[axis] - states[i].offset_m[axis]);
            let v = DVector::from_fn(6, |i, _| states[i].vel_mps[axis]);
            let u = -(&l * p) * gains.alpha - (&l * v) * gains.beta;
            for (expected, got) in u.iter().zip(&out) {
                assert!((expected - got[axis]).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn agents_in_formation_with_equal_velocities_need_no_acceleration() {
        let ring = RingDigraph::new(2, -0.5).unwrap();
        let gains = CouplingGains::new(1.0, 6.0).unwrap();
        let states: Vec<HorizontalState> = (0..4)
            .map(|i| {
                let offset = Vector2::new(i as f64 * 4.0, -(i as f64));
                HorizontalState {
                    pos_m: offset + Vector2::new(100.0, -30.0),
                    vel_mps: Vector2::new(3.0, -1.0),
                    offset_m: offset,
                }
            })
            .collect();
        let mut out = vec![Vector2::new(9.0, 9.0); 4];
        ring_accelerations(&ring, gains, &states, &mut out);
        assert!(out.iter().all(|u| u.norm() < 1e-12));
    }
}
