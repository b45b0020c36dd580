//! The flight kept in memory for the plots: every vehicle's state, attitude and command,
//! sampled at a fixed period (the coordinator's view: common frame, ENU, z up).

use nalgebra::{Vector2, Vector3};
use ringswarm_wire::time::SimTime;

use crate::swarm::{Swarm, SwarmPhase};

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
    /// An empty trace sampled every `period`.
    pub fn new(period: std::time::Duration) -> Self {
        Self {
            period,
            next: SimTime::ZERO,
            t_s: Vec::new(),
            samples: Vec::new(),
            consensus_start_s: None,
            end_s: None,
        }
    }

    /// Samples the swarm if a period has passed and every vehicle is known.
    pub fn observe(&mut self, swarm: &Swarm, now: SimTime) {
        if now < self.next {
            return;
        }
        let states: Option<Vec<_>> = (0..swarm.links().len())
            .map(|i| swarm.common_state(i))
            .collect();
        let Some(states) = states else {
            return;
        };
        self.next = now + self.period;
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
                let rpy =
                    swarm.links()[i]
                        .state()
                        .attitude
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
        self.t_s.push(now.as_secs_f64());
        self.samples.push(row);
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
