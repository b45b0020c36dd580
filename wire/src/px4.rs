//! PX4's numbers on the wire, shared by the coordinator and the emulator: the
//! `custom_mode` encoding of its flight modes (main mode in bits 16–23, sub mode in
//! 24–31, as pymavlink, MAVSDK and QGC decode them when the heartbeat says
//! `autopilot = PX4`) and the UDP ports of PX4 SITL instance `i`.

/// Main mode MANUAL.
pub const MAIN_MANUAL: u32 = 1;
/// Main mode ALTCTL.
pub const MAIN_ALTCTL: u32 = 2;
/// Main mode POSCTL (sub mode 1: ORBIT).
pub const MAIN_POSCTL: u32 = 3;
/// Main mode AUTO (the sub modes below).
pub const MAIN_AUTO: u32 = 4;
/// Main mode ACRO.
pub const MAIN_ACRO: u32 = 5;
/// Main mode OFFBOARD.
pub const MAIN_OFFBOARD: u32 = 6;
/// Main mode STABILIZED.
pub const MAIN_STABILIZED: u32 = 7;
/// POSCTL sub mode ORBIT.
pub const SUB_POSCTL_ORBIT: u32 = 1;
/// AUTO sub mode TAKEOFF.
pub const SUB_AUTO_TAKEOFF: u32 = 2;
/// AUTO sub mode LOITER (Hold).
pub const SUB_AUTO_LOITER: u32 = 3;
/// AUTO sub mode MISSION.
pub const SUB_AUTO_MISSION: u32 = 4;
/// AUTO sub mode RTL (Return).
pub const SUB_AUTO_RTL: u32 = 5;
/// AUTO sub mode LAND.
pub const SUB_AUTO_LAND: u32 = 6;

/// The `custom_mode` of a main and sub mode.
pub fn custom_mode(main: u32, sub: u32) -> u32 {
    ((main & 0xFF) << 16) | ((sub & 0xFF) << 24)
}

/// The main mode of a `custom_mode`.
pub fn main_mode(custom_mode: u32) -> u32 {
    (custom_mode >> 16) & 0xFF
}

/// The sub mode of a `custom_mode`.
pub fn sub_mode(custom_mode: u32) -> u32 {
    (custom_mode >> 24) & 0xFF
}

/// PX4's name for a `custom_mode` (`OFFBOARD`, `AUTO.LOITER`, `POSCTL.ORBIT`, …).
pub fn mode_name(custom_mode: u32) -> String {
    let (main, sub) = (main_mode(custom_mode), sub_mode(custom_mode));
    let auto = [
        "AUTO",
        "AUTO.READY",
        "AUTO.TAKEOFF",
        "AUTO.LOITER",
        "AUTO.MISSION",
        "AUTO.RTL",
        "AUTO.LAND",
        "AUTO.RTGS",
        "AUTO.FOLLOW_TARGET",
        "AUTO.PRECLAND",
        "AUTO.VTOL_TAKEOFF",
    ];
    match main {
        MAIN_MANUAL => "MANUAL".to_owned(),
        MAIN_ALTCTL => "ALTCTL".to_owned(),
        MAIN_POSCTL if sub == SUB_POSCTL_ORBIT => "POSCTL.ORBIT".to_owned(),
        MAIN_POSCTL => "POSCTL".to_owned(),
        MAIN_AUTO => auto
            .get(sub as usize)
            .map_or_else(|| format!("AUTO.{sub}"), |s| (*s).to_owned()),
        MAIN_ACRO => "ACRO".to_owned(),
        MAIN_OFFBOARD => "OFFBOARD".to_owned(),
        MAIN_STABILIZED => "STABILIZED".to_owned(),
        8 => "RATTITUDE".to_owned(),
        other => format!("PX4 main mode {other}"),
    }
}

/// PX4 SITL instance `i` listens for its offboard link on this port + i.
pub const OFFBOARD_LISTEN_PORT: u16 = 14580;
/// … and sends its offboard link to this port + i (where MAVSDK and ringswarm bind).
pub const OFFBOARD_PEER_PORT: u16 = 14540;
/// PX4 SITL instance `i` listens for its GCS link on this port + i.
pub const GCS_LISTEN_PORT: u16 = 18570;
/// … and sends its GCS link to this port (QGroundControl's).
pub const GCS_PEER_PORT: u16 = 14550;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn modes_encode_and_name_as_px4_does() {
        assert_eq!(custom_mode(MAIN_OFFBOARD, 0), 0x0006_0000);
        assert_eq!(custom_mode(MAIN_AUTO, SUB_AUTO_LOITER), 0x0304_0000);
        assert_eq!(custom_mode(MAIN_AUTO, SUB_AUTO_LAND), 0x0604_0000);
        assert_eq!(main_mode(0x0604_0000), MAIN_AUTO);
        assert_eq!(sub_mode(0x0604_0000), SUB_AUTO_LAND);
        assert_eq!(mode_name(0x0304_0000), "AUTO.LOITER");
        assert_eq!(
            mode_name(custom_mode(MAIN_POSCTL, SUB_POSCTL_ORBIT)),
            "POSCTL.ORBIT"
        );
        assert_eq!(mode_name(custom_mode(9, 0)), "PX4 main mode 9");
    }
}
