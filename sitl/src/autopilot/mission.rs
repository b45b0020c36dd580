//! The stored mission: its items, progress and transfer, and the reports
//! (MISSION_CURRENT, MISSION_ITEM_REACHED). An item and its rules are in `mission_item`,
//! the transfer protocol in `mission_transfer`, the flying in `mission_run`.

use mavlink::dialects::common::{
    MISSION_CURRENT_DATA, MISSION_ITEM_REACHED_DATA, MavMessage, MissionState,
};

use super::mission_item::{MissionItem, crc_of};
use super::mission_transfer::Transfer;
use super::{LinkId, Vehicle};

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

impl Vehicle {
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
        } else if self.mode == super::FlightMode::Mission {
            MissionState::MISSION_STATE_ACTIVE
        } else if self.navigator.mission.started {
            MissionState::MISSION_STATE_PAUSED
        } else {
            MissionState::MISSION_STATE_NOT_STARTED
        };
        let in_mission = matches!(
            self.mode,
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
