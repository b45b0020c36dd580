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
//! - [`profile`]: vehicle profiles (`ideal`, `x500`) with documented numbers.
//! - [`codec`], [`time`]: MAVLink framing and simulated time, from `ringswarm-wire`.
//! - [`autopilot`]: the sans-IO vehicle machine with PX4's wire behaviour.
//! - [`config_file`]: the TOML configuration of `ringswarm sitl --config`.
//! - [`pty`]: a vehicle served on a pseudo-terminal, as an autopilot on a serial port.
//! - [`udp`]: the tokio driver, one socket per link on PX4's ports, with fault injection
//!   ([`link_faults`] and [`delay_line`], also used by the coordinator's lockstep driver).
//! - [`params`], [`world`]: parameter table, geodetic world.
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
