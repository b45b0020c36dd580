//! Error types, one enum per layer (the maths' and the control's come from the core).
//! Each `Display` names the quantity, its value and why it was refused, so that a
//! message can be shown to the user as it is.

pub use ringswarm_core::error::{ConsensusError, ControlError};
use thiserror::Error;

/// Errors in what the user typed on the command line, beyond what clap checks.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum InputError {
    /// A vector that is not `x,y` with two finite numbers.
    #[error("{what} #{index}: \"{text}\" is not a pair of finite numbers \"x,y\" ({reason})")]
    BadVector {
        /// What the vector is.
        what: &'static str,
        /// 1-based position in the list.
        index: usize,
        /// The text given.
        text: String,
        /// Why it was refused.
        reason: String,
    },
    /// An empty list.
    #[error("{0} is empty")]
    Empty(&'static str),
    /// A ring too large for a dense eigenvalue analysis on this machine.
    #[error("m = {given} macro-vertices is too many to analyse densely (at most {max})")]
    TooLarge {
        /// The `m` given.
        given: usize,
        /// The largest accepted.
        max: usize,
    },
    /// A number out of its range.
    #[error("{name} must be a finite number in {range}, got {value}")]
    OutOfRange {
        /// The flag.
        name: &'static str,
        /// The range, as written.
        range: &'static str,
        /// The value given.
        value: f64,
    },
    /// An error of the maths layer.
    #[error(transparent)]
    Consensus(#[from] ConsensusError),
}

/// The swarm gave up before its flight (a handshake not complete in time, a vehicle's
/// handshake failed); the vehicles that flew were landed. `fly` and `demo` exit with
/// [`GaveUp::EXIT_CODE`].
#[derive(Debug, Clone, PartialEq, Error)]
#[error("{0}")]
pub struct GaveUp(pub String);

impl GaveUp {
    /// The process exit code for it.
    pub const EXIT_CODE: u8 = 3;
}

/// The divergence guard ended the consensus (the swarm ran away from the law's
/// prediction); the vehicles were held or landed by the loss policy. `fly` and `demo`
/// exit with [`GuardStopped::EXIT_CODE`].
#[derive(Debug, Clone, PartialEq, Error)]
#[error("{0}")]
pub struct GuardStopped(pub String);

impl GuardStopped {
    /// The process exit code for it.
    pub const EXIT_CODE: u8 = 4;
}

/// The fence ended the consensus (a vehicle could no longer stop inside its margin); the
/// vehicles were held or landed by `fence.action`. `fly` and `demo` exit with
/// [`FenceStopped::EXIT_CODE`].
#[derive(Debug, Clone, PartialEq, Error)]
#[error("{0}")]
pub struct FenceStopped(pub String);

impl FenceStopped {
    /// The process exit code for it.
    pub const EXIT_CODE: u8 = 5;
}

/// The safety filter could not keep two vehicles apart while the swarm flew its law; the
/// vehicles were held or landed by `safety.action`. `fly` and `demo` exit with
/// [`SeparationStopped::EXIT_CODE`].
#[derive(Debug, Clone, PartialEq, Error)]
#[error("{0}")]
pub struct SeparationStopped(pub String);

impl SeparationStopped {
    /// The process exit code for it.
    pub const EXIT_CODE: u8 = 6;
}

/// The landing ended without vehicles that were lost and not heard again in the 30 s
/// after it was ordered; they were left to their own failsafes. `fly` and `demo` exit
/// with [`VehiclesLost::EXIT_CODE`].
#[derive(Debug, Clone, PartialEq, Error)]
#[error("{0}")]
pub struct VehiclesLost(pub String);

impl VehiclesLost {
    /// The process exit code for it.
    pub const EXIT_CODE: u8 = 7;
}

/// A finished flight's outcome as the process sees it: [`GaveUp`] when the swarm gave up
/// before its flight, [`GuardStopped`] when the divergence guard ended the consensus.
///
/// # Errors
/// One of those two, carrying the summary's words.
pub fn flight_result(summary: &crate::record::metrics::Summary) -> anyhow::Result<()> {
    if let Some(failure) = &summary.failure {
        return Err(GaveUp(failure.clone()).into());
    }
    if let Some(guard) = &summary.guard {
        return Err(GuardStopped(guard.clone()).into());
    }
    if summary.stop_reason.as_deref() == Some("separation") {
        return Err(SeparationStopped(
            "two vehicles came too close and the safety action ended the consensus (events.csv names them)".to_owned(),
        )
        .into());
    }
    if !summary.left_lost.is_empty() {
        return Err(VehiclesLost(format!(
            "the landing ended without {}: lost, and left to their own failsafes (events.csv)",
            summary.left_lost.join(", ")
        ))
        .into());
    }
    if summary.stop_reason.as_deref() == Some("fence") {
        return Err(FenceStopped(
            "the fence ended the consensus (events.csv names the vehicle)".to_owned(),
        )
        .into());
    }
    Ok(())
}

/// The exit code `fly` and `demo` give a finished flight: 0, or that of [`GaveUp`],
/// [`GuardStopped`], [`SeparationStopped`] or [`FenceStopped`] (as [`flight_result`]).
pub fn exit_code(summary: &crate::record::metrics::Summary) -> u8 {
    match flight_result(summary) {
        Ok(()) => 0,
        Err(e) => code_of(&e),
    }
}

/// The process exit code for an error: that of [`GaveUp`], [`GuardStopped`],
/// [`FenceStopped`], [`SeparationStopped`] or [`VehiclesLost`], 2 for anything else (a usage error, a
/// value refused, a file that cannot be read).
pub fn code_of(err: &anyhow::Error) -> u8 {
    if err.is::<GaveUp>() {
        GaveUp::EXIT_CODE
    } else if err.is::<GuardStopped>() {
        GuardStopped::EXIT_CODE
    } else if err.is::<FenceStopped>() {
        FenceStopped::EXIT_CODE
    } else if err.is::<SeparationStopped>() {
        SeparationStopped::EXIT_CODE
    } else if err.is::<VehiclesLost>() {
        VehiclesLost::EXIT_CODE
    } else {
        2
    }
}
