//! A vehicle's attitude response, measured in flight: a pure delay plus a first-order lag
//! fitted to the roll and pitch the coordinator commanded and the ones the vehicle
//! reported back.
//!
//! Model: `θ̇(t) = (θ_sp(t − L) − θ(t)) / T`. Everything between a command and the report
//! that shows it is in `L` and `T`: the uplink, the vehicle's attitude and rate loops, its
//! estimator, the attitude report's own delay, the downlink. `summary.json` reports it per
//! vehicle (`models[].attitude_response`); docs/math.md ("The bandwidth gate") says what
//! it measured on the emulator and on PX4 SIH, and why the gate keeps the attitude P gain.
//!
//! Fit: for every candidate delay `L = j·Δ` (`j = 0..=`[`MAX_DELAY_STEPS`], `Δ` the
//! control period), least squares of `y = (θ₁ − θ₀)/(t₁ − t₀)` (two consecutive reports)
//! on `x = mean(θ_sp[k₀ − j], …, θ_sp[k₁ − 1 − j]) − θ₀` (`k₀` the tick of the first
//! report, `k₁` of the second: the commands that acted between them; one tick's when
//! the attitude is reported every tick), through the origin:
//! `1/T = Σxy/Σxx`, residual `Σyy − (Σxy)²/Σxx`. The delay with the least residual wins.
//! Running sums only: constant memory, no allocation, roll and pitch pooled.

/// Longest delay tried (control periods): 0.32 s at 50 Hz.
pub const MAX_DELAY_STEPS: usize = 16;
/// Fewest report pairs before a fit is given.
pub const MIN_SAMPLES: u64 = 250;
/// Least mean square excitation `Σxx / n` (rad²) before a fit is given: a hovering
/// vehicle's commands hardly move, and noise alone would fit anything.
pub const MIN_EXCITATION_RAD2: f64 = 1e-5;

/// Report pairs whose attitude moved faster than this (rad/s) on either axis are left
/// out: the vehicle's rate limit (PX4's MC_ROLLRATE_MAX is 220°/s) or its motors
/// saturate there, and a saturated step looks like a slow loop.
pub const MAX_RATE_RPS: f64 = 2.0;
/// Report pairs with a tracking error larger than this (rad) on either axis are left out,
/// for the same reason.
pub const MAX_ERROR_RAD: f64 = 0.3;

/// How many ticks apart a report pair's first report and the pair's end may be, plus the
/// longest delay: the commands a pair can be fitted against.
const SPAN: usize = MAX_DELAY_STEPS + 8;
/// The delays tried, zero included (an exclusive bound: the loops over them vectorise).
const DELAYS: usize = MAX_DELAY_STEPS + 1;
/// The commands kept: `SPAN` rounded up to a power of two, so that a tick's slot is a mask.
const HISTORY: usize = SPAN.next_power_of_two();

/// The slot of tick `k` in the command history.
fn slot(k: u64) -> usize {
    (k & (HISTORY as u64 - 1)) as usize
}

/// The fitted response.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct AttitudeResponse {
    /// The pure delay `L` (s).
    pub delay_s: f64,
    /// The first-order time constant `T` (s).
    pub time_constant_s: f64,
    /// `L + T` (s): the lag the law sees.
    pub response_s: f64,
    /// Report pairs fitted.
    pub samples: u64,
}

/// The running fit of one vehicle.
#[derive(Debug, Clone, PartialEq)]
pub struct ResponseFit {
    step_s: f64,
    tick: u64,
    /// Commanded roll and pitch of the latest ticks (rad), per axis, each tick at its
    /// [`slot`] and again `HISTORY` further: the commands of a pair's delays are then one
    /// contiguous run, read backwards from the first report's tick.
    commanded: [[f64; 2 * HISTORY]; 2],
    /// The previous report: its (roll, pitch) (rad), arrival (s) and tick.
    last: Option<([f64; 2], f64, u64)>,
    sxx: [f64; DELAYS],
    sxy: [f64; DELAYS],
    syy: f64,
    samples: u64,
    /// The fit of the sums as they were at `samples` report pairs: the safety filter and
    /// the fence ask for it for every vehicle on every tick, and the sums change only
    /// with a new pair.
    cache: FitCache,
}

/// The last fit and the pair count it was made at; equal to any other (it only remembers
/// what the sums already determine).
#[derive(Debug, Clone, Default)]
struct FitCache(std::cell::Cell<Option<(u64, Option<AttitudeResponse>)>>);

impl PartialEq for FitCache {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

impl ResponseFit {
    /// A fit for commands sent every `step_s` seconds (the control period, > 0).
    pub fn new(step_s: f64) -> Self {
        Self {
            step_s,
            tick: 0,
            commanded: [[0.0; 2 * HISTORY]; 2],
            last: None,
            sxx: [0.0; DELAYS],
            sxy: [0.0; DELAYS],
            syy: 0.0,
            samples: 0,
            cache: FitCache::default(),
        }
    }

    /// One control tick: the attitude reported since the previous tick, if a new report
    /// came (roll and pitch in rad, arrival in s), then the attitude commanded on this
    /// tick (rad). Non-finite values break the chain of reports; `None` for `reported`
    /// with `usable = false` (not flown on our attitude commands) does too.
    pub fn tick(&mut self, reported: Option<([f64; 2], f64)>, commanded: [f64; 2], usable: bool) {
        if !usable || !commanded.iter().all(|x| x.is_finite()) {
            self.last = None;
        }
        if usable && let Some((theta, at_s)) = reported {
            if theta.iter().all(|x| x.is_finite()) && at_s.is_finite() {
                if let Some((theta0, t0, k0)) = self.last {
                    self.fuse(theta, at_s, theta0, t0, k0);
                }
                self.last = Some((theta, at_s, self.tick));
            } else {
                self.last = None;
            }
        }
        let at = slot(self.tick);
        for (history, command) in self.commanded.iter_mut().zip(commanded) {
            history[at] = command;
            history[at + HISTORY] = command;
        }
        self.tick += 1;
    }

    fn fuse(&mut self, theta: [f64; 2], at_s: f64, theta0: [f64; 2], t0: f64, k0: u64) {
        let dt = at_s - t0;
        // A report pair further apart than the history covers says nothing exact.
        if !(dt > 0.0 && dt < 0.5) || self.tick - k0 + MAX_DELAY_STEPS as u64 >= SPAN as u64 {
            return;
        }
        let k_now = slot(k0);
        let linear = (0..2).all(|axis| {
            ((theta[axis] - theta0[axis]) / dt).abs() <= MAX_RATE_RPS
                && (self.commanded[axis][k_now] - theta0[axis]).abs() <= MAX_ERROR_RAD
        });
        if !linear {
            return;
        }
        // The delays that reach back no further than the first tick.
        let delays = (k0.min(MAX_DELAY_STEPS as u64) + 1) as usize;
        // The ticks between the two reports: k₀ up to the one before this.
        let ticks = (self.tick - k0).max(1) as usize;
        for axis in 0..2 {
            let y = (theta[axis] - theta0[axis]) / dt;
            self.syy += y * y;
            // What each delay pairs with: the mean of the commands of the ticks between
            // the reports, delayed by it (delay j: ticks k₀ − j up to the tick before
            // this less j), gathered first so that the sums below are straight loops
            // over arrays. A report every tick pairs with the command of tick k₀ − j
            // alone; reports several ticks apart pair with what acted between them,
            // not with one tick's command: a command that changes from tick to tick (a
            // filter braking on every other tick) otherwise reads as noise in x, which
            // shrinks the fitted rate and stretches the lag.
            let mut x = [0.0; DELAYS];
            for m in 0..ticks {
                let newest = slot(k0 + m as u64) + HISTORY;
                let window = &self.commanded[axis][newest + 1 - DELAYS..=newest];
                for (x, command) in x.iter_mut().zip(window.iter().rev()) {
                    *x += command;
                }
            }
            let mean = 1.0 / ticks as f64;
            for x in &mut x {
                *x = *x * mean - theta0[axis];
            }
            let sums = self.sxx.iter_mut().zip(self.sxy.iter_mut());
            for ((sxx, sxy), x) in sums.zip(&x).take(delays) {
                *sxx += x * x;
                *sxy += x * y;
            }
        }
        self.samples += 1;
    }

    /// The best fit so far, once there are [`MIN_SAMPLES`] report pairs with
    /// [`MIN_EXCITATION_RAD2`] of excitation and a lag that is positive and finite.
    pub fn fit(&self) -> Option<AttitudeResponse> {
        if self.samples < MIN_SAMPLES {
            return None;
        }
        if let Some((at, fit)) = self.cache.0.get()
            && at == self.samples
        {
            return fit;
        }
        let fit = self.fit_now();
        self.cache.0.set(Some((self.samples, fit)));
        fit
    }

    /// The least-squares fit of the sums as they are.
    fn fit_now(&self) -> Option<AttitudeResponse> {
        let n = 2.0 * self.samples as f64;
        let excited_from = least_excited_sum(n);
        // Every delay's quotients first, in a straight loop the compiler vectorises (the
        // fit runs for every vehicle on every tick that brings a report pair), then the
        // choice.
        let mut rates = [0.0; DELAYS];
        let mut residuals = [0.0; DELAYS];
        let mut admissible = [false; DELAYS];
        for j in 0..DELAYS {
            let rate = self.sxy[j] / self.sxx[j];
            rates[j] = rate;
            residuals[j] = self.syy - self.sxy[j] * rate;
            // Without short-circuits, so that the loop stays branch-free.
            admissible[j] = (self.sxx[j] >= excited_from) & (rate > 0.0) & rate.is_finite();
        }
        // The first admissible delay, then any with a smaller residual.
        let mut best = usize::MAX;
        let mut best_residual = 0.0;
        for j in 0..DELAYS {
            if admissible[j] && (best == usize::MAX || residuals[j] < best_residual) {
                best = j;
                best_residual = residuals[j];
            }
        }
        if best == usize::MAX {
            return None;
        }
        let j = best;
        let rate = rates[j];
        let delay_s = j as f64 * self.step_s;
        Some(AttitudeResponse {
            delay_s,
            time_constant_s: 1.0 / rate,
            response_s: delay_s + 1.0 / rate,
            samples: self.samples,
        })
    }
}

/// The least `Σxx` whose mean square over `n` samples (`n > 0`) reaches
/// [`MIN_EXCITATION_RAD2`] as the quotient rounds: `Σxx ≥ least_excited_sum(n)` exactly when
/// `Σxx / n ≥ MIN_EXCITATION_RAD2` (a rounded quotient never falls as its dividend grows),
/// without a division per delay.
fn least_excited_sum(n: f64) -> f64 {
    let mut sum = MIN_EXCITATION_RAD2 * n;
    while sum / n >= MIN_EXCITATION_RAD2 {
        sum = sum.next_down();
    }
    while sum / n < MIN_EXCITATION_RAD2 {
        sum = sum.next_up();
    }
    sum
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A vehicle that turns the command of tick `k − delay` into its attitude with a
    /// first-order lag `t_s`, exactly integrated over one 20 ms period, reported every
    /// tick; the command a sum of sines (rad).
    fn simulate(delay: usize, t_s: f64, ticks: usize) -> ResponseFit {
        simulate_sparse(delay, t_s, ticks, 1, 0.0)
    }

    /// The same vehicle reported every `every` ticks, the command of every other tick
    /// `chatter` rad off the sines (a filter that brakes on every other tick).
    fn simulate_sparse(
        delay: usize,
        t_s: f64,
        ticks: usize,
        every: usize,
        chatter: f64,
    ) -> ResponseFit {
        let dt = 0.02;
        let mut fit = ResponseFit::new(dt);
        let mut sent = vec![[0.0; 2]; ticks];
        let mut theta = [0.0f64; 2];
        let decay = (-dt / t_s).exp();
        for k in 0..ticks {
            let t = k as f64 * dt;
            let off = if k % 2 == 1 { chatter } else { 0.0 };
            let cmd = [
                0.1 * (1.3 * t).sin() + 0.05 * (4.1 * t).sin() + off,
                0.08 * (0.9 * t).cos() + 0.04 * (3.3 * t).sin() - off,
            ];
            let report = (k % every == 0).then_some((theta, t));
            fit.tick(report, cmd, true);
            sent[k] = cmd;
            let sp = if k >= delay {
                sent[k - delay]
            } else {
                [0.0; 2]
            };
            for a in 0..2 {
                theta[a] = sp[a] + (theta[a] - sp[a]) * decay;
            }
        }
        fit
    }

    /// Reports five ticks apart (10 Hz at 50 Hz), a command that changes by 0.1 rad from
    /// tick to tick: each report pair is fitted against the mean of the five commands
    /// that acted between its reports. The delay (2 ticks) is found and the lag within
    /// 15 % of the 0.15 s flown; the forward difference over 0.1 s makes it read long by
    /// `Δ/(1 − e^(−Δ/T)) = 0.1/(1 − e^(−2/3)) = 0.2055 s` at most (a command held over the
    /// whole interval): 0.2003 s, as without the chatter. Paired with the first tick's
    /// command alone, the chatter read as noise: no delay and a lag of 0.33 s.
    #[test]
    fn reports_several_ticks_apart_are_fitted_against_the_commands_between_them() {
        let fit = simulate_sparse(2, 0.15, 6000, 5, 0.05)
            .fit()
            .expect("a fit");
        assert!((fit.delay_s - 0.04).abs() < 1e-12, "{fit:?}");
        assert!(
            fit.time_constant_s > 0.15 && fit.time_constant_s < 0.2055,
            "{fit:?}"
        );
        // Reported every tick, the same vehicle fits exactly as before.
        let fit = simulate_sparse(2, 0.15, 6000, 1, 0.05)
            .fit()
            .expect("a fit");
        let rate = (1.0 - (-0.02f64 / 0.15).exp()) / 0.02;
        assert!((1.0 / fit.time_constant_s - rate).abs() < 1e-6, "{fit:?}");
    }

    #[test]
    fn a_known_delay_and_lag_are_found() {
        // 6 ticks (120 ms) and T = 0.18 s: the exact discrete response makes the forward
        // difference (1 − e^(−Δ/T))/Δ per radian of error, not 1/T; that is the rate the
        // least squares must find: 1/T' = (1 − e^(−0.02/0.18))/0.02 = 5.2573 1/s.
        let fit = simulate(6, 0.18, 3000).fit().expect("a fit");
        assert!((fit.delay_s - 0.12).abs() < 1e-12, "{fit:?}");
        let rate = (1.0 - (-0.02f64 / 0.18).exp()) / 0.02;
        assert!((1.0 / fit.time_constant_s - rate).abs() < 1e-6, "{fit:?}");
        assert!((fit.response_s - (0.12 + 1.0 / rate)).abs() < 1e-6);
        assert_eq!(fit.samples, 2999);
    }

    #[test]
    fn the_cached_fit_follows_every_new_pair() {
        let mut fit = simulate(3, 0.1, 400);
        let before = fit.fit().expect("a fit");
        assert_eq!(Some(before), fit.fit_now());
        // A pair that moves the sums: the next answer is the new least squares.
        let (theta0, t0, _) = fit.last.expect("a report");
        let theta = [theta0[0] + 0.01, theta0[1]];
        fit.tick(
            Some((theta, t0 + 0.02)),
            [theta0[0] + 0.05, theta0[1]],
            true,
        );
        let after = fit.fit().expect("a fit");
        assert_eq!(after.samples, before.samples + 1);
        assert_eq!(Some(after), fit.fit_now());
        assert_ne!(after.time_constant_s, before.time_constant_s);
    }

    #[test]
    fn the_excitation_floor_is_the_quotient_s_test_exactly() {
        for samples in [250_u64, 251, 300, 999, 1000, 4096, 14_686, 123_457, 1 << 40] {
            let n = 2.0 * samples as f64;
            let floor = least_excited_sum(n);
            assert!(floor / n >= MIN_EXCITATION_RAD2, "{samples}");
            assert!(floor.next_down() / n < MIN_EXCITATION_RAD2, "{samples}");
            for sum in [0.0, floor.next_down(), floor, floor.next_up(), 10.0 * floor] {
                assert_eq!(
                    sum >= floor,
                    sum / n >= MIN_EXCITATION_RAD2,
                    "{samples} samples, {sum}"
                );
            }
        }
    }

    #[test]
    fn no_fit_without_samples_or_excitation() {
        assert_eq!(simulate(2, 0.1, 100).fit(), None);
        let mut still = ResponseFit::new(0.02);
        for k in 0..1000 {
            still.tick(Some(([0.0, 0.0], k as f64 * 0.02)), [0.0, 0.0], true);
        }
        assert_eq!(still.fit(), None);
    }

    #[test]
    fn unusable_ticks_and_bad_numbers_break_the_chain() {
        let mut fit = ResponseFit::new(0.02);
        fit.tick(Some(([0.1, 0.0], 0.0)), [0.2, 0.0], true);
        fit.tick(Some(([f64::NAN, 0.0], 0.02)), [0.2, 0.0], true);
        fit.tick(Some(([0.1, 0.0], 0.04)), [0.2, 0.0], true);
        fit.tick(Some(([0.1, 0.0], 0.06)), [0.2, 0.0], false);
        fit.tick(Some(([0.1, 0.0], 0.08)), [0.2, 0.0], true);
        assert_eq!(fit.samples, 0);
        fit.tick(Some(([0.12, 0.0], 0.10)), [0.2, 0.0], true);
        assert_eq!(fit.samples, 1);
    }
}
