//! One function per message we build, one dispatch for what we read. Each inbound
//! conversion checks its values and returns a domain update; frames we do not use map to
//! `None`.

use mavlink::dialects::common::{
    AttitudeTargetTypemask, HEARTBEAT_DATA, MISSION_COUNT_DATA, MISSION_ITEM_INT_DATA,
    MavAutopilot, MavCmd, MavFrame, MavMessage, MavMissionType, MavModeFlag, MavParamType,
    MavSeverity, MavState, MavSysStatusSensor, MavType, PARAM_REQUEST_READ_DATA, PARAM_SET_DATA,
    PositionTargetTypemask, SET_ATTITUDE_TARGET_DATA, SET_POSITION_TARGET_LOCAL_NED_DATA,
    TIMESYNC_DATA,
};
use nalgebra::{Quaternion, UnitQuaternion, Vector3};

use super::command::{VehicleCommand, command_long};
use super::signer::Signer;
use crate::control::AttitudeThrust;
use crate::frame::Geodetic;
use crate::safety::{FenceItem, FenceItemKind};
use ringswarm_wire::codec::Encoder;

/// What a vehicle link sends, in domain terms: [`encode`] makes its MAVLink frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Outgoing<'a> {
    /// Our ground station's heartbeat.
    Heartbeat,
    /// A TIMESYNC request stamped `ts1_ns`.
    Timesync {
        /// The stamp (ns of the link's clock).
        ts1_ns: i64,
    },
    /// An attitude and thrust setpoint.
    Attitude {
        /// The setpoint.
        setpoint: &'a AttitudeThrust,
        /// The vehicle.
        target_system: u8,
        /// Our clock (ms).
        time_boot_ms: u32,
    },
    /// An acceleration setpoint (m/s², NED).
    Acceleration {
        /// The acceleration.
        accel_ned_mps2: &'a Vector3<f64>,
        /// The vehicle.
        target_system: u8,
        /// Our clock (ms).
        time_boot_ms: u32,
    },
    /// A command; `confirmation` counts its resends before this one.
    Command {
        /// The command.
        command: VehicleCommand,
        /// The vehicle.
        target_system: u8,
        /// Resends before this one.
        confirmation: u8,
    },
    /// The fence's item count (MISSION_COUNT, mission type FENCE).
    FenceCount {
        /// The vehicle.
        target_system: u8,
        /// Items.
        count: u16,
    },
    /// Fence item number `seq`.
    FenceItem {
        /// The vehicle.
        target_system: u8,
        /// Its number.
        seq: u16,
        /// The item.
        item: &'a FenceItem,
    },
    /// PARAM_REQUEST_READ by name.
    ParamRead {
        /// The vehicle.
        target_system: u8,
        /// The parameter's name (at most 16 bytes).
        name: &'a str,
    },
    /// PARAM_SET (the value as a float, as ArduPilot reads it).
    ParamSet {
        /// The vehicle.
        target_system: u8,
        /// The parameter's name (at most 16 bytes).
        name: &'a str,
        /// Its new value.
        value: f32,
    },
}

impl Outgoing<'_> {
    /// The MAVLink message.
    pub fn message(&self) -> MavMessage {
        match *self {
            Self::Heartbeat => gcs_heartbeat(),
            Self::Timesync { ts1_ns } => timesync_request(ts1_ns),
            Self::Attitude {
                setpoint,
                target_system,
                time_boot_ms,
            } => set_attitude_target(setpoint, target_system, time_boot_ms),
            Self::Acceleration {
                accel_ned_mps2,
                target_system,
                time_boot_ms,
            } => set_position_target_acceleration(accel_ned_mps2, target_system, time_boot_ms),
            Self::Command {
                command,
                target_system,
                confirmation,
            } => command_long(&command, target_system, confirmation),
            Self::FenceCount {
                target_system,
                count,
            } => fence_count(target_system, count),
            Self::FenceItem {
                target_system,
                seq,
                item,
            } => fence_item(target_system, seq, item),
            Self::ParamRead {
                target_system,
                name,
            } => param_request_read(target_system, name),
            Self::ParamSet {
                target_system,
                name,
                value,
            } => param_set(target_system, name, value),
        }
    }
}

/// A parameter name as the 16-byte field carries it (NUL-padded; a 16-byte name has no
/// terminator). Longer names are cut, which no parameter the coordinator uses needs.
fn param_id(name: &str) -> [u8; 16] {
    let mut id = [0u8; 16];
    let bytes = name.as_bytes();
    let n = bytes.len().min(16);
    id[..n].copy_from_slice(&bytes[..n]);
    id
}

/// PARAM_REQUEST_READ of `name` (index −1: by name) from `target_system`'s autopilot.
pub fn param_request_read(target_system: u8, name: &str) -> MavMessage {
    MavMessage::PARAM_REQUEST_READ(PARAM_REQUEST_READ_DATA {
        param_index: -1,
        target_system,
        target_component: 1,
        param_id: param_id(name).into(),
    })
}

/// PARAM_SET of `name` to `value`, typed REAL32: ArduPilot casts the float to the
/// parameter's own type (an integer parameter is sent as its value as a float).
pub fn param_set(target_system: u8, name: &str, value: f32) -> MavMessage {
    MavMessage::PARAM_SET(PARAM_SET_DATA {
        param_value: value,
        target_system,
        target_component: 1,
        param_id: param_id(name).into(),
        param_type: MavParamType::MAV_PARAM_TYPE_REAL32,
    })
}

/// Appends `out`'s frame to `bytes`: from `encoder`'s ids and sequence, signed by `signer`
/// when the link signs.
pub fn encode(
    encoder: &mut Encoder,
    signer: Option<&mut Signer>,
    out: &Outgoing<'_>,
    bytes: &mut Vec<u8>,
) {
    let msg = out.message();
    match signer {
        Some(signer) => signer.encode_into(encoder, &msg, bytes),
        None => encoder.encode_into(&msg, None, bytes),
    }
}

/// SET_ATTITUDE_TARGET with attitude and thrust, body rates ignored (type_mask 7).
pub fn set_attitude_target(
    sp: &AttitudeThrust,
    target_system: u8,
    time_boot_ms: u32,
) -> MavMessage {
    let q = sp.attitude_ned_frd;
    MavMessage::SET_ATTITUDE_TARGET(SET_ATTITUDE_TARGET_DATA {
        time_boot_ms,
        q: [q.w as f32, q.i as f32, q.j as f32, q.k as f32],
        body_roll_rate: 0.0,
        body_pitch_rate: 0.0,
        body_yaw_rate: 0.0,
        thrust: sp.thrust_norm.clamp(0.0, 1.0) as f32,
        target_system,
        target_component: 1,
        type_mask: AttitudeTargetTypemask::ATTITUDE_TARGET_TYPEMASK_BODY_ROLL_RATE_IGNORE
            | AttitudeTargetTypemask::ATTITUDE_TARGET_TYPEMASK_BODY_PITCH_RATE_IGNORE
            | AttitudeTargetTypemask::ATTITUDE_TARGET_TYPEMASK_BODY_YAW_RATE_IGNORE,
        thrust_body: [0.0; 3],
    })
}

/// SET_POSITION_TARGET_LOCAL_NED with an acceleration only (m/s², NED) and yaw 0 (nose
/// north, as the attitude setpoints): position, velocity and yaw rate ignored (type_mask
/// 1|2|4 + 8|16|32 + 2048 = 0x083F). PX4 turns it into thrust and attitude with its own
/// hover thrust.
pub fn set_position_target_acceleration(
    accel_ned_mps2: &Vector3<f64>,
    target_system: u8,
    time_boot_ms: u32,
) -> MavMessage {
    MavMessage::SET_POSITION_TARGET_LOCAL_NED(SET_POSITION_TARGET_LOCAL_NED_DATA {
        time_boot_ms,
        x: 0.0,
        y: 0.0,
        z: 0.0,
        vx: 0.0,
        vy: 0.0,
        vz: 0.0,
        afx: accel_ned_mps2.x as f32,
        afy: accel_ned_mps2.y as f32,
        afz: accel_ned_mps2.z as f32,
        yaw: 0.0,
        yaw_rate: 0.0,
        type_mask: PositionTargetTypemask::POSITION_TARGET_TYPEMASK_X_IGNORE
            | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_Y_IGNORE
            | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_Z_IGNORE
            | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VX_IGNORE
            | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VY_IGNORE
            | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VZ_IGNORE
            | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE,
        target_system,
        target_component: 1,
        coordinate_frame: MavFrame::MAV_FRAME_LOCAL_NED,
    })
}

/// MISSION_COUNT for a fence (mission type FENCE): `count` items follow on request.
pub fn fence_count(target_system: u8, count: u16) -> MavMessage {
    MavMessage::MISSION_COUNT(MISSION_COUNT_DATA {
        count,
        target_system,
        target_component: 1,
        mission_type: MavMissionType::MAV_MISSION_TYPE_FENCE,
        opaque_id: 0,
    })
}

/// MISSION_ITEM_INT number `seq` of a fence: MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION
/// (5001, param1 the vertex count) or MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION (5003, param1
/// the radius in m), latitude and longitude in degrees × 10⁷, frame GLOBAL (what
/// QGroundControl sends; fence items carry no altitude).
pub fn fence_item(target_system: u8, seq: u16, item: &FenceItem) -> MavMessage {
    let (command, param1) = match item.kind {
        FenceItemKind::PolygonVertex { vertex_count } => (
            MavCmd::MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION,
            f32::from(vertex_count),
        ),
        FenceItemKind::Circle { radius_m } => {
            (MavCmd::MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, radius_m as f32)
        }
    };
    MavMessage::MISSION_ITEM_INT(MISSION_ITEM_INT_DATA {
        param1,
        param2: 0.0,
        param3: 0.0,
        param4: 0.0,
        x: (item.lat_deg * 1e7).round() as i32,
        y: (item.lon_deg * 1e7).round() as i32,
        z: 0.0,
        seq,
        command,
        target_system,
        target_component: 1,
        frame: MavFrame::MAV_FRAME_GLOBAL,
        current: 0,
        autocontinue: 0,
        mission_type: MavMissionType::MAV_MISSION_TYPE_FENCE,
    })
}

/// TIMESYNC request (`tc1` 0) stamped `ts1_ns`: the vehicle answers with `tc1` its own
/// time and `ts1` echoed, which times the round trip.
pub fn timesync_request(ts1_ns: i64) -> MavMessage {
    MavMessage::TIMESYNC(TIMESYNC_DATA {
        tc1: 0,
        ts1: ts1_ns,
        target_system: 0,
        target_component: 0,
    })
}

/// The ground station's HEARTBEAT: type GCS, autopilot INVALID, no mode, state ACTIVE
/// (what QGroundControl and MAVSDK send at 1 Hz; PX4 watches it for data-link loss).
pub fn gcs_heartbeat() -> MavMessage {
    MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: 0,
        mavtype: MavType::MAV_TYPE_GCS,
        autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
        base_mode: MavModeFlag::empty(),
        system_status: MavState::MAV_STATE_ACTIVE,
        mavlink_version: 3,
    })
}

/// MAV_AUTOPILOT_PX4: the only autopilot whose mode numbers the coordinator speaks.
pub const AUTOPILOT_PX4: u8 = 12;

/// A readable name for a heartbeat's `autopilot` field.
pub fn autopilot_name(autopilot: u8) -> String {
    match autopilot {
        0 => "generic (MAV_AUTOPILOT_GENERIC)".to_owned(),
        3 => "ArduPilot (MAV_AUTOPILOT_ARDUPILOTMEGA)".to_owned(),
        8 => "none (MAV_AUTOPILOT_INVALID: a ground station or companion)".to_owned(),
        12 => "PX4 (MAV_AUTOPILOT_PX4)".to_owned(),
        other => format!("MAV_AUTOPILOT {other}"),
    }
}

/// What an inbound message tells the coordinator about a vehicle.
#[derive(Debug, Clone, PartialEq)]
pub enum Inbound {
    /// HEARTBEAT from an autopilot.
    Heartbeat {
        /// Armed flag.
        armed: bool,
        /// PX4 custom mode (main mode in bits 16–23, sub mode in 24–31).
        custom_mode: u32,
        /// MAV_AUTOPILOT value.
        autopilot: u8,
        /// System status CRITICAL or EMERGENCY: PX4 says CRITICAL while a failsafe acts.
        failsafe: bool,
    },
    /// LOCAL_POSITION_NED (m, m/s, the vehicle's own origin).
    LocalPosition {
        /// When the vehicle took it: its boot clock (ms, `time_boot_ms`).
        sampled_ms: u32,
        /// Position.
        pos_ned_m: Vector3<f64>,
        /// Velocity.
        vel_ned_mps: Vector3<f64>,
    },
    /// ATTITUDE_QUATERNION (body FRD → NED).
    Attitude(UnitQuaternion<f64>),
    /// GPS_GLOBAL_ORIGIN: where the local frame starts.
    Origin(Geodetic),
    /// EXTENDED_SYS_STATE: on the ground or not.
    Landed(bool),
    /// ESTIMATOR_STATUS: whether the estimate the coordinator flies on is good.
    Estimator {
        /// Attitude, horizontal and vertical velocity and relative horizontal position
        /// all flagged good ([`ESTIMATE_NEEDED`]).
        usable: bool,
        /// The flags as sent (ESTIMATOR_STATUS_FLAGS bits).
        flags: u16,
    },
    /// MISSION_REQUEST_INT (or the legacy MISSION_REQUEST) in a fence upload.
    FenceRequest {
        /// The item asked for.
        seq: u16,
        /// The system it is addressed to.
        target_system: u8,
    },
    /// MISSION_ACK of a fence upload.
    FenceAck {
        /// MAV_MISSION_RESULT value.
        result: u8,
        /// The system it is addressed to.
        target_system: u8,
    },
    /// A TIMESYNC answer (`tc1` ≠ 0): the `ts1` we sent, echoed.
    TimesyncReply {
        /// Our stamp (ns).
        ts1_ns: i64,
        /// The system it is addressed to (0: any).
        target_system: u8,
    },
    /// PARAM_VALUE: a parameter's name and value (as a float).
    ParamValue {
        /// Its name.
        name: String,
        /// Its value.
        value: f32,
    },
    /// STATUSTEXT of severity WARNING or worse (a refusal's reason: "PreArm: …",
    /// "Arm: …", "Mode change to … failed"); chunks are not joined.
    StatusText {
        /// MAV_SEVERITY value (0 emergency … 4 warning).
        severity: u8,
        /// The text, without its padding.
        text: String,
    },
    /// SYS_STATUS that reports its pre-arm check (MAV_SYS_STATUS_PREARM_CHECK present):
    /// whether it passes.
    Prearm(bool),
    /// COMMAND_ACK.
    Ack {
        /// MAV_CMD id.
        command: u16,
        /// MAV_RESULT value.
        result: u8,
        /// The system it is addressed to (0: all).
        target_system: u8,
    },
}

/// The ESTIMATOR_STATUS flags the coordinator needs set: attitude (1), horizontal
/// velocity (2), vertical velocity (4) and relative horizontal position (8). PX4 sends
/// LOCAL_POSITION_NED whatever its estimator's state (mavlink's LOCAL_POSITION_NED stream),
/// so these flags are what tells a dead-reckoned position from a good one.
pub const ESTIMATE_NEEDED: u16 = 0x0f;

/// Converts an inbound message; `None` for messages the coordinator does not use or
/// cannot trust (a non-finite attitude). Positions and origins are checked by the
/// vehicle's telemetry gate, which names what it refuses.
pub fn inbound(msg: &MavMessage) -> Option<Inbound> {
    match msg {
        MavMessage::HEARTBEAT(h) => Some(Inbound::Heartbeat {
            armed: h
                .base_mode
                .contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED),
            custom_mode: h.custom_mode,
            autopilot: h.autopilot as u8,
            failsafe: matches!(
                h.system_status,
                MavState::MAV_STATE_CRITICAL | MavState::MAV_STATE_EMERGENCY
            ),
        }),
        MavMessage::LOCAL_POSITION_NED(p) => {
            let pos = Vector3::new(p.x, p.y, p.z).map(f64::from);
            let vel = Vector3::new(p.vx, p.vy, p.vz).map(f64::from);
            // Checked by the vehicle's telemetry gate, which names a bad field.
            Some(Inbound::LocalPosition {
                sampled_ms: p.time_boot_ms,
                pos_ned_m: pos,
                vel_ned_mps: vel,
            })
        }
        MavMessage::ATTITUDE_QUATERNION(a) => {
            let q = Quaternion::new(
                f64::from(a.q1),
                f64::from(a.q2),
                f64::from(a.q3),
                f64::from(a.q4),
            );
            (q.coords.iter().all(|x| x.is_finite()) && q.norm() > 0.5)
                .then(|| Inbound::Attitude(UnitQuaternion::new_normalize(q)))
        }
        MavMessage::GPS_GLOBAL_ORIGIN(o) => Some(Inbound::Origin(Geodetic::from_mavlink(
            o.latitude,
            o.longitude,
            o.altitude,
        ))),
        MavMessage::EXTENDED_SYS_STATE(s) => Some(Inbound::Landed(
            s.landed_state == mavlink::dialects::common::MavLandedState::MAV_LANDED_STATE_ON_GROUND,
        )),
        MavMessage::ESTIMATOR_STATUS(e) => {
            let flags = e.flags.bits();
            Some(Inbound::Estimator {
                usable: flags & ESTIMATE_NEEDED == ESTIMATE_NEEDED,
                flags,
            })
        }
        MavMessage::MISSION_REQUEST_INT(r)
            if r.mission_type == MavMissionType::MAV_MISSION_TYPE_FENCE =>
        {
            Some(Inbound::FenceRequest {
                seq: r.seq,
                target_system: r.target_system,
            })
        }
        #[allow(deprecated)]
        MavMessage::MISSION_REQUEST(r)
            if r.mission_type == MavMissionType::MAV_MISSION_TYPE_FENCE =>
        {
            Some(Inbound::FenceRequest {
                seq: r.seq,
                target_system: r.target_system,
            })
        }
        MavMessage::MISSION_ACK(a) if a.mission_type == MavMissionType::MAV_MISSION_TYPE_FENCE => {
            Some(Inbound::FenceAck {
                result: a.mavtype as u8,
                target_system: a.target_system,
            })
        }
        MavMessage::TIMESYNC(t) if t.tc1 != 0 => Some(Inbound::TimesyncReply {
            ts1_ns: t.ts1,
            target_system: t.target_system,
        }),
        MavMessage::PARAM_VALUE(p) => {
            let name = p.param_id.to_str().ok()?.trim_end_matches('\0').to_owned();
            p.param_value.is_finite().then_some(Inbound::ParamValue {
                name,
                value: p.param_value,
            })
        }
        MavMessage::STATUSTEXT(t)
            if (t.severity as u8) <= MavSeverity::MAV_SEVERITY_WARNING as u8 =>
        {
            let text = String::from_utf8_lossy(t.text.as_slice());
            Some(Inbound::StatusText {
                severity: t.severity as u8,
                text: text.trim_end_matches('\0').trim().to_owned(),
            })
        }
        MavMessage::SYS_STATUS(s)
            if s.onboard_control_sensors_present
                .contains(MavSysStatusSensor::MAV_SYS_STATUS_PREARM_CHECK) =>
        {
            Some(Inbound::Prearm(
                s.onboard_control_sensors_health
                    .contains(MavSysStatusSensor::MAV_SYS_STATUS_PREARM_CHECK),
            ))
        }
        MavMessage::COMMAND_ACK(a) => Some(Inbound::Ack {
            command: a.command as u16,
            result: a.result as u8,
            target_system: a.target_system,
        }),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::{VehicleModel, attitude_thrust_from_acceleration};
    use crate::link::{Encoder, decode_datagram};

    #[test]
    fn set_attitude_target_golden_bytes() {
        // Level, thrust 0.5, to system 3, time_boot_ms 1000, from 255/190, sequence 0.
        let sp = AttitudeThrust {
            attitude_ned_frd: UnitQuaternion::identity(),
            thrust_norm: 0.5,
            thrust_n: 0.0,
        };
        let bytes = Encoder::new(255, 190).encode(&set_attitude_target(&sp, 3, 1000));
        // Payload (wire order): time_boot_ms u32, q[4] f32, three rates f32, thrust f32,
        // target_system, target_component, type_mask; the zero thrust_body extension and
        // trailing zeros are trimmed by MAVLink 2.
        let mut payload = Vec::new();
        payload.extend(1000u32.to_le_bytes());
        for x in [1.0f32, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.5] {
            payload.extend(x.to_le_bytes());
        }
        payload.extend([3, 1, 7]);
        assert_eq!(
            &bytes[..10],
            &[0xFD, payload.len() as u8, 0, 0, 0, 255, 190, 82, 0, 0]
        );
        assert_eq!(&bytes[10..10 + payload.len()], payload.as_slice());
        let crc = mavlink::calculate_crc(&bytes[1..10 + payload.len()], 49);
        assert_eq!(&bytes[10 + payload.len()..], &crc.to_le_bytes());
    }

    #[test]
    fn an_acceleration_setpoint_says_what_px4_reads() {
        let a = Vector3::new(1.5, -2.0, -0.25);
        let bytes = Encoder::new(253, 190).encode(&set_position_target_acceleration(&a, 4, 77));
        let frame = decode_datagram(&bytes).remove(0).unwrap();
        let MavMessage::SET_POSITION_TARGET_LOCAL_NED(d) = frame.msg else {
            panic!("wrong message")
        };
        // Position 1|2|4, velocity 8|16|32 and yaw rate 2048 ignored; acceleration and yaw
        // used.
        assert_eq!(d.type_mask.bits(), 0x083F);
        assert_eq!((d.afx, d.afy, d.afz), (1.5, -2.0, -0.25));
        assert_eq!(d.coordinate_frame, MavFrame::MAV_FRAME_LOCAL_NED);
        assert_eq!(
            (d.target_system, d.target_component, d.time_boot_ms),
            (4, 1, 77)
        );
        assert_eq!(d.yaw, 0.0);
    }

    #[test]
    fn gcs_heartbeat_golden_bytes() {
        let bytes = Encoder::new(253, 190).encode(&gcs_heartbeat());
        // custom_mode u32 0, type 6 (GCS), autopilot 8 (INVALID), base_mode 0,
        // system_status 4 (ACTIVE), mavlink_version 3; no zero trimming past the last 3.
        let payload = [0u8, 0, 0, 0, 6, 8, 0, 4, 3];
        assert_eq!(&bytes[..10], &[0xFD, 9, 0, 0, 0, 253, 190, 0, 0, 0]);
        assert_eq!(&bytes[10..19], &payload);
        let crc = mavlink::calculate_crc(&bytes[1..19], 50);
        assert_eq!(&bytes[19..], &crc.to_le_bytes());
    }

    #[test]
    fn a_setpoint_round_trips_with_w_first() {
        let model = VehicleModel::from_hover_throttle(2.0, 0.5).unwrap();
        let sp = attitude_thrust_from_acceleration(Vector3::new(1.0, 2.0, 0.0), 0.3, &model);
        let bytes = Encoder::new(255, 190).encode(&set_attitude_target(&sp, 1, 0));
        let frame = decode_datagram(&bytes).remove(0).unwrap();
        let MavMessage::SET_ATTITUDE_TARGET(d) = frame.msg else {
            panic!("wrong message")
        };
        let q = UnitQuaternion::new_normalize(
            Quaternion::new(d.q[0], d.q[1], d.q[2], d.q[3]).cast::<f64>(),
        );
        assert!(q.angle_to(&sp.attitude_ned_frd) < 1e-6);
        assert_eq!(d.type_mask.bits(), 7);
        assert!((f64::from(d.thrust) - sp.thrust_norm).abs() < 1e-6);
    }
}
