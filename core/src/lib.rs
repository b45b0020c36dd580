//! # ringswarm-core
//!
//! The sans-IO core of ringswarm, as `quinn-proto` is to `quinn`: everything that decides
//! what a swarm of quadrotors flying the ring-digraph consensus law does, with no
//! runtime, no socket, no clock and no file. Time comes in as an argument, datagrams come
//! in and go out as bytes; the application crate (`ringswarm`) drives it over UDP or in
//! lockstep with the emulator, records it and shows it.
//!
//! ## Layout
//! - [`consensus`]: the paper's maths, pure: ring digraph, stability bound on `k`, Yu's
//!   bound, gain design, final velocity, achievable-velocity planner, per-agent law.
//! - [`control`]: pure: altitude loop, actuator envelope and saturation, acceleration →
//!   attitude quaternion and normalised thrust, the in-flight hover-thrust, drag and
//!   response estimates.
//! - [`safety`]: pure: the pairwise barrier rows, the neighbour sweep, the fence and the
//!   weighted QP that keeps vehicles apart and inside the fence.
//! - [`frame`]: the common frame built from each vehicle's geodetic origin.
//! - [`link`]: the MAVLink edge: message ↔ domain conversions and the router of
//!   datagrams between sockets and vehicles. MAVLink types appear here (and in `wire`).
//! - [`vehicle`]: the sans-IO machine of one vehicle link: PX4's offboard handshake, the
//!   fence upload, link health, the telemetry gate.
//! - [`swarm`]: the sans-IO swarm machine: the laws at the control rate over every link,
//!   the safety filter, the divergence guard, the fence, the events.
//! - [`distributed`]: the swarm split into shards: which shard flies which vehicle, and
//!   the messages between shards.
//! - [`error`]: the maths' and the control's errors.
//!
//! The public surface a driver needs is [`swarm::Swarm`] (`handle_datagram`,
//! `handle_timeout`, `poll_timeout`, `poll_transmit`, `recycle`, `set_listen_lag`) and
//! its setup ([`swarm::SwarmSetup`]); the rest is there to be read and tested.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod assignment;
pub mod consensus;
pub mod control;
pub mod distributed;
pub mod error;
pub mod frame;
pub mod index;
pub mod link;
pub mod safety;
pub mod swarm;
pub mod vehicle;
