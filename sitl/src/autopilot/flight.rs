//! The navigator: what every mode but raw offboard attitude flies, as one trajectory
//! setpoint for the one position controller (PX4's flight tasks and navigator, reduced).
//!
//! ```text
//!  Position  ── on the ground: idle; in the air: brake and hold (a vehicle started in the
//!               air holds its start velocity instead, the pilot's job)
//!  Hold      ── brake to a stop point and hold it; goto (DO_REPOSITION) moves the point
//!               at its speed (MPC_XY_CRUISE by default)
//!  Takeoff   ── climb in place at MPC_TKO_SPEED (MPC_Z_V_AUTO_UP above MPC_LAND_ALT1) to
//!               the target; within NAV_MC_ALT_RAD of it ──► Hold at exactly the target
//!  Land      ── hold x/y, descend at the landing speed (MPC_Z_V_AUTO_DN ➝ MPC_LAND_SPEED)
//!  Return    ── Climb (in place, to the return altitude) ──► Cruise (home at cruise speed)
//!               ──► [RTL_LAND_DELAY ≠ 0: Descend to RTL_DESCEND_ALT ──► Loiter delay]
//!               ──► Land
//!  Mission   ── see `mission_run`
//!  Orbit     ── to the nearest point of the circle, then around it at the asked speed
//!               (DO_ORBIT), nose to the centre, fixed, free or along the circle
//! ```
//!
//! Auto targets travel through [`Approach`] (limited speed and acceleration), yaw slews
//! toward its target at MPC_YAWRAUTO_MAX. Frames: the vehicle's local NED.

use nalgebra::{Vector2, Vector3};

use super::Vehicle;
use super::mission_run::{MissionRun, bearing};
use super::mode::FlightMode;
use crate::position_control::{TrajectorySetpoint, wrap_pi};
use crate::time::SimTime;
use crate::trajectory::{Approach, Limits};

/// Where a Return is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum ReturnStage {
    /// Climbing in place to the return altitude.
    Climb,
    /// Flying home at the return altitude.
    Cruise,
    /// Descending above home to RTL_DESCEND_ALT.
    Descend,
    /// Waiting above home until the time (forever with `None`).
    Loiter(Option<SimTime>),
    /// Landing at home.
    Land,
}

/// What the navigator is doing.
#[derive(Debug, Clone, PartialEq)]
pub(super) enum Nav {
    /// Nothing to fly (disarmed, on the ground in a mode that does not take off, or
    /// OFFBOARD).
    Idle,
    /// Hold a point reached through `approach` within `limits`.
    Hold {
        approach: Approach,
        limits: Limits,
        yaw_rad: f64,
    },
    /// Hold a velocity (NED, m/s).
    Velocity { vel_ned_mps: Vector3<f64> },
    /// Position mode with centred sticks (PX4's simple position mode): brake with the
    /// velocity controller at zero horizontal velocity, holding the altitude, then lock
    /// the position once slower than [`BRAKE_LOCK_MPS`].
    Brake {
        z_m: f64,
        lock: Option<Vector3<f64>>,
    },
    /// Climb to `approach`'s target.
    Takeoff { approach: Approach, yaw_rad: f64 },
    /// Descend over `xy_m`.
    Land { xy_m: Vector2<f64> },
    /// Return to launch.
    Return {
        stage: ReturnStage,
        approach: Approach,
        yaw_rad: f64,
    },
    /// Fly the stored mission.
    Mission(MissionRun),
    /// Circle a point (DO_ORBIT).
    Orbit(Orbit),
}

/// What an orbit keeps its nose on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum OrbitYaw {
    /// The centre (ORBIT_YAW_BEHAVIOUR_HOLD_FRONT_TO_CIRCLE_CENTER, 0, the default).
    Centre,
    /// The heading when the orbit started (1).
    Initial(f64),
    /// Whatever it is (2).
    Free,
    /// Along the circle (3).
    Tangent,
}

/// An orbit: first to the nearest point of the circle, then around it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Orbit {
    /// Centre (local NED x, y) and altitude (local NED z).
    pub centre_m: Vector2<f64>,
    pub z_m: f64,
    /// Radius (m), positive clockwise seen from above.
    pub radius_m: f64,
    /// Speed along the circle (m/s).
    pub speed_mps: f64,
    pub yaw: OrbitYaw,
    /// Angle on the circle from north toward east (rad); `None` while still approaching.
    pub angle_rad: Option<f64>,
    pub approach: Approach,
}

/// Below this horizontal speed Position mode locks its position (m/s).
pub(super) const BRAKE_LOCK_MPS: f64 = 0.5;

/// Where a vehicle at `pos` moving at `vel` stops with the limits' deceleration
/// (`v²/(2a)` along the velocity, per plane).
pub(super) fn stop_point(pos: Vector3<f64>, vel: Vector3<f64>, limits: &Limits) -> Vector3<f64> {
    let brake = |v: f64, a: f64| {
        if a > 0.0 {
            v * v.abs() / (2.0 * a)
        } else {
            0.0
        }
    };
    let xy = vel.xy();
    let speed = xy.norm();
    let xy_stop = if speed > 1e-9 {
        xy / speed * brake(speed, limits.acc_xy_mps2)
    } else {
        Vector2::zeros()
    };
    pos + Vector3::new(xy_stop.x, xy_stop.y, brake(vel.z, limits.acc_z_mps2))
}

impl Vehicle {
    /// The height above the ground (m).
    pub(super) fn height_m(&self) -> f64 {
        self.plant.env.ground_z_ned_m - self.plant.state.pos_ned_m.z
    }

    /// The navigator state a mode starts with, from where the vehicle is now.
    pub(super) fn nav_for(&self, mode: FlightMode) -> Nav {
        let here = self.plant.state.pos_ned_m;
        let vel = self.plant.state.vel_ned_mps;
        let yaw = self.yaw_rad();
        let t = &self.tuning;
        match mode {
            FlightMode::Offboard => Nav::Idle,
            FlightMode::Hold => {
                let stop = stop_point(here, vel, &t.auto);
                Nav::Hold {
                    approach: Approach::new(here, vel, stop),
                    limits: t.auto,
                    yaw_rad: yaw,
                }
            }
            FlightMode::Position => Nav::Brake {
                z_m: here.z,
                lock: None,
            },
            FlightMode::Takeoff => {
                // MIS_TAKEOFF_ALT above the ground, never below where it is ("already
                // higher than takeoff altitude").
                let target_z = (self.plant.env.ground_z_ned_m - t.takeoff_alt_m).min(here.z);
                Nav::Takeoff {
                    approach: Approach::new(here, vel, Vector3::new(here.x, here.y, target_z)),
                    yaw_rad: yaw,
                }
            }
            FlightMode::Land => Nav::Land { xy_m: here.xy() },
            FlightMode::Return => Nav::Return {
                stage: ReturnStage::Climb,
                approach: Approach::new(here, vel, Vector3::new(here.x, here.y, self.return_z())),
                yaw_rad: yaw,
            },
            FlightMode::Mission => {
                Nav::Mission(MissionRun::start(self.navigator.mission.current_seq()))
            }
            // Set up by DO_ORBIT; entered otherwise, it holds.
            FlightMode::Orbit => Nav::Hold {
                approach: Approach::new(here, vel, stop_point(here, vel, &t.auto)),
                limits: t.auto,
                yaw_rad: yaw,
            },
        }
    }

    /// PX4's return altitude (multicopter, RTL_CONE_ANG > 0) as a local NED z: home +
    /// RTL_RETURN_ALT, or lower near home (home + 2·d within NAV_ACC_RAD), never below
    /// the current altitude.
    fn return_z(&self) -> f64 {
        let t = &self.tuning;
        let home_z = self.plant.env.ground_z_ned_m;
        let d = self.plant.state.pos_ned_m.xy().norm();
        let height = if d <= t.acceptance_radius_m {
            2.0 * d
        } else {
            t.rtl_return_alt_m.max(2.0 * t.acceptance_radius_m)
        };
        let height = height.min(t.rtl_return_alt_m);
        (home_z - height).min(self.plant.state.pos_ned_m.z)
    }

    /// Whether the current mode wants to leave the ground.
    pub(super) fn nav_wants_climb(&self) -> bool {
        match &self.navigator.nav {
            Nav::Takeoff { .. } => true,
            Nav::Mission(run) => run.wants_climb(),
            _ => false,
        }
    }

    /// One navigator step ending at `t`: advances the mode's reference and returns the
    /// trajectory setpoint, or `None` when the mode flies nothing.
    pub(super) fn nav_setpoint(&mut self, t: SimTime, dt_s: f64) -> Option<TrajectorySetpoint> {
        let tuning = self.tuning;
        let height = self.height_m();
        let mut nav = std::mem::replace(&mut self.navigator.nav, Nav::Idle);
        let (sp, yaw_target, next_mode) = match &mut nav {
            Nav::Idle => (None, self.yaw_rad(), None),
            Nav::Hold {
                approach,
                limits,
                yaw_rad,
            } => {
                let sp = approach.step(limits, dt_s);
                (Some(sp), *yaw_rad, None)
            }
            Nav::Brake { z_m, lock } => {
                let here = self.plant.state.pos_ned_m;
                if lock.is_none() && self.plant.state.vel_ned_mps.xy().norm() < BRAKE_LOCK_MPS {
                    *lock = Some(here);
                }
                let sp = match lock {
                    Some(p) => TrajectorySetpoint::hold(*p, f64::NAN),
                    None => TrajectorySetpoint {
                        pos_ned_m: Vector3::new(f64::NAN, f64::NAN, *z_m),
                        vel_ned_mps: Vector3::new(0.0, 0.0, f64::NAN),
                        ..TrajectorySetpoint::UNSET
                    },
                };
                (Some(sp), self.navigator.yaw_rad, None)
            }
            Nav::Velocity { vel_ned_mps } => {
                let sp = TrajectorySetpoint {
                    vel_ned_mps: *vel_ned_mps,
                    ..TrajectorySetpoint::UNSET
                };
                (Some(sp), self.navigator.yaw_rad, None)
            }
            Nav::Takeoff { approach, yaw_rad } => {
                let limits = Limits {
                    speed_up_mps: if height < tuning.land_alt1_m {
                        tuning.takeoff_speed_mps
                    } else {
                        tuning.auto.speed_up_mps
                    },
                    acc_z_mps2: tuning.takeoff_acc_mps2,
                    ..tuning.auto
                };
                let sp = approach.step(&limits, dt_s);
                let target_z = approach.target().z;
                let done = self.plant.state.pos_ned_m.z - target_z < tuning.altitude_radius_m;
                (Some(sp), *yaw_rad, done.then_some(FlightMode::Hold))
            }
            Nav::Land { xy_m } => (
                Some(self.land_setpoint(*xy_m)),
                self.navigator.yaw_rad,
                None,
            ),
            Nav::Return {
                stage,
                approach,
                yaw_rad,
            } => {
                let sp = self.return_step(t, stage, approach, yaw_rad, dt_s);
                (Some(sp), *yaw_rad, None)
            }
            Nav::Mission(run) => {
                let (sp, yaw, next) = self.mission_step(t, run, dt_s);
                (sp, yaw, next)
            }
            Nav::Orbit(orbit) => {
                let (sp, yaw) = self.orbit_step(orbit, dt_s);
                (Some(sp), yaw, None)
            }
        };
        self.navigator.nav = nav;
        self.slew_yaw(yaw_target, dt_s);
        if let Some(mode) = next_mode {
            self.switch_nav(mode);
            if sp.is_none() {
                // The mode that just ended flew nothing this step: the next one does.
                return self.nav_setpoint(t, dt_s);
            }
        }
        sp.map(|sp| TrajectorySetpoint {
            yaw_rad: self.navigator.yaw_rad,
            ..sp
        })
    }

    /// Changes mode keeping a Takeoff's or a mission's reference (so Hold holds exactly
    /// the point the vehicle was going to).
    fn switch_nav(&mut self, mode: FlightMode) {
        let carried = match &self.navigator.nav {
            Nav::Takeoff { approach, yaw_rad } => Some((*approach, *yaw_rad)),
            Nav::Mission(run) => run.hold_point(),
            _ => None,
        };
        self.enter_mode(mode);
        if let (FlightMode::Hold, Some((approach, yaw_rad))) = (mode, carried) {
            self.navigator.nav = Nav::Hold {
                approach,
                limits: self.tuning.auto,
                yaw_rad,
            };
        }
    }

    /// The landing setpoint over `xy_m`.
    pub(super) fn land_setpoint(&self, xy_m: Vector2<f64>) -> TrajectorySetpoint {
        let speed = self.tuning.land_speed_at(self.height_m());
        TrajectorySetpoint {
            pos_ned_m: Vector3::new(xy_m.x, xy_m.y, f64::NAN),
            vel_ned_mps: Vector3::new(f64::NAN, f64::NAN, speed),
            ..TrajectorySetpoint::UNSET
        }
    }

    fn return_step(
        &mut self,
        t: SimTime,
        stage: &mut ReturnStage,
        approach: &mut Approach,
        yaw_rad: &mut f64,
        dt_s: f64,
    ) -> TrajectorySetpoint {
        let tuning = self.tuning;
        let pos = self.plant.state.pos_ned_m;
        let home = Vector2::zeros();
        let close = |target: Vector3<f64>| (pos - target).norm() < tuning.altitude_radius_m;
        match *stage {
            ReturnStage::Climb if approach.arrived() && close(approach.target()) => {
                *stage = ReturnStage::Cruise;
                approach.retarget(Vector3::new(home.x, home.y, approach.target().z));
                if let Some(b) = bearing(pos.xy(), home) {
                    *yaw_rad = b;
                }
            }
            ReturnStage::Cruise if approach.arrived() && close(approach.target()) => {
                if tuning.rtl_land_delay_s == 0.0 {
                    *stage = ReturnStage::Land;
                } else {
                    *stage = ReturnStage::Descend;
                    let descend_z = self.plant.env.ground_z_ned_m - tuning.rtl_descend_alt_m;
                    approach.retarget(Vector3::new(home.x, home.y, descend_z.max(pos.z)));
                }
            }
            ReturnStage::Descend if approach.arrived() && close(approach.target()) => {
                let delay = tuning.rtl_land_delay_s;
                *stage =
                    ReturnStage::Loiter((delay >= 0.0).then(|| t + super::tuning::seconds(delay)));
            }
            ReturnStage::Loiter(Some(until)) if t >= until => *stage = ReturnStage::Land,
            _ => {}
        }
        match *stage {
            ReturnStage::Land => self.land_setpoint(home),
            _ => approach.step(&tuning.auto, dt_s),
        }
    }

    /// Moves the navigator's heading toward `target_rad` at MPC_YAWRAUTO_MAX.
    fn slew_yaw(&mut self, target_rad: f64, dt_s: f64) {
        let max_step = self.tuning.yaw_rate_auto_rps * dt_s;
        let error = wrap_pi(target_rad - self.navigator.yaw_rad);
        self.navigator.yaw_rad = wrap_pi(self.navigator.yaw_rad + error.clamp(-max_step, max_step));
    }
}

impl Vehicle {
    /// One orbit step: the approach to the circle, then the point running around it with
    /// its velocity and centripetal acceleration as feed-forward.
    fn orbit_step(&self, orbit: &mut Orbit, dt_s: f64) -> (TrajectorySetpoint, f64) {
        let here = self.plant.state.pos_ned_m;
        let r = orbit.radius_m.abs();
        let direction = orbit.radius_m.signum();
        let sp = match orbit.angle_rad {
            None => {
                let sp = orbit.approach.step(&self.tuning.auto, dt_s);
                if orbit.approach.arrived() {
                    let d = orbit.approach.target().xy() - orbit.centre_m;
                    orbit.angle_rad = Some(d.y.atan2(d.x));
                }
                sp
            }
            Some(angle) => {
                let next = angle + direction * orbit.speed_mps / r * dt_s;
                orbit.angle_rad = Some(wrap_pi(next));
                let (s, c) = next.sin_cos();
                let v = orbit.speed_mps * direction;
                TrajectorySetpoint {
                    pos_ned_m: Vector3::new(
                        orbit.centre_m.x + r * c,
                        orbit.centre_m.y + r * s,
                        orbit.z_m,
                    ),
                    vel_ned_mps: Vector3::new(-v * s, v * c, 0.0),
                    acc_ned_mps2: Vector3::new(
                        -orbit.speed_mps.powi(2) / r * c,
                        -orbit.speed_mps.powi(2) / r * s,
                        0.0,
                    ),
                    ..TrajectorySetpoint::UNSET
                }
            }
        };
        let to_centre = orbit.centre_m - here.xy();
        let yaw = match orbit.yaw {
            OrbitYaw::Centre => to_centre.y.atan2(to_centre.x),
            OrbitYaw::Initial(yaw) => yaw,
            OrbitYaw::Free => self.yaw_rad(),
            OrbitYaw::Tangent => {
                let v = sp.vel_ned_mps;
                if v.xy().norm() > 0.1 {
                    v.y.atan2(v.x)
                } else {
                    self.navigator.yaw_rad
                }
            }
        };
        (sp, yaw)
    }
}
