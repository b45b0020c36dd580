//! The stored mission: items in plain numbers, PX4's rules for accepting them, progress,
//! and the reports (MISSION_CURRENT, MISSION_ITEM_REACHED). The transfer protocol is in
//! `mission_transfer`, the flying in `mission_run`.
//!
//! Item rules (PX4's `mavlink_mission.cpp`): navigation commands in a global frame
//! (GLOBAL, GLOBAL_RELATIVE_ALT and their _INT forms), other commands in
//! MAV_FRAME_MISSION; anything else is MAV_MISSION_UNSUPPORTED_FRAME. Commands outside
//! [`SUPPORTED`] and the payload items are MAV_MISSION_UNSUPPORTED. A parameter a command
//! does not use must be 0 or NaN (MAV_MISSION_INVALID_PARAMn otherwise); latitude and
//! longitude must be on the Earth (INVALID_PARAM5_X / 6_Y).

use mavlink::dialects::common::{
    MISSION_CURRENT_DATA, MISSION_ITEM_INT_DATA, MISSION_ITEM_REACHED_DATA, MavCmd, MavMessage,
    MavMissionResult, MissionState,
};

use super::mission_transfer::Transfer;
use super::{LinkId, Vehicle};

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

/// The stored mission, its progress and the transfer in progress.
#[derive(Debug, Clone, PartialEq)]
pub struct MissionStore {
    items: Vec<MissionItem>,
    current: usize,
    finished: bool,
    started: bool,
    reached: Option<(u16, u8)>,
    pub(super) transfer: Transfer,
    pub(super) next_report: crate::time::SimTime,
    pub(super) crc: u32,
}

impl Default for MissionStore {
    fn default() -> Self {
        Self {
            items: Vec::new(),
            current: 0,
            finished: false,
            started: false,
            reached: None,
            transfer: Transfer::Idle,
            next_report: crate::time::SimTime::ZERO,
            crc: 0,
        }
    }
}

impl MissionStore {
    /// The stored items.
    pub fn items(&self) -> &[MissionItem] {
        &self.items
    }

    /// The index of the current item.
    pub fn current_seq(&self) -> usize {
        self.current
    }

    /// Whether a mission can be flown.
    pub fn is_valid(&self) -> bool {
        !self.items.is_empty()
    }

    /// Whether the last run reached its end.
    pub fn finished(&self) -> bool {
        self.finished
    }

    pub(super) fn set_current(&mut self, seq: usize) {
        self.current = seq;
    }

    pub(super) fn mark_started(&mut self) {
        if self.finished {
            self.current = 0;
        }
        self.finished = false;
        self.started = true;
    }

    pub(super) fn mark_finished(&mut self) {
        self.finished = true;
    }

    pub(super) fn replace(&mut self, items: Vec<MissionItem>, current: Option<usize>) {
        self.crc = crc_of(&items);
        let n = items.len();
        self.items = items;
        self.current = current.unwrap_or(self.current).min(n.saturating_sub(1));
        self.finished = false;
        self.started = false;
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

impl Vehicle {
    /// MISSION_CURRENT (and a pending MISSION_ITEM_REACHED, repeated up to 10 times at
    /// 1 Hz as PX4 does) on both links.
    pub(super) fn report_mission(&mut self) {
        let state = if self.mission.items.is_empty() {
            MissionState::MISSION_STATE_NO_MISSION
        } else if self.mission.finished {
            MissionState::MISSION_STATE_COMPLETE
        } else if self.mode == super::FlightMode::Mission {
            MissionState::MISSION_STATE_ACTIVE
        } else if self.mission.started {
            MissionState::MISSION_STATE_PAUSED
        } else {
            MissionState::MISSION_STATE_NOT_STARTED
        };
        let in_mission = matches!(
            self.mode,
            super::FlightMode::Mission | super::FlightMode::Takeoff | super::FlightMode::Land
        );
        let current = MavMessage::MISSION_CURRENT(MISSION_CURRENT_DATA {
            seq: self.mission.current as u16,
            total: if self.mission.items.is_empty() {
                u16::MAX
            } else {
                self.mission.items.len() as u16
            },
            mission_state: state,
            mission_mode: if in_mission { 1 } else { 2 },
            mission_id: self.mission.crc,
            fence_id: self.geofence.crc,
            rally_points_id: 0,
        });
        let reached = self.mission.reached.map(|(seq, left)| {
            self.mission.reached = left.checked_sub(1).map(|l| (seq, l));
            MavMessage::MISSION_ITEM_REACHED(MISSION_ITEM_REACHED_DATA { seq })
        });
        for link in [LinkId::Offboard, LinkId::Gcs] {
            self.send(link, &current);
            if let Some(r) = &reached {
                self.send(link, r);
            }
        }
    }

    /// An item was reached: MISSION_ITEM_REACHED now, then repeated with the reports.
    pub(super) fn note_item_reached(&mut self, seq: usize) {
        self.mission.reached = Some((seq as u16, 10));
        self.report_mission();
    }

    /// Stores a new plan (or none) and points a mission being flown at its current item.
    pub(super) fn replace_mission(&mut self, items: Vec<MissionItem>, current: Option<usize>) {
        self.mission.replace(items, current);
        let seq = self.mission.current_seq();
        if let super::flight::Nav::Mission(run) = &mut self.nav {
            run.jump(seq);
        }
    }

    /// Makes `seq` the current item (and tells the clients).
    pub(super) fn jump_to_item(&mut self, seq: usize) {
        self.mission.set_current(seq);
        self.mission.finished = false;
        if let super::flight::Nav::Mission(run) = &mut self.nav {
            run.jump(seq);
        }
        self.report_mission();
    }
}

/// A MAV_CMD from its number (the stored numbers came from valid enum values).
pub(super) fn mav_cmd(command: u16) -> MavCmd {
    use num_traits::FromPrimitive;
    MavCmd::from_u16(command).unwrap_or(MavCmd::MAV_CMD_NAV_WAYPOINT)
}
