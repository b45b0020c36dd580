//! The stopping row: a pair's row that holds when every vehicle can stop together and
//! stay apart ([`super::Rows::Stopping`]; docs/dense.md, "The synchronised stop").
//!
//! The barrier row ([`super::barrier`]) counts on each pair braking its relative motion
//! at the two vehicles' summed authority. In a packed block a vehicle has many pairs and
//! cannot brake each of them in its own direction: no single manoeuvre of all vehicles
//! meets every pair's assumption, so the barrier can let a block into a state from which
//! no manoeuvre keeps it apart. The stopping row counts on one manoeuvre instead, the
//! **synchronised stop**: after the command on its way (for `delay_s`) and the new one
//! (for `hold_s`), every vehicle brakes along its velocity and all come to rest together
//! after the common time `T`, the slowest stop of the swarm (`|vᵢ|/βᵢ` at its largest,
//! `βᵢ` the braking share). Braking at `vᵢ/T` is inside every share, and under it a
//! pair's relative motion is a straight segment from `Δp` to `Δp + Δv·T/2`. The row asks
//! that segment's far end to stay the separation `r` beyond the plane through the pair's
//! present direction `n`,
//!
//! ```text
//! nᵀ(Eᵢ − Eⱼ) ≥ r,   Eₖ = pₖ + vₖ(δ + h + T/2) + bₖ(δ²/2 + δ(h + T/2)) + uₖ(h²/2 + hT/2),
//! ```
//!
//! linear in the commands `u` (`b` the command on its way, `δ` the delay, `h` the hold).
//! With the near end on the same side (the start, which the commands barely move), the
//! whole segment is: the pair can stop apart. `T` is taken at its largest over what the
//! commands can do in `δ + h`, so a segment the commands make is never longer than the
//! row assumes. A vehicle not ours keeps its velocity (`Eₖ = pₖ + vₖ(δ + h + T)`).
//!
//! The commands on their way ([`super::on_way`]) each act for their period, `δ` after
//! they were given, less what a vehicle's lag has already passed on to its state. A
//! command moves the stop's end by only `h²/2 + hT/2` per m/s², so a pair at the
//! separation has its row broken by millimetres of model error; the swarm flies the
//! barrier rows (docs/dense.md, "The synchronised stop").
//!
//! Pure: no allocation, no clock.

use nalgebra::{Vector2, Vector3};

use super::stopping::Timing;
use super::{Agent, PairRow, Separation, Side, braking, limit};

/// Added to every search distance (m), for rounding.
const MARGIN_M: f64 = 0.01;

/// One tick's synchronised stop.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StopRows {
    /// When the new command acts and how long it holds.
    pub timing: Timing,
    /// The common stop time `T` (s) once the hold ends.
    pub stop_s: f64,
    /// The largest net acceleration on its way (m/s²), for the search.
    before_mps2: f64,
    /// The widest disc (m/s²), for the search.
    widest_mps2: f64,
    /// The fastest horizontal speed of a vehicle not ours (m/s), for the search: it does
    /// not stop, so its stop end runs ahead of one of ours at its speed.
    free_mps: f64,
    /// How far a vehicle braking from now can stop from where its row puts it (m), for
    /// the search: a pair the check may find in conflict has a row.
    deviation_m: f64,
}

impl StopRows {
    /// The stop for these agents; `before` is each one's net acceleration on its way over
    /// the two halves of the delay (missing: none), `braking_now` what the last check
    /// left: its stop time and the braking of the vehicles it turned to braking. `None`
    /// when no vehicle the filter commands can brake or the timing is not a number.
    pub fn new(
        agents: &[Agent],
        before: &[[Vector2<f64>; 2]],
        braking_now: (Option<f64>, &[Option<f64>]),
        timing: Timing,
    ) -> Option<Self> {
        let ahead_s = timing.delay_s + timing.hold_s;
        if !(ahead_s.is_finite() && timing.delay_s >= 0.0 && timing.hold_s >= 0.0) {
            return None;
        }
        let (mut stop_s, mut before_mps2, mut widest_mps2) = (0.0f64, 0.0f64, 0.0f64);
        let mut free_mps = 0.0f64;
        let mut any = false;
        for (k, a) in agents.iter().enumerate() {
            let Some(side) = a.side else {
                continue;
            };
            if !a.controlled {
                free_mps = free_mps.max(side.vel_mps.xy().norm());
                continue;
            }
            let on_way = before.get(k).copied().unwrap_or_default();
            let on_way_mps2 = on_way[0].norm().max(on_way[1].norm());
            let reach = limit(a) + a.drift_mps2.norm();
            before_mps2 = before_mps2.max(on_way_mps2);
            widest_mps2 = widest_mps2.max(limit(a));
            let b = braking(a);
            if b > 0.0 {
                let fastest = side.vel_mps.xy().norm() + reach.max(on_way_mps2) * ahead_s;
                stop_s = stop_s.max(fastest / b);
                any = true;
            }
        }
        let usable = any
            && [stop_s, before_mps2, widest_mps2, free_mps]
                .iter()
                .all(|x| x.is_finite());
        if !usable {
            return None;
        }
        // How far braking from when the command on its way ends (at the last check's
        // stop time, or at the rate a vehicle already brakes at) can end from where the
        // row puts the vehicle's stop without a new command.
        let (last_stop_s, committed) = braking_now;
        let mut deviation_m = 0.0f64;
        for (k, a) in agents.iter().enumerate() {
            let (Some(side), true) = (a.side, a.controlled) else {
                continue;
            };
            let on_way = before.get(k).copied().unwrap_or_default();
            let v = (side.vel_mps.xy() + (on_way[0] + on_way[1]) * (0.5 * timing.delay_s)).norm();
            let share = braking(a);
            if !(share > 0.0 && v > 0.0) {
                continue;
            }
            let rate = committed
                .get(k)
                .copied()
                .flatten()
                .or_else(|| last_stop_s.map(|t| v / t))
                .unwrap_or(v / stop_s)
                .min(share);
            let braking_m = v * v / (2.0 * rate);
            let modelled_m = v * (timing.hold_s + 0.5 * stop_s);
            deviation_m = deviation_m.max((braking_m - modelled_m).abs());
        }
        deviation_m.is_finite().then_some(Self {
            timing,
            stop_s,
            before_mps2,
            widest_mps2,
            free_mps,
            deviation_m,
        })
    }

    /// `h²/2 + hT/2`: how far a net acceleration held for the hold moves the stop's end
    /// (m per m/s²).
    pub fn gain_s2(&self) -> f64 {
        let h = self.timing.hold_s;
        0.5 * h * h + 0.5 * h * self.stop_s
    }

    /// A vehicle's stop end without its new command (scaled, m).
    fn end_m(
        &self,
        sep: &Separation,
        side: &Side,
        stops: bool,
        [b1, b2]: [Vector2<f64>; 2],
    ) -> Vector3<f64> {
        let (d, h, t) = (self.timing.delay_s, self.timing.hold_s, self.stop_s);
        let pos = sep.scaled(side.pos_m);
        let vel = sep.scaled(side.vel_mps);
        let z = pos.z + vel.z * (d + h + 0.5 * t);
        // Each half of the delay, τ = δ/2: its velocity change τb, flown for the rest of
        // the delay, the hold and half the stop.
        let tau = 0.5 * d;
        let after = h + 0.5 * t;
        let xy = if stops {
            pos.xy()
                + vel.xy() * (d + after)
                + b1 * (1.5 * tau * tau + tau * after)
                + b2 * (0.5 * tau * tau + tau * after)
        } else {
            pos.xy() + vel.xy() * (d + h + t)
        };
        Vector3::new(xy.x, xy.y, z)
    }

    /// The row of `i` and `j` (each with its accelerations on its way) keeping the scaled
    /// distance `keep_m`: `aᵀ(netᵢ − netⱼ) ≥ b` (m/s²). `None` when they coincide.
    pub fn row(
        &self,
        sep: &Separation,
        (ai, bi): (&Agent, [Vector2<f64>; 2]),
        (aj, bj): (&Agent, [Vector2<f64>; 2]),
        keep_m: f64,
    ) -> Option<PairRow> {
        let (si, sj) = (ai.side?, aj.side?);
        let dp = sep.scaled(si.pos_m - sj.pos_m);
        let distance = dp.norm();
        if !(distance > 0.0 && distance.is_finite()) {
            return None;
        }
        let n = dp / distance;
        let ends =
            self.end_m(sep, &si, ai.controlled, bi) - self.end_m(sep, &sj, aj.controlled, bj);
        let margin = n.dot(&ends) - keep_m;
        let gain = self.gain_s2();
        if gain.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
            return None;
        }
        let ahead_s = self.timing.delay_s + self.timing.hold_s + 0.5 * self.stop_s;
        Some(PairRow {
            a: Vector2::new(n.x, n.y),
            b: -margin / gain,
            h_mps: margin / ahead_s.max(1e-9),
            distance_m: distance,
            room_m: distance - keep_m,
        })
    }

    /// The distance (m, scaled) beyond which a pair whose relative scaled speed is at most
    /// `v_mps` has no stopping row that can bind (`b ≤ −(Lᵢ + Lⱼ) − 1`) with `keep_m`.
    pub fn distance_m(&self, keep_m: f64, v_mps: f64) -> f64 {
        let (d, h, t) = (self.timing.delay_s, self.timing.hold_s, self.stop_s);
        keep_m
            + v_mps.max(0.0) * (d + h + t)
            + 0.5 * self.free_mps * t
            + 2.0 * self.before_mps2 * (0.5 * d * d + d * (h + 0.5 * t))
            + (2.0 * self.widest_mps2 + 1.0) * self.gain_s2()
            + 2.0 * self.deviation_m
            + MARGIN_M
    }
}

#[cfg(test)]
mod tests {
    use super::super::tests::sep;
    use super::*;

    fn agent(p: [f64; 2], v: [f64; 2]) -> Agent {
        Agent {
            side: Some(Side {
                pos_m: Vector3::new(p[0], p[1], 10.0),
                vel_mps: Vector3::new(v[0], v[1], 0.0),
                accel_z_mps2: 0.0,
            }),
            controlled: true,
            weight: 1.0,
            drift_mps2: Vector2::zeros(),
            limit_mps2: 6.0,
            braking_mps2: 3.0,
            lag_s: 0.0,
            spread_m: 0.0,
            unseen_mps: 0.0,
        }
    }

    fn timing() -> Timing {
        Timing {
            delay_s: 0.01,
            hold_s: 0.01,
        }
    }

    #[test]
    fn the_stop_time_is_the_slowest_stop_over_what_the_commands_can_do() {
        let agents = [agent([0.0, 0.0], [4.0, 0.0]), agent([5.0, 0.0], [0.0, 1.0])];
        let rows = StopRows::new(&agents, &[], (None, &[]), timing()).expect("usable");
        // (4 m/s + 6 m/s² · 0.02 s) / 3 m/s².
        assert!((rows.stop_s - 4.12 / 3.0).abs() < 1e-12, "{}", rows.stop_s);
        let mut idle = agents;
        idle.iter_mut().for_each(|a| a.braking_mps2 = 0.0);
        assert!(StopRows::new(&idle, &[], (None, &[]), timing()).is_none());
    }

    #[test]
    fn the_row_holds_exactly_when_the_simulated_stop_ends_the_separation_away_along_n() {
        // Two vehicles closing head-on along east; the row is met with equality by the
        // commands whose stop ends exactly 3 m apart along east, found by flying the plan.
        let s = sep();
        let agents = [
            agent([0.0, 0.0], [2.0, 0.0]),
            agent([8.0, 0.0], [-1.0, 0.0]),
        ];
        let before = [Vector2::new(0.5, 0.0), Vector2::new(0.0, 0.0)];
        let rows =
            StopRows::new(&agents, &before.map(|b| [b; 2]), (None, &[]), timing()).expect("usable");
        let row = rows
            .row(
                &s,
                (&agents[1], [before[1]; 2]),
                (&agents[0], [before[0]; 2]),
                3.0,
            )
            .expect("apart");
        assert_eq!(row.a, Vector2::new(1.0, 0.0));
        // Fly: `before` for δ, `u` for h, then brake at v/T to rest after T.
        let fly = |a: &Agent, b: Vector2<f64>, u: Vector2<f64>| {
            let side = a.side.expect("known");
            let (mut p, mut v) = (side.pos_m.xy(), side.vel_mps.xy());
            let (d, h, t) = (rows.timing.delay_s, rows.timing.hold_s, rows.stop_s);
            p += v * d + b * (0.5 * d * d);
            v += b * d;
            p += v * h + u * (0.5 * h * h);
            v += u * h;
            p + v * (0.5 * t)
        };
        // Commands meeting the row with equality: u₁ − u₀ = b along east.
        let u0 = Vector2::new(-0.7, 0.2);
        let u1 = u0 + Vector2::new(row.b, 0.0);
        let gap = fly(&agents[1], before[1], u1) - fly(&agents[0], before[0], u0);
        assert!((gap.x - 3.0).abs() < 1e-9, "{}", gap.x);
        // The segment's far end without commands: 8 − 3·(δ + h + T/2) − 0.5·(δ²/2 + δ(h + T/2)).
        let (d, h, t) = (0.01, 0.01, rows.stop_s);
        let free = 8.0 - 3.0 * (d + h + 0.5 * t) - 0.5 * (0.5 * d * d + d * (h + 0.5 * t));
        assert!((row.b - (3.0 - free) / rows.gain_s2()).abs() < 1e-9);
    }

    #[test]
    fn no_pair_beyond_the_search_distance_has_a_row_that_can_bind() {
        let s = sep();
        let mut next = super::super::tests::uniform(11);
        let mut checked = 0;
        for _ in 0..20_000 {
            let mut v = || Vector2::new(12.0 * next() - 6.0, 12.0 * next() - 6.0);
            let (vi, vj) = (v(), v());
            let (bi, bj) = ([v() * 0.5, v() * 0.5], [v() * 0.5, v() * 0.5]);
            let mut agents = [
                agent([0.0, 0.0], [vi.x, vi.y]),
                agent([0.0, 0.0], [vj.x, vj.y]),
            ];
            agents[1].controlled = next() < 0.8;
            let t = Timing {
                delay_s: 0.05 * next(),
                hold_s: 0.001 + 0.05 * next(),
            };
            let rows = StopRows::new(&agents, &[bi, bj], (None, &[]), t).expect("usable");
            let reach = rows.distance_m(3.0, (vi - vj).norm());
            let dir = Vector2::new(next() - 0.5, next() - 0.5).normalize() * (reach * (1.0 + 1e-9));
            agents[0].side = agents[0].side.map(|side| Side {
                pos_m: Vector3::new(dir.x, dir.y, 10.0),
                ..side
            });
            let row = rows
                .row(&s, (&agents[0], bi), (&agents[1], bj), 3.0)
                .expect("apart");
            assert!(row.b <= -(12.0 + 1.0), "b {} at {} m", row.b, reach);
            checked += 1;
        }
        assert_eq!(checked, 20_000);
    }
}
