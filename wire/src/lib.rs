//! # ringswarm-wire
//!
//! What the coordinator (`ringswarm`) and the emulator (`ringswarm-sitl`) share on the
//! wire, in one crate that depends on neither: MAVLink framing ([`codec`]: datagrams ↔
//! frames with the `mavlink` crate as the payload codec), MAVLink 2 signing ([`signing`]:
//! keys, signatures, replay protection), PX4's thrust-direction-to-attitude construction
//! ([`attitude`]), the time type both machines
//! are driven with ([`time`]), PX4's geodetic projection ([`geo`]) and PX4's mode and port
//! numbers ([`px4`]), and ArduCopter's modes and parameter names ([`ardupilot`]). The coordinator takes its codec from here, not from the
//! emulator it is tested against.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod ardupilot;
pub mod attitude;
pub mod codec;
pub mod geo;
pub mod px4;
pub mod signing;
pub mod stream;
pub mod time;
