//! The flight kept in memory for the plots: every vehicle's state, attitude and command,
//! sampled at a fixed period (the coordinator's view: common frame, ENU, z up).
//!
//! Its memory is bounded: once it holds its budget of samples (vehicles × instants), every
//! other instant is dropped and the period doubles, so that a flight of any length keeps
//! between half and all of its budget, evenly spaced. The CSVs in the run directory keep
//! every tick; this is only what the figures draw.

use nalgebra::{Vector2, Vector3};
use ringswarm_wire::time::SimTime;

use crate::swarm::VehicleIndex;
use crate::swarm::{Swarm, SwarmPhase};

/// The fewest instants a trace keeps, however many vehicles share its budget.
pub const MIN_INSTANTS: usize = 64;

/// One vehicle at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// Position (m, ENU).
    pub pos_m: Vector3<f64>,
    /// Velocity (m/s, ENU).
    pub vel_mps: Vector3<f64>,
    /// Roll, pitch, yaw (rad, NED/FRD Euler), `NaN` before the first attitude.
    pub rpy_rad: Vector3<f64>,
    /// Commanded acceleration after saturation (m/s², ENU).
    pub cmd_mps2: Vector3<f64>,
    /// Commanded normalised thrust.
    pub thrust_norm: f64,
}

/// The flight, sampled.
#[derive(Debug, Clone)]
pub struct Trace {
    period: std::time::Duration,
    /// The most samples (vehicles × instants) kept.
    budget: usize,
    next: SimTime,
    /// Sample times (s).
    pub t_s: Vec<f64>,
    /// `samples[k][i]`: vehicle `i` at `t_s[k]`.
    pub samples: Vec<Vec<Sample>>,
    /// When consensus first started (s).
    pub consensus_start_s: Option<f64>,
    /// When the swarm started landing or ended (s).
    pub end_s: Option<f64>,
}

impl Trace {
    /// An empty trace sampled every `period` (at first), keeping at most `budget` samples
    /// (vehicles × instants; at least [`MIN_INSTANTS`] instants whatever the swarm).
    pub fn new(period: std::time::Duration, budget: usize) -> Self {
        Self {
            period,
            budget,
            next: SimTime::ZERO,
            t_s: Vec::new(),
            samples: Vec::new(),
            consensus_start_s: None,
            end_s: None,
        }
    }

    /// Samples the swarm if a period has passed and every vehicle is known.
    pub fn observe(&mut self, swarm: &Swarm, now: SimTime) {
        if !self.due(now) {
            return;
        }
        let states: Option<Vec<_>> = swarm.indices().map(|i| swarm.common_state(i)).collect();
        let Some(states) = states else {
            return;
        };
        self.consensus_start_s = swarm.consensus_started().map(SimTime::as_secs_f64);
        if self.end_s.is_none()
            && matches!(
                swarm.phase(),
                SwarmPhase::Landing(_) | SwarmPhase::Ended(_) | SwarmPhase::Stopped(_)
            )
        {
            self.end_s = Some(now.as_secs_f64());
        }
        let row = states
            .iter()
            .enumerate()
            .map(|(i, s)| {
                let rpy = swarm
                    .link(VehicleIndex(i))
                    .and_then(|l| l.state().attitude)
                    .map_or(Vector3::repeat(f64::NAN), |q| {
                        let (r, p, y) = q.euler_angles();
                        Vector3::new(r, p, y)
                    });
                Sample {
                    pos_m: s.pos_enu_m,
                    vel_mps: s.vel_enu_mps,
                    rpy_rad: rpy,
                    cmd_mps2: swarm.commands()[i],
                    thrust_norm: swarm.setpoints()[i].thrust_norm,
                }
            })
            .collect();
        self.push(now, row);
    }

    /// Whether an instant is to be sampled at `now`.
    fn due(&self, now: SimTime) -> bool {
        now >= self.next
    }

    /// Keeps `row` as the swarm at `now`, decimating when over budget.
    fn push(&mut self, now: SimTime, row: Vec<Sample>) {
        let instants = (self.budget / row.len().max(1)).max(MIN_INSTANTS);
        self.t_s.push(now.as_secs_f64());
        self.samples.push(row);
        self.next = now + self.period;
        if self.t_s.len() > instants {
            let mut k = 0;
            self.t_s.retain(|_| {
                k += 1;
                k % 2 == 1
            });
            let mut k = 0;
            self.samples.retain(|_| {
                k += 1;
                k % 2 == 1
            });
            self.period *= 2;
            let last = self.t_s.last().copied().unwrap_or(0.0);
            self.next = SimTime::from_secs_f64(last) + self.period;
        }
    }

    /// The period between the instants kept now.
    pub fn period(&self) -> std::time::Duration {
        self.period
    }

    /// Number of vehicles.
    pub fn vehicles(&self) -> usize {
        self.samples.first().map_or(0, Vec::len)
    }

    /// Vehicle `i`'s series of `f` over time.
    pub fn series(&self, i: usize, f: impl Fn(&Sample) -> f64) -> Vec<(f64, f64)> {
        self.t_s
            .iter()
            .zip(&self.samples)
            .map(|(t, row)| (*t, f(&row[i])))
            .collect()
    }

    /// The trace up to `t_s` (all of it for `None`).
    pub fn until(&self, t_s: Option<f64>) -> Self {
        let n = t_s.map_or(self.t_s.len(), |t| self.t_s.partition_point(|x| *x <= t));
        Self {
            period: self.period,
            budget: self.budget,
            next: self.next,
            t_s: self.t_s[..n].to_vec(),
            samples: self.samples[..n].to_vec(),
            consensus_start_s: self.consensus_start_s,
            end_s: self.end_s,
        }
    }

    /// The samples at the last time not after `t_s`.
    pub fn at(&self, t_s: Option<f64>) -> Option<&Vec<Sample>> {
        let t_s = t_s?;
        let n = self.t_s.partition_point(|x| *x <= t_s);
        self.samples.get(n.checked_sub(1)?)
    }

    /// Vehicle `i`'s horizontal path (m, ENU).
    pub fn path_xy(&self, i: usize) -> Vec<Vector2<f64>> {
        self.samples.iter().map(|row| row[i].pos_m.xy()).collect()
    }
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use super::*;

    fn row(vehicles: usize, t_s: f64) -> Vec<Sample> {
        vec![
            Sample {
                pos_m: Vector3::repeat(t_s),
                vel_mps: Vector3::zeros(),
                rpy_rad: Vector3::zeros(),
                cmd_mps2: Vector3::zeros(),
                thrust_norm: 0.5,
            };
            vehicles
        ]
    }

    #[test]
    fn a_long_flight_keeps_its_budget_evenly_spaced() {
        // 2 vehicles, 256 samples: 128 instants. 100 s every 50 ms would be 2001.
        let mut trace = Trace::new(Duration::from_millis(50), 2 * 128);
        let mut most = 0;
        for ms in (0..=100_000).step_by(10) {
            let now = SimTime::from_millis(ms);
            if trace.due(now) {
                trace.push(now, row(2, now.as_secs_f64()));
                most = most.max(trace.t_s.len());
            }
        }
        // 2001 instants halve four times (50 → 800 ms) to fit 128: 0, 0.8, … 100.0 s.
        assert_eq!(trace.period(), Duration::from_millis(800));
        assert!(most <= 128, "{most} instants kept");
        assert_eq!(trace.t_s.len(), 126);
        for (k, t) in trace.t_s.iter().enumerate() {
            assert!((t - 0.8 * k as f64).abs() < 1e-9, "instant {k} at {t} s");
            assert_eq!(trace.samples[k][1].pos_m.x, *t);
        }
    }

    #[test]
    fn a_thousand_vehicles_still_keep_the_fewest_instants() {
        let mut trace = Trace::new(Duration::from_millis(50), 1000);
        for k in 0..(MIN_INSTANTS as u64) {
            trace.push(SimTime::from_millis(50 * k), row(1000, 0.0));
        }
        assert_eq!(
            (trace.t_s.len(), trace.period()),
            (MIN_INSTANTS, Duration::from_millis(50))
        );
    }
}
