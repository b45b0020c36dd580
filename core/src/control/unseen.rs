//! The motion a vehicle's reported positions show and its reported velocities do not.
//!
//! An autopilot's estimator corrects its position from GNSS without always carrying the
//! correction in its velocity, so a vehicle's reported position can move while its
//! reported velocity says otherwise. PX4 SIH does so by 0.5–1.1 m/s over half-second
//! windows in most line swaps (docs/dense.md); ArduCopter SITL by 0.12 m/s at most. A
//! filter that carries positions by velocities is then blind to that much closing speed.
//!
//! Measured as the slope, by least squares over the last [`WINDOW_S`] of reports, of the
//! reported position less the trapezoidal integral of the reported velocity, both on the
//! vehicle's own clock (the report's timestamp, not its arrival: reports that arrive in a
//! burst were still measured apart). A fitted slope, not the difference of two positions,
//! so that white noise on the positions counts little: σ·√(12 / (N·W²)), 0.06 m/s for
//! 0.1 m of noise over 125 reports. The speed counted is the largest slope seen, forgotten
//! at [`FORGET_MPS_PER_S`], less [`DEADBAND_MPS`]. The least-squares sums run with the
//! window (a point added, the oldest taken away), so a report costs a few operations
//! whatever the rate; the slope is fitted at most every 15 ms.
//!
//! Pure: no clock, no allocation after the window has filled.

use std::collections::VecDeque;

use nalgebra::Vector2;

/// The window the slope is fitted over (s).
pub const WINDOW_S: f64 = 0.5;
/// A window shorter than this share of [`WINDOW_S`] gives no slope.
const LEAST_SPAN_SHARE: f64 = 0.9;
/// The fewest reports a window needs to give a slope.
const LEAST_REPORTS: usize = 5;
/// Reports further apart than this (s), or not later than the one before, start over.
pub const MAX_GAP_S: f64 = 0.5;
/// Slopes up to this are rounding, the trapezoid's error and noise (m/s): not counted.
pub const DEADBAND_MPS: f64 = 0.15;
/// How fast the largest slope seen is forgotten (m/s per s): 1 m/s in 20 s.
pub const FORGET_MPS_PER_S: f64 = 0.05;

/// One report in the window: its time from the window's base (s), and the position less
/// the integral of the velocity (m).
#[derive(Debug, Clone, Copy)]
struct Point {
    t_s: f64,
    residual_m: Vector2<f64>,
}

/// The slope is fitted at most this often (s, the vehicle's clock): every report at
/// 50 Hz, every fourth at 250 Hz. Windows 15 ms apart overlap by 97 %, so a peak is not
/// missed, and a 250 Hz swarm pays a quarter of the fits.
const FIT_EVERY_S: f64 = 0.015;

/// The window's points are re-anchored (their sums recomputed from the window) after
/// this many reports, so that the running sums stay small and their rounding does not
/// build up.
const REANCHOR_EVERY: u32 = 2048;

/// The least-squares sums of the window's points, in times and residuals from an anchor
/// (their count is the window's length).
#[derive(Debug, Clone, Copy, Default)]
struct Sums {
    st: f64,
    stt: f64,
    sr: Vector2<f64>,
    srt: Vector2<f64>,
}

impl Sums {
    /// Adds (`sign` 1) or takes away (−1) the point at time `t` with residual `r`.
    fn add(&mut self, t: f64, r: Vector2<f64>, sign: f64) {
        self.st += sign * t;
        self.stt += sign * t * t;
        self.sr += r * sign;
        self.srt += r * (sign * t);
    }
}

/// The unseen motion of one vehicle's reports.
#[derive(Debug, Clone, Default)]
pub struct UnseenMotion {
    window: VecDeque<Point>,
    /// The window's sums, about `anchor`.
    sums: Sums,
    /// The time (s, from the base) and residual (m) the sums are taken about.
    anchor: (f64, Vector2<f64>),
    /// Reports since the sums were last recomputed.
    since_anchor: u32,
    /// The time the points are measured from (s, the vehicle's clock).
    base_s: f64,
    /// The last report: time (s, the vehicle's clock), velocity (m/s) and the integral
    /// of the velocity so far (m, from the base).
    last: Option<(f64, Vector2<f64>, Vector2<f64>)>,
    /// The largest slope seen (m/s) and when (s, the vehicle's clock).
    peak: Option<(f64, f64)>,
    /// When the slope was last fitted (s, the vehicle's clock).
    fitted_at: Option<f64>,
}

impl UnseenMotion {
    /// Takes a report: the vehicle's time of it (s), its horizontal position (m) and
    /// velocity (m/s) in one frame. A report at the last one's time is the same sample
    /// and is skipped; one before it, or more than [`MAX_GAP_S`] after it, starts the
    /// window over (the peak is kept). Non-finite numbers are skipped.
    pub fn report(&mut self, t_s: f64, pos_m: Vector2<f64>, vel_mps: Vector2<f64>) {
        if !(t_s.is_finite() && pos_m.iter().chain(vel_mps.iter()).all(|x| x.is_finite())) {
            return;
        }
        if self.last.is_some_and(|(t0, _, _)| t0 == t_s) {
            return; // the same sample again
        }
        let integral_m = match self.last {
            Some((t0, v0, i0)) if t_s > t0 && t_s - t0 <= MAX_GAP_S => {
                i0 + 0.5 * (v0 + vel_mps) * (t_s - t0)
            }
            _ => {
                self.window.clear();
                self.base_s = t_s;
                Vector2::zeros()
            }
        };
        self.last = Some((t_s, vel_mps, integral_m));
        let t = t_s - self.base_s;
        let point = Point {
            t_s: t,
            residual_m: pos_m - integral_m,
        };
        if self.window.is_empty() {
            self.sums = Sums::default();
            self.anchor = (point.t_s, point.residual_m);
            self.since_anchor = 0;
        }
        self.window.push_back(point);
        self.sums.add(
            point.t_s - self.anchor.0,
            point.residual_m - self.anchor.1,
            1.0,
        );
        while self
            .window
            .get(1)
            .is_some_and(|second| t - second.t_s >= WINDOW_S)
        {
            if let Some(old) = self.window.pop_front() {
                self.sums.add(
                    old.t_s - self.anchor.0,
                    old.residual_m - self.anchor.1,
                    -1.0,
                );
            }
        }
        self.since_anchor += 1;
        if self.since_anchor >= REANCHOR_EVERY {
            self.reanchor();
        }
        if self
            .fitted_at
            .is_some_and(|at| t_s > at && t_s - at < FIT_EVERY_S)
        {
            return;
        }
        let Some(slope) = self.slope_mps() else {
            return;
        };
        self.fitted_at = Some(t_s);
        if slope >= self.speed_before_deadband(t_s) {
            self.peak = Some((slope, t_s));
        }
    }

    /// Starts the window over with the next report (a position the vehicle jumped to, or
    /// one against a new origin, is no motion); what was seen is kept.
    pub fn restart(&mut self) {
        self.window.clear();
        self.last = None;
    }

    /// Recomputes the sums from the window, about its first point.
    fn reanchor(&mut self) {
        self.since_anchor = 0;
        self.sums = Sums::default();
        let Some(first) = self.window.front() else {
            return;
        };
        self.anchor = (first.t_s, first.residual_m);
        for p in &self.window {
            self.sums
                .add(p.t_s - self.anchor.0, p.residual_m - self.anchor.1, 1.0);
        }
    }

    /// The least-squares slope of the residual over the window (m/s), when the window
    /// is long enough: from the running sums, a few operations a report.
    fn slope_mps(&self) -> Option<f64> {
        let (first, last) = (self.window.front()?, self.window.back()?);
        let n = self.window.len();
        if n < LEAST_REPORTS || last.t_s - first.t_s < LEAST_SPAN_SHARE * WINDOW_S {
            return None;
        }
        let Sums { st, stt, sr, srt } = self.sums;
        let nf = n as f64;
        let den = nf * stt - st * st;
        if den.is_nan() || den <= 0.0 {
            return None;
        }
        let slope = (srt * nf - sr * st) / den;
        Some(slope.norm()).filter(|s| s.is_finite())
    }

    /// The largest slope seen, less what has been forgotten since, at the vehicle's time
    /// `t_s` (m/s).
    fn speed_before_deadband(&self, t_s: f64) -> f64 {
        self.peak.map_or(0.0, |(peak, at)| {
            (peak - FORGET_MPS_PER_S * (t_s - at).max(0.0)).max(0.0)
        })
    }

    /// The speed the reports may move at beyond what their velocities say (m/s, ≥ 0), at
    /// the vehicle's time `t_s` (s).
    pub fn speed_mps(&self, t_s: f64) -> f64 {
        (self.speed_before_deadband(t_s) - DEADBAND_MPS).max(0.0)
    }

    /// [`Self::speed_mps`] at the last report's time.
    pub fn latest_speed_mps(&self) -> f64 {
        self.last.map_or(0.0, |(t, _, _)| self.speed_mps(t))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Reports every `dt_s` for `secs` s of a vehicle whose true motion is given, with
    /// the position moved by `drift(t)` that the velocity does not show.
    fn fly(
        dt_s: f64,
        secs: f64,
        motion: impl Fn(f64) -> (Vector2<f64>, Vector2<f64>),
        drift: impl Fn(f64) -> Vector2<f64>,
    ) -> UnseenMotion {
        let mut u = UnseenMotion::default();
        let steps = (secs / dt_s).round() as usize;
        for k in 0..=steps {
            let t = k as f64 * dt_s;
            let (p, v) = motion(t);
            u.report(t, p + drift(t), v);
        }
        u
    }

    #[test]
    fn consistent_reports_show_no_unseen_motion_even_turning_hard() {
        // A vehicle swinging at 2 m/s amplitude, 6 m/s² peak acceleration (ω = 3 rad/s),
        // reported at 50 Hz: the trapezoid's error per report is ω³·A·dt³/12 and the
        // slope it leaves far below the deadband.
        let (a, w) = (2.0 / 3.0, 3.0);
        let u = fly(
            0.02,
            20.0,
            |t| {
                (
                    Vector2::new(a * (w * t).sin(), -a * (w * t).cos()),
                    Vector2::new(a * w * (w * t).cos(), a * w * (w * t).sin()),
                )
            },
            |_| Vector2::zeros(),
        );
        let (peak, _) = u.peak.expect("slopes were fitted");
        assert!(peak < 0.01, "{peak}");
        assert_eq!(u.latest_speed_mps(), 0.0);
    }

    #[test]
    fn a_position_that_moves_against_its_velocity_is_measured_at_its_speed() {
        // The reported velocity says 0.2 m/s west; the positions go 0.78 m/s east
        // (a PX4 SIH vehicle at the end of a line swap): 0.98 m/s unseen.
        let u = fly(
            0.02,
            3.0,
            |t| (Vector2::new(-0.2 * t, 0.0), Vector2::new(-0.2, 0.0)),
            |t| Vector2::new(0.98 * t, 0.0),
        );
        let (peak, at) = u.peak.expect("slopes were fitted");
        assert!((peak - 0.98).abs() < 1e-9, "{peak}");
        // The newest window is the one at the end; the peak is as new.
        assert!((at - 3.0).abs() < 1e-9);
        assert!((u.latest_speed_mps() - (0.98 - DEADBAND_MPS)).abs() < 1e-9);
        // Forgotten at its rate: 10 s later, 0.5 m/s less.
        assert!((u.speed_mps(13.0) - (0.98 - 0.5 - DEADBAND_MPS)).abs() < 1e-9);
        assert_eq!(u.speed_mps(60.0), 0.0);
    }

    #[test]
    fn a_drift_that_stopped_is_forgotten_and_a_new_one_is_taken_at_once() {
        // 1 m/s of drift for the first 2 s, none for 10 s, then 0.4 m/s.
        let drift = |t: f64| {
            let x = if t < 2.0 {
                t
            } else if t < 12.0 {
                2.0
            } else {
                2.0 + 0.4 * (t - 12.0)
            };
            Vector2::new(0.0, x)
        };
        let at_rest = |_| (Vector2::zeros(), Vector2::zeros());
        let u = fly(0.02, 11.9, at_rest, drift);
        // The peak fell from 1 m/s at 2 s by 0.05 m/s a second.
        let expected = 1.0 - FORGET_MPS_PER_S * (11.9 - 2.0) - DEADBAND_MPS;
        assert!(
            (u.latest_speed_mps() - expected).abs() < 1e-6,
            "{}",
            u.latest_speed_mps()
        );
        let u = fly(0.02, 20.0, at_rest, drift);
        // From 12 s the new drift (0.4 m/s) is below what is left of the old one (0.5 at
        // 12 s), and takes over once the old one has been forgotten below it.
        let old_left = 1.0 - FORGET_MPS_PER_S * (20.0 - 2.0);
        assert!(old_left < 0.4);
        assert!(
            (u.latest_speed_mps() - (0.4 - DEADBAND_MPS)).abs() < 1e-6,
            "{}",
            u.latest_speed_mps()
        );
    }

    /// The slope fitted directly over the window's points, about its first.
    fn direct_slope(u: &UnseenMotion) -> f64 {
        let first = u.window.front().expect("points");
        let n = u.window.len() as f64;
        let (mut st, mut stt) = (0.0, 0.0);
        let (mut sr, mut srt) = (Vector2::zeros(), Vector2::zeros());
        for p in &u.window {
            let (t, r) = (p.t_s - first.t_s, p.residual_m - first.residual_m);
            st += t;
            stt += t * t;
            sr += r;
            srt += r * t;
        }
        ((srt * n - sr * st) / (n * stt - st * st)).norm()
    }

    #[test]
    fn the_running_sums_give_the_window_s_own_fit_over_a_long_flight() {
        // An hour at 250 Hz of a drift that keeps turning: the slope from the running
        // sums (re-anchored every 2048 reports) is the direct fit's within 1e-9 m/s.
        let mut u = UnseenMotion::default();
        let (mut worst, mut fastest): (f64, f64) = (0.0, 0.0);
        for k in 0..900_000u32 {
            let t = f64::from(k) * 0.004;
            let drift = Vector2::new((0.3 * t).sin(), (0.17 * t).cos()) * 0.8;
            u.report(
                t,
                Vector2::new(2.0 * t, 100.0) + drift,
                Vector2::new(2.0, 0.0),
            );
            if k % 997 == 0
                && let Some(slope) = u.slope_mps()
            {
                worst = worst.max((slope - direct_slope(&u)).abs());
                fastest = fastest.max(slope);
            }
        }
        assert!(worst < 1e-9, "{worst}");
        // The drift's speed is 0.8·√(0.3² cos² + 0.17² sin²): at most 0.8·√(0.3² + 0.17²)
        // = 0.276, and 0.24 or more where cos(0.3t) = ±1 (sampled about every 4 s here).
        let bound = 0.8 * (0.09f64 + 0.0289).sqrt();
        let (peak, _) = u.peak.expect("slopes were fitted");
        assert!(peak <= bound, "{peak}");
        assert!(fastest <= bound && fastest > 0.235, "{fastest}");
    }

    #[test]
    fn white_position_noise_counts_little() {
        // 0.1 m of position noise (a fixed pseudo-random sequence), 250 Hz, 60 s:
        // σ_slope = 0.1·√(12 / (125·0.25)) = 0.062 m/s; the largest of 15 000 windows
        // stays within five of those.
        let mut state = 0x2545_f491_4f6c_dd1d_u64;
        let mut noise = move || {
            // xorshift64*, then the sum of 12 uniforms less 6 (a unit normal, nearly).
            let mut s = 0.0;
            for _ in 0..12 {
                state ^= state >> 12;
                state ^= state << 25;
                state ^= state >> 27;
                s += (state.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64;
            }
            s - 6.0
        };
        let mut u = UnseenMotion::default();
        for k in 0..=15_000 {
            let t = k as f64 * 0.004;
            let p = Vector2::new(1.5 * t + 0.1 * noise(), 0.1 * noise());
            u.report(t, p, Vector2::new(1.5, 0.0));
        }
        let (peak, _) = u.peak.expect("slopes were fitted");
        assert!(peak < 5.0 * 0.062, "{peak}");
        assert!(peak > 0.062, "{peak}");
    }

    #[test]
    fn a_gap_or_a_clock_going_back_starts_the_window_over_and_bad_numbers_are_ignored() {
        let mut u = UnseenMotion::default();
        for k in 0..=50 {
            let t = k as f64 * 0.02;
            u.report(t, Vector2::new(0.0, 0.0), Vector2::zeros());
        }
        assert!(u.peak.is_some_and(|(p, _)| p == 0.0));
        // A reboot: the clock starts again at 0, 3 m away. Not a slope.
        u.report(0.0, Vector2::new(3.0, 0.0), Vector2::zeros());
        assert_eq!(u.window.len(), 1);
        // A second's gap, 5 m further: not a slope either.
        u.report(1.0, Vector2::new(8.0, 0.0), Vector2::zeros());
        assert_eq!(u.window.len(), 1);
        u.report(f64::NAN, Vector2::new(8.0, 0.0), Vector2::zeros());
        u.report(1.02, Vector2::new(f64::INFINITY, 0.0), Vector2::zeros());
        assert_eq!(u.window.len(), 1);
        assert_eq!(u.latest_speed_mps(), 0.0);
    }
}
