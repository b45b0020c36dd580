//! Drivers: what moves bytes and time between the sans-IO machines.
//!
//! - [`lockstep`]: the coordinator and N emulated vehicles in one process, virtual time,
//!   encoded MAVLink frames in between, seeded latency and loss. Deterministic.
//! - [`udp`]: tokio, one socket per vehicle, for real PX4 or `ringswarm sitl` vehicles.

pub mod lockstep;
pub mod udp;
