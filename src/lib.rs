//! # ringswarm
//!
//! A ground-control coordinator that flies quadrotors in formation over MAVLink with the
//! ring-digraph consensus law of Dennisselvan, Kumar and Mukherjee: `N = 2m` vehicles on a
//! ring of macro-vertices of size two, one gain `k`, double-integrator consensus in x/y,
//! a PD altitude loop, and attitude + thrust setpoints for each vehicle.
//!
//! ## Layout
//! The sans-IO core lives in the `ringswarm-core` crate (`core/`) and is re-exported here:
//! [`consensus`], [`control`], [`safety`], [`frame`], [`link`] (MAVLink ↔ domain, the
//! router), [`vehicle`] (one vehicle link's machine), [`swarm`] (the swarm machine).
//! This crate is the application around it:
//! - [`driver`]: what moves bytes and time: the UDP driver (tokio), the lockstep driver
//!   with the emulator (virtual time), the mirror, signals, how far behind its sockets
//!   the coordinator is.
//! - [`config`]: the coordinator's TOML configuration and its validation.
//! - [`record`]: the run directory (CSV, `.tlog`, `events.csv`, `summary.json`) and the
//!   bounded in-memory trace for the plots; [`plot`] draws them.
//! - [`view`]: the live view and the replay in a browser (state, web server).
//! - [`report`]: what the `analyze` and `plan` commands compute and print.
//! - [`security`]: the signing key file and the signing clock kept across restarts.
//! - [`flight`]: the flight runner: a swarm flown over real sockets in real time to the
//!   end, with its run directory, live view and mirrors (`fly` and `demo --realtime`).
//! - [`cmd`]: one file per subcommand (the I/O edges; none imports another); [`cli`]: the
//!   command line (clap).
//! - [`error`]: one error enum per layer, and the flight outcomes' exit codes.
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

pub use ringswarm_core::{
    assignment, consensus, control, distributed, frame, index, link, safety, swarm, vehicle,
};

pub mod cli;
pub mod cmd;
pub mod config;
pub mod driver;
pub mod error;
pub mod flight;
#[cfg(feature = "emulator")]
pub mod fuzzing;
pub mod plot;
pub mod record;
pub mod report;
pub mod security;
#[cfg(feature = "emulator")]
pub mod sweep;
pub mod view;
