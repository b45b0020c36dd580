//! The paper's mathematics, pure and synchronous: the ring digraph, Theorem 1 and Yu's
//! bound, gain design, the bandwidth gate, the consensus value, the achievable-velocity planner and the
//! per-agent horizontal law. Nothing here does I/O, reads a clock, logs or imports
//! tokio or mavlink.

mod bandwidth;
mod design;
mod graph;
mod law;
mod least_change;
mod planner;
mod spectrum;
mod stability;
mod velocity;

pub use bandwidth::{
    ATTITUDE_RATIO, BandwidthCheck, HOP_PRODUCT, SAMPLING_PRODUCT, check_bandwidth,
    check_bandwidth_with_hop, fastest_mode_per_s,
};
pub use design::{GainDesign, recommend_gains};
pub use graph::{Edge, Neighbours, RingDigraph};
pub use law::{HorizontalState, consensus_acceleration, formation_error_m, ring_accelerations};
pub use least_change::{LeastChange, REACH_MARGIN, least_change_velocities};
pub use planner::{
    AgentClass, Plan, PlanOutcome, PlanRequest, Retarget, g_and_h, plan, retarget_velocity,
};
pub use spectrum::{RingModes, RingSpectrum};
pub use stability::{
    CouplingGains, GainCheck, StabilityReport, analyze, closed_loop_abscissa,
    closed_loop_eigenvalues, closed_loop_matrix, eigenvalues, k_lower_bound,
    laplacian_is_stable_numerically, nonzero_eigenvalues, numeric_k_lower_bound, yu_bound,
};
pub use velocity::predicted_final_velocity;
