//! # ringswarm-sitl
//!
//! The software-in-the-loop emulator that ringswarm flies against when no hardware, PX4
//! build or Gazebo is at hand. It will hold:
//!
//! - `physics`: a pure, fixed-step rigid-body quadrotor with an attitude controller;
//! - `autopilot`: a sans-IO machine with PX4's wire behaviour (heartbeat, modes, arming,
//!   acknowledgements, the offboard-loss failsafe, parameters);
//! - `udp`: the tokio driver that serves one emulated vehicle per PX4 port pair.
//!
//! None of these exist yet; this crate is a placeholder in the workspace so that the
//! layout, the lockfile and CI already cover it. It never depends on `ringswarm`.
#![forbid(unsafe_code)]
#![warn(missing_docs)]
