//! A mission item in plain numbers and PX4's rules for accepting one, shared by the
//! mission and the fence (their storage, transfer and flying are elsewhere).
//!
//! Item rules (PX4's `mavlink_mission.cpp`): navigation commands in a global frame
//! (GLOBAL, GLOBAL_RELATIVE_ALT and their _INT forms), other commands in
//! MAV_FRAME_MISSION; anything else is MAV_MISSION_UNSUPPORTED_FRAME. Commands outside
//! [`SUPPORTED`] and the payload items are MAV_MISSION_UNSUPPORTED. A parameter a command
//! does not use must be 0 or NaN (MAV_MISSION_INVALID_PARAMn otherwise); latitude and
//! longitude must be on the Earth (INVALID_PARAM5_X / 6_Y).

use mavlink::dialects::common::{
    MISSION_ITEM_INT_DATA, MavCmd, MavFrame, MavMessage, MavMissionResult, MavMissionType,
};

/// MAV_CMD numbers the mission flies or accepts.
pub(super) mod cmd {
    pub const NAV_WAYPOINT: u16 = 16;
    pub const NAV_LOITER_UNLIM: u16 = 17;
    pub const NAV_LOITER_TIME: u16 = 19;
    pub const NAV_RETURN_TO_LAUNCH: u16 = 20;
    pub const NAV_LAND: u16 = 21;
    pub const NAV_TAKEOFF: u16 = 22;
    pub const NAV_DELAY: u16 = 93;
    pub const DO_CHANGE_SPEED: u16 = 178;
}

/// Payload commands PX4 stores in missions; an emulator without a camera or gimbal
/// accepts them and passes over them.
const PAYLOAD: [u16; 10] = [203, 204, 205, 206, 1000, 1001, 2000, 2001, 2500, 2501];

/// Commands accepted in a mission, with the parameters they use (1-based; 5-7 are x, y,
/// z) and whether they are positional (global frame).
pub(super) const SUPPORTED: [(u16, &[u8], bool); 8] = [
    (cmd::NAV_WAYPOINT, &[1, 2, 4, 5, 6, 7], true),
    (cmd::NAV_LOITER_UNLIM, &[3, 4, 5, 6, 7], true),
    (cmd::NAV_LOITER_TIME, &[1, 3, 4, 5, 6, 7], true),
    (cmd::NAV_LAND, &[1, 2, 4, 5, 6, 7], true),
    (cmd::NAV_TAKEOFF, &[1, 4, 5, 6, 7], true),
    (cmd::NAV_RETURN_TO_LAUNCH, &[], false),
    (cmd::NAV_DELAY, &[1, 2, 3, 4], false),
    (cmd::DO_CHANGE_SPEED, &[1, 2, 3, 4], false),
];

/// One stored mission item, in plain numbers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MissionItem {
    /// MAV_CMD.
    pub command: u16,
    /// MAV_FRAME.
    pub frame: u8,
    /// param1..param4.
    pub params: [f32; 4],
    /// Latitude (degE7) for global frames, else param5 as stored.
    pub x: i32,
    /// Longitude (degE7) for global frames, else param6 as stored.
    pub y: i32,
    /// Altitude (m, AMSL or above home by the frame), or param7.
    pub z: f32,
    /// Continue to the next item.
    pub autocontinue: u8,
}

impl MissionItem {
    /// Whether the altitude is relative to home.
    pub fn relative_alt(&self) -> bool {
        matches!(self.frame, 3 | 6)
    }

    /// Whether this item has a position.
    pub fn is_positional(&self) -> bool {
        SUPPORTED
            .iter()
            .any(|(c, _, positional)| *c == self.command && *positional)
    }

    /// Latitude and longitude (deg).
    pub fn lat_lon_deg(&self) -> (f64, f64) {
        (f64::from(self.x) * 1e-7, f64::from(self.y) * 1e-7)
    }
}

/// A checksum of the plan, PX4's `opaque_id` (CRC-32 of the items' numbers).
pub(super) fn crc_of(items: &[MissionItem]) -> u32 {
    let mut crc = 0xFFFF_FFFFu32;
    for item in items {
        let mut bytes = Vec::with_capacity(32);
        bytes.extend(item.command.to_le_bytes());
        bytes.push(item.frame);
        for p in item.params {
            bytes.extend(p.to_le_bytes());
        }
        bytes.extend(item.x.to_le_bytes());
        bytes.extend(item.y.to_le_bytes());
        bytes.extend(item.z.to_le_bytes());
        for b in bytes {
            crc ^= u32::from(b);
            for _ in 0..8 {
                crc = if crc & 1 != 0 {
                    (crc >> 1) ^ 0xEDB8_8320
                } else {
                    crc >> 1
                };
            }
        }
    }
    !crc
}

/// Checks one uploaded item against PX4's rules.
pub(super) fn check_item(item: &MissionItem) -> Result<(), MavMissionResult> {
    use MavMissionResult as R;
    let is_payload = PAYLOAD.contains(&item.command);
    let Some((_, used, positional)) = SUPPORTED
        .iter()
        .find(|(c, _, _)| *c == item.command)
        .copied()
        .or(is_payload.then_some((item.command, &[1, 2, 3, 4, 5, 6, 7][..], false)))
    else {
        return Err(R::MAV_MISSION_UNSUPPORTED);
    };
    let frame_ok = if positional {
        matches!(item.frame, 0 | 3 | 5 | 6)
    } else {
        item.frame == 2
    };
    if !frame_ok {
        return Err(R::MAV_MISSION_UNSUPPORTED_FRAME);
    }
    let errors = [
        R::MAV_MISSION_INVALID_PARAM1,
        R::MAV_MISSION_INVALID_PARAM2,
        R::MAV_MISSION_INVALID_PARAM3,
        R::MAV_MISSION_INVALID_PARAM4,
    ];
    for (i, p) in item.params.iter().enumerate() {
        let unused = !used.contains(&(i as u8 + 1));
        if (unused && !(p.is_nan() || *p == 0.0)) || p.is_infinite() {
            return Err(errors[i]);
        }
    }
    if positional {
        let (lat, lon) = item.lat_lon_deg();
        if lat.abs() > 90.0 {
            return Err(R::MAV_MISSION_INVALID_PARAM5_X);
        }
        if lon.abs() > 180.0 {
            return Err(R::MAV_MISSION_INVALID_PARAM6_Y);
        }
        if !item.z.is_finite() && item.command != cmd::NAV_LAND {
            return Err(R::MAV_MISSION_INVALID_PARAM7);
        }
    }
    Ok(())
}

/// An item from MISSION_ITEM_INT.
pub(super) fn item_from_int(m: &MISSION_ITEM_INT_DATA) -> MissionItem {
    MissionItem {
        command: m.command as u16,
        frame: m.frame as u8,
        params: [m.param1, m.param2, m.param3, m.param4],
        x: m.x,
        y: m.y,
        z: m.z,
        autocontinue: m.autocontinue,
    }
}

/// A MAV_CMD from its number (the stored numbers came from valid enum values).
pub(super) fn mav_cmd(command: u16) -> MavCmd {
    use num_traits::FromPrimitive;
    MavCmd::from_u16(command).unwrap_or(MavCmd::MAV_CMD_NAV_WAYPOINT)
}

/// A stored item as MISSION_ITEM_INT; PX4 answers with the _INT frames (5, 6),
/// deprecated in the XML but what flies.
#[allow(deprecated)]
pub(super) fn item_message_int(
    item: &MissionItem,
    seq: u16,
    to: (u8, u8),
    current: u8,
) -> MavMessage {
    let frame = match item.frame {
        0 | 5 => MavFrame::MAV_FRAME_GLOBAL_INT,
        3 | 6 => MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
        _ => MavFrame::MAV_FRAME_MISSION,
    };
    MavMessage::MISSION_ITEM_INT(MISSION_ITEM_INT_DATA {
        param1: item.params[0],
        param2: item.params[1],
        param3: item.params[2],
        param4: item.params[3],
        x: item.x,
        y: item.y,
        z: item.z,
        seq,
        command: mav_cmd(item.command),
        target_system: to.0,
        target_component: to.1,
        frame,
        current,
        autocontinue: item.autocontinue,
        mission_type: MavMissionType::MAV_MISSION_TYPE_MISSION,
    })
}

/// A stored item as the legacy MISSION_ITEM (degrees as floats), for a client that asked
/// with MISSION_REQUEST.
#[allow(deprecated)]
pub(super) fn item_message_float(
    item: &MissionItem,
    seq: u16,
    to: (u8, u8),
    current: u8,
) -> MavMessage {
    let (frame, scale) = match item.frame {
        0 | 5 => (MavFrame::MAV_FRAME_GLOBAL, 1e-7),
        3 | 6 => (MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT, 1e-7),
        _ => (MavFrame::MAV_FRAME_MISSION, 1.0),
    };
    MavMessage::MISSION_ITEM(mavlink::dialects::common::MISSION_ITEM_DATA {
        param1: item.params[0],
        param2: item.params[1],
        param3: item.params[2],
        param4: item.params[3],
        x: (f64::from(item.x) * scale) as f32,
        y: (f64::from(item.y) * scale) as f32,
        z: item.z,
        seq,
        command: mav_cmd(item.command),
        target_system: to.0,
        target_component: to.1,
        frame,
        current,
        autocontinue: item.autocontinue,
        mission_type: MavMissionType::MAV_MISSION_TYPE_MISSION,
    })
}

/// A legacy MISSION_ITEM (degrees as floats) as the MISSION_ITEM_INT it stands for.
#[allow(deprecated)]
pub(super) fn item_int_from_float(
    m: &mavlink::dialects::common::MISSION_ITEM_DATA,
) -> MISSION_ITEM_INT_DATA {
    let global = matches!(
        m.frame,
        MavFrame::MAV_FRAME_GLOBAL | MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT
    );
    let e7 = |v: f32| {
        if global {
            (f64::from(v) * 1e7)
                .round()
                .clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32
        } else {
            v as i32
        }
    };
    MISSION_ITEM_INT_DATA {
        param1: m.param1,
        param2: m.param2,
        param3: m.param3,
        param4: m.param4,
        x: e7(m.x),
        y: e7(m.y),
        z: m.z,
        seq: m.seq,
        command: m.command,
        target_system: m.target_system,
        target_component: m.target_component,
        frame: m.frame,
        current: m.current,
        autocontinue: m.autocontinue,
        mission_type: m.mission_type,
    }
}
