//! The vehicle's navigator, as PX4's `navigator` and `mc_pos_control` share the work:
//! what the current mode steers to ([`Nav`]), the heading it holds, the stored mission,
//! and the position controller that turns a target into attitude and thrust. The
//! vehicle's modes, commands and failsafes decide; the navigator holds what they decided.

use super::flight::Nav;
use super::mission::MissionStore;
use crate::position_control::PositionController;

/// The navigation state of one vehicle.
#[derive(Debug, Clone)]
pub(super) struct Navigator {
    /// What the current mode steers to.
    pub(super) nav: Nav,
    /// The heading the navigator holds (rad, NED).
    pub(super) yaw_rad: f64,
    /// The stored mission, its progress and its transfer.
    pub(super) mission: MissionStore,
    /// PX4's multicopter position controller.
    pub(super) pos_ctrl: PositionController,
    /// Whether the position controller flew the last step (it is reset when it takes
    /// over again).
    pub(super) pos_ctrl_active: bool,
}

impl Navigator {
    /// A navigator starting with `nav` on heading `yaw_rad`, no mission.
    pub(super) fn new(nav: Nav, yaw_rad: f64) -> Self {
        Self {
            nav,
            yaw_rad,
            mission: MissionStore::default(),
            pos_ctrl: PositionController::default(),
            pos_ctrl_active: false,
        }
    }
}
