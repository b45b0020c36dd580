//! The commands a vehicle link sends, in domain terms, and the one builder of their
//! COMMAND_LONG; names of commands and results taken from the MAVLink dialect.

use mavlink::dialects::common::{
    COMMAND_LONG_DATA, MavCmd, MavMessage, MavMissionResult, MavResult,
};
use num_traits::FromPrimitive;

/// What a link asks of its vehicle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum VehicleCommand {
    /// Arm (MAV_CMD_COMPONENT_ARM_DISARM, param1 1).
    Arm,
    /// Disarm (param1 0, not forced).
    Disarm,
    /// Switch to PX4 custom mode `main`/`sub` (MAV_CMD_DO_SET_MODE, base mode custom).
    SetMode {
        /// PX4's main mode.
        main: u32,
        /// PX4's sub mode (0: none).
        sub: u32,
    },
    /// Land where it is, on its current heading (MAV_CMD_NAV_LAND, NaN position and yaw).
    Land,
    /// Stream message `message_id` every `interval_us` µs, or stop it (`None`)
    /// (MAV_CMD_SET_MESSAGE_INTERVAL).
    StreamInterval {
        /// The MAVLink message id.
        message_id: u32,
        /// The interval (µs); `None` turns the stream off (−1).
        interval_us: Option<f32>,
    },
    /// Send message `message_id` once (MAV_CMD_REQUEST_MESSAGE).
    RequestMessage {
        /// The MAVLink message id.
        message_id: u32,
    },
}

impl VehicleCommand {
    /// The MAV_CMD the vehicle acknowledges it with.
    pub fn id(&self) -> u16 {
        self.mav_cmd() as u16
    }

    fn mav_cmd(&self) -> MavCmd {
        match self {
            Self::Arm | Self::Disarm => MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            Self::SetMode { .. } => MavCmd::MAV_CMD_DO_SET_MODE,
            Self::Land => MavCmd::MAV_CMD_NAV_LAND,
            Self::StreamInterval { .. } => MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
            Self::RequestMessage { .. } => MavCmd::MAV_CMD_REQUEST_MESSAGE,
        }
    }

    /// Its seven parameters.
    fn params(&self) -> [f32; 7] {
        let nan = f32::NAN;
        match *self {
            Self::Arm => [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            Self::Disarm => [0.0; 7],
            // Base mode MAV_MODE_FLAG_CUSTOM_MODE_ENABLED (1), then PX4's custom mode.
            Self::SetMode { main, sub } => [1.0, main as f32, sub as f32, 0.0, 0.0, 0.0, 0.0],
            // PX4: NaN latitude, longitude, altitude and yaw = here, current heading.
            Self::Land => [0.0, 0.0, 0.0, nan, nan, nan, nan],
            Self::StreamInterval {
                message_id,
                interval_us,
            } => [
                message_id as f32,
                interval_us.unwrap_or(-1.0),
                0.0,
                0.0,
                0.0,
                0.0,
                0.0,
            ],
            Self::RequestMessage { message_id } => {
                [message_id as f32, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
            }
        }
    }
}

/// The COMMAND_LONG for `command` to `target_system`'s autopilot; `confirmation` counts
/// the resends before it (0 for the first).
pub fn command_long(command: &VehicleCommand, target_system: u8, confirmation: u8) -> MavMessage {
    let p = command.params();
    MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
        target_system,
        target_component: 1,
        command: command.mav_cmd(),
        confirmation,
        param1: p[0],
        param2: p[1],
        param3: p[2],
        param4: p[3],
        param5: p[4],
        param6: p[5],
        param7: p[6],
    })
}

/// The dialect's name of MAV_CMD `id` ("MAV_CMD_NAV_LAND"), or "MAV_CMD `id`".
pub fn command_name(id: u16) -> String {
    MavCmd::from_u16(id).map_or_else(|| format!("MAV_CMD {id}"), |c| format!("{c:?}"))
}

/// The dialect's name of MAV_RESULT `result` without its prefix ("DENIED"), or
/// "MAV_RESULT `result`".
pub fn result_name(result: u8) -> String {
    MavResult::from_u8(result).map_or_else(
        || format!("MAV_RESULT {result}"),
        |r| {
            let name = format!("{r:?}");
            name.strip_prefix("MAV_RESULT_").unwrap_or(&name).to_owned()
        },
    )
}

/// The dialect's name of MAV_MISSION_RESULT `result` ("MAV_MISSION_NO_SPACE"), or
/// "MAV_MISSION_RESULT `result`".
pub fn mission_result_name(result: u8) -> String {
    MavMissionResult::from_u8(result).map_or_else(
        || format!("MAV_MISSION_RESULT {result}"),
        |r| format!("{r:?}"),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_come_from_the_dialect() {
        assert_eq!(command_name(21), "MAV_CMD_NAV_LAND");
        assert_eq!(command_name(176), "MAV_CMD_DO_SET_MODE");
        assert_eq!(command_name(511), "MAV_CMD_SET_MESSAGE_INTERVAL");
        assert_eq!(command_name(65_000), "MAV_CMD 65000");
        assert_eq!(result_name(0), "ACCEPTED");
        assert_eq!(result_name(2), "DENIED");
        assert_eq!(result_name(6), "CANCELLED");
        assert_eq!(result_name(200), "MAV_RESULT 200");
        assert_eq!(mission_result_name(4), "MAV_MISSION_NO_SPACE");
        assert_eq!(mission_result_name(13), "MAV_MISSION_INVALID_SEQUENCE");
        assert_eq!(mission_result_name(99), "MAV_MISSION_RESULT 99");
    }

    #[test]
    fn each_command_is_the_command_long_px4_reads() {
        let msg = command_long(&VehicleCommand::SetMode { main: 6, sub: 3 }, 7, 2);
        let MavMessage::COMMAND_LONG(c) = msg else {
            panic!("{msg:?}")
        };
        assert_eq!(
            (c.target_system, c.target_component, c.confirmation),
            (7, 1, 2)
        );
        assert_eq!(c.command, MavCmd::MAV_CMD_DO_SET_MODE);
        assert_eq!([c.param1, c.param2, c.param3], [1.0, 6.0, 3.0]);
        let MavMessage::COMMAND_LONG(c) = command_long(&VehicleCommand::Land, 1, 0) else {
            panic!()
        };
        assert_eq!(c.command as u16, VehicleCommand::Land.id());
        assert!(c.param4.is_nan() && c.param5.is_nan() && c.param7.is_nan());
        let off = VehicleCommand::StreamInterval {
            message_id: 30,
            interval_us: None,
        };
        let MavMessage::COMMAND_LONG(c) = command_long(&off, 1, 0) else {
            panic!()
        };
        assert_eq!((c.param1, c.param2), (30.0, -1.0));
        let MavMessage::COMMAND_LONG(c) = command_long(&VehicleCommand::Disarm, 1, 0) else {
            panic!()
        };
        assert_eq!((c.command as u16, c.param1), (400, 0.0));
    }
}
