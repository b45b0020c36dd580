//! The ArduPilot (ArduCopter 4.7) personality: what a vehicle configured with
//! [`Personality::ArduPilot`] does differently on the wire, read from ArduCopter's source
//! (`ArduCopter/mode_guided.cpp`, `GCS_MAVLink_Copter.cpp`, `motors.cpp`, `mode.h`). The
//! same physics and controllers fly underneath; the flight modes map onto the emulator's:
//!
//! | ArduCopter mode (number) | flown as |
//! |---|---|
//! | STABILIZE (0), the boot mode | Hold on the ground (there is no pilot to fly it) |
//! | GUIDED (4), GUIDED_NOGPS (20) | Offboard (attitude targets), Takeoff after NAV_TAKEOFF, then Hold |
//! | LOITER (5), BRAKE (17) | Hold; a vehicle started in the air is in LOITER, flown as Position |
//! | RTL (6), LAND (9), AUTO (3) | Return, Land, Mission |
//!
//! ```text
//!  boot ──ekf_settle──► position estimate: LOCAL_POSITION_NED, GPS_GLOBAL_ORIGIN and
//!        HOME_POSITION exist, SYS_STATUS's pre-arm bit set, arming allowed
//!        (before: ARM FAILED + "Arm: Need Position Estimate")
//!  any mode while disarmed (DO_SET_MODE needs param1 bit 0); armed, GUIDED, LOITER,
//!        RTL, BRAKE and AUTO need the position estimate ("Mode change to X failed")
//!  armed ──2 s──► motors run;  landed, motors idle, DISARM_DELAY s ──► disarmed
//!  LAND ──touchdown──► disarmed (still LAND)
//!  GUIDED(_NOGPS) SET_ATTITUDE_TARGET: thrust a climb rate (0.5 holds; 1 → +WPNAV_SPEED_UP,
//!        0 → −WPNAV_SPEED_DN), or with GUID_OPTIONS bit 3 a throttle times 1/cos(tilt)
//!        (ATC_ANGLE_BOOST); refused: bit 64, a mix of ignored and used body rates, a
//!        quaternion with | |q|² − 1 | > 1e-3; none for GUID_TIMEOUT s ──► level, hold
//!        the altitude, climb-rate reading again (no mode change)
//! ```
//!
//! Nothing is streamed until asked (SET_MESSAGE_INTERVAL, param3 must be 0), the
//! HEARTBEAT is ArduCopter's (autopilot 3, base mode 81/209, the plain mode number), a
//! mode change is answered once and its heartbeat sent at once, mission and fence items
//! are asked for with MISSION_REQUEST, and the offboard link (SITL's SERIAL0, MAVLink
//! channel 0) takes unsigned frames even with a signing key.

use std::time::Duration;

use mavlink::dialects::common::{
    HEARTBEAT_DATA, MavAutopilot, MavMessage, MavModeFlag, MavResult, MavSeverity, MavState,
    MavType, SET_ATTITUDE_TARGET_DATA,
};
use nalgebra::{Quaternion, UnitQuaternion};
use ringswarm_wire::ardupilot as ap;

use super::commands::ReceivedCommand;
use super::mode::FlightMode;
use super::offboard::{OffboardTarget, att_mask};
use super::{LinkId, Vehicle};
use crate::time::SimTime;

/// The motors start this long after arming (`ArduCopter/config.h`, ARMING_DELAY_SEC).
pub(super) const MOTOR_START_DELAY: Duration = Duration::from_secs(2);
/// ArduPilot's force-arm magic numbers in param2 of ARM_DISARM.
const FORCE_ARM: [f64; 2] = [2989.0, 21196.0];
/// The one that also forces a disarm in the air.
const FORCE_DISARM: f64 = 21196.0;
/// | |q|² − 1 | above this is not a unit quaternion (`Quaternion::is_unit_length`).
const UNIT_TOLERANCE: f64 = 1e-3;

/// What the personality keeps of its own.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct ApState {
    /// The mode number last taken (the heartbeat reports it while the emulator flies a
    /// mode it maps to).
    pub mode_number: u32,
    /// When the last valid guided attitude target arrived.
    pub last_target: Option<SimTime>,
    /// How long after boot the EKF has a position.
    pub ekf_settle: Duration,
    /// Since when it has sat landed with its motors idle, armed.
    pub idle_since: Option<SimTime>,
}

impl ApState {
    /// At boot: STABILIZE on the ground, LOITER for a vehicle started in the air.
    pub(super) fn at_boot(ekf_settle: Duration, in_air: bool) -> Self {
        Self {
            mode_number: if in_air { ap::LOITER } else { ap::STABILIZE },
            last_target: None,
            ekf_settle,
            idle_since: None,
        }
    }
}

/// The emulator mode an ArduCopter mode number is flown as; `None` for modes it cannot
/// fly (those need a pilot or hardware).
pub(super) fn mode_of(number: u32) -> Option<FlightMode> {
    match number {
        ap::STABILIZE | ap::LOITER | ap::BRAKE => Some(FlightMode::Hold),
        ap::GUIDED | ap::GUIDED_NOGPS => Some(FlightMode::Offboard),
        ap::RTL => Some(FlightMode::Return),
        ap::LAND => Some(FlightMode::Land),
        ap::AUTO => Some(FlightMode::Mission),
        _ => None,
    }
}

/// Whether a heartbeat saying `number` fits the emulator flying `mode`.
fn reports(number: u32, mode: FlightMode) -> bool {
    match number {
        ap::GUIDED | ap::GUIDED_NOGPS => matches!(
            mode,
            FlightMode::Offboard | FlightMode::Takeoff | FlightMode::Hold
        ),
        ap::LOITER => matches!(mode, FlightMode::Hold | FlightMode::Position),
        other => mode_of(other) == Some(mode),
    }
}

/// The number a mode the emulator entered by itself is reported as.
fn number_of(mode: FlightMode) -> u32 {
    match mode {
        FlightMode::Position => ap::LOITER,
        FlightMode::Hold => ap::BRAKE,
        FlightMode::Takeoff | FlightMode::Offboard => ap::GUIDED,
        FlightMode::Land => ap::LAND,
        FlightMode::Return => ap::RTL,
        FlightMode::Mission => ap::AUTO,
        FlightMode::Orbit => 7, // CIRCLE
    }
}

/// Whether a mode needs a position estimate to be entered armed (`requires_GPS`).
fn needs_position(number: u32) -> bool {
    matches!(
        number,
        ap::GUIDED | ap::LOITER | ap::RTL | ap::BRAKE | ap::AUTO
    )
}

impl Vehicle {
    /// Whether the vehicle plays ArduPilot.
    pub(super) fn is_ardupilot(&self) -> bool {
        self.ap.is_some()
    }

    /// Whether its EKF has a position (ArduPilot; always for PX4's personality and for a
    /// vehicle started in the air).
    pub(super) fn ekf_ready(&self, now: SimTime) -> bool {
        match &self.ap {
            Some(s) => self.cfg.start.in_air || now.saturating_since(self.boot_at) >= s.ekf_settle,
            None => true,
        }
    }

    /// The heartbeat's mode number.
    pub(super) fn ap_custom_mode(&self) -> u32 {
        match &self.ap {
            Some(s) if reports(s.mode_number, self.modes.mode) => s.mode_number,
            _ => number_of(self.modes.mode),
        }
    }

    /// ArduCopter's HEARTBEAT (`GCS_MAVLink_Copter.cpp`): base mode 81, +128 armed;
    /// system status CRITICAL in a failsafe, STANDBY on the ground, ACTIVE in the air.
    pub(super) fn ap_heartbeat(&self) -> MavMessage {
        let mut base_mode = MavModeFlag::from_bits_truncate(ap::BASE_MODE);
        if self.modes.armed() {
            base_mode |= MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED;
        }
        let system_status = match (self.modes.failsafe, self.modes.landed()) {
            (true, _) => MavState::MAV_STATE_CRITICAL,
            (false, true) => MavState::MAV_STATE_STANDBY,
            (false, false) => MavState::MAV_STATE_ACTIVE,
        };
        MavMessage::HEARTBEAT(HEARTBEAT_DATA {
            custom_mode: self.ap_custom_mode(),
            mavtype: MavType::MAV_TYPE_QUADROTOR,
            autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
            base_mode,
            system_status,
            mavlink_version: 3,
        })
    }

    /// Sends a heartbeat on every link now, as ArduPilot does on a mode change.
    fn heartbeat_now(&mut self) {
        let hb = self.ap_heartbeat();
        for link in [LinkId::Offboard, LinkId::Gcs] {
            self.send(link, &hb);
        }
    }

    /// DO_SET_MODE (or SET_MODE) as ArduCopter takes it: param1 bit 0, the mode number in
    /// param2; any mode it flies while disarmed, the position modes armed only with a
    /// position estimate.
    pub(super) fn ap_set_mode(&mut self, now: SimTime, cmd: &ReceivedCommand) -> MavResult {
        let base = cmd.params[0].map_or(0, |b| b as u32);
        let Some(number) = cmd.params[1].filter(|_| base & 1 == 1) else {
            return MavResult::MAV_RESULT_DENIED;
        };
        let number = number as u32;
        let name = ap::mode_name(number);
        let Some(mode) = mode_of(number) else {
            self.send_statustext(
                MavSeverity::MAV_SEVERITY_WARNING,
                &format!("Mode change to {name} failed: not flown by this vehicle"),
            );
            return MavResult::MAV_RESULT_FAILED;
        };
        if self.modes.armed() && needs_position(number) && !self.ekf_ready(now) {
            self.send_statustext(
                MavSeverity::MAV_SEVERITY_WARNING,
                &format!("Mode change to {name} failed: requires position"),
            );
            return MavResult::MAV_RESULT_FAILED;
        }
        if let Some(s) = &mut self.ap {
            s.mode_number = number;
            s.last_target = None;
        }
        self.modes.failsafe = false;
        if mode == FlightMode::Offboard {
            // Guided's angle controller starts level on the current heading, climb 0.
            self.offboard = Some(self.guided_hold_target());
            self.offboard_signal = Some(now);
        }
        self.enter_mode(mode);
        self.heartbeat_now();
        MavResult::MAV_RESULT_ACCEPTED
    }

    /// Level on the current heading, holding the altitude (climb rate 0).
    fn guided_hold_target(&self) -> OffboardTarget {
        OffboardTarget::AttitudeClimb {
            attitude: UnitQuaternion::from_euler_angles(0.0, 0.0, self.yaw_rad()),
            climb_up_mps: 0.0,
            yawspeed_ff_rps: f64::NAN,
        }
    }

    /// ARM_DISARM as ArduCopter answers it: FAILED with its STATUSTEXT before the EKF has
    /// a position or in a mode that does not arm (LAND, RTL, BRAKE); a disarm in the air
    /// only forced (21196).
    pub(super) fn ap_arm_disarm(&mut self, now: SimTime, cmd: &ReceivedCommand) -> MavResult {
        let force = cmd.params[1].is_some_and(|p| FORCE_ARM.contains(&p));
        match cmd.params[0] {
            Some(1.0) if self.modes.armed() => MavResult::MAV_RESULT_ACCEPTED,
            Some(1.0) => {
                let number = self.ap_custom_mode();
                let refusal = if !self.ekf_ready(now) {
                    Some(if needs_position(number) {
                        "Arm: Need Position Estimate"
                    } else {
                        "PreArm: EKF3 waiting for GPS config data"
                    })
                } else if !force && matches!(number, ap::LAND | ap::RTL | ap::BRAKE) {
                    Some("Arm: Mode not armable")
                } else {
                    None
                };
                if let Some(text) = refusal {
                    self.send_statustext(MavSeverity::MAV_SEVERITY_CRITICAL, text);
                    return MavResult::MAV_RESULT_FAILED;
                }
                self.arm(now);
                MavResult::MAV_RESULT_ACCEPTED
            }
            Some(0.0) => {
                if !self.modes.armed() {
                    MavResult::MAV_RESULT_ACCEPTED
                } else if self.modes.landed() || cmd.params[1] == Some(FORCE_DISARM) {
                    self.disarm("commanded");
                    MavResult::MAV_RESULT_ACCEPTED
                } else {
                    MavResult::MAV_RESULT_FAILED
                }
            }
            _ => MavResult::MAV_RESULT_DENIED,
        }
    }

    /// NAV_TAKEOFF in GUIDED: param7 metres above home; FAILED disarmed, in the air, or
    /// below where it is.
    pub(super) fn ap_takeoff(&mut self, cmd: &ReceivedCommand) -> MavResult {
        let guided = self.ap.is_some_and(|s| s.mode_number == ap::GUIDED);
        let height = self.plant.env.ground_z_ned_m - self.plant.state.pos_ned_m.z;
        let Some(alt) = cmd.params[6].filter(|a| *a > height) else {
            return MavResult::MAV_RESULT_FAILED;
        };
        if !(guided && self.modes.armed() && self.modes.landed()) {
            return MavResult::MAV_RESULT_FAILED;
        }
        self.enter_mode(FlightMode::Takeoff);
        let here = self.plant.state.pos_ned_m;
        let target = nalgebra::Vector3::new(here.x, here.y, self.plant.env.ground_z_ned_m - alt);
        if let super::flight::Nav::Takeoff { approach, .. } = &mut self.navigator.nav {
            approach.retarget(target);
        }
        MavResult::MAV_RESULT_ACCEPTED
    }

    /// NAV_LAND: LAND.
    pub(super) fn ap_land(&mut self) -> MavResult {
        if let Some(s) = &mut self.ap {
            s.mode_number = ap::LAND;
        }
        self.modes.failsafe = false;
        self.enter_mode(FlightMode::Land);
        self.heartbeat_now();
        MavResult::MAV_RESULT_ACCEPTED
    }

    /// SET_ATTITUDE_TARGET as ArduCopter reads it: only in GUIDED or GUIDED_NOGPS (else
    /// dropped silently), refused by the mask and quaternion rules, the thrust a climb
    /// rate or, with GUID_OPTIONS bit 3, a throttle boosted by 1/cos(tilt).
    pub(super) fn ap_attitude_target(&mut self, now: SimTime, m: &SET_ATTITUDE_TARGET_DATA) {
        let guided = self
            .ap
            .is_some_and(|s| matches!(s.mode_number, ap::GUIDED | ap::GUIDED_NOGPS));
        if !guided || !reports(self.ap_custom_mode(), self.modes.mode) {
            self.counters.rejected_setpoints += 1;
            return;
        }
        let mask = m.type_mask.bits();
        let rates_ignored =
            mask & (att_mask::ROLL_RATE | att_mask::PITCH_RATE | att_mask::YAW_RATE);
        let mixed = rates_ignored != 0 && rates_ignored != 7;
        let q = Quaternion::new(m.q[0], m.q[1], m.q[2], m.q[3]).cast::<f64>();
        let unit = q.coords.iter().all(|x| x.is_finite())
            && (q.norm_squared() - 1.0).abs() <= UNIT_TOLERANCE;
        let attitude_ignored = mask & att_mask::ATTITUDE != 0;
        if mask & att_mask::THROTTLE != 0 || mixed || !unit || attitude_ignored {
            // ArduPilot calls init(): it stops and holds (the body-rate-only target the
            // emulator does not fly is refused the same way).
            self.counters.rejected_setpoints += 1;
            self.offboard = Some(self.guided_hold_target());
            return;
        }
        let attitude = UnitQuaternion::new_normalize(q);
        let yawspeed_ff_rps = if rates_ignored == 7 {
            f64::NAN
        } else {
            f64::from(m.body_yaw_rate)
        };
        let thrust = f64::from(m.thrust);
        if !thrust.is_finite() {
            self.counters.rejected_setpoints += 1;
            return;
        }
        let as_throttle =
            (self.params.value("GUID_OPTIONS") as u32) & ap::GUID_OPTIONS_THRUST_AS_THRUST != 0;
        let target = if as_throttle {
            let throttle = thrust.clamp(-1.0, 1.0).max(0.0);
            let boosted = if self.params.value("ATC_ANGLE_BOOST") != 0.0 {
                // AC_AttitudeControl_Multi::get_throttle_boosted: 1/cos of the target's
                // tilt, the cosine floored at 0.1.
                let cos_tilt = (attitude * nalgebra::Vector3::z()).z.clamp(0.1, 1.0);
                throttle / cos_tilt
            } else {
                throttle
            };
            OffboardTarget::Attitude {
                attitude,
                thrust: boosted.min(1.0),
                yawspeed_ff_rps,
            }
        } else {
            let t = thrust.clamp(0.0, 1.0);
            let climb_up_mps = if t >= 0.5 {
                (t - 0.5) * 2.0 * self.params.value("WPNAV_SPEED_UP") / 100.0
            } else {
                -(0.5 - t) * 2.0 * self.params.value("WPNAV_SPEED_DN") / 100.0
            };
            OffboardTarget::AttitudeClimb {
                attitude,
                climb_up_mps,
                yawspeed_ff_rps,
            }
        };
        if self.modes.mode != FlightMode::Offboard {
            // GUIDED after a takeoff holds; an attitude target takes the angle controller.
            self.enter_mode(FlightMode::Offboard);
        }
        if let Some(s) = &mut self.ap {
            s.last_target = Some(now);
        }
        self.note_offboard(now, target);
    }

    /// GUID_TIMEOUT without an attitude target in GUIDED: level, hold the altitude, read
    /// thrust as a climb rate again; no mode change.
    pub(super) fn ap_guided_timeout(&mut self, t: SimTime) {
        let Some(s) = self.ap else { return };
        if self.modes.mode != FlightMode::Offboard {
            return;
        }
        let timeout = Duration::from_secs_f64(self.params.value("GUID_TIMEOUT").max(0.1));
        let Some(last) = s.last_target else { return };
        if t.saturating_since(last) > timeout {
            self.offboard = Some(self.guided_hold_target());
            if let Some(s) = &mut self.ap {
                s.last_target = None;
            }
            tracing::info!(
                sysid = self.cfg.system_id,
                "guided timeout: levelled, holding altitude"
            );
        }
    }

    /// REQUEST_DATA_STREAM: a group of ArduPilot's streams at `rate_hz` on `link`
    /// (`start` 0 stops them): 0 all, 2 EXTENDED_STATUS (SYS_STATUS, GPS_RAW_INT),
    /// 6 POSITION (LOCAL_POSITION_NED, GLOBAL_POSITION_INT), 10 EXTRA1 (ATTITUDE), the
    /// groups of `GCS_MAVLink_Parameters.cpp` the emulator has messages for.
    pub(super) fn ap_request_data_stream(
        &mut self,
        now: SimTime,
        link: LinkId,
        group: u8,
        rate_hz: u16,
        start: u8,
    ) {
        const EXTENDED_STATUS: [u32; 2] = [1, 24];
        const POSITION: [u32; 2] = [32, 33];
        const EXTRA1: [u32; 1] = [30];
        let ids: Vec<u32> = match group {
            0 => EXTENDED_STATUS
                .iter()
                .chain(&POSITION)
                .chain(&EXTRA1)
                .copied()
                .collect(),
            2 => EXTENDED_STATUS.to_vec(),
            6 => POSITION.to_vec(),
            10 => EXTRA1.to_vec(),
            _ => return,
        };
        let interval = if start == 0 || rate_hz == 0 {
            Some(None)
        } else {
            Some(Some(Duration::from_secs_f64(
                1.0 / f64::from(rate_hz.min(50)),
            )))
        };
        for id in ids {
            self.set_interval(now, link, id, interval);
        }
    }

    /// Whether the motors run (ArduPilot: 2 s after arming).
    pub(super) fn motors_started(&self, t: SimTime) -> bool {
        !self.is_ardupilot()
            || self.modes.took_off()
            || t.saturating_since(self.modes.armed_at()) >= MOTOR_START_DELAY
    }

    /// ArduCopter's automatic disarms on the ground: right after touchdown in LAND, and
    /// after DISARM_DELAY s landed with the motors idle (`motors.cpp auto_disarm_check`).
    pub(super) fn ap_landed_disarm(&mut self, t: SimTime) {
        if !self.modes.armed() || !self.modes.landed() {
            if let Some(s) = &mut self.ap {
                s.idle_since = None;
            }
            return;
        }
        if self.modes.mode == FlightMode::Land && self.modes.took_off() {
            let settled = self
                .modes
                .landed_since()
                .is_some_and(|since| t.saturating_since(since) >= Duration::from_secs(1));
            if settled {
                self.disarm("landed");
            }
            return;
        }
        let delay = self.params.value("DISARM_DELAY");
        let weight_n = self.cfg.profile.mass_kg * crate::profile::GRAVITY_MPS2;
        let idle = self.plant.state.motor_thrust_n.sum() < 0.05 * weight_n;
        let Some(s) = &mut self.ap else { return };
        if !idle {
            s.idle_since = None;
            return;
        }
        let since = *s.idle_since.get_or_insert(t);
        if delay > 0.0 && t.saturating_since(since) >= Duration::from_secs_f64(delay) {
            self.disarm("DISARM_DELAY: landed and idle");
        }
    }
}
