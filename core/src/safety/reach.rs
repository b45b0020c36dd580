//! How far each vehicle looks for pairs: the distance beyond which no pair's barrier row
//! can bind, whatever the commands inside the envelopes.
//!
//! A row `aᵀ(uᵢ − uⱼ) ≥ b` is dropped when `b ≤ −(Lᵢ + Lⱼ) − 1` (no command inside the
//! two discs can break it). From [`super::barrier`], with the closing rate `s ≥ −V`
//! (`V` a bound on the pair's scaled relative speed), the curvature term `≥ 0` and the
//! vertical term at most `Z`:
//!
//! ```text
//! b = −γh³ − known − A·s/√(2A·room) ≤ −γ(r − V)³ + A·V/r + Z,   r = √(2A·room) > V,
//! ```
//!
//! decreasing in `r` (and so in the distance). It is at most `−(2L + 1)` once
//! `r ≥ V + x`, `γx³ = 2L + 1 + Z + A` (as `A·V/r ≤ A`), which holds once
//!
//! ```text
//! D ≥ r_h + V·τ + A_hi·τ²/2 + (V + x)²/(2·A_lo) + margin,
//! ```
//!
//! `A_lo`, `A_hi` the least and greatest braking authority a pair can have, `L` the
//! widest disc, `τ` the state age. A pair's unseen speed `δ` enters its row as `V` does
//! (`s − δ ≥ −(V + δ)`, the age's growth `(|Δv| + δ)τ`), so `V + δ` stands for `V`, `δ`
//! twice the largest agent's. The pair search ([`super::flow`]) keeps a pair within
//! the bound at its own relative speed, and looks into a cell of vehicles only when the
//! bound at the fastest relative speed their velocities allow reaches it.
//!
//! Pure: no allocation, no clock.

use super::{Agent, Separation, braking, limit};

/// Added to every bound (m), for rounding.
const MARGIN_M: f64 = 0.01;

/// The bound for one tick's agents.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReachBound {
    /// `r_h + 2·spread + A_hi·τ²/2 + margin` (m): the widest spread of an agent counted
    /// on both sides.
    base_m: f64,
    /// The state age `τ` (s).
    age_s: f64,
    /// `x` (m/s).
    x_mps: f64,
    /// `2·A_lo` (m/s²).
    two_a_lo: f64,
    /// The largest unseen closing speed of a pair (m/s): twice the largest agent's.
    unseen_mps: f64,
}

impl ReachBound {
    /// The bound for these agents; `None` when no pair can be bounded (no commanded
    /// vehicle with braking authority, or a gain or age that is not a positive number):
    /// then only the cap limits the search.
    pub fn new(sep: &Separation, age_s: f64, agents: &[Agent]) -> Option<Self> {
        let commanded = agents.iter().filter(|a| a.controlled && a.side.is_some());
        let (mut a_lo, mut a_hi, mut widest) = (f64::INFINITY, 0.0f64, 0.0f64);
        for a in commanded {
            let b = braking(a);
            if b > 0.0 {
                a_lo = a_lo.min(b);
            }
            a_hi = a_hi.max(b);
            widest = widest.max(limit(a));
        }
        let vertical = agents
            .iter()
            .filter_map(|a| a.side.map(|s| s.accel_z_mps2.abs()))
            .filter(|z| z.is_finite())
            .fold(0.0f64, f64::max);
        let known = agents
            .iter()
            .filter_map(|a| a.side)
            .any(|s| sep.scaled(s.vel_mps).iter().all(|c| c.is_finite()));
        let (a_hi, z) = (2.0 * a_hi, 2.0 * sep.vertical_scale() * vertical);
        let usable = a_lo.is_finite()
            && a_lo > 0.0
            && sep.gamma > 0.0
            && sep.gamma.is_finite()
            && age_s.is_finite()
            && age_s >= 0.0
            && known;
        if !usable {
            return None;
        }
        let x = ((2.0 * widest + 1.0 + z + a_hi) / sep.gamma).cbrt();
        // A pair keeps its two spreads more than the separation, and may close at its two
        // unseen speeds more than its velocities say: the largest of each, counted twice.
        let (spread, unseen) = agents
            .iter()
            .filter(|a| a.side.is_some())
            .fold((0.0f64, 0.0f64), |(s, u), a| {
                (s.max(a.spread()), u.max(a.unseen()))
            });
        Some(Self {
            base_m: sep.horizontal_m + 2.0 * spread + 0.5 * a_hi * age_s * age_s + MARGIN_M,
            unseen_mps: 2.0 * unseen,
            age_s,
            x_mps: x,
            two_a_lo: 2.0 * a_lo,
        })
    }

    /// The distance (m, scaled) beyond which a pair whose relative scaled speed is at
    /// most `v_mps` has no row that can bind.
    pub fn distance_m(&self, v_mps: f64) -> f64 {
        let v = v_mps.max(0.0) + self.unseen_mps;
        self.base_m + v * self.age_s + (v + self.x_mps).powi(2) / self.two_a_lo
    }
}

#[cfg(test)]
mod tests {
    use super::super::tests::sep;
    use nalgebra::{Vector2, Vector3};

    use super::super::{Side, pair_row_spread};
    use super::*;

    fn agent(p: Vector3<f64>, v: Vector3<f64>, az: f64, limit: f64, braking: f64) -> Agent {
        Agent {
            side: Some(Side {
                pos_m: p,
                vel_mps: v,
                accel_z_mps2: az,
            }),
            controlled: true,
            weight: 1.0,
            drift_mps2: Vector2::zeros(),
            limit_mps2: limit,
            braking_mps2: braking,
            lag_s: 0.0,
            spread_m: 0.0,
            unseen_mps: 0.0,
        }
    }

    #[test]
    fn no_pair_beyond_the_bound_at_its_relative_speed_has_a_row_that_can_bind() {
        // Random pairs with random speeds, vertical accelerations, envelopes and ages:
        // every pair at least the bound at its own relative speed apart has
        // b ≤ −(Lᵢ + Lⱼ) − 1.
        let s = sep();
        let mut next = super::super::tests::uniform(3);
        let mut checked = 0;
        for _ in 0..20_000 {
            let mut v = || Vector3::new(8.0 * next() - 4.0, 8.0 * next() - 4.0, 2.0 * next() - 1.0);
            let (vi, vj, vk) = (v(), v(), v());
            let (li, lj) = (2.0 + 6.0 * next(), 2.0 + 6.0 * next());
            let (azi, azj) = (2.0 * next() - 1.0, 2.0 * next() - 1.0);
            let age = 0.3 * next();
            // Unseen speeds for half of the pairs (positions moving beyond velocities).
            let unseen = if next() < 0.5 { 1.5 } else { 0.0 };
            let (ui, uj) = (unseen * next(), unseen * next());
            let third = agent(Vector3::new(500.0, 0.0, 0.0), vk, 0.0, 4.0, 2.0);
            let mut pair = [
                Agent {
                    unseen_mps: ui,
                    ..agent(Vector3::zeros(), vi, azi, li, 0.5 * li)
                },
                Agent {
                    unseen_mps: uj,
                    ..agent(Vector3::zeros(), vj, azj, lj, 0.5 * lj)
                },
                third,
            ];
            let bound = ReachBound::new(&s, age, &pair).expect("usable");
            let reach = bound.distance_m(s.scaled(vi - vj).norm());
            // A direction with a vertical part, the pair just beyond the bound.
            let dir = Vector3::new(next() - 0.5, next() - 0.5, 0.3 * (next() - 0.5)).normalize();
            let scaled_dir = s.scaled(dir).norm();
            let distance = reach * (1.0 + 1e-9) / scaled_dir;
            pair[0].side = Some(Side {
                pos_m: dir * distance,
                ..pair[0].side.expect("known")
            });
            let (si, sj) = (pair[0].side.expect("known"), pair[1].side.expect("known"));
            let row = pair_row_spread(&s, &si, &sj, 0.5 * li + 0.5 * lj, age, 0.0, ui + uj)
                .expect("apart");
            assert!(row.b <= -(li + lj) - 1.0, "b {} at {} m", row.b, reach);
            checked += 1;
        }
        assert_eq!(checked, 20_000);
    }

    #[test]
    fn the_bound_is_the_separation_the_age_s_growth_and_the_braking_room() {
        let s = sep();
        let at_rest = [
            agent(Vector3::zeros(), Vector3::zeros(), 0.0, 6.0, 3.0),
            agent(Vector3::new(4.0, 0.0, 0.0), Vector3::zeros(), 0.0, 6.0, 3.0),
        ];
        let bound = ReachBound::new(&s, 0.1, &at_rest).expect("usable");
        // 3 m + A_hi·τ²/2 (A_hi = 6, τ = 0.1 s) + 0.01 + (V·τ) + (V + x)²/(2·3), with
        // γx³ = 2·6 + 1 + 0 + 6 = 19.
        let x = 19f64.cbrt();
        for v in [0.0, 2.5] {
            let expected = 3.0 + 0.5 * 6.0 * 0.01 + 0.01 + v * 0.1 + (v + x) * (v + x) / 6.0;
            let got = bound.distance_m(v);
            assert!((got - expected).abs() < 1e-12, "{v}: {got} vs {expected}");
        }
        // An agent's unseen speed counts twice (the pair may have two such), as speed.
        let mut unseen = at_rest;
        unseen[1].unseen_mps = 0.4;
        let with = ReachBound::new(&s, 0.1, &unseen).expect("usable");
        assert!((with.distance_m(2.5) - bound.distance_m(3.3)).abs() < 1e-12);
        // Nobody commanded: no bound.
        let mut idle = at_rest;
        idle.iter_mut().for_each(|a| a.controlled = false);
        assert!(ReachBound::new(&s, 0.1, &idle).is_none());
    }
}
