//! The core's error types, one enum per layer. Each `Display` names the quantity, its
//! value and why it was refused, so that a message can be shown to the user as it is.

use thiserror::Error;

/// Errors of the pure consensus maths ([`crate::consensus`]).
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ConsensusError {
    /// `m = 0`: a ring needs at least one macro-vertex.
    #[error("the ring needs at least one macro-vertex (m = 0 given; N = 2m agents)")]
    NoMacroVertices,
    /// The ring has macro-vertices of size two, so the agent count must be even.
    #[error("the ring needs an even number of agents (N = 2m); {0} given")]
    OddAgentCount(usize),
    /// A NaN or infinite input.
    #[error("{name} must be a finite number, got {value}")]
    NonFinite {
        /// The quantity, as the user knows it.
        name: &'static str,
        /// The value given.
        value: f64,
    },
    /// A quantity that must be strictly positive.
    #[error("{name} must be greater than zero, got {value}")]
    NotPositive {
        /// The quantity.
        name: &'static str,
        /// The value given.
        value: f64,
    },
    /// A per-agent list whose length does not match the ring.
    #[error("{what}: expected one entry per agent ({expected}), got {got}")]
    WrongLength {
        /// What the list holds.
        what: &'static str,
        /// `N`.
        expected: usize,
        /// The length given.
        got: usize,
    },
    /// `k = −2`: `Σ wᵢ = m(2+k) = 0` and the consensus value is undefined.
    #[error("k = {k} makes the weights of the consensus value sum to zero (m(2+k) = 0)")]
    DegenerateConsensus {
        /// The gain.
        k: f64,
    },
    /// Consensus weights that sum to zero: the consensus value is undefined.
    #[error("the consensus weights sum to zero")]
    ZeroWeightSum,
    /// A design interval `[k̂, k]` that is empty or leaves the stable range.
    #[error("design gain k̂ = {design_k} must satisfy k_min = {k_min:.6} < k̂ ≤ k = {k}")]
    BadDesignGain {
        /// `k̂`.
        design_k: f64,
        /// `k`.
        k: f64,
        /// The stability bound.
        k_min: f64,
    },
    /// The eigenvalue iteration did not converge (not expected for these matrices).
    #[error("the eigenvalue computation did not converge for a {size}x{size} matrix")]
    EigenvaluesDidNotConverge {
        /// Matrix size.
        size: usize,
    },
}

/// Errors of the control layer ([`crate::control`]): vehicle model and envelope.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ControlError {
    /// A NaN or infinite parameter.
    #[error("{name} must be a finite number, got {value}")]
    NonFinite {
        /// The parameter.
        name: &'static str,
        /// The value given.
        value: f64,
    },
    /// A parameter outside its admissible range.
    #[error("{name} = {value} is out of range: {expected}")]
    OutOfRange {
        /// The parameter.
        name: &'static str,
        /// The value given.
        value: f64,
        /// The admissible range, in words.
        expected: &'static str,
    },
    /// Per-vehicle slices of different lengths.
    #[error("{what}: expected {expected} entries, got {got}")]
    WrongLength {
        /// What the slice holds.
        what: &'static str,
        /// Expected length.
        expected: usize,
        /// Length given.
        got: usize,
    },
}
