//! Each autopilot's dialect on the wire: which mode the coordinator flies a vehicle in
//! and which it hands it to, how its modes are numbered and named, in which order it is
//! armed and switched, which streams must be asked for, what its parameters are called
//! and how the law's thrust is written for it. The vehicle machine asks these questions
//! of the vehicle's [`Autopilot`] and never branches on it itself.
//!
//! | | PX4 | ArduPilot (ArduCopter) |
//! |---|---|---|
//! | flown in | OFFBOARD (main 6) | GUIDED (4); GUIDED_NOGPS (20) also counts |
//! | handed to | AUTO.LOITER (Hold) | BRAKE (17): holds on its own estimate, pilot input ignored |
//! | lands in | AUTO.LAND | LAND (9), disarms itself on touchdown |
//! | order | stream, arm, OFFBOARD (needs the stream) | stream, GUIDED (any mode is taken disarmed), arm |
//! | streams | its onboard link streams; the unread ones are turned off | none until asked: each one the coordinator reads is asked for |
//! | thrust | collective 0..1 | with GUID_OPTIONS bit 3 a throttle 0..1 (hover MOT_THST_HOVER) that ArduPilot multiplies by 1/cos(tilt) while ATC_ANGLE_BOOST = 1 |

use ringswarm_wire::{ardupilot, px4};

use super::command::VehicleCommand;
use crate::control::AttitudeThrust;

/// The autopilot a vehicle runs, as its HEARTBEAT says.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Autopilot {
    /// PX4 (MAV_AUTOPILOT_PX4, 12).
    Px4,
    /// ArduPilot's ArduCopter (MAV_AUTOPILOT_ARDUPILOTMEGA, 3).
    ArduPilot,
}

/// The autopilot a vehicle is configured to run (`[[vehicle]] autopilot`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum AutopilotChoice {
    /// Whatever the first HEARTBEAT says (PX4 or ArduPilot).
    #[default]
    Auto,
    /// Only this one: a vehicle whose HEARTBEAT says otherwise is refused by name.
    Only(Autopilot),
}

impl AutopilotChoice {
    /// Parses the configuration's word (`auto`, `px4`, `ardupilot`).
    ///
    /// # Errors
    /// Any other word, named.
    pub fn parse(word: &str) -> Result<Self, String> {
        match word {
            "auto" => Ok(Self::Auto),
            "px4" => Ok(Self::Only(Autopilot::Px4)),
            "ardupilot" => Ok(Self::Only(Autopilot::ArduPilot)),
            other => Err(format!(
                "autopilot = \"{other}\" is not one of \"auto\", \"px4\", \"ardupilot\""
            )),
        }
    }
}

/// What the handshake does with one parameter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ParamAction {
    /// Read it.
    Read,
    /// Set it to this value.
    Set(f32),
    /// Set these bits of it (an integer bit mask), keeping the others.
    SetBits(u32),
    /// Set it to `value` only if `flag`, read in an earlier step, is not 0.
    SetIfOn {
        /// The value.
        value: f32,
        /// The flag (read before).
        flag: ardupilot::ParamName,
    },
}

/// One parameter the handshake reads or writes, by its names.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ParamStep {
    /// Its names.
    pub param: ardupilot::ParamName,
    /// What to do.
    pub action: ParamAction,
}

/// MAV_CMD_SET_MESSAGE_INTERVAL period of a stream.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum StreamRate {
    /// Every telemetry interval (positions).
    Telemetry,
    /// Every attitude interval.
    Attitude,
    /// This many µs.
    Fixed(f32),
    /// Off (−1).
    Off,
}

/// LOCAL_POSITION_NED, ATTITUDE_QUATERNION, SYS_STATUS and EXTENDED_SYS_STATE.
const LOCAL_POSITION_NED: u32 = 32;
const ATTITUDE_QUATERNION: u32 = 31;
const SYS_STATUS: u32 = 1;
const EXTENDED_SYS_STATE: u32 = 245;

/// Streams of PX4's onboard link (`mavlink_main.cpp`, MAVLINK_MODE_ONBOARD) the
/// coordinator does not read, turned off on its link (interval −1): every one of them is
/// a datagram the vehicle sends and the coordinator parses for nothing, and together they
/// are most of what a large swarm would send it. ATTITUDE (100 Hz on PX4's onboard link)
/// and GLOBAL_POSITION_INT (50) first, then HIGHRES_IMU (50), ODOMETRY (30), RC_CHANNELS
/// (20), the 10 Hz ones (ALTITUDE, DISTANCE_SENSOR, ATTITUDE_TARGET, SERVO_OUTPUT_RAW,
/// VFR_HUD, POSITION_TARGET_LOCAL_NED and _GLOBAL_INT, NAV_CONTROLLER_OUTPUT), and
/// SYS_STATUS, GPS_RAW_INT, BATTERY_STATUS, HOME_POSITION. A stream the autopilot does
/// not have is refused harmlessly; a ground station on another link keeps its own.
const PX4_UNREAD_STREAMS: [u32; 17] = [
    30, 33, 105, 331, 65, 141, 132, 83, 36, 74, 85, 87, 62, 1, 24, 147, 242,
];

/// What the coordinator asks of ArduPilot: positions and attitude at its rates, the
/// landed state at 5 Hz (the landing's end) and SYS_STATUS at 2 Hz (its pre-arm bit
/// says when the EKF is ready to arm).
const ARDUPILOT_STREAMS: [(u32, StreamRate); 4] = [
    (LOCAL_POSITION_NED, StreamRate::Telemetry),
    (ATTITUDE_QUATERNION, StreamRate::Attitude),
    (EXTENDED_SYS_STATE, StreamRate::Fixed(200_000.0)),
    (SYS_STATUS, StreamRate::Fixed(500_000.0)),
];

impl Autopilot {
    /// The autopilot a HEARTBEAT's `autopilot` field names, if the coordinator speaks it.
    pub fn from_heartbeat(mav_autopilot: u8) -> Option<Self> {
        match mav_autopilot {
            super::convert::AUTOPILOT_PX4 => Some(Self::Px4),
            ardupilot::AUTOPILOT => Some(Self::ArduPilot),
            _ => None,
        }
    }

    /// Its name in messages (`PX4`, `ArduPilot`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Px4 => "PX4",
            Self::ArduPilot => "ArduPilot",
        }
    }

    /// Its word in files and the configuration (`px4`, `ardupilot`).
    pub fn key(self) -> &'static str {
        match self {
            Self::Px4 => "px4",
            Self::ArduPilot => "ardupilot",
        }
    }

    /// The mode the coordinator flies it in.
    pub fn fly_mode(self) -> VehicleCommand {
        match self {
            Self::Px4 => VehicleCommand::SetMode {
                main: px4::MAIN_OFFBOARD,
                sub: 0,
            },
            Self::ArduPilot => VehicleCommand::SetMode {
                main: ardupilot::GUIDED,
                sub: 0,
            },
        }
    }

    /// The fly mode's name (`OFFBOARD`, `GUIDED`).
    pub fn fly_mode_name(self) -> &'static str {
        match self {
            Self::Px4 => "OFFBOARD",
            Self::ArduPilot => "GUIDED",
        }
    }

    /// How long after its last setpoint the vehicle's own failsafe takes over and brakes
    /// (s), with the autopilot's defaults: PX4 leaves OFFBOARD after COM_OF_LOSS_T (1 s)
    /// for COM_OBL_RC_ACT (Position by default, Hold without a radio). `None` for
    /// ArduPilot: after GUID_TIMEOUT it levels and drifts in GUIDED, and nothing brakes
    /// it but a mode change (its GCS failsafe is off by default).
    pub fn setpoint_loss_brakes_after_s(self) -> Option<f64> {
        match self {
            Self::Px4 => Some(1.0),
            Self::ArduPilot => None,
        }
    }

    /// How long it goes on flying the last setpoint it got when no new one comes (s), by
    /// the values its handshake read: PX4 until its offboard loss failsafe
    /// (COM_OF_LOSS_T, 1 s by default; [`Self::setpoint_loss_brakes_after_s`]); ArduPilot
    /// until GUID_TIMEOUT (3 s by default, at least 0.1 s as it applies it; read), after
    /// which it levels and drifts ([`Self::levels_after_setpoint_loss`]).
    pub fn setpoint_held_s(self, read: impl Fn(&ardupilot::ParamName) -> Option<f32>) -> f64 {
        match self {
            Self::Px4 => 1.0,
            Self::ArduPilot => read(&ardupilot::GUID_TIMEOUT)
                .map(f64::from)
                .filter(|t| t.is_finite())
                .unwrap_or(3.0)
                .max(0.1),
        }
    }

    /// Whether, once its setpoints stop for [`Self::setpoint_held_s`], it levels and
    /// drifts in its fly mode, slowed by its drag alone (ArduPilot, which has no
    /// horizontal hold in GUIDED's angle sub-mode), rather than braking in a failsafe.
    pub fn levels_after_setpoint_loss(self) -> bool {
        self == Self::ArduPilot
    }

    /// The mode it is handed to when it cannot be flown on: it brakes and holds on its
    /// own estimate.
    pub fn hold_mode(self) -> VehicleCommand {
        match self {
            Self::Px4 => VehicleCommand::SetMode {
                main: px4::MAIN_AUTO,
                sub: px4::SUB_AUTO_LOITER,
            },
            Self::ArduPilot => VehicleCommand::SetMode {
                main: ardupilot::BRAKE,
                sub: 0,
            },
        }
    }

    /// Whether the fly mode is taken before arming (ArduPilot: any mode is accepted
    /// disarmed, and arming in GUIDED skips the throttle check) rather than after (PX4:
    /// OFFBOARD is taken armed, on a running setpoint stream).
    pub fn mode_before_arming(self) -> bool {
        self == Self::ArduPilot
    }

    /// Whether `custom_mode` is a mode in which it flies our setpoints.
    pub fn in_fly_mode(self, custom_mode: u32) -> bool {
        match self {
            Self::Px4 => px4::main_mode(custom_mode) == px4::MAIN_OFFBOARD,
            Self::ArduPilot => {
                custom_mode == ardupilot::GUIDED || custom_mode == ardupilot::GUIDED_NOGPS
            }
        }
    }

    /// Whether `custom_mode` is the hold mode it is handed to.
    pub fn in_hold(self, custom_mode: u32) -> bool {
        match self {
            Self::Px4 => {
                px4::main_mode(custom_mode) == px4::MAIN_AUTO
                    && px4::sub_mode(custom_mode) == px4::SUB_AUTO_LOITER
            }
            Self::ArduPilot => custom_mode == ardupilot::BRAKE,
        }
    }

    /// Whether `custom_mode` is its landing mode.
    pub fn in_land(self, custom_mode: u32) -> bool {
        match self {
            Self::Px4 => {
                px4::main_mode(custom_mode) == px4::MAIN_AUTO
                    && px4::sub_mode(custom_mode) == px4::SUB_AUTO_LAND
            }
            Self::ArduPilot => custom_mode == ardupilot::LAND,
        }
    }

    /// Its name for `custom_mode`.
    pub fn mode_name(self, custom_mode: u32) -> String {
        match self {
            Self::Px4 => px4::mode_name(custom_mode),
            Self::ArduPilot => ardupilot::mode_name(custom_mode),
        }
    }

    /// The stream intervals the link asks for when it starts streaming.
    pub fn streams(self) -> Vec<(u32, StreamRate)> {
        match self {
            Self::Px4 => [
                (LOCAL_POSITION_NED, StreamRate::Telemetry),
                (ATTITUDE_QUATERNION, StreamRate::Attitude),
            ]
            .into_iter()
            .chain(PX4_UNREAD_STREAMS.map(|id| (id, StreamRate::Off)))
            .collect(),
            Self::ArduPilot => ARDUPILOT_STREAMS.to_vec(),
        }
    }

    /// The parameters its handshake reads and writes, in order, for a coordinator of
    /// system id `own_system_id`. ArduPilot: its hover throttle and angle boost read (the
    /// thrust written for it depends on both), GUID_OPTIONS bit 3 set (thrust as a
    /// throttle, not a climb rate), and, only when its GCS failsafe is on (FS_GCS_ENABLE),
    /// MAV_GCS_SYSID made the coordinator's so that the failsafe watches the coordinator's
    /// heartbeat (left alone otherwise: it also decides whose MANUAL_CONTROL and RC
    /// overrides the vehicle takes, an operator's ground station's). What is written is
    /// put back at the end of the flight. With a fence to give (`fenced`), its geofence is
    /// switched on for the uploaded polygons and circles alone (FENCE_TYPE 4,
    /// FENCE_ENABLE 1): ArduPilot keeps an uploaded fence but acts on it only then. PX4:
    /// none (its geofence acts on an uploaded fence by GF_ACTION).
    pub fn setup_params(self, own_system_id: u8, fenced: bool) -> Vec<ParamStep> {
        match self {
            Self::Px4 => Vec::new(),
            Self::ArduPilot => {
                let mut steps = ardupilot_guided_params(own_system_id);
                if fenced {
                    steps.extend([
                        // The uploaded fence only: bits 1 and 2 (FENCE_TYPE's default 7)
                        // would add a 100 m altitude ceiling and a circle of FENCE_RADIUS
                        // (150 m in SITL) about home, which a cruising swarm leaves.
                        ParamStep {
                            param: ardupilot::FENCE_TYPE,
                            action: ParamAction::Set(ardupilot::FENCE_TYPE_POLYGON as f32),
                        },
                        ParamStep {
                            param: ardupilot::FENCE_ENABLE,
                            action: ParamAction::Set(1.0),
                        },
                    ]);
                }
                steps
            }
        }
    }

    /// The hover throttle it reports among the values its handshake read (0..1), if any.
    pub fn reported_hover(
        self,
        read: impl Fn(&ardupilot::ParamName) -> Option<f32>,
    ) -> Option<f64> {
        match self {
            Self::Px4 => None,
            Self::ArduPilot => read(&ardupilot::MOT_THST_HOVER)
                .map(f64::from)
                .filter(|h| *h > 0.0 && *h < 1.0),
        }
    }

    /// Whether it multiplies the thrust it is sent by 1/cos(tilt), by the values its
    /// handshake read (ArduPilot's ATC_ANGLE_BOOST, 1 when unread: its default).
    pub fn angle_boost(self, read: impl Fn(&ardupilot::ParamName) -> Option<f32>) -> bool {
        match self {
            Self::Px4 => false,
            Self::ArduPilot => read(&ardupilot::ATC_ANGLE_BOOST).is_none_or(|v| v != 0.0),
        }
    }

    /// Whether it says when it is ready to arm (SYS_STATUS's pre-arm health bit), so the
    /// link waits for that instead of arming into a refusal.
    pub fn reports_prearm(self) -> bool {
        self == Self::ArduPilot
    }

    /// The `thrust` field of SET_ATTITUDE_TARGET for the law's setpoint. PX4 reads the
    /// collective thrust along the body axis. ArduPilot (thrust as throttle) multiplies
    /// what it gets by 1/cos(tilt of the target) while `angle_boost` (ATC_ANGLE_BOOST),
    /// so it is sent the vertical share, which its boost turns back into the collective.
    pub fn thrust_field(self, setpoint: &AttitudeThrust, angle_boost: bool) -> f64 {
        let thrust = setpoint.thrust_norm;
        match self {
            Self::Px4 => thrust,
            Self::ArduPilot if angle_boost => {
                // The body z axis in NED is R·(0, 0, 1); its down component is the
                // cosine of the tilt. ArduPilot floors the cosine at 0.1.
                let q = setpoint.attitude_ned_frd;
                let cos_tilt = (q * nalgebra::Vector3::z()).z.clamp(0.1, 1.0);
                thrust * cos_tilt
            }
            Self::ArduPilot => thrust,
        }
    }
}

/// ArduPilot's parameters for guided attitude control and its ground station.
fn ardupilot_guided_params(own_system_id: u8) -> Vec<ParamStep> {
    vec![
        ParamStep {
            param: ardupilot::MOT_THST_HOVER,
            action: ParamAction::Read,
        },
        ParamStep {
            param: ardupilot::ATC_ANGLE_BOOST,
            action: ParamAction::Read,
        },
        ParamStep {
            param: ardupilot::GUID_TIMEOUT,
            action: ParamAction::Read,
        },
        ParamStep {
            param: ardupilot::GUID_OPTIONS,
            action: ParamAction::SetBits(ardupilot::GUID_OPTIONS_THRUST_AS_THRUST),
        },
        ParamStep {
            param: ardupilot::FS_GCS_ENABLE,
            action: ParamAction::Read,
        },
        ParamStep {
            param: ardupilot::MAV_GCS_SYSID,
            action: ParamAction::SetIfOn {
                value: f32::from(own_system_id),
                flag: ardupilot::FS_GCS_ENABLE,
            },
        },
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::UnitQuaternion;

    #[test]
    fn modes_are_each_autopilots_own() {
        let (px4, ap) = (Autopilot::Px4, Autopilot::ArduPilot);
        assert!(px4.in_fly_mode(px4::custom_mode(px4::MAIN_OFFBOARD, 0)));
        assert!(!px4.in_fly_mode(4));
        assert!(ap.in_fly_mode(4) && ap.in_fly_mode(20) && !ap.in_fly_mode(5));
        assert!(ap.in_hold(17) && !ap.in_hold(5));
        assert!(ap.in_land(9) && !ap.in_land(px4::custom_mode(4, 6)));
        assert!(px4.in_land(px4::custom_mode(4, 6)));
        assert_eq!(ap.mode_name(20), "GUIDED_NOGPS");
        assert_eq!(px4.mode_name(px4::custom_mode(4, 3)), "AUTO.LOITER");
        assert_eq!(ap.fly_mode(), VehicleCommand::SetMode { main: 4, sub: 0 });
        assert_eq!(ap.hold_mode(), VehicleCommand::SetMode { main: 17, sub: 0 });
        assert_eq!(Autopilot::from_heartbeat(3), Some(ap));
        assert_eq!(Autopilot::from_heartbeat(12), Some(px4));
        assert_eq!(Autopilot::from_heartbeat(0), None);
    }

    #[test]
    fn ardupilot_sets_its_guided_thrust_and_ground_station_and_its_fence_when_fenced() {
        let names = |steps: Vec<ParamStep>| -> Vec<(&str, ParamAction)> {
            steps.iter().map(|s| (s.param.current, s.action)).collect()
        };
        let guided = [
            ("MOT_THST_HOVER", ParamAction::Read),
            ("ATC_ANGLE_BOOST", ParamAction::Read),
            ("GUID_TIMEOUT", ParamAction::Read),
            ("GUID_OPTIONS", ParamAction::SetBits(8)),
            ("FS_GCS_ENABLE", ParamAction::Read),
            (
                "MAV_GCS_SYSID",
                ParamAction::SetIfOn {
                    value: 253.0,
                    flag: ringswarm_wire::ardupilot::FS_GCS_ENABLE,
                },
            ),
        ];
        assert_eq!(names(Autopilot::ArduPilot.setup_params(253, false)), guided);
        let fenced = names(Autopilot::ArduPilot.setup_params(253, true));
        assert_eq!(fenced[..6], guided);
        assert_eq!(
            fenced[6..],
            [
                ("FENCE_TYPE", ParamAction::Set(4.0)),
                ("FENCE_ENABLE", ParamAction::Set(1.0))
            ]
        );
        assert!(Autopilot::Px4.setup_params(253, true).is_empty());
    }

    #[test]
    fn the_choice_is_parsed_by_name() {
        assert_eq!(AutopilotChoice::parse("auto"), Ok(AutopilotChoice::Auto));
        assert_eq!(
            AutopilotChoice::parse("ardupilot"),
            Ok(AutopilotChoice::Only(Autopilot::ArduPilot))
        );
        let err = AutopilotChoice::parse("apm").unwrap_err();
        assert!(
            err.contains("\"apm\"") && err.contains("\"ardupilot\""),
            "{err}"
        );
    }

    #[test]
    fn ardupilot_is_sent_the_vertical_share_its_angle_boost_restores() {
        // 30° of pitch: ArduPilot multiplies the throttle by 1/cos 30°.
        let tilt = 30f64.to_radians();
        let sp = AttitudeThrust {
            attitude_ned_frd: UnitQuaternion::from_euler_angles(0.0, tilt, 0.0),
            thrust_norm: 0.6,
            thrust_n: 0.0,
        };
        let sent = Autopilot::ArduPilot.thrust_field(&sp, true);
        assert!((sent - 0.6 * tilt.cos()).abs() < 1e-12, "{sent}");
        assert!((sent / tilt.cos() - 0.6).abs() < 1e-12);
        assert_eq!(Autopilot::ArduPilot.thrust_field(&sp, false), 0.6);
        assert_eq!(Autopilot::Px4.thrust_field(&sp, true), 0.6);
        // Rolled and pitched: the cosine of the whole tilt is cos(roll)·cos(pitch).
        let sp = AttitudeThrust {
            attitude_ned_frd: UnitQuaternion::from_euler_angles(0.2, 0.3, 1.0),
            ..sp
        };
        let sent = Autopilot::ArduPilot.thrust_field(&sp, true);
        assert!((sent - 0.6 * 0.2f64.cos() * 0.3f64.cos()).abs() < 1e-12);
    }

    #[test]
    fn ardupilot_is_asked_for_every_stream_px4_has_its_unread_ones_turned_off() {
        let ap = Autopilot::ArduPilot.streams();
        assert!(ap.iter().all(|(_, rate)| *rate != StreamRate::Off));
        let ids: Vec<u32> = ap.iter().map(|(id, _)| *id).collect();
        assert_eq!(ids, [32, 31, 245, 1]);
        let px4 = Autopilot::Px4.streams();
        assert_eq!(px4.len(), 19);
        assert_eq!(
            px4.iter().filter(|(_, r)| *r == StreamRate::Off).count(),
            17
        );
    }
}
