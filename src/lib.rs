//! # ringswarm
//!
//! A ground-control coordinator that flies quadrotors in formation over MAVLink with the
//! ring-digraph consensus law of Dennisselvan, Kumar and Mukherjee: `N = 2m` vehicles on a
//! ring of macro-vertices of size two, one gain `k`, double-integrator consensus in x/y,
//! a PD altitude loop, and attitude + thrust setpoints for each vehicle.
//!
//! ## Layout
//! - [`consensus`]: the paper's maths, pure: ring digraph, stability bound on `k`, Yu's
//!   bound, gain design, final velocity, achievable-velocity planner, per-agent law.
//! - [`control`]: pure: altitude loop, actuator envelope and saturation, acceleration →
//!   attitude quaternion and normalised thrust, frame conversions.
//! - [`safety`]: pure: the pairwise barrier rows, the neighbour sweep, the fence and the
//!   weighted QP that keeps vehicles apart and inside the fence.
//! - [`frame`]: the common frame built from each vehicle's geodetic origin (pure).
//! - [`link`]: the MAVLink edge: framing and message ↔ domain conversions.
//! - [`vehicle`]: sans-IO machine for one vehicle: PX4 offboard handshake, link health.
//! - [`swarm`]: sans-IO swarm machine: the laws at the control rate over every link.
//! - [`driver`]: lockstep (virtual time, in-memory) driver of the swarm and the emulator.
//! - [`report`]: what the `analyze` and `plan` commands compute and print.
//! - [`sitl_cmd`]: `ringswarm sitl`, the emulator on real UDP sockets (I/O edge).
//! - [`config`]: the coordinator's TOML configuration and its validation.
//! - [`view`]: the live view and the replay in a browser (state, web server).
//! - [`cli`]: the command line (clap).
//! - [`error`]: one error enum per layer.
//!
//! ```
//! use ringswarm::consensus::{RingDigraph, CouplingGains, analyze};
//! let ring = RingDigraph::new(4, -0.5)?;
//! let report = analyze(&ring, Some(CouplingGains::new(1.0, 6.0)?))?;
//! assert!(report.stable);
//! assert!((report.k_min + 1.0).abs() < 1e-12);
//! # Ok::<(), ringswarm::error::ConsensusError>(())
//! ```
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod cli;
pub mod config;
pub mod consensus;
pub mod control;
#[cfg(feature = "emulator")]
pub mod demo_cmd;
pub mod driver;
pub mod error;
pub mod fly_cmd;
pub mod frame;
#[cfg(feature = "emulator")]
pub mod fuzzing;
pub mod link;
pub mod plot;
pub mod record;
pub mod report;
pub mod safety;
pub mod security;
pub mod sign_setup_cmd;
#[cfg(feature = "emulator")]
pub mod sitl_cmd;
pub mod swarm;
pub mod vehicle;
pub mod view;
pub mod view_cmd;
