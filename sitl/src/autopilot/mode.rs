//! PX4 flight modes and their `custom_mode` encoding (main mode in bits 16–23, sub mode
//! in bits 24–31), as pymavlink's `mode_string_v10`, MAVSDK and QGC decode them when the
//! heartbeat says `autopilot = PX4`.

use ringswarm_wire::px4::{
    MAIN_AUTO, MAIN_OFFBOARD, MAIN_POSCTL, SUB_AUTO_LAND as SUB_LAND,
    SUB_AUTO_LOITER as SUB_LOITER, SUB_AUTO_MISSION as SUB_MISSION, SUB_AUTO_RTL as SUB_RTL,
    SUB_AUTO_TAKEOFF as SUB_TAKEOFF, SUB_POSCTL_ORBIT as SUB_ORBIT,
};

/// The modes the emulator flies.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FlightMode {
    /// POSCTL: a pilot holds position, or, for a vehicle started in the air, its velocity.
    Position,
    /// AUTO.TAKEOFF: climb to MIS_TAKEOFF_ALT, then Hold.
    Takeoff,
    /// AUTO.LOITER ("Hold"): hold the position where the mode was entered.
    Hold,
    /// AUTO.LAND: descend at MPC_LAND_SPEED holding the horizontal position.
    Land,
    /// AUTO.MISSION: fly the stored mission.
    Mission,
    /// AUTO.RTL: climb to the return altitude, fly home, land.
    Return,
    /// Orbit (MAV_CMD_DO_ORBIT): circle a point; reported as POSCTL sub mode ORBIT.
    Orbit,
    /// OFFBOARD: track the streamed attitude and thrust setpoints.
    Offboard,
}

impl FlightMode {
    /// The heartbeat's `custom_mode`.
    pub fn custom_mode(self) -> u32 {
        let (main, sub) = match self {
            Self::Position => (MAIN_POSCTL, 0),
            Self::Takeoff => (MAIN_AUTO, SUB_TAKEOFF),
            Self::Hold => (MAIN_AUTO, SUB_LOITER),
            Self::Land => (MAIN_AUTO, SUB_LAND),
            Self::Mission => (MAIN_AUTO, SUB_MISSION),
            Self::Return => (MAIN_AUTO, SUB_RTL),
            Self::Orbit => (MAIN_POSCTL, SUB_ORBIT),
            Self::Offboard => (MAIN_OFFBOARD, 0),
        };
        ringswarm_wire::px4::custom_mode(main, sub)
    }

    /// The mode a DO_SET_MODE / SET_MODE asks for (`main`, `sub` as PX4 numbers); `None`
    /// for modes the emulator does not fly (manual modes need a pilot). An orbit needs its
    /// parameters: only MAV_CMD_DO_ORBIT starts one.
    pub fn from_px4(main: u32, sub: u32) -> Option<Self> {
        match (main, sub) {
            (MAIN_POSCTL, _) => Some(Self::Position),
            (MAIN_AUTO, SUB_TAKEOFF) => Some(Self::Takeoff),
            (MAIN_AUTO, SUB_LOITER) => Some(Self::Hold),
            (MAIN_AUTO, SUB_LAND) => Some(Self::Land),
            (MAIN_AUTO, SUB_MISSION) => Some(Self::Mission),
            (MAIN_AUTO, SUB_RTL) => Some(Self::Return),
            (MAIN_OFFBOARD, _) => Some(Self::Offboard),
            _ => None,
        }
    }

    /// The name pymavlink prints for this mode.
    pub fn name(self) -> &'static str {
        match self {
            Self::Position => "POSCTL",
            Self::Takeoff => "TAKEOFF",
            Self::Hold => "LOITER",
            Self::Land => "LAND",
            Self::Mission => "MISSION",
            Self::Return => "RTL",
            Self::Orbit => "ORBIT",
            Self::Offboard => "OFFBOARD",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn offboard_is_main_mode_six_in_bits_16_to_23() {
        assert_eq!(FlightMode::Offboard.custom_mode(), 0x0006_0000);
        assert_eq!(FlightMode::Hold.custom_mode(), 0x0304_0000);
        assert_eq!(FlightMode::Land.custom_mode(), 0x0604_0000);
    }

    #[test]
    fn decoding_inverts_encoding() {
        for mode in [
            FlightMode::Position,
            FlightMode::Takeoff,
            FlightMode::Hold,
            FlightMode::Land,
            FlightMode::Mission,
            FlightMode::Return,
            FlightMode::Offboard,
        ] {
            let c = mode.custom_mode();
            assert_eq!(FlightMode::from_px4((c >> 16) & 0xFF, c >> 24), Some(mode));
        }
        assert_eq!(FlightMode::from_px4(1, 0), None); // MANUAL
    }
}
