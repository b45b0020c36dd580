//! The subcommands, one file each: the I/O edges that read files and flags, run a driver
//! and print or write what came of it.

pub mod analyze;
#[cfg(feature = "emulator")]
pub mod demo;
pub mod fly;
pub mod keygen;
pub mod plan;
pub mod sign_setup;
#[cfg(feature = "emulator")]
pub mod sitl;
#[cfg(feature = "emulator")]
pub mod sweep;
pub mod view;
