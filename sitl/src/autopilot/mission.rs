//! The MAVLink mission protocol as PX4's `mavlink_mission.cpp` speaks it, for mission
//! items (fence and rally plans: only their clearing is accepted).
//!
//! ```text
//!  Idle ──MISSION_COUNT n>0──► Receiving: MISSION_REQUEST_INT seq, re-sent every 250 ms;
//!        │                     an item out of sequence is ignored (the timer asks again);
//!        │                     a bad item ends the transfer with its MISSION_ACK error;
//!        │                     after the last: MISSION_ACK ACCEPTED, the new plan replaces
//!        │                     the stored one (never before, never on failure)
//!        ├─MISSION_COUNT 0──► cleared, MISSION_ACK ACCEPTED
//!        ├─MISSION_REQUEST_LIST──► Sending: MISSION_COUNT (re-sent every 250 ms until the
//!        │                     first request), MISSION_ITEM_INT per MISSION_REQUEST_INT,
//!        │                     Idle on the client's MISSION_ACK
//!        └─MISSION_CLEAR_ALL──► cleared, MISSION_ACK ACCEPTED
//!  Receiving/Sending ──5 s without a message from the partner──► Idle (no ack, as PX4)
//! ```
//!
//! Item rules (PX4's): navigation commands in a global frame (GLOBAL, GLOBAL_RELATIVE_ALT
//! and their _INT forms), other commands in MAV_FRAME_MISSION; anything else is
//! MAV_MISSION_UNSUPPORTED_FRAME. Commands outside [`SUPPORTED`] are
//! MAV_MISSION_UNSUPPORTED. A parameter a command does not use must be 0 or NaN
//! (MAV_MISSION_INVALID_PARAMn otherwise); latitude and longitude must be on the Earth
//! (INVALID_PARAM5_X / 6_Y). Legacy MISSION_REQUEST and MISSION_ITEM are answered too.

use std::time::Duration;

use mavlink::dialects::common::{
    MISSION_ACK_DATA, MISSION_COUNT_DATA, MISSION_CURRENT_DATA, MISSION_ITEM_INT_DATA,
    MISSION_ITEM_REACHED_DATA, MISSION_REQUEST_INT_DATA, MavCmd, MavFrame, MavMessage,
    MavMissionResult, MavMissionType, MissionState,
};

use super::{LinkId, Vehicle};
use crate::time::SimTime;

/// How often a request (or the count of a download) is repeated.
const RETRY: Duration = Duration::from_millis(250);
/// How long a transfer waits for its partner before it is dropped.
const TRANSFER_TIMEOUT: Duration = Duration::from_secs(5);
/// Most items a mission may have (PX4 SITL's storage).
const MAX_ITEMS: usize = 10_000;

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

/// Where a transfer is.
#[derive(Debug, Clone, PartialEq)]
enum Transfer {
    Idle,
    Receiving {
        link: LinkId,
        partner: (u8, u8),
        count: usize,
        items: Vec<MissionItem>,
        last_heard: SimTime,
        last_request: SimTime,
        legacy: bool,
        current: Option<usize>,
    },
    Sending {
        link: LinkId,
        partner: (u8, u8),
        last_heard: SimTime,
        last_sent: SimTime,
        requested: bool,
    },
}

/// The stored mission, its progress and the transfer in progress.
#[derive(Debug, Clone, PartialEq)]
pub struct MissionStore {
    items: Vec<MissionItem>,
    current: usize,
    finished: bool,
    started: bool,
    reached: Option<(u16, u8)>,
    transfer: Transfer,
    next_report: SimTime,
    crc: u32,
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
            next_report: SimTime::ZERO,
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

    fn replace(&mut self, items: Vec<MissionItem>, current: Option<usize>) {
        self.crc = crc_of(&items);
        let n = items.len();
        self.items = items;
        self.current = current.unwrap_or(self.current).min(n.saturating_sub(1));
        self.finished = false;
        self.started = false;
    }
}

/// A checksum of the plan, PX4's `opaque_id` (CRC-32 of the items' numbers).
fn crc_of(items: &[MissionItem]) -> u32 {
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
fn item_from_int(m: &MISSION_ITEM_INT_DATA) -> MissionItem {
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
    /// Whether a mission message is for this vehicle's autopilot (system, and component
    /// 1, 190 or broadcast, as PX4 accepts).
    fn mission_for_us(&mut self, target_system: u8, target_component: u8) -> bool {
        let ours = target_system == self.cfg.system_id && matches!(target_component, 0 | 1 | 190);
        if !ours {
            self.counters.foreign_target += 1;
        }
        ours
    }

    fn send_mission_ack(
        &mut self,
        link: LinkId,
        to: (u8, u8),
        result: MavMissionResult,
        mission_type: MavMissionType,
    ) {
        let opaque_id = if result == MavMissionResult::MAV_MISSION_ACCEPTED {
            self.mission.crc
        } else {
            0
        };
        let ack = MavMessage::MISSION_ACK(MISSION_ACK_DATA {
            target_system: to.0,
            target_component: to.1,
            mavtype: result,
            mission_type,
            opaque_id,
        });
        self.send(link, &ack);
    }

    fn request_item(&mut self, link: LinkId, to: (u8, u8), seq: usize, legacy: bool) {
        let data = MISSION_REQUEST_INT_DATA {
            seq: seq as u16,
            target_system: to.0,
            target_component: to.1,
            mission_type: MavMissionType::MAV_MISSION_TYPE_MISSION,
        };
        #[allow(deprecated)]
        let msg = if legacy {
            MavMessage::MISSION_REQUEST(mavlink::dialects::common::MISSION_REQUEST_DATA {
                seq: data.seq,
                target_system: data.target_system,
                target_component: data.target_component,
                mission_type: data.mission_type,
            })
        } else {
            MavMessage::MISSION_REQUEST_INT(data)
        };
        self.send(link, &msg);
    }

    /// MISSION_COUNT: starts an upload (or clears with 0).
    pub(super) fn on_mission_count(
        &mut self,
        now: SimTime,
        link: LinkId,
        sender: (u8, u8),
        m: &MISSION_COUNT_DATA,
    ) -> bool {
        if !self.mission_for_us(m.target_system, m.target_component) {
            return false;
        }
        let count = usize::from(m.count);
        if m.mission_type != MavMissionType::MAV_MISSION_TYPE_MISSION {
            // Fence and rally plans are not flown: only their clearing is accepted.
            let result = if count == 0 {
                MavMissionResult::MAV_MISSION_ACCEPTED
            } else {
                MavMissionResult::MAV_MISSION_UNSUPPORTED
            };
            self.send_mission_ack(link, sender, result, m.mission_type);
            return true;
        }
        match &self.mission.transfer {
            Transfer::Receiving {
                partner,
                items,
                legacy,
                ..
            } if *partner == sender && items.is_empty() => {
                // The partner did not hear our first request: ask again.
                let legacy = *legacy;
                self.request_item(link, sender, 0, legacy);
                return true;
            }
            Transfer::Idle => {}
            _ => {
                self.send_mission_ack(
                    link,
                    sender,
                    MavMissionResult::MAV_MISSION_ERROR,
                    m.mission_type,
                );
                return true;
            }
        }
        if count > MAX_ITEMS {
            self.send_mission_ack(
                link,
                sender,
                MavMissionResult::MAV_MISSION_NO_SPACE,
                m.mission_type,
            );
            return true;
        }
        if count == 0 {
            self.mission.replace(Vec::new(), Some(0));
            self.send_mission_ack(
                link,
                sender,
                MavMissionResult::MAV_MISSION_ACCEPTED,
                m.mission_type,
            );
            return true;
        }
        self.mission.transfer = Transfer::Receiving {
            link,
            partner: sender,
            count,
            items: Vec::with_capacity(count),
            last_heard: now,
            last_request: now,
            legacy: false,
            current: None,
        };
        self.request_item(link, sender, 0, false);
        true
    }

    /// MISSION_ITEM_INT (or a legacy MISSION_ITEM converted to it) during an upload.
    pub(super) fn on_mission_item(
        &mut self,
        now: SimTime,
        link: LinkId,
        sender: (u8, u8),
        m: &MISSION_ITEM_INT_DATA,
        legacy: bool,
    ) -> bool {
        if !self.mission_for_us(m.target_system, m.target_component) {
            return false;
        }
        let Transfer::Receiving {
            partner,
            count,
            items,
            last_heard,
            last_request,
            legacy: transfer_legacy,
            current,
            ..
        } = &mut self.mission.transfer
        else {
            // The last item again after the final ack: the partner missed the ack.
            if usize::from(m.seq) + 1 == self.mission.items.len() {
                self.send_mission_ack(
                    link,
                    sender,
                    MavMissionResult::MAV_MISSION_ACCEPTED,
                    m.mission_type,
                );
            }
            return true;
        };
        if *partner != sender {
            return true;
        }
        if m.mission_type != MavMissionType::MAV_MISSION_TYPE_MISSION {
            self.send_mission_ack(
                link,
                sender,
                MavMissionResult::MAV_MISSION_ERROR,
                m.mission_type,
            );
            return true;
        }
        *last_heard = now;
        *transfer_legacy = legacy;
        if usize::from(m.seq) != items.len() {
            return true; // out of sequence: the retry timer asks for the right one
        }
        let item = item_from_int(m);
        // A legacy MISSION_ITEM carries degrees as floats; an _INT frame there is wrong.
        if legacy && matches!(item.frame, 5 | 6) {
            self.mission.transfer = Transfer::Idle;
            self.send_mission_ack(
                link,
                sender,
                MavMissionResult::MAV_MISSION_UNSUPPORTED_FRAME,
                m.mission_type,
            );
            return true;
        }
        if let Err(result) = check_item(&item) {
            tracing::debug!(
                sysid = self.cfg.system_id,
                seq = m.seq,
                ?result,
                "mission item refused"
            );
            self.mission.transfer = Transfer::Idle;
            self.send_mission_ack(link, sender, result, m.mission_type);
            return true;
        }
        items.push(item);
        if m.current != 0 {
            *current = Some(usize::from(m.seq));
        }
        if items.len() < *count {
            *last_request = now;
            let (next, legacy) = (items.len(), *transfer_legacy);
            self.request_item(link, sender, next, legacy);
            return true;
        }
        let (items, current) = (std::mem::take(items), *current);
        self.mission.transfer = Transfer::Idle;
        self.mission.replace(items, current);
        self.send_mission_ack(
            link,
            sender,
            MavMissionResult::MAV_MISSION_ACCEPTED,
            m.mission_type,
        );
        tracing::info!(
            sysid = self.cfg.system_id,
            items = self.mission.items.len(),
            "mission stored"
        );
        true
    }

    /// MISSION_REQUEST_LIST: starts a download.
    pub(super) fn on_mission_request_list(
        &mut self,
        now: SimTime,
        link: LinkId,
        sender: (u8, u8),
        target: (u8, u8),
        mission_type: MavMissionType,
    ) -> bool {
        if !self.mission_for_us(target.0, target.1) {
            return false;
        }
        if self.mission.transfer != Transfer::Idle {
            return true; // busy: PX4 only says so in a status text
        }
        let count = if mission_type == MavMissionType::MAV_MISSION_TYPE_MISSION {
            self.mission.items.len()
        } else {
            0
        };
        if mission_type == MavMissionType::MAV_MISSION_TYPE_MISSION {
            self.mission.transfer = Transfer::Sending {
                link,
                partner: sender,
                last_heard: now,
                last_sent: now,
                requested: false,
            };
        }
        self.send_mission_count(link, sender, count, mission_type);
        true
    }

    fn send_mission_count(
        &mut self,
        link: LinkId,
        to: (u8, u8),
        count: usize,
        mission_type: MavMissionType,
    ) {
        let msg = MavMessage::MISSION_COUNT(MISSION_COUNT_DATA {
            count: count as u16,
            target_system: to.0,
            target_component: to.1,
            mission_type,
            opaque_id: self.mission.crc,
        });
        self.send(link, &msg);
    }

    /// MISSION_REQUEST_INT (or legacy MISSION_REQUEST) during a download.
    pub(super) fn on_mission_request(
        &mut self,
        now: SimTime,
        link: LinkId,
        sender: (u8, u8),
        target: (u8, u8),
        seq: u16,
    ) -> bool {
        if !self.mission_for_us(target.0, target.1) {
            return false;
        }
        let Transfer::Sending {
            partner,
            last_heard,
            requested,
            ..
        } = &mut self.mission.transfer
        else {
            return true;
        };
        if *partner != sender {
            return true;
        }
        *last_heard = now;
        *requested = true;
        let Some(item) = self.mission.items.get(usize::from(seq)).copied() else {
            self.mission.transfer = Transfer::Idle;
            self.send_mission_ack(
                link,
                sender,
                MavMissionResult::MAV_MISSION_ERROR,
                MavMissionType::MAV_MISSION_TYPE_MISSION,
            );
            return true;
        };
        // PX4 answers with the _INT frames (5, 6), deprecated in the XML but what flies.
        #[allow(deprecated)]
        let frame = match item.frame {
            0 => MavFrame::MAV_FRAME_GLOBAL_INT,
            3 => MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
            5 => MavFrame::MAV_FRAME_GLOBAL_INT,
            6 => MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
            _ => MavFrame::MAV_FRAME_MISSION,
        };
        let command = mav_cmd(item.command);
        let msg = MavMessage::MISSION_ITEM_INT(MISSION_ITEM_INT_DATA {
            param1: item.params[0],
            param2: item.params[1],
            param3: item.params[2],
            param4: item.params[3],
            x: item.x,
            y: item.y,
            z: item.z,
            seq,
            command,
            target_system: sender.0,
            target_component: sender.1,
            frame,
            current: u8::from(usize::from(seq) == self.mission.current),
            autocontinue: item.autocontinue,
            mission_type: MavMissionType::MAV_MISSION_TYPE_MISSION,
        });
        self.send(link, &msg);
        true
    }

    /// MISSION_ACK from the client: a download is over.
    pub(super) fn on_mission_ack(&mut self, sender: (u8, u8), target: (u8, u8)) -> bool {
        if !self.mission_for_us(target.0, target.1) {
            return false;
        }
        if let Transfer::Sending { partner, .. } = self.mission.transfer
            && partner == sender
        {
            self.mission.transfer = Transfer::Idle;
        }
        true
    }

    /// MISSION_CLEAR_ALL.
    pub(super) fn on_mission_clear(
        &mut self,
        link: LinkId,
        sender: (u8, u8),
        target: (u8, u8),
        mission_type: MavMissionType,
    ) -> bool {
        if !self.mission_for_us(target.0, target.1) {
            return false;
        }
        if self.mission.transfer != Transfer::Idle {
            return true;
        }
        if matches!(
            mission_type,
            MavMissionType::MAV_MISSION_TYPE_MISSION | MavMissionType::MAV_MISSION_TYPE_ALL
        ) {
            self.mission.replace(Vec::new(), Some(0));
        }
        self.send_mission_ack(
            link,
            sender,
            MavMissionResult::MAV_MISSION_ACCEPTED,
            mission_type,
        );
        true
    }

    /// MISSION_SET_CURRENT: no answer but the next MISSION_CURRENT, as PX4.
    pub(super) fn on_mission_set_current(&mut self, target: (u8, u8), seq: u16) -> bool {
        if !self.mission_for_us(target.0, target.1) {
            return false;
        }
        if self.mission.transfer == Transfer::Idle && usize::from(seq) < self.mission.items.len() {
            self.jump_to_item(usize::from(seq));
        }
        true
    }

    /// Retries and timeouts of the transfer in progress, and the 1 Hz MISSION_CURRENT.
    pub(super) fn mission_timers(&mut self, now: SimTime) {
        match &mut self.mission.transfer {
            Transfer::Receiving {
                link,
                partner,
                items,
                last_heard,
                last_request,
                legacy,
                ..
            } => {
                if now - *last_heard > TRANSFER_TIMEOUT {
                    tracing::warn!(sysid = self.cfg.system_id, "mission sync timeout");
                    self.mission.transfer = Transfer::Idle;
                } else if now - *last_request >= RETRY {
                    *last_request = now;
                    let (link, partner, seq, legacy) = (*link, *partner, items.len(), *legacy);
                    self.request_item(link, partner, seq, legacy);
                }
            }
            Transfer::Sending {
                link,
                partner,
                last_heard,
                last_sent,
                requested,
            } => {
                if now - *last_heard > TRANSFER_TIMEOUT {
                    self.mission.transfer = Transfer::Idle;
                } else if !*requested && now - *last_sent >= RETRY {
                    *last_sent = now;
                    let (link, partner) = (*link, *partner);
                    let n = self.mission.items.len();
                    self.send_mission_count(
                        link,
                        partner,
                        n,
                        MavMissionType::MAV_MISSION_TYPE_MISSION,
                    );
                }
            }
            Transfer::Idle => {}
        }
        if now >= self.mission.next_report {
            self.mission.next_report = now + Duration::from_secs(1);
            self.report_mission();
        }
    }

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
            fence_id: 0,
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
fn mav_cmd(command: u16) -> MavCmd {
    use num_traits::FromPrimitive;
    MavCmd::from_u16(command).unwrap_or(MavCmd::MAV_CMD_NAV_WAYPOINT)
}
