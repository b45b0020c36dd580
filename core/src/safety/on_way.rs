//! The commands on their way: each vehicle's net commands of the last calls, and what they
//! still do before a new command acts.
//!
//! A new command acts after the delay `δ` (the state's age less a period) and holds for
//! the period `h`; the one given `m` calls ago acts over `[δ − mh, δ − (m − 1)h]` from now,
//! where that is still ahead. What they do until `δ` is kept as two constant
//! accelerations, one over each half of the delay, which give the velocity and the
//! position at `δ` exactly.
//!
//! A vehicle whose acceleration follows its commands through a first-order lag `τ`
//! (its attitude response; counted in `δ` as if it were a delay) is different: its state
//! already shows part of its recent commands. Under the lag, a command's velocity is
//! given at the same mean time as under a delay of `τ` (an exponential's mean is its time
//! constant), so where it comes to rest is the same; what differs is how much of each
//! command is still to come. The part of a command fed to the lag after the state was
//! measured is counted as before, one delay `τ` later; of the part fed before, only what
//! the lag has not yet passed on counts (`τ·a₀` for an output `a₀` then, given at mean
//! time `τ`). The two halves then give the velocity the commands still add and, once
//! they have, the same position: where the vehicle would come to rest.
//!
//! Pure: no clock.

use std::collections::VecDeque;

use nalgebra::Vector2;

use super::stopping::Timing;

/// The most calls remembered.
const MOST_CALLS: usize = 64;

/// Each vehicle's last net commands, the newest first (`None`: not ours then).
#[derive(Debug, Clone, Default)]
pub(super) struct OnWay {
    nets: Vec<VecDeque<Option<Vector2<f64>>>>,
}

impl OnWay {
    /// Records a call's net commands, one per vehicle.
    pub(super) fn record(&mut self, nets: impl ExactSizeIterator<Item = Option<Vector2<f64>>>) {
        self.nets.resize_with(nets.len(), VecDeque::new);
        for (history, net) in self.nets.iter_mut().zip(nets) {
            history.push_front(net);
            history.truncate(MOST_CALLS);
        }
    }

    /// Whether any call's command of vehicle `k` is remembered.
    pub(super) fn known(&self, k: usize) -> bool {
        self.nets.get(k).is_some_and(|h| !h.is_empty())
    }

    /// Vehicle `k`'s accelerations over the two halves of the delay (m/s²), its
    /// acceleration following its commands through a lag of `lag_s` (0: a pure delay);
    /// zero where no command of ours is known.
    pub(super) fn halves(&self, k: usize, timing: Timing, lag_s: f64) -> [Vector2<f64>; 2] {
        let (delay_s, hold_s) = (timing.delay_s, timing.hold_s);
        let zero = [Vector2::zeros(); 2];
        let Some(history) = self.nets.get(k) else {
            return zero;
        };
        if !(delay_s > 0.0 && hold_s > 0.0 && delay_s.is_finite()) {
            return zero;
        }
        // The lag is inside the delay: never longer.
        let lag_s = if lag_s.is_finite() {
            lag_s.clamp(0.0, delay_s)
        } else {
            0.0
        };
        // The velocity the commands still on their way add, and the position they add
        // by `δ` when each is taken as given at its mean time.
        let (mut dv, mut dp) = (Vector2::zeros(), Vector2::zeros());
        // The lag's output when the state was measured, `a₀`: a command fed over `[s, e]`
        // before then adds `a(e^{min(e, 0)/τ} − e^{s/τ})`. From the first such command
        // on, `e^{s/τ}` falls by `r = e^{−h/τ}` a call further back.
        let mut output = Vector2::zeros();
        let mut calls = history.iter().enumerate();
        let mut next_before = None;
        for (m, net) in calls.by_ref() {
            // As a delay: acts over [start, end]; fed to the lag `τ` earlier.
            let end_s = delay_s - m as f64 * hold_s;
            let start_s = end_s - hold_s;
            let a = net.unwrap_or_else(Vector2::zeros);
            if end_s > lag_s {
                // Fed after the state, in whole or in part: a delay of `τ`.
                let fed_from_s = (start_s - lag_s).max(0.0) + lag_s;
                let length_s = end_s - fed_from_s;
                dv += a * length_s;
                dp += a * (length_s * (delay_s - 0.5 * (fed_from_s + end_s)));
            } else if lag_s <= 0.0 {
                break;
            }
            if lag_s > 0.0 && start_s < lag_s {
                let r = (-hold_s / lag_s).exp();
                let x = ((start_s - lag_s) / lag_s).exp();
                output += a * ((x / r).min(1.0) - x);
                next_before = Some((x * r, r));
                break;
            }
        }
        if let Some((x, r)) = next_before {
            // Every older command was fed wholly before: `a·x(1/r − 1)`.
            let (mut sum, mut weight) = (Vector2::zeros(), 1.0);
            for (_, net) in calls {
                if let Some(a) = net {
                    sum += a * weight;
                }
                weight *= r;
            }
            output += sum * (x * (1.0 / r - 1.0));
        }
        // What the lag still holds, `τ·a₀`, given at mean time `τ`.
        dv += output * lag_s;
        dp += output * (lag_s * (delay_s - lag_s));
        // Two halves of τ = δ/2: τ(b₁ + b₂) = Δv, τ²(3b₁ + b₂)/2 = Δp.
        let tau = 0.5 * delay_s;
        let first = (dp - dv * (0.5 * tau)) / (tau * tau);
        [first, dv / tau - first]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fly(history: &[Vector2<f64>], timing: Timing) -> (Vector2<f64>, Vector2<f64>) {
        // The commands of the history in their slots, flown one after the other from now
        // to the delay: the one given m + 1 calls ago over [δ − (m + 1)h, δ − mh].
        let (mut p, mut v) = (Vector2::zeros(), Vector2::zeros());
        let (delay_s, hold_s) = (timing.delay_s, timing.hold_s);
        let slots = (delay_s / hold_s).ceil() as usize;
        for m in (0..slots).rev() {
            let end_s = delay_s - m as f64 * hold_s;
            let dt = end_s - (end_s - hold_s).max(0.0);
            let a = history.get(m).copied().unwrap_or_else(Vector2::zeros);
            p += v * dt + a * (0.5 * dt * dt);
            v += a * dt;
        }
        (p, v)
    }

    #[test]
    fn the_two_halves_give_the_velocity_and_position_the_commands_on_their_way_give() {
        let history = [
            Vector2::new(1.0, -2.0),
            Vector2::new(3.0, 0.5),
            Vector2::new(-1.0, 1.0),
            Vector2::new(0.2, 4.0),
        ];
        let mut on_way = OnWay::default();
        for net in history.iter().rev() {
            on_way.record([Some(*net), None].into_iter());
        }
        for delay_s in [0.01, 0.025, 0.03, 0.07, 0.5] {
            let timing = Timing {
                delay_s,
                hold_s: 0.01,
            };
            let [b1, b2] = on_way.halves(0, timing, 0.0);
            let tau = 0.5 * delay_s;
            let v = (b1 + b2) * tau;
            let p = b1 * (1.5 * tau * tau) + b2 * (0.5 * tau * tau);
            let (p_true, v_true) = fly(&history, timing);
            assert!((v - v_true).norm() < 1e-12, "{delay_s}: {v} vs {v_true}");
            assert!((p - p_true).norm() < 1e-12, "{delay_s}: {p} vs {p_true}");
            // Not ours: nothing on its way.
            assert_eq!(on_way.halves(1, timing, 0.0), [Vector2::zeros(); 2]);
        }
        // One command held for the whole delay is both halves.
        let mut one = OnWay::default();
        one.record([Some(Vector2::new(2.0, 1.0))].into_iter());
        let timing = Timing {
            delay_s: 0.01,
            hold_s: 0.01,
        };
        let [b1, b2] = one.halves(0, timing, 0.0);
        assert!((b1 - Vector2::new(2.0, 1.0)).norm() < 1e-9);
        assert!((b2 - Vector2::new(2.0, 1.0)).norm() < 1e-9);
    }

    /// A lag `τ` driven by `u` for `d` from `(p, v, a)`, integrated exactly.
    fn lagged(
        (p, v, a): (Vector2<f64>, Vector2<f64>, Vector2<f64>),
        u: Vector2<f64>,
        d: f64,
        lag_s: f64,
    ) -> (Vector2<f64>, Vector2<f64>, Vector2<f64>) {
        let e = (-d / lag_s).exp();
        let gap = a - u;
        (
            p + v * d + u * (0.5 * d * d) + gap * (lag_s * (d - lag_s * (1.0 - e))),
            v + u * d + gap * (lag_s * (1.0 - e)),
            u + gap * e,
        )
    }

    #[test]
    fn under_a_lag_the_halves_give_what_the_commands_still_add_and_where_it_comes_to_rest() {
        // Twelve commands, the newest first, each fed to the lag over
        // [δ − (m + 1)h − τ, δ − mh − τ] (the delay δ counts the lag); the state is
        // measured at 0, part-way through. Flown exactly through the lag to 6 s, long after
        // the last, against the state at 0 carried on by the halves and then coasting.
        let history: Vec<Vector2<f64>> = (0..12)
            .map(|m| {
                let m = m as f64;
                Vector2::new(3.0 * (0.7 * m).sin() - 0.5, 2.0 * (1.3 * m).cos() + 0.2 * m)
            })
            .collect();
        let mut on_way = OnWay::default();
        for net in history.iter().rev() {
            on_way.record([Some(*net)].into_iter());
        }
        let hold_s = 0.02;
        for (delay_s, lag_s) in [(0.19, 0.17), (0.5, 0.05), (0.12, 0.12), (0.3, 0.1)] {
            let timing = Timing { delay_s, hold_s };
            let end_of = |m: usize| delay_s - m as f64 * hold_s - lag_s;
            let mut cuts: Vec<f64> = (0..=history.len()).map(end_of).collect();
            cuts.extend([0.0, 6.0]);
            cuts.sort_by(f64::total_cmp);
            let input = |t: f64| {
                (0..history.len())
                    .find(|&m| end_of(m + 1) <= t && t < end_of(m))
                    .map_or_else(Vector2::zeros, |m| history[m])
            };
            let mut state = (Vector2::zeros(), Vector2::zeros(), Vector2::zeros());
            let mut at_zero = state;
            for w in cuts.windows(2) {
                if w[0] == 0.0 {
                    at_zero = state;
                }
                state = lagged(state, input(0.5 * (w[0] + w[1])), w[1] - w[0], lag_s);
            }
            let (p0, v0, _) = at_zero;
            let (p_end, v_end, a_end) = state;
            assert!(a_end.norm() < 1e-12);
            let [b1, b2] = on_way.halves(0, timing, lag_s);
            let tau = 0.5 * delay_s;
            let dv = (b1 + b2) * tau;
            let dp = b1 * (1.5 * tau * tau) + b2 * (0.5 * tau * tau);
            let p_model = p0 + v0 * 6.0 + dp + dv * (6.0 - delay_s);
            assert!(
                (v0 + dv - v_end).norm() < 1e-12,
                "{lag_s}: {} vs {v_end}",
                v0 + dv
            );
            assert!(
                (p_model - p_end).norm() < 1e-11,
                "{lag_s}: {p_model} vs {p_end}"
            );
            // Counting the lag as a delay alone counts what the state shows again, unless
            // every command was fed to the lag after the state.
            let [c1, c2] = on_way.halves(0, timing, 0.0);
            let as_delay = v0 + (c1 + c2) * tau;
            if end_of(history.len()) >= 0.0 {
                assert!((as_delay - v_end).norm() < 1e-12, "{lag_s}");
            } else {
                assert!((as_delay - v_end).norm() > 1e-2, "{lag_s}");
            }
        }
    }
}
