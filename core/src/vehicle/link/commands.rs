//! What the link sends and what answers mean: the handshake (stream, arm, OFFBOARD), the
//! landing and disarm, the hand-over to the vehicle's own Hold, the vehicle's own
//! decisions after a loss, and each command's acknowledgement, retries included.

use std::time::Duration;

use ringswarm_wire::time::SimTime;

use super::super::{LinkEvent, PX4_MAIN_AUTO, PX4_MAIN_OFFBOARD, PX4_SUB_AUTO_LOITER, Phase};
use super::{Pending, VehicleLink};
use crate::link::{Command, Outgoing};

/// MAV_RESULT_ACCEPTED.
const ACCEPTED: u8 = 0;
/// How long an ACCEPTED for DO_SET_MODE waits for a second, real answer (PX4 main sends
/// it a few milliseconds after its early ACCEPTED).
pub(super) const MODE_ACK_SETTLE: Duration = Duration::from_millis(100);
/// Message ids the coordinator asks to be streamed, and GPS_GLOBAL_ORIGIN asked for (at
/// the start of streaming, then with every heartbeat until it has come).
const LOCAL_POSITION_NED: u32 = 32;
const ATTITUDE_QUATERNION: u32 = 31;
const GPS_GLOBAL_ORIGIN: u32 = 49;
/// Streams of PX4's onboard link (`mavlink_main.cpp`, MAVLINK_MODE_ONBOARD) the
/// coordinator does not read, turned off on its link (interval −1): every one of them is
/// a datagram the vehicle sends and the coordinator parses for nothing, and together they
/// are most of what a large swarm would send it. ATTITUDE (100 Hz on PX4's onboard link)
/// and GLOBAL_POSITION_INT (50) first, then HIGHRES_IMU (50), ODOMETRY (30), RC_CHANNELS
/// (20), the 10 Hz ones (ALTITUDE, DISTANCE_SENSOR, ATTITUDE_TARGET, SERVO_OUTPUT_RAW,
/// VFR_HUD, POSITION_TARGET_LOCAL_NED and _GLOBAL_INT, NAV_CONTROLLER_OUTPUT), and
/// SYS_STATUS, GPS_RAW_INT, BATTERY_STATUS, HOME_POSITION. A stream the autopilot does
/// not have is refused harmlessly; a ground station on another link keeps its own.
const UNREAD_STREAMS: [u32; 17] = [
    30, 33, 105, 331, 65, 141, 132, 83, 36, 74, 85, 87, 62, 1, 24, 147, 242,
];

impl VehicleLink {
    pub(super) fn hand_to_hold(&mut self, now: SimTime, reason: String, resume_when_fresh: bool) {
        self.phase = Phase::VehicleHold;
        self.held = Some(resume_when_fresh);
        self.hold_confirmed = false;
        self.heartbeats_out_of_offboard = 0;
        self.events.push_back(LinkEvent::HandedToHold(reason));
        let hold = Command::SetMode {
            main: PX4_MAIN_AUTO,
            sub: PX4_SUB_AUTO_LOITER,
        };
        self.send_pending(now, hold, 1);
    }

    pub(super) fn request_land(&mut self, now: SimTime) {
        self.phase = Phase::Landing;
        self.send_pending(now, Command::Land, 1);
    }

    pub(super) fn request_disarm(&mut self, now: SimTime) {
        self.phase = Phase::Disarming;
        self.events.push_back(LinkEvent::Landed);
        self.send_pending(now, Command::Disarm, 1);
    }

    pub(super) fn finish(&mut self) {
        self.pending = None;
        self.phase = Phase::Done;
        self.events.push_back(LinkEvent::Disarmed);
    }

    /// Heard again after a loss. Before it first flew, the handshake starts over. After,
    /// the vehicle's own decisions win: still armed in OFFBOARD, it is taken on; anything
    /// else it chose (its failsafe's Hold, Return or Land, a disarm) is left alone unless
    /// `retake_offboard`. A vehicle we had handed to its Hold and that is in it without a
    /// failsafe (PX4 says CRITICAL while one acts) stays ours.
    pub(super) fn recover(&mut self, now: SimTime) {
        self.events.push_back(LinkEvent::Recovered);
        // In the Hold we asked for, and not because its own failsafe chose it.
        let ours = self.held.is_some() && self.state.in_hold() && !self.state.failsafe;
        if !ours {
            self.held = None;
        }
        if self.land_requested {
            self.request_land(now);
        } else if ours {
            self.phase = Phase::VehicleHold;
        } else if !self.has_flown
            || self.cfg.retake_offboard
            || (self.state.armed && self.state.in_offboard())
        {
            // Still armed in OFFBOARD (a loss shorter than its COM_OF_LOSS_T): the usual
            // stream then DO_SET_MODE, which it already is in; no arming.
            self.start_streaming(now);
        } else {
            self.left_offboard(now);
        }
    }

    /// The vehicle left OFFBOARD (or disarmed) by itself.
    pub(super) fn left_offboard(&mut self, now: SimTime) {
        self.pending = None;
        self.events.push_back(LinkEvent::LeftOffboard {
            custom_mode: self.state.custom_mode,
            armed: self.state.armed,
        });
        if self.cfg.retake_offboard {
            self.start_streaming(now);
        } else {
            self.phase = Phase::Overridden;
        }
    }

    pub(super) fn start_streaming(&mut self, now: SimTime) {
        self.phase = Phase::Streaming(now);
        self.pending = None;
        self.next_setpoint = now;
        let us = |d: std::time::Duration| Some(d.as_micros() as f32);
        let streams = [
            (LOCAL_POSITION_NED, us(self.cfg.telemetry_interval)),
            (ATTITUDE_QUATERNION, us(self.cfg.attitude_interval)),
        ];
        let off = UNREAD_STREAMS.map(|id| (id, None));
        for (message_id, interval_us) in streams.into_iter().chain(off) {
            let stream = Command::StreamInterval {
                message_id,
                interval_us,
            };
            self.send_command(stream, 0);
        }
        self.request_origin();
        self.start_fence_upload(now);
    }

    /// Asks for GPS_GLOBAL_ORIGIN once (fire and forget: the heartbeat timer asks again
    /// while it has not come, so a lost request or answer costs a second, not the 5 s
    /// of PX4's slow origin stream).
    pub(super) fn request_origin(&mut self) {
        let origin = Command::RequestMessage {
            message_id: GPS_GLOBAL_ORIGIN,
        };
        self.send_command(origin, 0);
    }

    /// A heartbeat may show that a command took effect even if its ack was lost.
    pub(super) fn advance_on_state(&mut self, now: SimTime) {
        if self.phase == Phase::Arming && self.state.armed {
            self.request_offboard(now);
        }
        if self.phase == Phase::Offboarding && self.state.armed && self.state.in_offboard() {
            self.enter_flying();
        }
        if self.phase == Phase::Landing {
            if self.pending.is_some_and(|p| p.command == Command::Land) && self.state.in_land() {
                self.pending = None;
                self.events.push_back(LinkEvent::Landing);
            }
            if self.state.landed {
                if self.state.armed {
                    self.request_disarm(now);
                } else {
                    self.events.push_back(LinkEvent::Landed);
                    self.finish();
                }
            }
        }
        if self.phase == Phase::Disarming && !self.state.armed {
            self.finish();
        }
    }

    pub(super) fn enter_flying(&mut self) {
        self.pending = None;
        self.phase = Phase::Flying;
        self.has_flown = true;
        self.held = None;
        self.heartbeats_out_of_offboard = 0;
        self.events.push_back(LinkEvent::Flying);
    }

    pub(super) fn on_ack(&mut self, now: SimTime, command: u16, result: u8) {
        let Some(pending) = self.pending else { return };
        if pending.command.id() != command {
            return;
        }
        if result != ACCEPTED {
            self.events
                .push_back(LinkEvent::Refused { command, result });
            if let Some(p) = &mut self.pending
                && p.accepted
            {
                // The real answer after an early ACCEPTED: refused after all.
                p.accepted = false;
                p.deadline = now + self.cfg.ack_timeout;
            }
            return; // resent at the deadline
        }
        match self.phase {
            Phase::Arming => self.request_offboard(now),
            Phase::Offboarding => {
                if let Some(p) = &mut self.pending {
                    p.accepted = true;
                    p.deadline = now + MODE_ACK_SETTLE;
                }
            }
            Phase::Landing => {
                self.pending = None;
                self.events.push_back(LinkEvent::Landing);
            }
            Phase::Disarming => self.finish(),
            Phase::VehicleHold => {
                self.pending = None;
                self.hold_confirmed = true;
            }
            _ => {}
        }
    }

    pub(super) fn request_arm(&mut self, now: SimTime) {
        self.phase = Phase::Arming;
        self.send_pending(now, Command::Arm, 1);
    }

    pub(super) fn request_offboard(&mut self, now: SimTime) {
        self.phase = Phase::Offboarding;
        let offboard = Command::SetMode {
            main: PX4_MAIN_OFFBOARD,
            sub: 0,
        };
        self.send_pending(now, offboard, 1);
    }

    pub(super) fn send_pending(&mut self, now: SimTime, command: Command, attempt: u8) {
        self.send_command(command, attempt - 1);
        self.pending = Some(Pending {
            command,
            attempt,
            deadline: now + self.cfg.ack_timeout,
            accepted: false,
        });
    }

    /// Sends `command`; `confirmation` counts its resends before this one.
    pub(super) fn send_command(&mut self, command: Command, confirmation: u8) {
        let target_system = self.cfg.system_id;
        self.queue(Outgoing::Command {
            command,
            target_system,
            confirmation,
        });
    }
}
