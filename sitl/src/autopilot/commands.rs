//! Commands (COMMAND_LONG, COMMAND_INT, SET_MODE): every one is answered with a
//! COMMAND_ACK on the link it came from, UNSUPPORTED for commands the emulator does not
//! implement. Unused parameters (NaN on the wire) arrive as `None`.

use std::time::Duration;

use mavlink::dialects::common::{COMMAND_ACK_DATA, MavCmd, MavMessage, MavResult};

use super::mode::FlightMode;
use super::{LinkId, Vehicle};
use crate::time::SimTime;

/// PX4's magic number in param2 of ARM_DISARM that forces the action.
const FORCE_MAGIC: f32 = 21196.0;

/// A command with its seven parameters (`None` = unused).
#[derive(Debug, Clone, Copy)]
pub(super) struct Command {
    pub id: MavCmd,
    pub params: [Option<f32>; 7],
}

impl Command {
    /// A command from its wire parameters; NaN marks an unused parameter.
    pub fn from_wire(id: MavCmd, params: [f32; 7]) -> Self {
        Self {
            id,
            params: params.map(|x| if x.is_nan() { None } else { Some(x) }),
        }
    }
}

impl Vehicle {
    pub(super) fn run_command(
        &mut self,
        now: SimTime,
        link: LinkId,
        sender: (u8, u8),
        cmd: Command,
    ) {
        let result = match cmd.id {
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM => self.cmd_arm_disarm(now, &cmd),
            MavCmd::MAV_CMD_DO_SET_MODE => self.cmd_set_mode(now, &cmd),
            MavCmd::MAV_CMD_NAV_LAND => {
                self.failsafe = false;
                self.enter_mode(FlightMode::Land);
                MavResult::MAV_RESULT_ACCEPTED
            }
            MavCmd::MAV_CMD_NAV_TAKEOFF => self.cmd_takeoff(&cmd),
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
        let ack = MavMessage::COMMAND_ACK(COMMAND_ACK_DATA {
            command: cmd.id,
            result,
            progress: 0,
            result_param2: 0,
            target_system: sender.0,
            target_component: sender.1,
        });
        self.send(link, &ack);
    }

    fn cmd_arm_disarm(&mut self, now: SimTime, cmd: &Command) -> MavResult {
        let force = cmd.params[1] == Some(FORCE_MAGIC);
        match cmd.params[0] {
            Some(1.0) => {
                self.arm(now);
                MavResult::MAV_RESULT_ACCEPTED
            }
            Some(0.0) => {
                if !self.armed {
                    MavResult::MAV_RESULT_ACCEPTED
                } else if self.landed || force {
                    self.disarm(if force { "forced" } else { "commanded" });
                    MavResult::MAV_RESULT_ACCEPTED
                } else {
                    MavResult::MAV_RESULT_DENIED
                }
            }
            _ => MavResult::MAV_RESULT_DENIED,
        }
    }

    fn cmd_set_mode(&mut self, now: SimTime, cmd: &Command) -> MavResult {
        let (Some(main), sub) = (cmd.params[1], cmd.params[2].unwrap_or(0.0)) else {
            return MavResult::MAV_RESULT_DENIED;
        };
        let Some(mode) = FlightMode::from_px4(main as u32, sub as u32) else {
            return MavResult::MAV_RESULT_UNSUPPORTED;
        };
        if mode == FlightMode::Offboard && !self.stream_is_live(now) {
            return MavResult::MAV_RESULT_TEMPORARILY_REJECTED;
        }
        if mode == FlightMode::Takeoff && !self.armed {
            return MavResult::MAV_RESULT_DENIED;
        }
        self.failsafe = false;
        self.enter_mode(mode);
        MavResult::MAV_RESULT_ACCEPTED
    }

    fn cmd_takeoff(&mut self, cmd: &Command) -> MavResult {
        if !self.armed {
            return MavResult::MAV_RESULT_DENIED;
        }
        if let Some(alt) = cmd.params[6].filter(|a| *a > 0.0 && a.is_finite()) {
            // param7 is an AMSL altitude; store it as a height above the home ground.
            let home_amsl = self.world.reference.alt_amsl_m - self.world.ground_down_m;
            let height = (f64::from(alt) - home_amsl).max(0.5);
            // Out of MIS_TAKEOFF_ALT's range: keep the parameter's value, as PX4 clamps.
            if self.params.set("MIS_TAKEOFF_ALT", height as f32).is_err() {
                tracing::debug!(
                    sysid = self.cfg.system_id,
                    height,
                    "takeoff altitude out of range"
                );
            }
        }
        self.failsafe = false;
        self.enter_mode(FlightMode::Takeoff);
        MavResult::MAV_RESULT_ACCEPTED
    }

    fn cmd_message_interval(&mut self, now: SimTime, link: LinkId, cmd: &Command) -> MavResult {
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

    fn cmd_request_message(&mut self, now: SimTime, link: LinkId, cmd: &Command) -> MavResult {
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
