//! Breaking jams: pairwise barrier filters deadlock in symmetric conflicts (two vehicles
//! head-on, a block whose every path crosses its centre): each pair holds the other
//! still, and the law's pull towards the places never wins.
//!
//! [`JamWatch`] finds them: a vehicle is *held* on a tick when one of its pair rows is
//! active (the filter's answer meets it with nothing to spare) and the filter took at
//! least [`JamSettings::restrained_share`] of its command away (`|uᵢ − ūᵢ| ≥ s·|uᵢ|`, the
//! law's command `uᵢ` against the filter's `ūᵢ`): a filter that only trims the command
//! of a ring converging slowly does not hold it. It is *jammed* once it
//! has been held for [`JamSettings::hold_s`] while still more than
//! [`JamSettings::min_error_m`] from its place and no closer to it by
//! [`JamSettings::progress_m`] than when the hold began. A hold goes on through breaks
//! shorter than [`JamSettings::gap_s`] (a filter that binds every other tick holds all
//! the same). It stays jammed until it has not been held for [`JamSettings::release_s`].
//!
//! [`crate::safety::layers`] breaks them by sending one side of each jam over the other
//! on another layer (the default). [`rotation_bias`] breaks them in the plane instead,
//! with a consistent rotational preference: every active pair with a jammed vehicle
//! turns about its midpoint counter-clockwise (seen from above), each vehicle
//! accelerated along the pair's normal turned by +90°, the two in opposite directions
//! and in inverse proportion to their weights. Like a barrier row,
//! the bias is `+a` on one vehicle and `−a` on the other in weighted terms, so it keeps
//! `Σ wᵢuᵢ` (and with it the consensus value); the filter after it still keeps every
//! pair apart.
//!
//! Pure and synchronous.

use std::time::Duration;

use nalgebra::Vector2;
use ringswarm_wire::time::SimTime;

/// When a held vehicle counts as jammed, and how hard a jam is turned.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JamSettings {
    /// How long a vehicle is held without progress before it is jammed.
    pub hold_s: f64,
    /// How much closer to its place it must have come meanwhile to count as progressing (m).
    pub progress_m: f64,
    /// A vehicle closer than this to its place is never jammed (m).
    pub min_error_m: f64,
    /// The longest break in a hold (s).
    pub gap_s: f64,
    /// The least share of a vehicle's command the filter must take away for an active row
    /// to hold it.
    pub restrained_share: f64,
    /// How long it must go unheld to be released.
    pub release_s: f64,
    /// The turning acceleration of an equal-weight pair, each vehicle (m/s²).
    pub bias_mps2: f64,
    /// Jams passed on another layer (`crate::safety::layers`); `None`: turned.
    pub layer: Option<crate::safety::layers::LayerRule>,
}

impl Default for JamSettings {
    fn default() -> Self {
        Self {
            hold_s: 5.0,
            progress_m: 0.5,
            min_error_m: 1.0,
            gap_s: 1.0,
            restrained_share: 0.5,
            release_s: 2.0,
            bias_mps2: 1.0,
            layer: None,
        }
    }
}

/// One vehicle's watch.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
struct Held {
    /// Since when it has been held without a break, and its distance to its place then.
    since: Option<(SimTime, f64)>,
    /// When it was last held.
    last: Option<SimTime>,
    jammed: bool,
}

/// What changed on a tick.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct JamChange {
    /// Vehicles jammed on this tick.
    pub jammed: Vec<usize>,
    /// Vehicles released on this tick.
    pub released: Vec<usize>,
}

/// Which vehicles are jammed.
#[derive(Debug, Clone, Default)]
pub struct JamWatch {
    held: Vec<Held>,
    marks: Vec<bool>,
}

impl JamWatch {
    /// Takes a tick at `now`: the active pair rows `(i, j)` (`i == j`: a one-vehicle row,
    /// which holds nobody against anybody and is ignored), whether the filter took at
    /// least [`JamSettings::restrained_share`] of each vehicle's command away (missing:
    /// no), and each vehicle's distance to its place (m; `None`: unknown, which ends its
    /// watch).
    pub fn update(
        &mut self,
        settings: &JamSettings,
        now: SimTime,
        active: &[(usize, usize)],
        restrained: &[bool],
        error_m: &[Option<f64>],
    ) -> JamChange {
        let n = error_m.len();
        self.held.resize(n, Held::default());
        self.marks.clear();
        self.marks.resize(n, false);
        let restrained = |k: usize| restrained.get(k).copied().unwrap_or(false);
        for &(i, j) in active {
            if i != j && i < n && j < n {
                self.marks[i] |= restrained(i);
                self.marks[j] |= restrained(j);
            }
        }
        let mut change = JamChange::default();
        let secs = |s: f64| Duration::from_secs_f64(s.max(0.0));
        for (k, (held, error)) in self.held.iter_mut().zip(error_m).enumerate() {
            let Some(error) = *error else {
                if std::mem::take(held).jammed {
                    change.released.push(k);
                }
                continue;
            };
            if self.marks[k] {
                held.last = Some(now);
                let (since, at_start) = *held.since.get_or_insert((now, error));
                let stuck = now.saturating_since(since) >= secs(settings.hold_s)
                    && error > settings.min_error_m
                    && error > at_start - settings.progress_m;
                if stuck && !held.jammed {
                    held.jammed = true;
                    change.jammed.push(k);
                }
                if !stuck && error <= at_start - settings.progress_m {
                    // Progress: the watch starts again from here.
                    held.since = Some((now, error));
                }
            } else {
                let free_for = held.last.map_or(Duration::MAX, |t| now.saturating_since(t));
                if free_for >= secs(settings.gap_s) {
                    held.since = None;
                }
                if held.jammed && free_for >= secs(settings.release_s) {
                    held.jammed = false;
                    change.released.push(k);
                }
            }
            if held.jammed && error <= settings.min_error_m {
                held.jammed = false;
                held.since = None;
                change.released.push(k);
            }
        }
        change
    }

    /// Whether vehicle `k` is jammed.
    pub fn is_jammed(&self, k: usize) -> bool {
        self.held.get(k).is_some_and(|h| h.jammed)
    }

    /// Whether any vehicle is jammed.
    pub fn any(&self) -> bool {
        self.held.iter().any(|h| h.jammed)
    }

    /// Whether no vehicle is held or jammed: a tick with no active pair row then changes
    /// nothing, and need not be taken.
    pub fn idle(&self) -> bool {
        self.held.iter().all(|h| h.since.is_none() && !h.jammed)
    }
}

/// Adds the turning bias of every active pair `(i, j)` with a jammed vehicle to the
/// horizontal commands (m/s², ENU): `+b·(2wⱼ/(wᵢ+wⱼ))·t` on `i` and `−b·(2wᵢ/(wᵢ+wⱼ))·t`
/// on `j`, `t` the unit vector from `j` to `i` turned by +90°, `b` the settings' bias.
/// `Σ wᵢΔuᵢ = 0` for every pair. Pairs at the same place, or with a weight that is not
/// positive, are left alone.
pub fn rotation_bias(
    settings: &JamSettings,
    watch: &JamWatch,
    active: &[(usize, usize)],
    positions_m: &[Option<Vector2<f64>>],
    weights: &[f64],
    commands: &mut [Vector2<f64>],
) {
    let n = commands.len().min(positions_m.len()).min(weights.len());
    for &(i, j) in active {
        if i == j || i >= n || j >= n || !(watch.is_jammed(i) || watch.is_jammed(j)) {
            continue;
        }
        let (Some(pi), Some(pj)) = (positions_m[i], positions_m[j]) else {
            continue;
        };
        let (wi, wj) = (weights[i], weights[j]);
        let Some(normal) = (pi - pj).try_normalize(1e-6) else {
            continue;
        };
        if !(wi > 0.0 && wj > 0.0) {
            continue;
        }
        let turn = Vector2::new(-normal.y, normal.x) * settings.bias_mps2;
        commands[i] += turn * (2.0 * wj / (wi + wj));
        commands[j] -= turn * (2.0 * wi / (wi + wj));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn s(v: f64) -> SimTime {
        SimTime::from_secs_f64(v)
    }

    /// Vehicles 0 and 1, 8 m from their places, in an active row every 20 ms tick from 0
    /// to `ticks`, restrained as `restrained` says.
    fn hold_pair(watch: &mut JamWatch, ticks: u32, restrained: &[bool]) {
        let errors = [Some(8.0), Some(8.0)];
        for k in 0..=ticks {
            let t = s(f64::from(k) * 0.02);
            watch.update(&JamSettings::default(), t, &[(0, 1)], restrained, &errors);
        }
    }

    #[test]
    fn a_vehicle_held_without_progress_is_jammed_after_the_hold_and_released_later() {
        let settings = JamSettings::default();
        let mut watch = JamWatch::default();
        let active = [(0, 1)];
        let errors = [Some(8.0), Some(8.0), Some(8.0)];
        for k in 0..250 {
            let t = s(f64::from(k) * 0.02);
            let change = watch.update(&settings, t, &active, &[true; 3], &errors);
            assert!(change.jammed.is_empty(), "jammed at {t:?}");
        }
        // 5 s held (0 → 5.0 s), 8 m from its place, no closer: jammed, not vehicle 2.
        let change = watch.update(&settings, s(5.0), &active, &[true; 3], &errors);
        assert_eq!(change.jammed, vec![0, 1]);
        assert!(watch.is_jammed(0) && !watch.is_jammed(2));
        // Unheld for less than 2 s: still jammed; then released.
        assert!(
            watch
                .update(&settings, s(6.9), &[], &[true; 3], &errors)
                .released
                .is_empty()
        );
        assert_eq!(
            watch
                .update(&settings, s(7.0), &[], &[true; 3], &errors)
                .released,
            vec![0, 1]
        );
        // Released and unheld past the gap: nothing left for a quiet tick to change.
        assert!(watch.idle());
        assert!(!watch.any());
    }

    #[test]
    fn a_row_that_only_trims_a_command_holds_nobody() {
        // 10 s in an active row: the filter took half or more of 1's command away, not of
        // 0's: only 1 is jammed.
        let mut watch = JamWatch::default();
        assert!(watch.idle());
        hold_pair(&mut watch, 500, &[false, true]);
        assert!(!watch.is_jammed(0) && watch.is_jammed(1));
        assert!(!watch.idle());
        // Nothing said of a vehicle: not restrained.
        let mut watch = JamWatch::default();
        hold_pair(&mut watch, 500, &[]);
        assert!(!watch.any());
    }

    #[test]
    fn a_hold_goes_on_through_short_breaks_and_ends_at_a_long_one() {
        let settings = JamSettings::default();
        let errors = [Some(8.0), Some(8.0)];
        // Held every other tick for 5 s: jammed.
        let mut watch = JamWatch::default();
        for k in 0..=250 {
            let active: &[(usize, usize)] = if k % 2 == 0 { &[(0, 1)] } else { &[] };
            watch.update(
                &settings,
                s(f64::from(k) * 0.02),
                active,
                &[true; 3],
                &errors,
            );
        }
        assert!(watch.is_jammed(0));
        // Held 3 s, free 1 s, held 3 s: the break ends the hold, no jam.
        let mut watch = JamWatch::default();
        for k in 0..=350 {
            let t = f64::from(k) * 0.02;
            let active: &[(usize, usize)] = if (3.0..4.0).contains(&t) {
                &[]
            } else {
                &[(0, 1)]
            };
            watch.update(&settings, s(t), active, &[true; 3], &errors);
        }
        assert!(!watch.any());
    }

    #[test]
    fn progress_or_a_place_reached_is_no_jam() {
        let settings = JamSettings::default();
        let mut watch = JamWatch::default();
        // Closing 0.2 m/s: 0.5 m every 2.5 s restarts the watch: never 5 s without it.
        for k in 0..1000 {
            let t = f64::from(k) * 0.02;
            let error = 20.0 - 0.2 * t;
            let change = watch.update(
                &settings,
                s(t),
                &[(0, 1)],
                &[true; 2],
                &[Some(error), Some(error)],
            );
            assert!(change.jammed.is_empty(), "jammed at {t} s");
        }
        // At its place (0.5 m off) it is never jammed however long it is held.
        let mut watch = JamWatch::default();
        for k in 0..1000 {
            let t = s(f64::from(k) * 0.02);
            let change = watch.update(&settings, t, &[(0, 1)], &[true; 2], &[Some(0.5), Some(0.5)]);
            assert!(change.jammed.is_empty());
        }
        // A one-vehicle row (the fence) holds nobody.
        let mut watch = JamWatch::default();
        for k in 0..1000 {
            let t = s(f64::from(k) * 0.02);
            watch.update(&settings, t, &[(0, 0)], &[true], &[Some(9.0)]);
        }
        assert!(!watch.any());
    }

    #[test]
    fn the_bias_turns_a_pair_and_keeps_the_weighted_sum() {
        let settings = JamSettings::default();
        let mut watch = JamWatch::default();
        hold_pair(&mut watch, 250, &[true; 2]);
        assert!(watch.is_jammed(0));
        // Vehicle 0 east of vehicle 1: normal east, turned +90°: north for 0, south for 1.
        let positions = [Some(Vector2::new(2.0, 0.0)), Some(Vector2::new(-2.0, 0.0))];
        let weights = [1.0, 6.0];
        let mut commands = [Vector2::new(-1.0, 0.0), Vector2::new(1.0, 0.0)];
        let before: Vector2<f64> = commands.iter().zip(&weights).map(|(u, w)| u * *w).sum();
        rotation_bias(
            &settings,
            &watch,
            &[(0, 1)],
            &positions,
            &weights,
            &mut commands,
        );
        let after: Vector2<f64> = commands.iter().zip(&weights).map(|(u, w)| u * *w).sum();
        assert!((after - before).norm() < 1e-12);
        // 2·6/7 north on the light vehicle, 2·1/7 south on the heavy one.
        assert!((commands[0] - Vector2::new(-1.0, 12.0 / 7.0)).norm() < 1e-12);
        assert!((commands[1] - Vector2::new(1.0, -2.0 / 7.0)).norm() < 1e-12);
        // Nothing for a pair with no jammed vehicle.
        let mut untouched = [Vector2::zeros(); 3];
        let three = [positions[0], positions[1], Some(Vector2::new(0.0, 5.0))];
        rotation_bias(
            &settings,
            &JamWatch::default(),
            &[(0, 2)],
            &three,
            &[1.0; 3],
            &mut untouched,
        );
        assert_eq!(untouched, [Vector2::zeros(); 3]);
    }
}
