//! # ringswarm-sitl
//!
//! A software-in-the-loop quadrotor emulator that behaves like a PX4 SITL instance on the
//! wire, so that ringswarm (and pymavlink, MAVSDK or MAVProxy) can fly it with no
//! hardware, PX4 build or Gazebo.
//!
//! ## Layout
//! - [`physics`]: pure, fixed-step rigid-body quadrotor (integrated as PX4's SIH does),
//!   motors, drag, wind, ground.
//! - [`control`]: PX4-like attitude P → rate PID → mixer.
//! - [`position_control`]: PX4's multicopter position controller (position P → velocity
//!   PID → thrust vector → attitude), which flies every mode but raw offboard attitude.
//! - [`trajectory`]: the limited-speed, limited-acceleration reference of auto modes.
//! - [`profile`]: vehicle profiles (`ideal`, `x500`, `arducopter`) with documented numbers.
//! - [`codec`], [`time`]: MAVLink framing and simulated time, from `ringswarm-wire`.
//! - [`autopilot`]: the sans-IO vehicle machine with PX4's wire behaviour, or per vehicle
//!   ArduCopter's (`autopilot/ardupilot.rs`), around the types it owns: its plant (airframe,
//!   wind, battery), its mode machine, its mission transfer and its links' stream tables.
//! - [`params`], [`world`]: parameter table, geodetic world.
//! - [`config_file`]: the TOML configuration of `ringswarm sitl --config`.
//! - [`udp`]: where vehicles sit on UDP (PX4 SITL's ports, MAVLink networks, whom a link
//!   answers) and the simulated clock; [`fleet`]: the tokio driver that runs them, one
//!   worker task per core stepping a group of vehicles on a 1 ms tick.
//! - [`pty`]: a vehicle served on a pseudo-terminal, as an autopilot on a serial port.
//! - [`link_faults`], [`delay_line`], [`faulty_line`]: loss, latency, jitter and
//!   duplication of a simulated link: the one fault-send path of the fleet and of the
//!   coordinator's lockstep driver.
//! - [`keystore`], [`key_writer`]: each vehicle's signing key kept across restarts, in
//!   PX4's file format, written off the workers' threads.
//!
//! It never depends on `ringswarm`.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod autopilot;
pub mod config_file;
pub mod control;
pub mod delay_line;
pub mod faulty_line;
pub mod fleet;
pub mod key_writer;
pub mod keystore;
pub mod link_faults;
pub mod params;
pub mod physics;
pub mod position_control;
pub mod profile;
pub mod pty;
pub mod trajectory;
pub mod udp;
pub mod world;

pub use ringswarm_wire::{codec, time};
