//! # ringswarm-sitl
//!
//! A software-in-the-loop quadrotor emulator that behaves like a PX4 SITL instance on the
//! wire, so that ringswarm (and pymavlink, MAVSDK or MAVProxy) can fly it with no
//! hardware, PX4 build or Gazebo.
//!
//! ## Layout
//! - [`physics`]: pure, fixed-step rigid-body quadrotor (RK4), motors, drag, wind, ground.
//! - [`control`]: PX4-like attitude P → rate PID → mixer, and the position/velocity
//!   controller used by Hold, Land and the pilot.
//! - [`profile`]: vehicle profiles (`ideal`, `x500`) with documented numbers.
//! - [`codec`]: MAVLink framing of datagrams with the `mavlink` crate as payload codec.
//! - [`autopilot`]: the sans-IO vehicle machine with PX4's wire behaviour.
//! - [`config_file`]: the TOML configuration of `ringswarm sitl --config`.
//! - [`udp`]: the tokio driver, one socket per link on PX4's ports, with fault injection.
//! - [`params`], [`world`], [`time`]: parameter table, geodetic world, simulated time.
//!
//! It never depends on `ringswarm`.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod autopilot;
pub mod codec;
pub mod config_file;
pub mod control;
pub mod params;
pub mod physics;
pub mod profile;
pub mod time;
pub mod udp;
pub mod world;
