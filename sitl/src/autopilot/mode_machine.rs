//! Where the vehicle is in its life: armed or not, its flight mode and failsafe, on the
//! ground or not, and PX4's rules for disarming on the ground (`COM_DISARM_LAND` after a
//! landing, `COM_DISARM_PRFLT` when it never took off). What a change sets off (the
//! controller's reset, the navigator, events, reports) is the vehicle's part.

use std::time::Duration;

use super::mode::FlightMode;
use crate::time::SimTime;

/// The arming state, the flight mode and the ground contact of one vehicle.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct ModeMachine {
    /// The flight mode.
    pub(super) mode: FlightMode,
    /// In a failsafe (offboard loss, geofence, data link) that took the mode.
    pub(super) failsafe: bool,
    armed: bool,
    landed: bool,
    took_off: bool,
    landed_since: Option<SimTime>,
    armed_at: SimTime,
}

impl ModeMachine {
    /// At boot: PX4 boots into Hold (AUTO.LOITER), disarmed, on the ground; a vehicle
    /// started in the air is armed, flown off the ground, with a pilot in Position mode.
    pub(super) fn at_boot(in_air: bool) -> Self {
        Self {
            mode: if in_air {
                FlightMode::Position
            } else {
                FlightMode::Hold
            },
            failsafe: false,
            armed: in_air,
            landed: !in_air,
            took_off: in_air,
            landed_since: None,
            armed_at: SimTime::ZERO,
        }
    }

    pub(super) fn armed(&self) -> bool {
        self.armed
    }

    /// On the ground (as the last [`ModeMachine::observe_ground`] found).
    pub(super) fn landed(&self) -> bool {
        self.landed
    }

    /// Left the ground since it was armed (or was armed in the air).
    pub(super) fn took_off(&self) -> bool {
        self.took_off
    }

    /// When it last touched down, while it is on the ground.
    pub(super) fn landed_since(&self) -> Option<SimTime> {
        self.landed_since
    }

    /// When it was last armed.
    pub(super) fn armed_at(&self) -> SimTime {
        self.armed_at
    }

    /// Arms at `t`; false if it already was.
    pub(super) fn arm(&mut self, t: SimTime) -> bool {
        if self.armed {
            return false;
        }
        self.armed = true;
        self.armed_at = t;
        self.took_off = !self.landed;
        true
    }

    /// Disarms (which ends a failsafe); false if it was not armed.
    pub(super) fn disarm(&mut self) -> bool {
        if !self.armed {
            return false;
        }
        self.armed = false;
        self.failsafe = false;
        true
    }

    /// Takes the mode; false if it already was the mode.
    pub(super) fn set_mode(&mut self, mode: FlightMode) -> bool {
        if self.mode == mode {
            return false;
        }
        self.mode = mode;
        true
    }

    /// Whether the vehicle is on the ground at `t` (the land detector's answer).
    pub(super) fn observe_ground(&mut self, on_ground: bool, t: SimTime) {
        if on_ground != self.landed {
            self.landed = on_ground;
            self.landed_since = on_ground.then_some(t);
            if !on_ground {
                self.took_off = true;
            }
        }
    }

    /// PX4's disarm on the ground at `t`, with why: landed for `after_landing` after a
    /// flight (`None`: never), or armed for `before_takeoff` without taking off (`None`:
    /// never).
    pub(super) fn ground_disarm_due(
        &self,
        t: SimTime,
        after_landing: Option<Duration>,
        before_takeoff: Option<Duration>,
    ) -> Option<&'static str> {
        if !self.armed || !self.landed {
            return None;
        }
        if self.took_off {
            let since = self.landed_since?;
            (t.saturating_since(since) >= after_landing?).then_some("landed")
        } else {
            (t.saturating_since(self.armed_at) >= before_takeoff?)
                .then_some("no takeoff after arming")
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn s(v: f64) -> SimTime {
        SimTime::ZERO + Duration::from_secs_f64(v)
    }

    const TWO_S: Option<Duration> = Some(Duration::from_secs(2));
    const TEN_S: Option<Duration> = Some(Duration::from_secs(10));

    #[test]
    fn boots_on_the_ground_in_hold_or_in_the_air_armed_in_position() {
        let ground = ModeMachine::at_boot(false);
        assert_eq!(
            (
                ground.mode,
                ground.armed(),
                ground.landed(),
                ground.took_off()
            ),
            (FlightMode::Hold, false, true, false)
        );
        let air = ModeMachine::at_boot(true);
        assert_eq!(
            (air.mode, air.armed(), air.landed(), air.took_off()),
            (FlightMode::Position, true, false, true)
        );
    }

    #[test]
    fn a_flight_disarms_two_seconds_after_touchdown_not_before() {
        let mut m = ModeMachine::at_boot(false);
        assert!(m.arm(s(1.0)));
        assert!(!m.arm(s(1.5)), "arming twice changes nothing");
        m.observe_ground(false, s(3.0));
        assert!(m.took_off());
        m.observe_ground(true, s(20.0));
        assert_eq!(m.landed_since(), Some(s(20.0)));
        assert_eq!(m.ground_disarm_due(s(21.999), TWO_S, TEN_S), None);
        assert_eq!(m.ground_disarm_due(s(22.0), TWO_S, TEN_S), Some("landed"));
        assert_eq!(m.ground_disarm_due(s(99.0), None, TEN_S), None);
        m.failsafe = true;
        assert!(m.disarm());
        assert!(!m.failsafe, "disarming ends the failsafe");
        assert!(!m.disarm());
        assert_eq!(m.ground_disarm_due(s(99.0), TWO_S, TEN_S), None);
    }

    #[test]
    fn armed_without_a_takeoff_disarms_after_the_preflight_delay() {
        let mut m = ModeMachine::at_boot(false);
        m.arm(s(5.0));
        assert!(!m.took_off());
        assert_eq!(m.ground_disarm_due(s(14.9), TWO_S, TEN_S), None);
        assert_eq!(
            m.ground_disarm_due(s(15.0), TWO_S, TEN_S),
            Some("no takeoff after arming")
        );
        assert_eq!(m.ground_disarm_due(s(15.0), TWO_S, None), None);
    }

    #[test]
    fn a_mode_change_is_reported_once() {
        let mut m = ModeMachine::at_boot(false);
        assert!(m.set_mode(FlightMode::Offboard));
        assert!(!m.set_mode(FlightMode::Offboard));
        assert_eq!(m.mode, FlightMode::Offboard);
    }
}
