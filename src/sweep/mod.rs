//! Sweeps: many lockstep flights of one scenario over a grid of settings, on every core,
//! each flight a row (docs/sweeps.md).
//!
//! - [`spec`]: the spec file, its axes and its flights (cells × replicates, each seeded).
//! - [`keys`]: setting a dotted key of the coordinator file.
//! - [`flight`]: one flight, flown to the end of its duration without a run directory.
//! - [`rows`]: a flight's row, the journal it is kept in, and its columns.
//! - [`parquet`]: the rows as `results.parquet`.
//! - [`map`]: a metric over two axes, the worst cells, and the theory's boundary.
//! - [`draw`]: a map as a heat map.
//! - [`part`]: which flights a part of a split sweep flies (`--part K/N`).

pub mod draw;
pub mod flight;
pub mod keys;
pub mod map;
pub mod parquet;
pub mod part;
pub mod rows;
pub mod spec;

pub use flight::{Flown, config_of, fly};
pub use part::Part;
pub use rows::{Cell, FlightRow};
pub use spec::{Flight, Sweep};
