//! ArduPilot's (ArduCopter's) numbers on the wire, shared by the coordinator and the
//! emulator: its flight modes (HEARTBEAT `custom_mode` is the plain mode number,
//! `ArduCopter/mode.h`), the base mode it reports, and the names of the parameters a
//! ground station reads and writes in both spellings (Copter 4.7 renamed the MAVLink ones).

/// MAV_AUTOPILOT_ARDUPILOTMEGA: the HEARTBEAT `autopilot` of every ArduPilot vehicle.
pub const AUTOPILOT: u8 = 3;

/// STABILIZE (the mode ArduCopter boots in).
pub const STABILIZE: u32 = 0;
/// ALT_HOLD.
pub const ALT_HOLD: u32 = 2;
/// AUTO.
pub const AUTO: u32 = 3;
/// GUIDED: takes SET_ATTITUDE_TARGET (and position, velocity targets); arming in it needs
/// a position estimate.
pub const GUIDED: u32 = 4;
/// LOITER.
pub const LOITER: u32 = 5;
/// RTL.
pub const RTL: u32 = 6;
/// LAND: descends where it is and disarms itself on touchdown.
pub const LAND: u32 = 9;
/// BRAKE: stops and holds its position on its own estimate, pilot input ignored.
pub const BRAKE: u32 = 17;
/// GUIDED_NOGPS: SET_ATTITUDE_TARGET only.
pub const GUIDED_NOGPS: u32 = 20;

/// HEARTBEAT `base_mode` bits ArduCopter always sets: CUSTOM_MODE_ENABLED (1),
/// STABILIZE_ENABLED (16), MANUAL_INPUT_ENABLED (64) = 81; SAFETY_ARMED (128) is added
/// when armed (209).
pub const BASE_MODE: u8 = 81;

/// GUID_OPTIONS bit 3: SET_ATTITUDE_TARGET's `thrust` is a throttle, not a climb rate.
pub const GUID_OPTIONS_THRUST_AS_THRUST: u32 = 8;

/// ArduCopter's name for a mode number (`GUIDED`, `LAND`, …).
pub fn mode_name(custom_mode: u32) -> String {
    let names = [
        "STABILIZE",
        "ACRO",
        "ALT_HOLD",
        "AUTO",
        "GUIDED",
        "LOITER",
        "RTL",
        "CIRCLE",
        "",
        "LAND",
        "",
        "DRIFT",
        "",
        "SPORT",
        "FLIP",
        "AUTOTUNE",
        "POSHOLD",
        "BRAKE",
        "THROW",
        "AVOID_ADSB",
        "GUIDED_NOGPS",
        "SMART_RTL",
        "FLOWHOLD",
        "FOLLOW",
        "ZIGZAG",
        "SYSTEMID",
        "AUTOROTATE",
        "AUTO_RTL",
        "TURTLE",
    ];
    match names.get(custom_mode as usize) {
        Some(name) if !name.is_empty() => (*name).to_owned(),
        _ => format!("ArduCopter mode {custom_mode}"),
    }
}

/// A parameter as ArduPilot names it: the current name first, then the one Copter 4.6
/// and older use (the same where nothing was renamed).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ParamName {
    /// Copter 4.7's name.
    pub current: &'static str,
    /// Copter 4.6's name.
    pub legacy: &'static str,
}

impl ParamName {
    /// A parameter Copter 4.7 did not rename.
    pub const fn unrenamed(name: &'static str) -> Self {
        Self {
            current: name,
            legacy: name,
        }
    }

    /// Both spellings, the current one first (one when they are the same).
    pub fn spellings(&self) -> impl Iterator<Item = &'static str> {
        let legacy = (self.legacy != self.current).then_some(self.legacy);
        std::iter::once(self.current).chain(legacy)
    }

    /// Whether `name` is one of its spellings.
    pub fn is(&self, name: &str) -> bool {
        name == self.current || name == self.legacy
    }
}

/// The vehicle's own system id.
pub const MAV_SYSID: ParamName = ParamName {
    current: "MAV_SYSID",
    legacy: "SYSID_THISMAV",
};
/// The system id whose traffic its GCS failsafe counts (default 255).
pub const MAV_GCS_SYSID: ParamName = ParamName {
    current: "MAV_GCS_SYSID",
    legacy: "SYSID_MYGCS",
};
/// Whether (and how) the GCS failsafe acts (0: off, the default).
pub const FS_GCS_ENABLE: ParamName = ParamName::unrenamed("FS_GCS_ENABLE");
/// Guided-mode options (bit 3: thrust as thrust).
pub const GUID_OPTIONS: ParamName = ParamName::unrenamed("GUID_OPTIONS");
/// Seconds without a guided setpoint before it levels and holds altitude.
pub const GUID_TIMEOUT: ParamName = ParamName::unrenamed("GUID_TIMEOUT");
/// The learnt hover throttle (0..1).
pub const MOT_THST_HOVER: ParamName = ParamName::unrenamed("MOT_THST_HOVER");
/// Whether a throttle is multiplied by 1/cos(tilt) (1, the default) or not (0).
pub const ATC_ANGLE_BOOST: ParamName = ParamName::unrenamed("ATC_ANGLE_BOOST");
/// Whether the geofence acts (0, 1).
pub const FENCE_ENABLE: ParamName = ParamName::unrenamed("FENCE_ENABLE");
/// Which fences act (bits: 1 altitude max, 2 circle about home, 4 the uploaded polygons
/// and circles, 8 altitude min).
pub const FENCE_TYPE: ParamName = ParamName::unrenamed("FENCE_TYPE");
/// FENCE_TYPE bit 2: the uploaded inclusion polygons and circles.
pub const FENCE_TYPE_POLYGON: u32 = 4;

/// Seconds a landed, idle, armed vehicle waits before it disarms itself.
pub const DISARM_DELAY: ParamName = ParamName::unrenamed("DISARM_DELAY");

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mode_names_are_arducopters() {
        assert_eq!(mode_name(GUIDED), "GUIDED");
        assert_eq!(mode_name(GUIDED_NOGPS), "GUIDED_NOGPS");
        assert_eq!(mode_name(LAND), "LAND");
        assert_eq!(mode_name(BRAKE), "BRAKE");
        assert_eq!(mode_name(8), "ArduCopter mode 8");
        assert_eq!(mode_name(99), "ArduCopter mode 99");
    }

    #[test]
    fn renamed_parameters_have_two_spellings() {
        assert_eq!(
            MAV_GCS_SYSID.spellings().collect::<Vec<_>>(),
            ["MAV_GCS_SYSID", "SYSID_MYGCS"]
        );
        assert_eq!(
            GUID_OPTIONS.spellings().collect::<Vec<_>>(),
            ["GUID_OPTIONS"]
        );
        assert!(MAV_SYSID.is("SYSID_THISMAV") && MAV_SYSID.is("MAV_SYSID"));
        assert!(!MAV_SYSID.is("MAV_GCS_SYSID"));
    }
}
