//! The MAVLink mission protocol as PX4's `mavlink_mission.cpp` speaks it, for mission
//! items and fence plans (rally plans: only their clearing is accepted); the items' rules
//! are in `mission` and `geofence`.
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
//! Legacy MISSION_REQUEST and MISSION_ITEM are answered in kind.

use std::time::Duration;

use mavlink::dialects::common::{
    MISSION_ACK_DATA, MISSION_COUNT_DATA, MISSION_ITEM_INT_DATA, MISSION_REQUEST_INT_DATA,
    MavFrame, MavMessage, MavMissionResult, MavMissionType,
};

use super::geofence::{MAX_FENCE_ITEMS, check_fence_item};
use super::mission_item::{MissionItem, check_item, item_from_int, mav_cmd};
use super::{LinkId, Vehicle};
use crate::time::SimTime;

/// How often a request (or the count of a download) is repeated.
const RETRY: Duration = Duration::from_millis(250);
/// How long a transfer waits for its partner before it is dropped.
const TRANSFER_TIMEOUT: Duration = Duration::from_secs(5);
/// Most items a mission may have (PX4 SITL's storage).
const MAX_ITEMS: usize = 10_000;

/// Where a transfer is.
#[derive(Debug, Clone, PartialEq)]
pub(super) enum Transfer {
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
        mission_type: MavMissionType,
    },
    Sending {
        link: LinkId,
        partner: (u8, u8),
        last_heard: SimTime,
        last_sent: SimTime,
        requested: bool,
        mission_type: MavMissionType,
    },
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
            self.plan_crc(mission_type)
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

    /// The stored plan's checksum (`opaque_id`) of a mission type.
    fn plan_crc(&self, mission_type: MavMissionType) -> u32 {
        match mission_type {
            MavMissionType::MAV_MISSION_TYPE_MISSION => self.navigator.mission.crc,
            MavMissionType::MAV_MISSION_TYPE_FENCE => self.geofence.crc,
            _ => 0,
        }
    }

    /// Items in the stored plan of a mission type.
    fn plan_len(&self, mission_type: MavMissionType) -> usize {
        match mission_type {
            MavMissionType::MAV_MISSION_TYPE_MISSION => self.navigator.mission.items().len(),
            MavMissionType::MAV_MISSION_TYPE_FENCE => self.geofence.items().len(),
            _ => 0,
        }
    }

    fn request_item(
        &mut self,
        link: LinkId,
        to: (u8, u8),
        seq: usize,
        legacy: bool,
        mission_type: MavMissionType,
    ) {
        let data = MISSION_REQUEST_INT_DATA {
            seq: seq as u16,
            target_system: to.0,
            target_component: to.1,
            mission_type,
        };
        // ArduPilot asks every item with MISSION_REQUEST (MissionItemProtocol.cpp).
        let legacy = legacy || self.is_ardupilot();
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
        let max = match m.mission_type {
            MavMissionType::MAV_MISSION_TYPE_MISSION => MAX_ITEMS,
            MavMissionType::MAV_MISSION_TYPE_FENCE => MAX_FENCE_ITEMS,
            _ => {
                // Rally plans are not flown: only their clearing is accepted.
                let result = if count == 0 {
                    MavMissionResult::MAV_MISSION_ACCEPTED
                } else {
                    MavMissionResult::MAV_MISSION_UNSUPPORTED
                };
                self.send_mission_ack(link, sender, result, m.mission_type);
                return true;
            }
        };
        match &self.navigator.mission.transfer {
            Transfer::Receiving {
                partner,
                items,
                legacy,
                mission_type,
                ..
            } if *partner == sender && items.is_empty() && *mission_type == m.mission_type => {
                // The partner did not hear our first request: ask again.
                let legacy = *legacy;
                self.request_item(link, sender, 0, legacy, m.mission_type);
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
        if count > max {
            self.send_mission_ack(
                link,
                sender,
                MavMissionResult::MAV_MISSION_NO_SPACE,
                m.mission_type,
            );
            return true;
        }
        if count == 0 {
            if m.mission_type == MavMissionType::MAV_MISSION_TYPE_FENCE {
                self.replace_fence(Vec::new());
            } else {
                self.replace_mission(Vec::new(), Some(0));
            }
            self.send_mission_ack(
                link,
                sender,
                MavMissionResult::MAV_MISSION_ACCEPTED,
                m.mission_type,
            );
            return true;
        }
        self.navigator.mission.transfer = Transfer::Receiving {
            link,
            partner: sender,
            count,
            items: Vec::with_capacity(count),
            last_heard: now,
            last_request: now,
            legacy: false,
            current: None,
            mission_type: m.mission_type,
        };
        self.request_item(link, sender, 0, false, m.mission_type);
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
            mission_type,
            ..
        } = &mut self.navigator.mission.transfer
        else {
            // The last item again after the final ack: the partner missed the ack.
            if usize::from(m.seq) + 1 == self.plan_len(m.mission_type) {
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
        let mission_type = *mission_type;
        if m.mission_type != mission_type {
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
            self.navigator.mission.transfer = Transfer::Idle;
            self.send_mission_ack(
                link,
                sender,
                MavMissionResult::MAV_MISSION_UNSUPPORTED_FRAME,
                m.mission_type,
            );
            return true;
        }
        let checked = if mission_type == MavMissionType::MAV_MISSION_TYPE_FENCE {
            check_fence_item(&item, legacy)
        } else {
            check_item(&item)
        };
        if let Err(result) = checked {
            tracing::debug!(
                sysid = self.cfg.system_id,
                seq = m.seq,
                ?result,
                "mission item refused"
            );
            self.navigator.mission.transfer = Transfer::Idle;
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
            self.request_item(link, sender, next, legacy, mission_type);
            return true;
        }
        let (items, current) = (std::mem::take(items), *current);
        self.navigator.mission.transfer = Transfer::Idle;
        if mission_type == MavMissionType::MAV_MISSION_TYPE_FENCE {
            self.replace_fence(items);
            self.send_mission_ack(
                link,
                sender,
                MavMissionResult::MAV_MISSION_ACCEPTED,
                mission_type,
            );
            return true;
        }
        self.replace_mission(items, current);
        self.send_mission_ack(
            link,
            sender,
            MavMissionResult::MAV_MISSION_ACCEPTED,
            m.mission_type,
        );
        tracing::info!(
            sysid = self.cfg.system_id,
            items = self.navigator.mission.items().len(),
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
        let restart = matches!(
            self.navigator.mission.transfer,
            Transfer::Sending { partner, .. } if partner == sender
        );
        if self.navigator.mission.transfer != Transfer::Idle && !restart {
            return true; // busy: PX4 only says so in a status text
        }
        let count = self.plan_len(mission_type);
        if matches!(
            mission_type,
            MavMissionType::MAV_MISSION_TYPE_MISSION | MavMissionType::MAV_MISSION_TYPE_FENCE
        ) {
            self.navigator.mission.transfer = Transfer::Sending {
                link,
                partner: sender,
                last_heard: now,
                last_sent: now,
                requested: false,
                mission_type,
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
            opaque_id: self.plan_crc(mission_type),
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
        legacy: bool,
    ) -> bool {
        if !self.mission_for_us(target.0, target.1) {
            return false;
        }
        let Transfer::Sending {
            partner,
            last_heard,
            requested,
            mission_type,
            ..
        } = &mut self.navigator.mission.transfer
        else {
            return true;
        };
        if *partner != sender {
            return true;
        }
        *last_heard = now;
        *requested = true;
        let mission_type = *mission_type;
        let fence = mission_type == MavMissionType::MAV_MISSION_TYPE_FENCE;
        let stored = if fence {
            self.geofence.items()
        } else {
            self.navigator.mission.items()
        };
        let Some(mut item) = stored.get(usize::from(seq)).copied() else {
            self.navigator.mission.transfer = Transfer::Idle;
            self.send_mission_ack(
                link,
                sender,
                MavMissionResult::MAV_MISSION_ERROR,
                mission_type,
            );
            return true;
        };
        if fence {
            // PX4 keeps no altitude frame for fence points: they come back absolute, with
            // param2-4 zero and autocontinue 0.
            item.frame = 0;
            item.params[1..].fill(0.0);
            item.autocontinue = 0;
        }
        // As PX4, `current` compares with the mission's current item whatever the type.
        let current = u8::from(usize::from(seq) == self.navigator.mission.current_seq());
        let mut msg = if legacy {
            item_message_float(&item, seq, sender, current)
        } else {
            item_message_int(&item, seq, sender, current)
        };
        match &mut msg {
            MavMessage::MISSION_ITEM_INT(d) => d.mission_type = mission_type,
            #[allow(deprecated)]
            MavMessage::MISSION_ITEM(d) => d.mission_type = mission_type,
            _ => {}
        }
        self.send(link, &msg);
        true
    }

    /// MISSION_ACK from the client: a download is over.
    pub(super) fn on_mission_ack(&mut self, sender: (u8, u8), target: (u8, u8)) -> bool {
        if !self.mission_for_us(target.0, target.1) {
            return false;
        }
        if let Transfer::Sending { partner, .. } = self.navigator.mission.transfer
            && partner == sender
        {
            self.navigator.mission.transfer = Transfer::Idle;
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
        if self.navigator.mission.transfer != Transfer::Idle {
            return true;
        }
        if matches!(
            mission_type,
            MavMissionType::MAV_MISSION_TYPE_MISSION | MavMissionType::MAV_MISSION_TYPE_ALL
        ) {
            self.replace_mission(Vec::new(), Some(0));
        }
        if matches!(
            mission_type,
            MavMissionType::MAV_MISSION_TYPE_FENCE | MavMissionType::MAV_MISSION_TYPE_ALL
        ) {
            self.replace_fence(Vec::new());
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
        if self.navigator.mission.transfer == Transfer::Idle
            && usize::from(seq) < self.navigator.mission.items().len()
        {
            self.jump_to_item(usize::from(seq));
        }
        true
    }

    /// Retries and timeouts of the transfer in progress, and the 1 Hz MISSION_CURRENT.
    pub(super) fn mission_timers(&mut self, now: SimTime) {
        match &mut self.navigator.mission.transfer {
            Transfer::Receiving {
                link,
                partner,
                items,
                last_heard,
                last_request,
                legacy,
                mission_type,
                ..
            } => {
                if now.saturating_since(*last_heard) > TRANSFER_TIMEOUT {
                    tracing::warn!(sysid = self.cfg.system_id, "mission sync timeout");
                    self.navigator.mission.transfer = Transfer::Idle;
                } else if now.saturating_since(*last_request) >= RETRY {
                    *last_request = now;
                    let (link, partner, seq, legacy, kind) =
                        (*link, *partner, items.len(), *legacy, *mission_type);
                    self.request_item(link, partner, seq, legacy, kind);
                }
            }
            Transfer::Sending {
                link,
                partner,
                last_heard,
                last_sent,
                requested,
                mission_type,
            } => {
                if now.saturating_since(*last_heard) > TRANSFER_TIMEOUT {
                    self.navigator.mission.transfer = Transfer::Idle;
                } else if !*requested && now.saturating_since(*last_sent) >= RETRY {
                    *last_sent = now;
                    let (link, partner, kind) = (*link, *partner, *mission_type);
                    let n = self.plan_len(kind);
                    self.send_mission_count(link, partner, n, kind);
                }
            }
            Transfer::Idle => {}
        }
        if now >= self.navigator.mission.next_report {
            self.navigator.mission.next_report = now + Duration::from_secs(1);
            self.report_mission();
        }
    }
}

/// A stored item as MISSION_ITEM_INT; PX4 answers with the _INT frames (5, 6),
/// deprecated in the XML but what flies.
#[allow(deprecated)]
fn item_message_int(item: &MissionItem, seq: u16, to: (u8, u8), current: u8) -> MavMessage {
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
fn item_message_float(item: &MissionItem, seq: u16, to: (u8, u8), current: u8) -> MavMessage {
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
