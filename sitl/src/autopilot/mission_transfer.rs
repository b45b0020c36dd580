//! The MAVLink mission protocol as PX4's `mavlink_mission.cpp` speaks it, for mission
//! items and fence plans (rally plans: only their clearing is accepted), as a sans-IO
//! machine: it reads the stored plans, asks the vehicle for [`TransferStep`]s (send this,
//! acknowledge that, store this plan) and keeps no plan of its own. The items' rules are in
//! `mission_item` and `geofence`.
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

use std::collections::VecDeque;
use std::time::Duration;

use mavlink::dialects::common::{
    MISSION_COUNT_DATA, MISSION_ITEM_INT_DATA, MISSION_REQUEST_INT_DATA, MavMessage,
    MavMissionResult, MavMissionType,
};

use super::LinkId;
use super::geofence::{MAX_FENCE_ITEMS, check_fence_item};
use super::mission_item::{
    MissionItem, check_item, item_from_int, item_message_float, item_message_int,
};
use crate::time::SimTime;

/// How often a request (or the count of a download) is repeated.
const RETRY: Duration = Duration::from_millis(250);
/// How long a transfer waits for its partner before it is dropped.
const TRANSFER_TIMEOUT: Duration = Duration::from_secs(5);
/// Most items a mission may have (PX4 SITL's storage).
const MAX_ITEMS: usize = 10_000;

/// A sender or target: (system, component).
type Peer = (u8, u8);

/// What the vehicle has stored, as the transfer reads it.
#[derive(Debug, Clone, Copy)]
pub(super) struct StoredPlans<'a> {
    /// The mission's items and checksum.
    pub(super) mission: &'a [MissionItem],
    pub(super) mission_crc: u32,
    /// The mission's current item.
    pub(super) current_seq: usize,
    /// The fence plan's items and checksum.
    pub(super) fence: &'a [MissionItem],
    pub(super) fence_crc: u32,
}

impl StoredPlans<'_> {
    fn items(&self, mission_type: MavMissionType) -> &[MissionItem] {
        match mission_type {
            MavMissionType::MAV_MISSION_TYPE_MISSION => self.mission,
            MavMissionType::MAV_MISSION_TYPE_FENCE => self.fence,
            _ => &[],
        }
    }

    fn crc(&self, mission_type: MavMissionType) -> u32 {
        match mission_type {
            MavMissionType::MAV_MISSION_TYPE_MISSION => self.mission_crc,
            MavMissionType::MAV_MISSION_TYPE_FENCE => self.fence_crc,
            _ => 0,
        }
    }
}

/// What the transfer asks of the vehicle, in order.
#[derive(Debug, Clone, PartialEq)]
pub(super) enum TransferStep {
    /// Send a request, a count or an item (boxed: a message is large, and a transfer's
    /// steps are few).
    Send(LinkId, Box<MavMessage>),
    /// Replace the stored plan of a type (`Store` of no items clears it); `current` is
    /// the mission's new current item, if the plan named one.
    Store {
        mission_type: MavMissionType,
        items: Vec<MissionItem>,
        current: Option<usize>,
    },
    /// MISSION_ACK; an accepted one carries the stored plan's checksum as it is when the
    /// ack is sent (after a `Store` before it).
    Ack {
        link: LinkId,
        to: Peer,
        result: MavMissionResult,
        mission_type: MavMissionType,
    },
}

/// Where a transfer is.
#[derive(Debug, Clone, PartialEq)]
enum Transfer {
    Idle,
    Receiving {
        link: LinkId,
        partner: Peer,
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
        partner: Peer,
        last_heard: SimTime,
        last_sent: SimTime,
        requested: bool,
        mission_type: MavMissionType,
    },
}

/// One vehicle's mission transfer.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct MissionTransfer {
    state: Transfer,
    /// ArduPilot asks every item with MISSION_REQUEST (MissionItemProtocol.cpp).
    always_legacy_requests: bool,
    system_id: u8,
    steps: VecDeque<TransferStep>,
}

impl MissionTransfer {
    pub(super) fn new(system_id: u8, always_legacy_requests: bool) -> Self {
        Self {
            state: Transfer::Idle,
            always_legacy_requests,
            system_id,
            steps: VecDeque::new(),
        }
    }

    /// Whether no transfer is in progress.
    pub(super) fn is_idle(&self) -> bool {
        self.state == Transfer::Idle
    }

    /// The next thing to do, if any.
    pub(super) fn poll_step(&mut self) -> Option<TransferStep> {
        self.steps.pop_front()
    }

    fn ack(&mut self, link: LinkId, to: Peer, result: MavMissionResult, kind: MavMissionType) {
        self.steps.push_back(TransferStep::Ack {
            link,
            to,
            result,
            mission_type: kind,
        });
    }

    fn store(
        &mut self,
        mission_type: MavMissionType,
        items: Vec<MissionItem>,
        current: Option<usize>,
    ) {
        self.steps.push_back(TransferStep::Store {
            mission_type,
            items,
            current,
        });
    }

    fn request_item(
        &mut self,
        link: LinkId,
        to: Peer,
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
        #[allow(deprecated)]
        let msg = if legacy || self.always_legacy_requests {
            MavMessage::MISSION_REQUEST(mavlink::dialects::common::MISSION_REQUEST_DATA {
                seq: data.seq,
                target_system: data.target_system,
                target_component: data.target_component,
                mission_type: data.mission_type,
            })
        } else {
            MavMessage::MISSION_REQUEST_INT(data)
        };
        self.steps
            .push_back(TransferStep::Send(link, Box::new(msg)));
    }

    fn send_count(
        &mut self,
        link: LinkId,
        to: Peer,
        plans: &StoredPlans<'_>,
        mission_type: MavMissionType,
    ) {
        let msg = MavMessage::MISSION_COUNT(MISSION_COUNT_DATA {
            count: plans.items(mission_type).len() as u16,
            target_system: to.0,
            target_component: to.1,
            mission_type,
            opaque_id: plans.crc(mission_type),
        });
        self.steps
            .push_back(TransferStep::Send(link, Box::new(msg)));
    }

    /// MISSION_COUNT: starts an upload (or clears with 0).
    pub(super) fn on_count(
        &mut self,
        now: SimTime,
        link: LinkId,
        sender: Peer,
        m: &MISSION_COUNT_DATA,
    ) {
        let count = usize::from(m.count);
        let kind = m.mission_type;
        let max = match kind {
            MavMissionType::MAV_MISSION_TYPE_MISSION => MAX_ITEMS,
            MavMissionType::MAV_MISSION_TYPE_FENCE => MAX_FENCE_ITEMS,
            _ => {
                // Rally plans are not flown: only their clearing is accepted.
                let result = if count == 0 {
                    MavMissionResult::MAV_MISSION_ACCEPTED
                } else {
                    MavMissionResult::MAV_MISSION_UNSUPPORTED
                };
                self.ack(link, sender, result, kind);
                return;
            }
        };
        match &self.state {
            Transfer::Receiving {
                partner,
                items,
                legacy,
                mission_type,
                ..
            } if *partner == sender && items.is_empty() && *mission_type == kind => {
                // The partner did not hear our first request: ask again.
                let legacy = *legacy;
                self.request_item(link, sender, 0, legacy, kind);
                return;
            }
            Transfer::Idle => {}
            _ => {
                self.ack(link, sender, MavMissionResult::MAV_MISSION_ERROR, kind);
                return;
            }
        }
        if count > max {
            self.ack(link, sender, MavMissionResult::MAV_MISSION_NO_SPACE, kind);
            return;
        }
        if count == 0 {
            self.store(kind, Vec::new(), Some(0));
            self.ack(link, sender, MavMissionResult::MAV_MISSION_ACCEPTED, kind);
            return;
        }
        self.state = Transfer::Receiving {
            link,
            partner: sender,
            count,
            items: Vec::with_capacity(count),
            last_heard: now,
            last_request: now,
            legacy: false,
            current: None,
            mission_type: kind,
        };
        self.request_item(link, sender, 0, false, kind);
    }

    /// MISSION_ITEM_INT (or a legacy MISSION_ITEM converted to it) during an upload.
    pub(super) fn on_item(
        &mut self,
        now: SimTime,
        link: LinkId,
        sender: Peer,
        m: &MISSION_ITEM_INT_DATA,
        legacy: bool,
        plans: &StoredPlans<'_>,
    ) {
        let Transfer::Receiving {
            partner,
            items,
            last_heard,
            legacy: transfer_legacy,
            mission_type,
            ..
        } = &mut self.state
        else {
            // The last item again after the final ack: the partner missed the ack.
            if usize::from(m.seq) + 1 == plans.items(m.mission_type).len() {
                self.ack(
                    link,
                    sender,
                    MavMissionResult::MAV_MISSION_ACCEPTED,
                    m.mission_type,
                );
            }
            return;
        };
        if *partner != sender {
            return;
        }
        if m.mission_type != *mission_type {
            self.ack(
                link,
                sender,
                MavMissionResult::MAV_MISSION_ERROR,
                m.mission_type,
            );
            return;
        }
        *last_heard = now;
        *transfer_legacy = legacy;
        if usize::from(m.seq) != items.len() {
            return; // out of sequence: the retry timer asks for the right one
        }
        let kind = *mission_type;
        let item = item_from_int(m);
        if let Err(result) = check_uploaded(&item, kind, legacy) {
            tracing::debug!(
                sysid = self.system_id,
                seq = m.seq,
                ?result,
                "mission item refused"
            );
            self.state = Transfer::Idle;
            self.ack(link, sender, result, kind);
            return;
        }
        self.accept_item(now, link, sender, item, m.current != 0);
    }

    /// Keeps an item that passed its checks; asks for the next one, or stores the plan
    /// after the last.
    fn accept_item(
        &mut self,
        now: SimTime,
        link: LinkId,
        sender: Peer,
        item: MissionItem,
        is_current: bool,
    ) {
        let Transfer::Receiving {
            count,
            items,
            last_request,
            legacy,
            current,
            mission_type,
            ..
        } = &mut self.state
        else {
            return;
        };
        let kind = *mission_type;
        if is_current {
            *current = Some(items.len());
        }
        items.push(item);
        if items.len() < *count {
            *last_request = now;
            let (next, legacy) = (items.len(), *legacy);
            self.request_item(link, sender, next, legacy, kind);
            return;
        }
        let (items, current) = (std::mem::take(items), *current);
        self.state = Transfer::Idle;
        let n = items.len();
        self.store(kind, items, current);
        self.ack(link, sender, MavMissionResult::MAV_MISSION_ACCEPTED, kind);
        if kind == MavMissionType::MAV_MISSION_TYPE_MISSION {
            tracing::info!(sysid = self.system_id, items = n, "mission stored");
        }
    }

    /// MISSION_REQUEST_LIST: starts a download.
    pub(super) fn on_request_list(
        &mut self,
        now: SimTime,
        link: LinkId,
        sender: Peer,
        mission_type: MavMissionType,
        plans: &StoredPlans<'_>,
    ) {
        let restart = matches!(
            self.state,
            Transfer::Sending { partner, .. } if partner == sender
        );
        if !self.is_idle() && !restart {
            return; // busy: PX4 only says so in a status text
        }
        if matches!(
            mission_type,
            MavMissionType::MAV_MISSION_TYPE_MISSION | MavMissionType::MAV_MISSION_TYPE_FENCE
        ) {
            self.state = Transfer::Sending {
                link,
                partner: sender,
                last_heard: now,
                last_sent: now,
                requested: false,
                mission_type,
            };
        }
        self.send_count(link, sender, plans, mission_type);
    }

    /// MISSION_REQUEST_INT (or legacy MISSION_REQUEST) during a download.
    pub(super) fn on_request(
        &mut self,
        now: SimTime,
        link: LinkId,
        sender: Peer,
        seq: u16,
        legacy: bool,
        plans: &StoredPlans<'_>,
    ) {
        let Transfer::Sending {
            partner,
            last_heard,
            requested,
            mission_type,
            ..
        } = &mut self.state
        else {
            return;
        };
        if *partner != sender {
            return;
        }
        *last_heard = now;
        *requested = true;
        let kind = *mission_type;
        let Some(mut item) = plans.items(kind).get(usize::from(seq)).copied() else {
            self.state = Transfer::Idle;
            self.ack(link, sender, MavMissionResult::MAV_MISSION_ERROR, kind);
            return;
        };
        if kind == MavMissionType::MAV_MISSION_TYPE_FENCE {
            // PX4 keeps no altitude frame for fence points: they come back absolute, with
            // param2-4 zero and autocontinue 0.
            item.frame = 0;
            item.params[1..].fill(0.0);
            item.autocontinue = 0;
        }
        // As PX4, `current` compares with the mission's current item whatever the type.
        let current = u8::from(usize::from(seq) == plans.current_seq);
        let mut msg = if legacy {
            item_message_float(&item, seq, sender, current)
        } else {
            item_message_int(&item, seq, sender, current)
        };
        match &mut msg {
            MavMessage::MISSION_ITEM_INT(d) => d.mission_type = kind,
            #[allow(deprecated)]
            MavMessage::MISSION_ITEM(d) => d.mission_type = kind,
            _ => {}
        }
        self.steps
            .push_back(TransferStep::Send(link, Box::new(msg)));
    }

    /// MISSION_ACK from the client: a download is over.
    pub(super) fn on_ack(&mut self, sender: Peer) {
        if let Transfer::Sending { partner, .. } = self.state
            && partner == sender
        {
            self.state = Transfer::Idle;
        }
    }

    /// MISSION_CLEAR_ALL (ignored during a transfer).
    pub(super) fn on_clear(&mut self, link: LinkId, sender: Peer, mission_type: MavMissionType) {
        if !self.is_idle() {
            return;
        }
        for kind in [
            MavMissionType::MAV_MISSION_TYPE_MISSION,
            MavMissionType::MAV_MISSION_TYPE_FENCE,
        ] {
            if mission_type == kind || mission_type == MavMissionType::MAV_MISSION_TYPE_ALL {
                self.store(kind, Vec::new(), Some(0));
            }
        }
        self.ack(
            link,
            sender,
            MavMissionResult::MAV_MISSION_ACCEPTED,
            mission_type,
        );
    }

    /// Retries and timeouts of the transfer in progress.
    pub(super) fn handle_timeout(&mut self, now: SimTime, plans: &StoredPlans<'_>) {
        match &mut self.state {
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
                    tracing::warn!(sysid = self.system_id, "mission sync timeout");
                    self.state = Transfer::Idle;
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
                    self.state = Transfer::Idle;
                } else if !*requested && now.saturating_since(*last_sent) >= RETRY {
                    *last_sent = now;
                    let (link, partner, kind) = (*link, *partner, *mission_type);
                    self.send_count(link, partner, plans, kind);
                }
            }
            Transfer::Idle => {}
        }
    }
}

/// An uploaded item's checks: a legacy MISSION_ITEM carries degrees as floats, so an
/// _INT frame there is wrong; then the rules of its plan type.
fn check_uploaded(
    item: &MissionItem,
    kind: MavMissionType,
    legacy: bool,
) -> Result<(), MavMissionResult> {
    if legacy && matches!(item.frame, 5 | 6) {
        return Err(MavMissionResult::MAV_MISSION_UNSUPPORTED_FRAME);
    }
    if kind == MavMissionType::MAV_MISSION_TYPE_FENCE {
        check_fence_item(item, legacy)
    } else {
        check_item(item)
    }
}

#[cfg(test)]
#[path = "tests_transfer.rs"]
mod tests;
