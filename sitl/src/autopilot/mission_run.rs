//! AUTO.MISSION: flies the stored items one after the other, as PX4's navigator does.
//!
//! ```text
//!  item ──► [landed and the item is higher than NAV_MC_ALT_RAD above: climb in place
//!            first (not reported)] ──► fly to it at the cruise speed
//!       ──► reached (horizontal ≤ param2 or NAV_ACC_RAD, vertical ≤ NAV_MC_ALT_RAD, yaw
//!           within 12° when the item has one) ──► hold param1 s ──► MISSION_ITEM_REACHED
//!           ──► next item
//!  NAV_TAKEOFF: climb in place to its altitude (a waypoint when already flying)
//!  NAV_LAND: fly there at the current altitude, land; reached on the ground
//!  NAV_RETURN_TO_LAUNCH: reached at once; the vehicle switches to Return
//!  NAV_LOITER_UNLIM: fly there and stay; NAV_LOITER_TIME: stay param1 s
//!  NAV_DELAY: wait param1 s where the vehicle is; DO_CHANGE_SPEED: cruise = param2
//!           (≤ 0: MPC_XY_CRUISE); payload items: passed over
//!  after the last item ──► Hold at the last point ("Mission finished, loitering")
//! ```
//!
//! Yaw: the item's (param4, degrees) or, when NaN, toward the waypoint until inside its
//! acceptance radius. Altitudes of relative frames are above home (the start point on
//! the ground).

use nalgebra::{Vector2, Vector3};

use super::Vehicle;
use super::mission_item::{MissionItem, cmd};
use super::mode::FlightMode;
use super::tuning::seconds;
use crate::position_control::TrajectorySetpoint;
use crate::time::SimTime;
use crate::trajectory::Approach;

/// The heading from `from` to `to` (rad), or `None` when they are within a metre.
pub(super) fn bearing(from: Vector2<f64>, to: Vector2<f64>) -> Option<f64> {
    let d = to - from;
    (d.norm() > 1.0).then(|| d.y.atan2(d.x))
}

/// PX4's MIS_YAW_ERR: how close the heading must be for an item with a yaw (rad).
const YAW_ACCEPTANCE_RAD: f64 = 12.0 * std::f64::consts::PI / 180.0;

/// What the current item is doing.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Stage {
    /// The item has not been looked at yet.
    Begin,
    /// Climbing in place before a first item that is higher (PX4's inserted takeoff).
    Climb,
    /// Flying to the item's point.
    Fly,
    /// At the point, waiting until the time (or forever).
    Wait(Option<SimTime>),
    /// Descending for NAV_LAND.
    Landing,
}

/// The mission being flown.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct MissionRun {
    seq: usize,
    stage: Stage,
    approach: Option<Approach>,
    speed_xy_mps: Option<f64>,
    yaw_rad: Option<f64>,
}

impl MissionRun {
    /// Starts at item `seq`.
    pub fn start(seq: usize) -> Self {
        Self {
            seq,
            stage: Stage::Begin,
            approach: None,
            speed_xy_mps: None,
            yaw_rad: None,
        }
    }

    /// Restarts at item `seq` (MISSION_SET_CURRENT while flying).
    pub fn jump(&mut self, seq: usize) {
        self.seq = seq;
        self.stage = Stage::Begin;
    }

    /// A new cruise speed (DO_CHANGE_SPEED as a command).
    pub fn set_speed(&mut self, speed_mps: f64) {
        self.speed_xy_mps = Some(speed_mps);
    }

    /// Whether the mission needs to leave the ground.
    pub fn wants_climb(&self) -> bool {
        matches!(self.stage, Stage::Begin | Stage::Climb | Stage::Fly)
    }

    /// The point to hold when the mission ends.
    pub fn hold_point(&self) -> Option<(Approach, f64)> {
        self.approach.map(|a| (a, self.yaw_rad.unwrap_or(0.0)))
    }
}

impl Vehicle {
    /// The local NED point of a positional item (NaN coordinates keep `here`'s).
    fn item_point(&self, item: &MissionItem) -> Vector3<f64> {
        let here = self.plant.state.pos_ned_m;
        let frame = self.global_frame();
        let (lat, lon) = item.lat_lon_deg();
        let alt = f64::from(item.z);
        let alt_amsl = if item.relative_alt() {
            frame.home_alt_amsl_m + alt
        } else {
            alt
        };
        let p = frame.to_local(lat, lon, if alt.is_finite() { alt_amsl } else { 0.0 });
        let no_xy = item.x == 0 && item.y == 0;
        Vector3::new(
            if no_xy { here.x } else { p.x },
            if no_xy { here.y } else { p.y },
            if alt.is_finite() { p.z } else { here.z },
        )
    }

    /// One mission step: the setpoint, the yaw target and a mode to switch to.
    pub(super) fn mission_step(
        &mut self,
        t: SimTime,
        run: &mut MissionRun,
        dt_s: f64,
    ) -> (Option<TrajectorySetpoint>, f64, Option<FlightMode>) {
        // Items that take no time are done in the same step, a bounded number of them.
        for _ in 0..64 {
            let Some(item) = self.navigator.mission.items().get(run.seq).copied() else {
                self.navigator.mission.mark_finished();
                self.report_mission();
                if self.modes.landed() {
                    tracing::info!(sysid = self.cfg.system_id, "mission finished, landed");
                } else {
                    tracing::info!(sysid = self.cfg.system_id, "mission finished, loitering");
                }
                return (None, self.navigator.yaw_rad, Some(FlightMode::Hold));
            };
            if run.stage == Stage::Begin {
                match self.begin_item(t, run, &item) {
                    ItemStart::Done => {
                        self.advance(run);
                        continue;
                    }
                    ItemStart::Return => {
                        self.advance(run);
                        return (None, self.navigator.yaw_rad, Some(FlightMode::Return));
                    }
                    ItemStart::Flying => {}
                }
            }
            return self.fly_item(t, run, &item, dt_s);
        }
        (None, self.navigator.yaw_rad, None)
    }

    fn advance(&mut self, run: &mut MissionRun) {
        run.seq += 1;
        run.stage = Stage::Begin;
        let n = self.navigator.mission.items().len();
        self.navigator.mission.set_current(run.seq.min(n));
        if run.seq >= n {
            // Past the last item (a final RTL included): the mission is complete, as PX4
            // reports it (MAVSDK's progress reads it from MISSION_CURRENT).
            self.navigator.mission.mark_finished();
        }
        self.note_item_reached(run.seq - 1);
    }

    fn begin_item(&mut self, t: SimTime, run: &mut MissionRun, item: &MissionItem) -> ItemStart {
        let here = self.plant.state.pos_ned_m;
        match item.command {
            cmd::DO_CHANGE_SPEED => {
                let speed = f64::from(item.params[1]);
                run.speed_xy_mps = (speed > 0.0).then_some(speed);
                ItemStart::Done
            }
            cmd::NAV_RETURN_TO_LAUNCH => ItemStart::Return,
            cmd::NAV_DELAY => {
                let delay = f64::from(item.params[0]).max(0.0);
                let point = run.approach.map_or(here, |a| a.target());
                run.approach = Some(Approach::new(here, self.plant.state.vel_ned_mps, point));
                run.stage = Stage::Wait(Some(t + seconds(delay)));
                ItemStart::Flying
            }
            c if item.is_positional() => {
                let target = self.item_point(item);
                let approach = run
                    .approach
                    .map(|mut a| {
                        a.retarget(target);
                        a
                    })
                    .unwrap_or_else(|| Approach::new(here, self.plant.state.vel_ned_mps, target));
                run.approach = Some(approach);
                let yaw = f64::from(item.params[3]);
                run.yaw_rad = yaw.is_finite().then(|| yaw.to_radians());
                let higher = here.z - target.z > self.tuning.altitude_radius_m;
                run.stage = if self.modes.landed() && higher && c != cmd::NAV_LAND {
                    let mut climb = Approach::new(here, Vector3::zeros(), here);
                    climb.retarget(Vector3::new(here.x, here.y, target.z));
                    run.approach = Some(climb);
                    Stage::Climb
                } else {
                    Stage::Fly
                };
                ItemStart::Flying
            }
            _ => ItemStart::Done, // payload items: nothing to do without a payload
        }
    }

    fn fly_item(
        &mut self,
        t: SimTime,
        run: &mut MissionRun,
        item: &MissionItem,
        dt_s: f64,
    ) -> (Option<TrajectorySetpoint>, f64, Option<FlightMode>) {
        let tuning = self.tuning;
        let here = self.plant.state.pos_ned_m;
        let Some(mut approach) = run.approach else {
            return (None, self.navigator.yaw_rad, None);
        };
        let target = approach.target();
        let radius = if item.params[1] > 0.0 && item.command == cmd::NAV_WAYPOINT {
            f64::from(item.params[1])
        } else {
            tuning.acceptance_radius_m
        };
        let dist_xy = (target.xy() - here.xy()).norm();
        let dz = (target.z - here.z).abs();
        let mut yaw_target = run.yaw_rad.unwrap_or(self.navigator.yaw_rad);
        if run.yaw_rad.is_none()
            && dist_xy > radius
            && let Some(b) = bearing(here.xy(), target.xy())
        {
            yaw_target = b;
        }
        let speed = run.speed_xy_mps.unwrap_or(tuning.auto.speed_xy_mps);
        match run.stage {
            Stage::Climb => {
                let sp = approach.step(&tuning.auto_at(speed), dt_s);
                if dz < tuning.altitude_radius_m {
                    let point = self.item_point(item);
                    approach.retarget(point);
                    run.stage = Stage::Fly;
                }
                run.approach = Some(approach);
                (Some(sp), self.navigator.yaw_rad, None)
            }
            Stage::Fly => {
                let land = item.command == cmd::NAV_LAND;
                let sp = approach.step(&tuning.auto_at(speed), dt_s);
                run.approach = Some(approach);
                let yaw_ok = run.yaw_rad.is_none_or(|y| {
                    crate::position_control::wrap_pi(y - self.yaw_rad()).abs() < YAW_ACCEPTANCE_RAD
                });
                let arrived = if land {
                    dist_xy <= tuning.acceptance_radius_m.min(1.0) && approach.arrived()
                } else {
                    dist_xy <= radius && dz <= tuning.altitude_radius_m && yaw_ok
                };
                if arrived {
                    run.stage = match item.command {
                        cmd::NAV_LAND => Stage::Landing,
                        cmd::NAV_LOITER_UNLIM => Stage::Wait(None),
                        cmd::NAV_LOITER_TIME => {
                            Stage::Wait(Some(t + seconds(f64::from(item.params[0]).max(0.0))))
                        }
                        _ => {
                            let hold = f64::from(item.params[0]);
                            Stage::Wait(Some(t + seconds(hold.max(0.0))))
                        }
                    };
                }
                (Some(sp), yaw_target, None)
            }
            Stage::Wait(until) => {
                let sp = approach.step(&tuning.auto_at(speed), dt_s);
                run.approach = Some(approach);
                if until.is_some_and(|u| t >= u) {
                    self.advance(run);
                }
                (Some(sp), yaw_target, None)
            }
            Stage::Landing => {
                let sp = self.land_setpoint(target.xy());
                if self.modes.landed() {
                    self.advance(run);
                }
                (Some(sp), self.navigator.yaw_rad, None)
            }
            Stage::Begin => (None, self.navigator.yaw_rad, None),
        }
    }
}

/// What starting an item led to.
enum ItemStart {
    /// Done at once (DO items).
    Done,
    /// Return to launch.
    Return,
    /// The item flies.
    Flying,
}
