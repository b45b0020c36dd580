//! The integration tests, in one binary: one link instead of one per file, and the test
//! harness runs every test of every file in parallel (a file of its own each took a
//! link of its own, and ran after the one before). `allocations.rs` stays apart: its
//! counting allocator would count every other test.

#[path = "../common/mod.rs"]
mod common;

mod ardupilot;
mod cli;
mod config;
mod config_random;
mod formation_growth;
mod fuzz_smoke;
mod lockstep_dense;
mod lockstep_failsafe;
mod lockstep_fence;
mod lockstep_hostile;
mod lockstep_model_error;
mod lockstep_model_matrix;
mod lockstep_networks;
mod lockstep_paper_sim1;
mod lockstep_planner;
mod lockstep_policies;
mod lockstep_safety;
mod lockstep_shards;
mod lockstep_signing;
mod paper_examples;
mod properties;
mod scenario_table;
mod scenarios;
mod sweep;
mod udp_loop;
mod vehicle_handshake;
mod web_view;
