//! Wall time the lockstep loop spends in each of its phases, kept once asked for: where a
//! benchmark's time goes. A few clock reads per step; the flight is the same.

use std::time::{Duration, Instant};

/// Wall time the lockstep loop spent in each of its phases
/// ([`super::Lockstep::keep_phase_times`]).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PhaseTimes {
    /// The vehicles' steps: physics, inner loops, autopilot, telemetry built and encoded.
    pub vehicles: Duration,
    /// The coordinator's timers and control ticks: the law, the saturation, setpoints
    /// built and encoded.
    pub coordinator: Duration,
    /// Datagrams carried both ways: the link conditions, decoding, each side's handling
    /// of what it received. An observer's work counts in the phase that calls it.
    pub delivery: Duration,
}

/// The clock behind [`PhaseTimes`].
#[derive(Debug, Clone, Copy)]
pub(super) struct PhaseClock {
    times: PhaseTimes,
    lap_start: Instant,
}

impl PhaseClock {
    /// Starts counting now.
    pub(super) fn start() -> Self {
        Self {
            times: PhaseTimes::default(),
            lap_start: Instant::now(),
        }
    }

    /// The times so far.
    pub(super) fn times(&self) -> PhaseTimes {
        self.times
    }

    /// Adds the time since the last lap to one phase.
    pub(super) fn lap(&mut self, phase: fn(&mut PhaseTimes) -> &mut Duration) {
        let now = Instant::now();
        *phase(&mut self.times) += now - self.lap_start;
        self.lap_start = now;
    }
}
