//! Simulated time: a newtype over the time since the emulator started.
//!
//! Every machine and integrator takes `now` as an argument and never reads a clock, so the
//! same inputs give the same outputs and lockstep drivers can run faster than real time.

use std::ops::Add;
use std::time::Duration;

/// Time since the start of the simulation, in whole microseconds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
pub struct SimTime(u64);

impl SimTime {
    /// The start.
    pub const ZERO: Self = Self(0);

    /// Never: later than any time.
    pub const MAX: Self = Self(u64::MAX);

    /// From microseconds.
    pub const fn from_micros(us: u64) -> Self {
        Self(us)
    }

    /// From milliseconds.
    pub const fn from_millis(ms: u64) -> Self {
        Self(ms * 1000)
    }

    /// From seconds (rounded down to the microsecond; negative and NaN give zero).
    pub fn from_secs_f64(s: f64) -> Self {
        Self((s * 1e6).max(0.0) as u64)
    }

    /// Microseconds since the start.
    pub const fn as_micros(self) -> u64 {
        self.0
    }

    /// Milliseconds since the start (MAVLink's `time_boot_ms`, wrapping at `u32`).
    pub const fn boot_ms(self) -> u32 {
        (self.0 / 1000) as u32
    }

    /// Seconds since the start.
    pub fn as_secs_f64(self) -> f64 {
        self.0 as f64 * 1e-6
    }

    /// `self − earlier`, or zero if `earlier` is later.
    ///
    /// There is no `SimTime - SimTime`: an operator that quietly gave zero for a time
    /// running backwards hid exactly the bugs it should show. A caller says which it means,
    /// this or [`SimTime::checked_since`].
    ///
    /// ```compile_fail
    /// use ringswarm_wire::time::SimTime;
    /// let _ = SimTime::from_millis(2) - SimTime::from_millis(1);
    /// ```
    pub fn saturating_since(self, earlier: Self) -> Duration {
        Duration::from_micros(self.0.saturating_sub(earlier.0))
    }

    /// `self − earlier`, or `None` if `earlier` is later.
    pub fn checked_since(self, earlier: Self) -> Option<Duration> {
        self.0.checked_sub(earlier.0).map(Duration::from_micros)
    }
}

impl Add<Duration> for SimTime {
    type Output = Self;
    fn add(self, rhs: Duration) -> Self {
        Self(self.0.saturating_add(rhs.as_micros() as u64))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn differences_say_what_a_backwards_time_gives() {
        let (a, b) = (SimTime::from_millis(1500), SimTime::from_micros(250));
        assert_eq!(a.saturating_since(b), Duration::from_micros(1_499_750));
        assert_eq!(a.checked_since(b), Some(Duration::from_micros(1_499_750)));
        assert_eq!(b.saturating_since(a), Duration::ZERO);
        assert_eq!(b.checked_since(a), None);
        assert_eq!(a.checked_since(a), Some(Duration::ZERO));
    }
}
