//! The commands on their way: each vehicle's net commands of the last calls, and what they
//! still do before a new command acts.
//!
//! A new command acts after the delay `δ` (the state's age less a period) and holds for
//! the period `h`; the one given `m` calls ago acts over `[δ − mh, δ − (m − 1)h]` from now,
//! where that is still ahead. What they do until `δ` is kept as two constant
//! accelerations, one over each half of the delay, which give the velocity and the
//! position at `δ` exactly.
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

    /// Vehicle `k`'s accelerations over the two halves of the delay (m/s²); zero where no
    /// command of ours is known.
    pub(super) fn halves(&self, k: usize, timing: Timing) -> [Vector2<f64>; 2] {
        let (delay_s, hold_s) = (timing.delay_s, timing.hold_s);
        let zero = [Vector2::zeros(); 2];
        let Some(history) = self.nets.get(k) else {
            return zero;
        };
        if !(delay_s > 0.0 && hold_s > 0.0 && delay_s.is_finite()) {
            return zero;
        }
        // The velocity and position the commands still on their way add by `δ`.
        let (mut dv, mut dp) = (Vector2::zeros(), Vector2::zeros());
        for (m, net) in history.iter().enumerate() {
            let end_s = delay_s - m as f64 * hold_s;
            if end_s <= 0.0 {
                break;
            }
            let start_s = (end_s - hold_s).max(0.0);
            let a = net.unwrap_or_else(Vector2::zeros);
            let length_s = end_s - start_s;
            dv += a * length_s;
            dp += a * (length_s * (delay_s - 0.5 * (start_s + end_s)));
        }
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
            let [b1, b2] = on_way.halves(0, timing);
            let tau = 0.5 * delay_s;
            let v = (b1 + b2) * tau;
            let p = b1 * (1.5 * tau * tau) + b2 * (0.5 * tau * tau);
            let (p_true, v_true) = fly(&history, timing);
            assert!((v - v_true).norm() < 1e-12, "{delay_s}: {v} vs {v_true}");
            assert!((p - p_true).norm() < 1e-12, "{delay_s}: {p} vs {p_true}");
            // Not ours: nothing on its way.
            assert_eq!(on_way.halves(1, timing), [Vector2::zeros(); 2]);
        }
        // One command held for the whole delay is both halves.
        let mut one = OnWay::default();
        one.record([Some(Vector2::new(2.0, 1.0))].into_iter());
        let timing = Timing {
            delay_s: 0.01,
            hold_s: 0.01,
        };
        let [b1, b2] = one.halves(0, timing);
        assert!((b1 - Vector2::new(2.0, 1.0)).norm() < 1e-9);
        assert!((b2 - Vector2::new(2.0, 1.0)).norm() < 1e-9);
    }
}
