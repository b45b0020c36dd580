//! The stored mission: its items and progress, the reports
//! (MISSION_CURRENT, MISSION_ITEM_REACHED). An item and its rules are in `mission_item`,
//! the transfer protocol in `mission_transfer`, the flying in `mission_run`.

use std::time::Duration;

use mavlink::dialects::common::{
    MISSION_ACK_DATA, MISSION_CURRENT_DATA, MISSION_ITEM_REACHED_DATA, MavMessage,
    MavMissionResult, MavMissionType, MissionState,
};

use super::mission_item::item_int_from_float;
use super::mission_item::{MissionItem, crc_of};
use super::mission_transfer::{StoredPlans, TransferStep};
use super::{LinkId, Vehicle};
use crate::time::SimTime;

/// The stored mission and its progress.
#[derive(Debug, Clone, PartialEq)]
pub struct MissionStore {
    items: Vec<MissionItem>,
    current: usize,
    finished: bool,
    started: bool,
    reached: Option<(u16, u8)>,
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

impl Vehicle {
    /// A mission-protocol message: checked for this autopilot (system, and component 1,
    /// 190 or broadcast, as PX4 accepts), handed to the transfer, and what the transfer
    /// asks for done.
    pub(super) fn on_mission_message(
        &mut self,
        now: SimTime,
        link: LinkId,
        sender: (u8, u8),
        msg: &MavMessage,
    ) -> bool {
        let Some(target) = mission_target(msg) else {
            return false;
        };
        let ours = target.0 == self.cfg.system_id && matches!(target.1, 0 | 1 | 190);
        if !ours {
            self.counters.foreign_target += 1;
            return false;
        }
        let plans = stored_plans(&self.navigator.mission, &self.geofence);
        let transfer = &mut self.mission_transfer;
        #[allow(deprecated)]
        match msg {
            MavMessage::MISSION_COUNT(m) => transfer.on_count(now, link, sender, m),
            MavMessage::MISSION_ITEM_INT(m) => {
                transfer.on_item(now, link, sender, m, false, &plans)
            }
            MavMessage::MISSION_ITEM(m) => {
                let m = item_int_from_float(m);
                transfer.on_item(now, link, sender, &m, true, &plans);
            }
            MavMessage::MISSION_REQUEST_LIST(m) => {
                transfer.on_request_list(now, link, sender, m.mission_type, &plans);
            }
            MavMessage::MISSION_REQUEST_INT(m) => {
                transfer.on_request(now, link, sender, m.seq, false, &plans);
            }
            MavMessage::MISSION_REQUEST(m) => {
                transfer.on_request(now, link, sender, m.seq, true, &plans);
            }
            MavMessage::MISSION_ACK(_) => transfer.on_ack(sender),
            MavMessage::MISSION_CLEAR_ALL(m) => transfer.on_clear(link, sender, m.mission_type),
            MavMessage::MISSION_SET_CURRENT(m) => {
                // No answer but the next MISSION_CURRENT, as PX4.
                let seq = usize::from(m.seq);
                if transfer.is_idle() && seq < self.navigator.mission.items().len() {
                    self.jump_to_item(seq);
                }
            }
            _ => {}
        }
        self.do_transfer_steps();
        true
    }

    /// The transfer's retries and timeouts, and the 1 Hz MISSION_CURRENT.
    pub(super) fn mission_timers(&mut self, now: SimTime) {
        // Only a transfer under way has timers (and reads the stored plans).
        if !self.mission_transfer.is_idle() {
            let plans = stored_plans(&self.navigator.mission, &self.geofence);
            self.mission_transfer.handle_timeout(now, &plans);
        }
        self.do_transfer_steps();
        if now >= self.navigator.mission.next_report {
            self.navigator.mission.next_report = now + Duration::from_secs(1);
            self.report_mission();
        }
    }

    /// Sends, stores and acknowledges what the transfer asked for, in its order.
    fn do_transfer_steps(&mut self) {
        while let Some(step) = self.mission_transfer.poll_step() {
            match step {
                TransferStep::Send(link, msg) => self.send(link, msg.as_ref()),
                TransferStep::Store {
                    mission_type: MavMissionType::MAV_MISSION_TYPE_FENCE,
                    items,
                    ..
                } => self.replace_fence(items),
                TransferStep::Store { items, current, .. } => self.replace_mission(items, current),
                TransferStep::Ack {
                    link,
                    to,
                    result,
                    mission_type,
                } => {
                    let opaque_id = match (result, mission_type) {
                        (
                            MavMissionResult::MAV_MISSION_ACCEPTED,
                            MavMissionType::MAV_MISSION_TYPE_MISSION,
                        ) => self.navigator.mission.crc,
                        (
                            MavMissionResult::MAV_MISSION_ACCEPTED,
                            MavMissionType::MAV_MISSION_TYPE_FENCE,
                        ) => self.geofence.crc,
                        _ => 0,
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
            }
        }
    }

    /// MISSION_CURRENT (and a pending MISSION_ITEM_REACHED, repeated up to 10 times at
    /// 1 Hz as PX4 does) on both links. ArduPilot sends neither unasked (they belong to
    /// its stream groups).
    pub(super) fn report_mission(&mut self) {
        if self.is_ardupilot() {
            return;
        }
        let state = if self.navigator.mission.items.is_empty() {
            MissionState::MISSION_STATE_NO_MISSION
        } else if self.navigator.mission.finished {
            MissionState::MISSION_STATE_COMPLETE
        } else if self.modes.mode == super::FlightMode::Mission {
            MissionState::MISSION_STATE_ACTIVE
        } else if self.navigator.mission.started {
            MissionState::MISSION_STATE_PAUSED
        } else {
            MissionState::MISSION_STATE_NOT_STARTED
        };
        let in_mission = matches!(
            self.modes.mode,
            super::FlightMode::Mission | super::FlightMode::Takeoff | super::FlightMode::Land
        );
        let current = MavMessage::MISSION_CURRENT(MISSION_CURRENT_DATA {
            seq: self.navigator.mission.current as u16,
            total: if self.navigator.mission.items.is_empty() {
                u16::MAX
            } else {
                self.navigator.mission.items.len() as u16
            },
            mission_state: state,
            mission_mode: if in_mission { 1 } else { 2 },
            mission_id: self.navigator.mission.crc,
            fence_id: self.geofence.crc,
            rally_points_id: 0,
        });
        let reached = self.navigator.mission.reached.map(|(seq, left)| {
            self.navigator.mission.reached = left.checked_sub(1).map(|l| (seq, l));
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
        self.navigator.mission.reached = Some((seq as u16, 10));
        self.report_mission();
    }

    /// Stores a new plan (or none) and points a mission being flown at its current item.
    pub(super) fn replace_mission(&mut self, items: Vec<MissionItem>, current: Option<usize>) {
        self.navigator.mission.replace(items, current);
        let seq = self.navigator.mission.current_seq();
        if let super::flight::Nav::Mission(run) = &mut self.navigator.nav {
            run.jump(seq);
        }
    }

    /// Makes `seq` the current item (and tells the clients).
    pub(super) fn jump_to_item(&mut self, seq: usize) {
        self.navigator.mission.set_current(seq);
        self.navigator.mission.finished = false;
        if let super::flight::Nav::Mission(run) = &mut self.navigator.nav {
            run.jump(seq);
        }
        self.report_mission();
    }
}

/// The (system, component) a mission-protocol message is addressed to; `None` for any
/// other message.
#[allow(deprecated)]
fn mission_target(msg: &MavMessage) -> Option<(u8, u8)> {
    Some(match msg {
        MavMessage::MISSION_COUNT(m) => (m.target_system, m.target_component),
        MavMessage::MISSION_ITEM_INT(m) => (m.target_system, m.target_component),
        MavMessage::MISSION_ITEM(m) => (m.target_system, m.target_component),
        MavMessage::MISSION_REQUEST_LIST(m) => (m.target_system, m.target_component),
        MavMessage::MISSION_REQUEST_INT(m) => (m.target_system, m.target_component),
        MavMessage::MISSION_REQUEST(m) => (m.target_system, m.target_component),
        MavMessage::MISSION_ACK(m) => (m.target_system, m.target_component),
        MavMessage::MISSION_CLEAR_ALL(m) => (m.target_system, m.target_component),
        MavMessage::MISSION_SET_CURRENT(m) => (m.target_system, m.target_component),
        _ => return None,
    })
}

/// The plans the transfer reads: the stored mission and fence.
fn stored_plans<'a>(mission: &'a MissionStore, fence: &'a super::Geofence) -> StoredPlans<'a> {
    StoredPlans {
        mission: mission.items(),
        mission_crc: mission.crc,
        current_seq: mission.current_seq(),
        fence: fence.items(),
        fence_crc: fence.crc,
    }
}
