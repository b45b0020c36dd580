//! The gate every position report passes before the swarm flies on it (pure, no I/O).
//!
//! - **Values.** A report with a non-finite field, a speed above
//!   [`MAX_REPORTED_SPEED_MPS`] or a position farther than [`MAX_LOCAL_DISTANCE_M`] from
//!   its origin is refused, naming the field. A GPS_GLOBAL_ORIGIN outside the Earth's
//!   ranges, or farther than [`MAX_ORIGIN_DISTANCE_M`] from the first origin the vehicle
//!   reported, is refused too.
//! - **Origin changes.** Positions are compared in the frame of the first origin (the
//!   anchor): each origin's offset from it is added to the local position. An estimator
//!   that moves its origin and shifts its local positions to match (PX4 does both) stays
//!   continuous there; the vehicle is re-anchored with a warning.
//! - **Jumps.** A report farther from the previous one than its velocity explains (more
//!   than [`JUMP_SLACK_M`] plus `½·`[`JUMP_ACCEL_MPS2`]`·dt²`) is refused: an origin that
//!   moved without its positions, a position reset, a glitch. Reports that keep following
//!   the new track consistently are taken again once they have done so for the confirm
//!   time (the caller's state timeout, so the swarm has already counted the vehicle as
//!   lost and handed it to its own Hold by then), with a warning naming the jump.

use std::time::Duration;

use nalgebra::Vector3;
use ringswarm_wire::time::SimTime;

use crate::frame::{CommonFrame, Geodetic};

/// Largest speed a position report may claim (m/s): well above any multicopter.
pub const MAX_REPORTED_SPEED_MPS: f64 = 100.0;
/// Largest distance of a local position from its origin (m).
pub const MAX_LOCAL_DISTANCE_M: f64 = 1.0e5;
/// Largest distance of a new origin from the vehicle's first one (m).
pub const MAX_ORIGIN_DISTANCE_M: f64 = 1.0e5;
/// Position error beyond the velocity's prediction that is still plausible (m).
pub const JUMP_SLACK_M: f64 = 5.0;
/// Acceleration allowed between two reports in the jump check (m/s²): 3 g.
pub const JUMP_ACCEL_MPS2: f64 = 30.0;
/// The longest gap between two reports measured on the vehicle's own clock (s); a longer
/// one (or one that runs backwards: a reboot) is measured by their arrival.
pub const MAX_SAMPLE_GAP_S: f64 = 60.0;

/// What became of a position report.
#[derive(Debug, Clone, PartialEq)]
pub enum PositionVerdict {
    /// Taken.
    Accepted,
    /// Taken after a jump followed consistently for the confirm time; the jump (m).
    Reset {
        /// How far the track jumped.
        jump_m: f64,
    },
    /// Refused, and why (naming the field or the jump).
    Refused(String),
}

/// What became of a GPS_GLOBAL_ORIGIN.
#[derive(Debug, Clone, PartialEq)]
pub enum OriginVerdict {
    /// The first origin: the anchor.
    First,
    /// The same origin again (within a centimetre).
    Same,
    /// A new origin, this far (m) from the previous one: re-anchored.
    Changed {
        /// Distance between the two origins.
        shift_m: f64,
    },
    /// Refused, and why.
    Refused(String),
}

#[derive(Debug, Clone, Copy)]
struct Sample {
    t: SimTime,
    /// When the vehicle took it, by its own boot clock (ms), if it said.
    sampled_ms: Option<u32>,
    pos_anchor_ned_m: Vector3<f64>,
    vel_ned_mps: Vector3<f64>,
}

/// The gate of one vehicle.
#[derive(Debug, Clone, Default)]
pub struct TelemetryGate {
    anchor: Option<CommonFrame>,
    origin: Option<Geodetic>,
    origin_in_anchor_ned_m: Vector3<f64>,
    last: Option<Sample>,
    candidate: Option<(SimTime, Sample)>,
}

impl TelemetryGate {
    /// The current origin, once one was taken.
    pub fn origin(&self) -> Option<Geodetic> {
        self.origin
    }

    /// Checks a GPS_GLOBAL_ORIGIN and takes it if it is plausible.
    pub fn origin_report(&mut self, origin: Geodetic) -> OriginVerdict {
        if !(origin.lat_deg.abs() <= 90.0 && origin.lon_deg.abs() <= 180.0) {
            return OriginVerdict::Refused(format!(
                "GPS_GLOBAL_ORIGIN latitude/longitude {:.7}/{:.7} deg is not on the Earth",
                origin.lat_deg, origin.lon_deg
            ));
        }
        if !(-1000.0..=20_000.0).contains(&origin.alt_amsl_m) {
            return OriginVerdict::Refused(format!(
                "GPS_GLOBAL_ORIGIN altitude {:.3} m is outside [-1000, 20000] m",
                origin.alt_amsl_m
            ));
        }
        let Some(anchor) = self.anchor else {
            self.anchor = Some(CommonFrame::new(origin));
            self.origin = Some(origin);
            return OriginVerdict::First;
        };
        let in_anchor = anchor.offset_ned_m(&origin);
        if in_anchor.norm() > MAX_ORIGIN_DISTANCE_M {
            return OriginVerdict::Refused(format!(
                "GPS_GLOBAL_ORIGIN moved {:.0} m from the vehicle's first origin (more than {MAX_ORIGIN_DISTANCE_M} m)",
                in_anchor.norm()
            ));
        }
        let shift_m = (in_anchor - self.origin_in_anchor_ned_m).norm();
        if shift_m < 0.01 {
            return OriginVerdict::Same;
        }
        self.origin = Some(origin);
        self.origin_in_anchor_ned_m = in_anchor;
        OriginVerdict::Changed { shift_m }
    }

    /// Checks a LOCAL_POSITION_NED received at `now` (taken at `sampled_ms` of the
    /// vehicle's boot clock, its `time_boot_ms`, when known); a jump is taken once the new
    /// track has been followed consistently for `confirm`.
    pub fn position_report(
        &mut self,
        now: SimTime,
        sampled_ms: Option<u32>,
        pos_local_ned_m: Vector3<f64>,
        vel_ned_mps: Vector3<f64>,
        confirm: Duration,
    ) -> PositionVerdict {
        if let Some(problem) = implausible(&pos_local_ned_m, &vel_ned_mps) {
            return PositionVerdict::Refused(problem);
        }
        let sample = Sample {
            t: now,
            sampled_ms,
            pos_anchor_ned_m: pos_local_ned_m + self.origin_in_anchor_ned_m,
            vel_ned_mps,
        };
        let Some(last) = self.last else {
            self.last = Some(sample);
            return PositionVerdict::Accepted;
        };
        let jump_m = deviation_m(&last, &sample);
        if jump_m <= allowed_m(&last, &sample) {
            self.last = Some(sample);
            self.candidate = None;
            return PositionVerdict::Accepted;
        }
        let since = match self.candidate {
            Some((since, prev)) if deviation_m(&prev, &sample) <= allowed_m(&prev, &sample) => {
                since
            }
            _ => now,
        };
        if now.saturating_since(since) >= confirm {
            self.last = Some(sample);
            self.candidate = None;
            return PositionVerdict::Reset { jump_m };
        }
        self.candidate = Some((since, sample));
        PositionVerdict::Refused(format!(
            "LOCAL_POSITION_NED jumped {jump_m:.1} m from where its velocity put it"
        ))
    }
}

/// The time between two samples (s): by the vehicle's own clock when both carry it and
/// it ran forward by less than [`MAX_SAMPLE_GAP_S`] (not a reboot or a wrap), else by
/// their arrival. Arrival alone is wrong for a burst: reports that waited unread (a
/// stall of the coordinator, a radio's buffer) arrive together but were taken apart.
fn dt_s(prev: &Sample, next: &Sample) -> f64 {
    if let (Some(a), Some(b)) = (prev.sampled_ms, next.sampled_ms) {
        let dt = f64::from(b.wrapping_sub(a)) * 1e-3;
        if dt <= MAX_SAMPLE_GAP_S {
            return dt;
        }
    }
    next.t.saturating_since(prev.t).as_secs_f64()
}

/// How far `next` is from where `prev`'s velocity put it (m).
fn deviation_m(prev: &Sample, next: &Sample) -> f64 {
    let dt = dt_s(prev, next);
    (next.pos_anchor_ned_m - (prev.pos_anchor_ned_m + prev.vel_ned_mps * dt)).norm()
}

fn allowed_m(prev: &Sample, next: &Sample) -> f64 {
    let dt = dt_s(prev, next);
    JUMP_SLACK_M + 0.5 * JUMP_ACCEL_MPS2 * dt * dt
}

/// The first field of a report that cannot be true, named.
fn implausible(pos: &Vector3<f64>, vel: &Vector3<f64>) -> Option<String> {
    // Every report is checked: the names are looked for only when a value is not finite.
    if !(pos.iter().all(|v| v.is_finite()) & vel.iter().all(|v| v.is_finite())) {
        let names = ["x", "y", "z", "vx", "vy", "vz"];
        for (name, value) in names.iter().zip(pos.iter().chain(vel.iter())) {
            if !value.is_finite() {
                return Some(format!("LOCAL_POSITION_NED.{name} is {value}"));
            }
        }
    }
    if vel.norm() > MAX_REPORTED_SPEED_MPS {
        return Some(format!(
            "LOCAL_POSITION_NED speed {:.1} m/s is above {MAX_REPORTED_SPEED_MPS} m/s",
            vel.norm()
        ));
    }
    if pos.norm() > MAX_LOCAL_DISTANCE_M {
        return Some(format!(
            "LOCAL_POSITION_NED position {:.0} m from its origin is beyond {MAX_LOCAL_DISTANCE_M} m",
            pos.norm()
        ));
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    const CONFIRM: Duration = Duration::from_millis(300);

    fn ms(t: u64) -> SimTime {
        SimTime::from_millis(t)
    }

    fn origin(north_m: f64) -> Geodetic {
        // 1 m north is 1/111 194.9 deg on PX4's sphere (R = 6 371 000 m).
        Geodetic {
            lat_deg: 47.0 + north_m / (6_371_000.0_f64.to_radians()),
            lon_deg: 8.0,
            alt_amsl_m: 500.0,
        }
    }

    #[test]
    fn non_finite_fast_and_far_reports_are_refused_by_name() {
        let mut g = TelemetryGate::default();
        let v = Vector3::zeros();
        let nan = Vector3::new(0.0, f64::NAN, 0.0);
        let PositionVerdict::Refused(why) = g.position_report(ms(0), None, nan, v, CONFIRM) else {
            panic!("NaN taken")
        };
        assert_eq!(why, "LOCAL_POSITION_NED.y is NaN");
        let PositionVerdict::Refused(why) = g.position_report(
            ms(0),
            None,
            v,
            Vector3::new(0.0, 0.0, f64::INFINITY),
            CONFIRM,
        ) else {
            panic!("inf taken")
        };
        assert_eq!(why, "LOCAL_POSITION_NED.vz is inf");
        let fast = Vector3::new(80.0, 80.0, 0.0); // 113.1 m/s
        assert!(matches!(
            g.position_report(ms(0), None, v, fast, CONFIRM),
            PositionVerdict::Refused(w) if w.contains("113.1 m/s")
        ));
        let far = Vector3::new(2.0e5, 0.0, 0.0);
        assert!(matches!(
            g.position_report(ms(0), None, far, v, CONFIRM),
            PositionVerdict::Refused(w) if w.contains("200000 m")
        ));
    }

    #[test]
    fn a_flight_at_20_mps_passes_and_a_10_m_jump_does_not() {
        let mut g = TelemetryGate::default();
        let v = Vector3::new(20.0, 0.0, 0.0);
        for k in 0..50 {
            let p = v * (k as f64 * 0.02);
            assert_eq!(
                g.position_report(ms(20 * k), None, p, v, CONFIRM),
                PositionVerdict::Accepted
            );
        }
        // At 1.0 s the vehicle is at 20 m; a report at 30 m is 10 m off (allowed 5.006 m).
        let verdict = g.position_report(ms(1000), None, Vector3::new(30.0, 0.0, 0.0), v, CONFIRM);
        assert_eq!(
            verdict,
            PositionVerdict::Refused(
                "LOCAL_POSITION_NED jumped 10.0 m from where its velocity put it".to_owned()
            )
        );
    }

    #[test]
    fn a_burst_of_reports_that_waited_unread_is_measured_by_the_vehicles_clock() {
        // At 20 m/s, a report every 4 ms up to 10.000 s; then the coordinator reads nothing
        // for 0.8 s and takes the 200 reports of that time together, at 10.8 s.
        let v = Vector3::new(20.0, 0.0, 0.0);
        let at = |k: u32| v * (f64::from(k) * 0.004);
        let mut by_clock = TelemetryGate::default();
        let mut by_arrival = TelemetryGate::default();
        for g in [&mut by_clock, &mut by_arrival] {
            assert_eq!(
                g.position_report(ms(10_000), Some(10_000), at(0), v, CONFIRM),
                PositionVerdict::Accepted
            );
        }
        // By the vehicle's clock the next report is 4 ms later, where its velocity put it;
        // by arrival it is 0.8 s later, 20 · 0.8 − 0.08 = 15.92 m short of that (allowed
        // 5 + ½ · 30 · 0.8² = 14.6 m).
        for k in 1..=200 {
            assert_eq!(
                by_clock.position_report(ms(10_800), Some(10_000 + 4 * k), at(k), v, CONFIRM),
                PositionVerdict::Accepted,
                "report {k}"
            );
        }
        assert_eq!(
            by_arrival.position_report(ms(10_800), None, at(1), v, CONFIRM),
            PositionVerdict::Refused(
                "LOCAL_POSITION_NED jumped 15.9 m from where its velocity put it".to_owned()
            )
        );
        // A clock that ran backwards (a reboot) is not believed: arrival again.
        let mut rebooted = TelemetryGate::default();
        rebooted.position_report(ms(10_000), Some(10_000), at(0), v, CONFIRM);
        assert!(matches!(
            rebooted.position_report(ms(10_800), Some(5), at(1), v, CONFIRM),
            PositionVerdict::Refused(_)
        ));
    }

    #[test]
    fn a_new_track_is_taken_after_the_confirm_time_and_not_before() {
        let mut g = TelemetryGate::default();
        let v = Vector3::zeros();
        assert_eq!(
            g.position_report(ms(0), None, v, v, CONFIRM),
            PositionVerdict::Accepted
        );
        let moved = Vector3::new(0.0, 50.0, 0.0);
        // Consistent on the new track from 20 ms: refused until 320 ms, taken at 320 ms.
        for t in (20..320).step_by(20) {
            assert!(matches!(
                g.position_report(ms(t), None, moved, v, CONFIRM),
                PositionVerdict::Refused(_)
            ));
        }
        assert_eq!(
            g.position_report(ms(320), None, moved, v, CONFIRM),
            PositionVerdict::Reset { jump_m: 50.0 }
        );
        assert_eq!(
            g.position_report(ms(340), None, moved, v, CONFIRM),
            PositionVerdict::Accepted
        );
    }

    #[test]
    fn an_origin_moved_with_its_positions_is_continuous_and_one_moved_alone_is_a_jump() {
        let mut g = TelemetryGate::default();
        let v = Vector3::zeros();
        assert_eq!(g.origin_report(origin(0.0)), OriginVerdict::First);
        assert_eq!(g.origin_report(origin(0.0)), OriginVerdict::Same);
        assert_eq!(
            g.position_report(ms(0), None, Vector3::new(100.0, 0.0, -50.0), v, CONFIRM),
            PositionVerdict::Accepted
        );
        // The estimator moves its origin 100 m north and its local x by −100 m.
        let OriginVerdict::Changed { shift_m } = g.origin_report(origin(100.0)) else {
            panic!("not a change")
        };
        assert!((shift_m - 100.0).abs() < 0.01, "shift {shift_m}");
        assert_eq!(
            g.position_report(ms(20), None, Vector3::new(0.0, 0.0, -50.0), v, CONFIRM),
            PositionVerdict::Accepted
        );
        // Then the origin moves another 100 m north but the positions do not follow.
        assert!(matches!(
            g.origin_report(origin(200.0)),
            OriginVerdict::Changed { .. }
        ));
        let verdict = g.position_report(ms(40), None, Vector3::new(0.0, 0.0, -50.0), v, CONFIRM);
        assert!(
            matches!(&verdict, PositionVerdict::Refused(w) if w.contains("jumped 100.0 m")),
            "{verdict:?}"
        );
    }

    #[test]
    fn impossible_origins_are_refused() {
        let mut g = TelemetryGate::default();
        let mut o = origin(0.0);
        o.lat_deg = 91.0;
        assert!(matches!(g.origin_report(o), OriginVerdict::Refused(_)));
        assert_eq!(g.origin_report(origin(0.0)), OriginVerdict::First);
        assert!(matches!(
            g.origin_report(origin(2.0e5)),
            OriginVerdict::Refused(w) if w.contains("200000 m")
        ));
        assert_eq!(g.origin(), Some(origin(0.0)));
    }
}
