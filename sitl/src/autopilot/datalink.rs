//! PX4's data-link-loss failsafe: ground-station heartbeats (HEARTBEAT with type GCS,
//! from any system) are tracked; once one has been heard, silence for COM_DL_LOSS_T plus
//! PX4's 2.5 s heartbeat staleness is a lost link. NAV_DLL_ACT says what then happens
//! to an armed vehicle (0 nothing, the default; 1 Hold; 2 Return; 3 Land; 5 Terminate;
//! 6 Disarm); a vehicle already landing keeps landing. Hearing the station again does not
//! undo the action (PX4 clears it on the next mode change). With NAV_DLL_ACT > 0, arming
//! needs a connected ground station, as PX4's "No connection to the GCS" check.

use std::time::Duration;

use super::{FlightMode, Vehicle};
use crate::time::SimTime;

/// PX4's `HEARTBEAT_TIMEOUT_US`: a heartbeat keeps the station "connected" this long.
const HEARTBEAT_STALE: Duration = Duration::from_millis(2500);

/// The ground-station link's state.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub(super) struct DataLink {
    last_gcs_heartbeat: Option<SimTime>,
    lost: bool,
}

impl Vehicle {
    /// A HEARTBEAT from a ground station arrived at `now`.
    pub(super) fn note_gcs_heartbeat(&mut self, now: SimTime) {
        if self.datalink.lost {
            tracing::info!(sysid = self.cfg.system_id, "ground station link regained");
        }
        self.datalink = DataLink {
            last_gcs_heartbeat: Some(now),
            lost: false,
        };
    }

    /// Whether a ground station is connected (heard within the staleness window and not
    /// declared lost).
    pub(super) fn gcs_connected(&self, now: SimTime) -> bool {
        self.datalink
            .last_gcs_heartbeat
            .is_some_and(|t| now.saturating_since(t) <= HEARTBEAT_STALE)
    }

    /// The data-link-loss check of one step.
    pub(super) fn check_datalink(&mut self, now: SimTime) {
        let Some(last) = self.datalink.last_gcs_heartbeat else {
            return;
        };
        if self.datalink.lost {
            return;
        }
        if now.saturating_since(last) <= HEARTBEAT_STALE + self.tuning.datalink_loss {
            return;
        }
        self.datalink.lost = true;
        tracing::warn!(
            sysid = self.cfg.system_id,
            silent_ms = now.saturating_since(last).as_millis() as u64,
            "connection to ground station lost"
        );
        let action = self.tuning.datalink_loss_action;
        if action == 0 || !self.modes.armed() || self.modes.mode == FlightMode::Land {
            return;
        }
        self.modes.failsafe = true;
        match action {
            1 => self.enter_mode(FlightMode::Hold),
            2 => self.enter_mode(FlightMode::Return),
            3 => self.enter_mode(FlightMode::Land),
            5 | 6 => self.disarm("data link loss failsafe"),
            _ => {}
        }
    }
}
