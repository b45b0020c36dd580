//! The ring digraph with macro-vertices of size two and one gain `k`.
//!
//! Agents are numbered from 0 here (`i = 0..N`), while the paper numbers them from 1:
//! the paper's odd agent `2i−1` is our even index `2i−2`. With that shift:
//!
//! - agent `2j` (paper: odd) listens to its partner `2j+1` with weight `k` and to the
//!   previous macro-vertex's second agent `2j−1` (wrapping to `N−1`) with weight 1;
//! - agent `2j+1` (paper: even) listens to its partner `2j` with weight 1.
//!
//! For `m = 1` both edges of agent 0 point at agent 1, so it listens to it with weight
//! `1 + k`. The Laplacian is the out-Laplacian of those weights and its left null vector
//! is `w = (1, 1+k, 1, 1+k, …)`.
//!
//! This module is pure: no I/O, no clock, no logging.

use nalgebra::{DMatrix, DVector};

use crate::error::ConsensusError;

/// One incoming edge of an agent: it listens to `from` with `weight`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Edge {
    /// The 0-based index of the agent listened to.
    pub from: usize,
    /// The edge weight `a_ij` (dimensionless, may be negative).
    pub weight: f64,
}

/// A ring digraph on `N = 2m` agents with macro-vertices of size two and gain `k`.
///
/// Any finite `k` is accepted so that unstable gains can be analysed; whether `k` is
/// stable is the job of [`crate::consensus::analyze`].
#[derive(Debug, Clone, PartialEq)]
pub struct RingDigraph {
    macro_vertices: usize,
    k: f64,
}

impl RingDigraph {
    /// Builds the ring with `macro_vertices = m ≥ 1` and gain `k`.
    ///
    /// # Errors
    /// [`ConsensusError::NoMacroVertices`] for `m = 0`, [`ConsensusError::NonFinite`]
    /// for a NaN or infinite `k`.
    pub fn new(macro_vertices: usize, k: f64) -> Result<Self, ConsensusError> {
        if macro_vertices == 0 {
            return Err(ConsensusError::NoMacroVertices);
        }
        check_finite("k", k)?;
        Ok(Self { macro_vertices, k })
    }

    /// Builds the ring for `agents = N` vehicles, which must be even and at least 2.
    ///
    /// # Errors
    /// [`ConsensusError::OddAgentCount`] for an odd `N`, [`ConsensusError::NoMacroVertices`]
    /// for `N = 0`, and the errors of [`RingDigraph::new`].
    pub fn for_agents(agents: usize, k: f64) -> Result<Self, ConsensusError> {
        if agents % 2 == 1 {
            return Err(ConsensusError::OddAgentCount(agents));
        }
        Self::new(agents / 2, k)
    }

    /// The number of macro-vertices `m`.
    pub fn macro_vertices(&self) -> usize {
        self.macro_vertices
    }

    /// The number of agents `N = 2m`.
    pub fn agents(&self) -> usize {
        2 * self.macro_vertices
    }

    /// The gain `k`.
    pub fn k(&self) -> f64 {
        self.k
    }

    /// The incoming edges of agent `i` (0-based): two for the first agent of a
    /// macro-vertex (one when `m = 1`, where both point at the partner), one for the second.
    ///
    /// # Panics
    /// If `i ≥ N`: agent indices are validated where they enter the program.
    pub fn neighbours(&self, i: usize) -> Neighbours {
        let n = self.agents();
        assert!(i < n, "agent index {i} out of range for {n} agents");
        if i % 2 == 1 {
            return Neighbours::one(Edge {
                from: i - 1,
                weight: 1.0,
            });
        }
        let partner = i + 1;
        let previous = (i + n - 1) % n;
        if previous == partner {
            Neighbours::one(Edge {
                from: partner,
                weight: 1.0 + self.k,
            })
        } else {
            Neighbours::two(
                Edge {
                    from: partner,
                    weight: self.k,
                },
                Edge {
                    from: previous,
                    weight: 1.0,
                },
            )
        }
    }

    /// The out-Laplacian `L` (`N × N`): `L_ii = Σ_j a_ij`, `L_ij = −a_ij`.
    pub fn laplacian(&self) -> DMatrix<f64> {
        let n = self.agents();
        let mut l = DMatrix::zeros(n, n);
        for i in 0..n {
            for edge in self.neighbours(i).iter() {
                l[(i, edge.from)] -= edge.weight;
                l[(i, i)] += edge.weight;
            }
        }
        l
    }

    /// The left null vector `w = (1, 1+k, 1, 1+k, …)` with `w·L = 0`.
    pub fn left_null_vector(&self) -> DVector<f64> {
        DVector::from_fn(self.agents(), |i, _| self.w(i))
    }

    /// Component `i` of the left null vector.
    pub fn w(&self, i: usize) -> f64 {
        if i.is_multiple_of(2) {
            1.0
        } else {
            1.0 + self.k
        }
    }

    /// `Σ wᵢ = m(2+k)`, the normaliser of the consensus value.
    pub fn w_sum(&self) -> f64 {
        self.macro_vertices as f64 * (2.0 + self.k)
    }
}

/// The incoming edges of one agent (one or two), without allocation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Neighbours {
    edges: [Edge; 2],
    len: usize,
}

impl Neighbours {
    fn one(edge: Edge) -> Self {
        Self {
            edges: [edge, edge],
            len: 1,
        }
    }

    fn two(first: Edge, second: Edge) -> Self {
        Self {
            edges: [first, second],
            len: 2,
        }
    }

    /// The edges as a slice.
    pub fn as_slice(&self) -> &[Edge] {
        &self.edges[..self.len]
    }

    /// Iterates over the edges.
    pub fn iter(&self) -> impl Iterator<Item = &Edge> {
        self.as_slice().iter()
    }
}

/// Rejects NaN and infinities, naming the quantity.
pub(crate) fn check_finite(name: &'static str, value: f64) -> Result<(), ConsensusError> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(ConsensusError::NonFinite { name, value })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn laplacian_matches_the_paper_for_four_macro_vertices() {
        let k = 0.7;
        let l = RingDigraph::new(4, k).unwrap().laplacian();
        // Rows written out from the paper's eq. (laplacian), 0-based.
        let mut expected = DMatrix::<f64>::zeros(8, 8);
        for j in 0..4 {
            let (odd, even) = (2 * j, 2 * j + 1);
            let prev = (odd + 7) % 8;
            expected[(odd, odd)] = 1.0 + k;
            expected[(odd, even)] = -k;
            expected[(odd, prev)] = -1.0;
            expected[(even, odd)] = -1.0;
            expected[(even, even)] = 1.0;
        }
        assert_eq!(l, expected);
    }

    #[test]
    fn single_macro_vertex_merges_both_edges() {
        let l = RingDigraph::new(1, 0.5).unwrap().laplacian();
        assert_eq!(l, DMatrix::from_row_slice(2, 2, &[1.5, -1.5, -1.0, 1.0]));
    }

    #[test]
    fn rows_sum_to_zero_and_w_is_a_left_null_vector() {
        for m in 1..=12 {
            for k in [-1.7, -1.0, -0.3, 0.0, 2.5] {
                let ring = RingDigraph::new(m, k).unwrap();
                let l = ring.laplacian();
                let w = ring.left_null_vector();
                let ones = DVector::from_element(ring.agents(), 1.0);
                assert!((&l * ones).amax() < 1e-12);
                assert!((w.transpose() * &l).amax() < 1e-12);
                assert!((w.sum() - ring.w_sum()).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn zero_macro_vertices_and_odd_agent_counts_are_rejected() {
        assert_eq!(
            RingDigraph::new(0, 1.0),
            Err(ConsensusError::NoMacroVertices)
        );
        assert_eq!(
            RingDigraph::for_agents(5, 1.0),
            Err(ConsensusError::OddAgentCount(5))
        );
        assert!(matches!(
            RingDigraph::new(3, f64::NAN),
            Err(ConsensusError::NonFinite { name: "k", .. })
        ));
    }
}
