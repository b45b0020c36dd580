//! Commands (COMMAND_LONG, COMMAND_INT, SET_MODE): every one is answered with a
//! COMMAND_ACK on the link it came from, UNSUPPORTED for commands the emulator does not
//! implement. Unused parameters (NaN on the wire, INT32_MAX for COMMAND_INT's x and y)
//! and non-finite ones (PX4 tests them with `PX4_ISFINITE`) arrive as `None`;
//! COMMAND_INT's x and y in a global frame arrive in degrees.
//!
//! Mode changes follow PX4's commander: while disarmed any mode the emulator flies is
//! accepted (arming then needs a mode that can run); while armed, OFFBOARD needs the
//! offboard signal and AUTO.MISSION a mission, else TEMPORARILY_REJECTED.

use std::time::Duration;

use mavlink::dialects::common::{COMMAND_ACK_DATA, MavCmd, MavMessage, MavResult};
use nalgebra::Vector3;

use super::flight::{Nav, Orbit, OrbitYaw};
use super::mode::FlightMode;
use super::{LinkId, Vehicle};
use crate::time::SimTime;
use crate::trajectory::Approach;

/// PX4's magic number in param2 of ARM_DISARM that forces the action.
const FORCE_MAGIC: f64 = 21196.0;
/// MAV_DO_REPOSITION_FLAGS_CHANGE_MODE.
const REPOSITION_CHANGE_MODE: u32 = 1;

/// A command with its seven parameters (`None` = unused).
#[derive(Debug, Clone, Copy)]
pub(super) struct ReceivedCommand {
    /// The command.
    pub id: MavCmd,
    pub params: [Option<f64>; 7],
}

impl ReceivedCommand {
    /// A COMMAND_LONG's parameters; NaN marks an unused parameter.
    pub fn from_wire(id: MavCmd, params: [f32; 7]) -> Self {
        Self {
            id,
            params: params.map(|x| x.is_finite().then_some(f64::from(x))),
        }
    }

    /// A COMMAND_INT's parameters: x and y are degrees·10⁷ in global frames (INT32_MAX
    /// is unused), plain numbers otherwise.
    pub fn from_int(id: MavCmd, params: [f32; 4], x: i32, y: i32, z: f32, global: bool) -> Self {
        let scale = if global { 1e-7 } else { 1.0 };
        let xy = |v: i32| (v != i32::MAX).then_some(f64::from(v) * scale);
        let p = params.map(|x| x.is_finite().then_some(f64::from(x)));
        Self {
            id,
            params: [
                p[0],
                p[1],
                p[2],
                p[3],
                xy(x),
                xy(y),
                z.is_finite().then_some(f64::from(z)),
            ],
        }
    }
}

impl Vehicle {
    pub(super) fn run_command(
        &mut self,
        now: SimTime,
        link: LinkId,
        sender: (u8, u8),
        cmd: ReceivedCommand,
    ) {
        let ardupilot = self.is_ardupilot();
        let result = match cmd.id {
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM if ardupilot => self.ap_arm_disarm(now, &cmd),
            MavCmd::MAV_CMD_DO_SET_MODE if ardupilot => self.ap_set_mode(now, &cmd),
            MavCmd::MAV_CMD_NAV_LAND if ardupilot => self.ap_land(),
            MavCmd::MAV_CMD_NAV_TAKEOFF if ardupilot => self.ap_takeoff(&cmd),
            // ArduPilot: param3 (the response target) must be 0.
            MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL
                if ardupilot && cmd.params[2].is_some_and(|p| p != 0.0) =>
            {
                MavResult::MAV_RESULT_DENIED
            }
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM => self.cmd_arm_disarm(now, &cmd),
            MavCmd::MAV_CMD_DO_SET_MODE => self.cmd_set_mode(now, &cmd),
            MavCmd::MAV_CMD_NAV_LAND => {
                self.modes.failsafe = false;
                self.enter_mode(FlightMode::Land);
                MavResult::MAV_RESULT_ACCEPTED
            }
            MavCmd::MAV_CMD_NAV_TAKEOFF => self.cmd_takeoff(&cmd),
            MavCmd::MAV_CMD_NAV_RETURN_TO_LAUNCH => {
                self.modes.failsafe = false;
                self.enter_mode(FlightMode::Return);
                MavResult::MAV_RESULT_ACCEPTED
            }
            MavCmd::MAV_CMD_DO_REPOSITION => self.cmd_reposition(&cmd),
            MavCmd::MAV_CMD_DO_ORBIT => self.cmd_orbit(&cmd),
            MavCmd::MAV_CMD_DO_CHANGE_SPEED => self.cmd_change_speed(&cmd),
            MavCmd::MAV_CMD_MISSION_START => self.cmd_mission_start(now, &cmd),
            MavCmd::MAV_CMD_DO_SET_MISSION_CURRENT => self.cmd_set_mission_current(&cmd),
            MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL => self.cmd_message_interval(now, link, &cmd),
            MavCmd::MAV_CMD_REQUEST_MESSAGE => self.cmd_request_message(now, link, &cmd),
            // Superseded by REQUEST_MESSAGE, still sent by older clients.
            #[allow(deprecated)]
            MavCmd::MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES => {
                self.send_message_now(now, link, 148);
                MavResult::MAV_RESULT_ACCEPTED
            }
            _ => {
                self.counters.unsupported_commands += 1;
                MavResult::MAV_RESULT_UNSUPPORTED
            }
        };
        tracing::debug!(sysid = self.cfg.system_id, command = ?cmd.id, ?result, "command");
        self.send_ack(link, sender, cmd.id, result);
    }

    /// A COMMAND_ACK for `command` to `to` on `link`.
    pub(super) fn send_ack(
        &mut self,
        link: LinkId,
        to: (u8, u8),
        command: MavCmd,
        result: MavResult,
    ) {
        let ack = MavMessage::COMMAND_ACK(COMMAND_ACK_DATA {
            command,
            result,
            progress: 0,
            result_param2: 0,
            target_system: to.0,
            target_component: to.1,
        });
        self.send(link, &ack);
    }

    /// A COMMAND_LONG or COMMAND_INT: PX4 main's MAVLink module answers DO_SET_MODE at
    /// once with ACCEPTED, and its commander then sends the real answer (a few ms later on
    /// PX4; in the same step here). Clients must read the second, as with PX4.
    pub(super) fn run_wire_command(
        &mut self,
        now: SimTime,
        link: LinkId,
        sender: (u8, u8),
        cmd: ReceivedCommand,
    ) {
        // ArduPilot answers once.
        if cmd.id == MavCmd::MAV_CMD_DO_SET_MODE && !self.is_ardupilot() {
            self.send_ack(link, sender, cmd.id, MavResult::MAV_RESULT_ACCEPTED);
        }
        self.run_command(now, link, sender, cmd);
    }

    fn cmd_arm_disarm(&mut self, now: SimTime, cmd: &ReceivedCommand) -> MavResult {
        let force = cmd.params[1] == Some(FORCE_MAGIC);
        match cmd.params[0] {
            Some(1.0) => {
                if !self.modes.armed() && !force && !self.arming_allowed(now) {
                    return MavResult::MAV_RESULT_TEMPORARILY_REJECTED;
                }
                self.arm(now);
                MavResult::MAV_RESULT_ACCEPTED
            }
            Some(0.0) => {
                if !self.modes.armed() {
                    MavResult::MAV_RESULT_ACCEPTED
                } else if self.modes.landed() || force {
                    self.disarm(if force { "forced" } else { "commanded" });
                    MavResult::MAV_RESULT_ACCEPTED
                } else {
                    MavResult::MAV_RESULT_DENIED
                }
            }
            _ => MavResult::MAV_RESULT_DENIED,
        }
    }

    /// PX4's arming checks that the emulator can fail: not breaching the geofence (with
    /// GF_ACTION set), the mode must be able to run, and with NAV_DLL_ACT set a ground
    /// station must be connected.
    fn arming_allowed(&mut self, now: SimTime) -> bool {
        if self.geofence_denies_arming() {
            tracing::info!(
                sysid = self.cfg.system_id,
                "arming denied: geofence breached"
            );
            self.send_statustext(
                mavlink::dialects::common::MavSeverity::MAV_SEVERITY_CRITICAL,
                "Arming denied: Resolve system health failures first",
            );
            return false;
        }
        if !self.can_run(now, self.modes.mode) {
            tracing::info!(
                sysid = self.cfg.system_id,
                mode = self.modes.mode.name(),
                "arming denied: mode cannot run"
            );
            return false;
        }
        if self.tuning.datalink_loss_action > 0 && !self.gcs_connected(now) {
            tracing::info!(
                sysid = self.cfg.system_id,
                "arming denied: no connection to the ground station"
            );
            return false;
        }
        true
    }

    fn cmd_set_mode(&mut self, now: SimTime, cmd: &ReceivedCommand) -> MavResult {
        let (Some(main), sub) = (cmd.params[1], cmd.params[2].unwrap_or(0.0)) else {
            return MavResult::MAV_RESULT_DENIED;
        };
        let Some(mode) = FlightMode::from_px4(main as u32, sub as u32) else {
            return MavResult::MAV_RESULT_UNSUPPORTED;
        };
        if self.modes.armed() && !self.can_run(now, mode) {
            return MavResult::MAV_RESULT_TEMPORARILY_REJECTED;
        }
        self.modes.failsafe = false;
        self.enter_mode(mode);
        MavResult::MAV_RESULT_ACCEPTED
    }

    /// NAV_TAKEOFF: param7 is the target altitude AMSL (NaN: the current altitude plus
    /// MIS_TAKEOFF_ALT), never below the current altitude.
    fn cmd_takeoff(&mut self, cmd: &ReceivedCommand) -> MavResult {
        self.modes.failsafe = false;
        self.enter_mode(FlightMode::Takeoff);
        if let Some(alt_amsl) = cmd.params[6].filter(|a| a.is_finite()) {
            let frame = self.global_frame();
            let here = self.plant.state.pos_ned_m;
            let target_z =
                (frame.home_alt_amsl_m - alt_amsl + self.plant.env.ground_z_ned_m).min(here.z);
            if let Nav::Takeoff { approach, .. } = &mut self.navigator.nav {
                approach.retarget(Vector3::new(here.x, here.y, target_z));
            }
        }
        MavResult::MAV_RESULT_ACCEPTED
    }

    /// DO_REPOSITION as PX4 takes it: with the change-mode flag (param2 bit 0) it switches
    /// to Hold, without it it is only accepted in Hold; an armed vehicle in the air then
    /// flies to latitude/longitude (param5/6, NaN: here) at altitude param7 (AMSL, NaN:
    /// here) at param1 m/s (≤ 0 or NaN: MPC_XY_CRUISE), facing param4 (radians, as PX4
    /// reads it; NaN: the current heading).
    fn cmd_reposition(&mut self, cmd: &ReceivedCommand) -> MavResult {
        let flags = cmd.params[1].map_or(0, |f| f as u32);
        if flags & REPOSITION_CHANGE_MODE == 0 && self.modes.mode != FlightMode::Hold {
            return MavResult::MAV_RESULT_DENIED;
        }
        let Some(target) = self.target_of(cmd) else {
            return MavResult::MAV_RESULT_DENIED;
        };
        if self.modes.mode != FlightMode::Hold {
            self.modes.failsafe = false;
            self.enter_mode(FlightMode::Hold);
        }
        if !self.modes.armed() || self.modes.landed() {
            return MavResult::MAV_RESULT_ACCEPTED;
        }
        let here = self.plant.state.pos_ned_m;
        let speed = cmd.params[0]
            .filter(|s| *s > 0.0)
            .unwrap_or(self.tuning.auto.speed_xy_mps);
        let yaw = cmd.params[3].unwrap_or_else(|| self.yaw_rad());
        let approach = match &self.navigator.nav {
            Nav::Hold { approach, .. } => {
                let mut a = *approach;
                a.retarget(target);
                a
            }
            _ => Approach::new(here, self.plant.state.vel_ned_mps, target),
        };
        self.navigator.nav = Nav::Hold {
            approach,
            limits: self.tuning.auto_at(speed),
            yaw_rad: yaw,
        };
        MavResult::MAV_RESULT_ACCEPTED
    }

    /// The local NED point of a command's latitude/longitude (param5/6, degrees) and AMSL
    /// altitude (param7), each unused one taken from where the vehicle is; `None` for a
    /// latitude or longitude off the Earth.
    fn target_of(&self, cmd: &ReceivedCommand) -> Option<Vector3<f64>> {
        let (lat, lon, alt) = (cmd.params[4], cmd.params[5], cmd.params[6]);
        if lat.is_some_and(|v| v.abs() > 90.0) || lon.is_some_and(|v| v.abs() > 180.0) {
            return None;
        }
        let here = self
            .world
            .to_geodetic(&(self.cfg.start.pos_world_ned_m + self.plant.state.pos_ned_m));
        Some(self.global_frame().to_local(
            lat.unwrap_or(here.lat_deg),
            lon.unwrap_or(here.lon_deg),
            alt.unwrap_or(here.alt_amsl_m),
        ))
    }

    /// DO_ORBIT: radius param1 (m, 1..=1000, positive clockwise; NaN: 10), speed param2
    /// (m/s; NaN: 1; at most what MPC_ACC_HOR allows on that radius), yaw behaviour param3
    /// (0 centre, 1 initial heading, 2 free, 3 tangent; NaN: 0), centre param5/6
    /// (lat/lon; NaN: here), altitude param7 (AMSL; NaN: here). Needs a flying vehicle.
    fn cmd_orbit(&mut self, cmd: &ReceivedCommand) -> MavResult {
        if !self.modes.armed() || self.modes.landed() {
            return MavResult::MAV_RESULT_TEMPORARILY_REJECTED;
        }
        let radius = cmd.params[0].unwrap_or(10.0);
        let speed = cmd.params[1].unwrap_or(1.0);
        let yaw = match cmd.params[2].map_or(0, |y| y as i64) {
            0 => OrbitYaw::Centre,
            1 => OrbitYaw::Initial(self.yaw_rad()),
            2 => OrbitYaw::Free,
            3 => OrbitYaw::Tangent,
            _ => return MavResult::MAV_RESULT_DENIED,
        };
        let usable = (1.0..=1000.0).contains(&radius.abs()) && speed.is_finite() && speed >= 0.0;
        let (true, Some(centre)) = (usable, self.target_of(cmd)) else {
            return MavResult::MAV_RESULT_DENIED;
        };
        let here = self.plant.state.pos_ned_m;
        // The centripetal acceleration v²/r stays within MPC_ACC_HOR.
        let speed = speed.min((self.tuning.auto.acc_xy_mps2 * radius.abs()).sqrt());
        let out = here.xy() - centre.xy();
        let dir = if out.norm() > 1e-6 {
            out / out.norm()
        } else {
            nalgebra::Vector2::new(1.0, 0.0)
        };
        let entry = centre.xy() + dir * radius.abs();
        self.modes.failsafe = false;
        self.enter_mode(FlightMode::Orbit);
        self.navigator.nav = Nav::Orbit(Orbit {
            centre_m: centre.xy(),
            z_m: centre.z,
            radius_m: radius,
            speed_mps: speed,
            yaw,
            angle_rad: None,
            approach: Approach::new(
                here,
                self.plant.state.vel_ned_mps,
                Vector3::new(entry.x, entry.y, centre.z),
            ),
        });
        MavResult::MAV_RESULT_ACCEPTED
    }

    /// DO_CHANGE_SPEED: param2 m/s for the leg being flown (Hold/goto or a mission);
    /// −1 leaves it, 0 or less otherwise goes back to MPC_XY_CRUISE.
    fn cmd_change_speed(&mut self, cmd: &ReceivedCommand) -> MavResult {
        let speed = match cmd.params[1] {
            Some(-1.0) => return MavResult::MAV_RESULT_ACCEPTED,
            Some(s) if s > 0.0 => s,
            _ => self.tuning.auto.speed_xy_mps,
        };
        match &mut self.navigator.nav {
            Nav::Hold { limits, .. } => *limits = self.tuning.auto_at(speed),
            Nav::Mission(run) => run.set_speed(speed),
            _ => {}
        }
        MavResult::MAV_RESULT_ACCEPTED
    }

    /// MISSION_START: AUTO.MISSION from item param1 (−1: the current one), and arms.
    fn cmd_mission_start(&mut self, now: SimTime, cmd: &ReceivedCommand) -> MavResult {
        let n = self.navigator.mission.items().len() as f64;
        let first = cmd.params[0];
        if !self.navigator.mission.is_valid() || first.is_none_or(|f| !(-1.0..n).contains(&f)) {
            return MavResult::MAV_RESULT_DENIED;
        }
        self.modes.failsafe = false;
        self.enter_mode(FlightMode::Mission);
        if let Some(f) = first.filter(|f| *f >= 0.0) {
            self.jump_to_item(f as usize);
        }
        if !self.modes.armed() {
            if !self.arming_allowed(now) {
                return MavResult::MAV_RESULT_TEMPORARILY_REJECTED;
            }
            self.arm(now);
        }
        MavResult::MAV_RESULT_ACCEPTED
    }

    /// DO_SET_MISSION_CURRENT: param1 the item (−1: keep), param2 0 or 1.
    fn cmd_set_mission_current(&mut self, cmd: &ReceivedCommand) -> MavResult {
        let (Some(seq), reset) = (cmd.params[0], cmd.params[1].unwrap_or(0.0)) else {
            return MavResult::MAV_RESULT_DENIED;
        };
        if seq < -1.0 || !(reset == 0.0 || reset == 1.0) {
            return MavResult::MAV_RESULT_DENIED;
        }
        if !self.navigator.mission.is_valid() || seq >= self.navigator.mission.items().len() as f64
        {
            return MavResult::MAV_RESULT_FAILED;
        }
        if seq >= 0.0 {
            self.jump_to_item(seq as usize);
        }
        MavResult::MAV_RESULT_ACCEPTED
    }

    fn cmd_message_interval(
        &mut self,
        now: SimTime,
        link: LinkId,
        cmd: &ReceivedCommand,
    ) -> MavResult {
        let (Some(id), Some(interval_us)) = (cmd.params[0], cmd.params[1]) else {
            return MavResult::MAV_RESULT_DENIED;
        };
        let interval = match interval_us {
            -1.0 => Some(None),
            0.0 => None, // back to the default
            x if x > 0.0 => Some(Some(Duration::from_micros(x as u64))),
            _ => return MavResult::MAV_RESULT_DENIED,
        };
        if self.set_interval(now, link, id as u32, interval) {
            MavResult::MAV_RESULT_ACCEPTED
        } else {
            MavResult::MAV_RESULT_UNSUPPORTED
        }
    }

    fn cmd_request_message(
        &mut self,
        now: SimTime,
        link: LinkId,
        cmd: &ReceivedCommand,
    ) -> MavResult {
        let Some(id) = cmd.params[0] else {
            return MavResult::MAV_RESULT_DENIED;
        };
        if self.send_message_now(now, link, id as u32) {
            MavResult::MAV_RESULT_ACCEPTED
        } else {
            MavResult::MAV_RESULT_UNSUPPORTED
        }
    }
}
