//! What the link sends and what answers mean: the handshake (stream, arm, the fly mode,
//! in the order the vehicle's autopilot takes them), the landing and disarm, the
//! hand-over to the vehicle's own hold mode, the vehicle's own decisions after a loss,
//! and each command's acknowledgement, retries included.

use std::time::Duration;

use ringswarm_wire::time::SimTime;

use super::super::params::ParamSession;
use super::super::{LinkEvent, Phase};
use super::{Pending, VehicleLink};
use crate::link::{Outgoing, StreamRate, VehicleCommand};

/// MAV_RESULT_ACCEPTED.
const ACCEPTED: u8 = 0;
/// How long an ACCEPTED for DO_SET_MODE waits for a second, real answer (PX4 main sends
/// it a few milliseconds after its early ACCEPTED).
pub(super) const MODE_ACK_SETTLE: Duration = Duration::from_millis(100);
/// GPS_GLOBAL_ORIGIN, asked for at the start of streaming, then with every heartbeat
/// until it has come.
const GPS_GLOBAL_ORIGIN: u32 = 49;
/// MAV_RESULT_FAILED: ArduPilot's answer to an arm its checks refuse.
const FAILED: u8 = 4;

impl VehicleLink {
    pub(super) fn hand_to_hold(&mut self, now: SimTime, reason: String, resume_when_fresh: bool) {
        self.phase = Phase::VehicleHold;
        self.held = Some(resume_when_fresh);
        self.hold_confirmed = None;
        self.heartbeats_out_of_offboard = 0;
        self.events.push_back(LinkEvent::HandedToHold(reason));
        let hold = self.state.dialect().hold_mode();
        self.send_pending(now, hold, 1);
    }

    pub(super) fn request_land(&mut self, now: SimTime) {
        self.phase = Phase::Landing;
        self.send_pending(now, VehicleCommand::Land, 1);
    }

    pub(super) fn request_disarm(&mut self, now: SimTime) {
        self.phase = Phase::Disarming;
        self.events.push_back(LinkEvent::Landed);
        self.send_pending(now, VehicleCommand::Disarm, 1);
    }

    /// Disarmed on the ground: done, once what the handshake wrote on the vehicle is put
    /// back (the link stays Disarming meanwhile).
    pub(super) fn finish(&mut self, now: SimTime) {
        self.pending = None;
        if self.restore_running() {
            return; // already putting back
        }
        self.events.push_back(LinkEvent::Disarmed);
        self.close(now);
    }

    /// Done with a disarmed vehicle: at once, or once what the handshake wrote on it is put
    /// back (Disarming meanwhile).
    pub(super) fn close(&mut self, now: SimTime) {
        if self.start_restore(now) {
            self.phase = Phase::Disarming;
        } else if !self.restore_running() {
            self.phase = Phase::Done;
        } else {
            self.phase = Phase::Disarming;
        }
    }

    /// Starts putting back what the handshake wrote on the vehicle (a write still in
    /// flight included), once; `true` when it started now.
    pub(super) fn start_restore(&mut self, now: SimTime) -> bool {
        let changed = self
            .params
            .as_ref()
            .map(ParamSession::to_restore)
            .unwrap_or_default();
        if changed.is_empty() || self.restore.is_some() {
            return false;
        }
        let mut restore =
            ParamSession::restore(&changed, self.cfg.ack_timeout, self.cfg.max_attempts);
        let sends = restore.start(now);
        self.restore = Some(restore);
        self.send_params(sends);
        true
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
            || (self.state.armed && self.state.in_fly_mode())
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
            autopilot: self.state.dialect(),
            custom_mode: self.state.custom_mode,
            armed: self.state.armed,
        });
        if self.cfg.retake_offboard {
            self.start_streaming(now);
        } else {
            self.phase = Phase::Overridden;
            // Someone else flies it now: its parameters go back at once (ArduPilot's
            // MAV_GCS_SYSID decides whose RC overrides it takes).
            self.start_restore(now);
        }
    }

    pub(super) fn start_streaming(&mut self, now: SimTime) {
        self.phase = Phase::Streaming(now);
        self.pending = None;
        self.next_setpoint = now;
        let us = |d: std::time::Duration| Some(d.as_micros() as f32);
        for (message_id, rate) in self.state.dialect().streams() {
            let interval_us = match rate {
                StreamRate::Telemetry => us(self.cfg.telemetry_interval),
                StreamRate::Attitude => us(self.cfg.attitude_interval),
                StreamRate::Fixed(us) => Some(us),
                StreamRate::Off => None,
            };
            let stream = VehicleCommand::StreamInterval {
                message_id,
                interval_us,
            };
            self.send_command(stream, 0);
        }
        self.request_origin();
        self.start_fence_upload(now);
        let sends = self
            .params
            .as_mut()
            .map(|p| p.start(now))
            .unwrap_or_default();
        self.send_params(sends);
    }

    /// The next step of the handshake from what the vehicle is now: arm, switch to the fly
    /// mode (in the order its autopilot takes them), or fly.
    pub(super) fn next_handshake_step(&mut self, now: SimTime) {
        let (armed, in_mode) = (self.state.armed, self.state.in_fly_mode());
        if self.state.dialect().mode_before_arming() {
            if !in_mode {
                self.request_fly_mode(now);
            } else if !armed {
                self.request_arm(now);
            } else {
                self.enter_flying();
            }
        } else if armed {
            self.request_fly_mode(now);
        } else {
            self.request_arm(now);
        }
    }

    /// The fly mode was taken (acknowledged, or shown by the heartbeat).
    pub(super) fn mode_taken(&mut self, now: SimTime) {
        if self.state.dialect().mode_before_arming() && !self.state.armed {
            self.request_arm(now);
        } else {
            self.enter_flying();
        }
    }

    /// The vehicle armed (acknowledged, or shown by the heartbeat).
    fn armed_now(&mut self, now: SimTime) {
        if self.state.dialect().mode_before_arming() {
            self.enter_flying();
        } else {
            self.request_fly_mode(now);
        }
    }

    /// Asks for GPS_GLOBAL_ORIGIN once (fire and forget: the heartbeat timer asks again
    /// while it has not come, so a lost request or answer costs a second, not the 5 s
    /// of PX4's slow origin stream).
    pub(super) fn request_origin(&mut self) {
        let origin = VehicleCommand::RequestMessage {
            message_id: GPS_GLOBAL_ORIGIN,
        };
        self.send_command(origin, 0);
    }

    /// A heartbeat may show that a command took effect even if its ack was lost.
    pub(super) fn advance_on_state(&mut self, now: SimTime) {
        if self.phase == Phase::Arming && self.state.armed {
            self.armed_now(now);
        }
        if self.phase == Phase::Offboarding
            && self.state.in_fly_mode()
            && (self.state.armed || self.state.dialect().mode_before_arming())
        {
            self.mode_taken(now);
        }
        if self.phase == Phase::Landing {
            if self
                .pending
                .is_some_and(|p| p.command == VehicleCommand::Land)
                && self.state.in_land()
            {
                self.pending = None;
                self.events.push_back(LinkEvent::Landing);
            }
            if self.state.landed {
                if self.state.armed {
                    self.request_disarm(now);
                } else {
                    self.events.push_back(LinkEvent::Landed);
                    self.finish(now);
                }
            }
        }
        if self.phase == Phase::Disarming && !self.state.armed {
            self.finish(now);
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
            if self.phase == Phase::Arming
                && result == FAILED
                && self.state.dialect().reports_prearm()
            {
                // Its checks said no (an EKF not yet ready, named in its STATUSTEXT):
                // wait for them again; the swarm's handshake timeout bounds the wait.
                self.pending = None;
                self.state.prearm_ok = None;
                self.phase = Phase::Streaming(now);
                return;
            }
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
            Phase::Arming => self.armed_now(now),
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
            Phase::Disarming => self.finish(now),
            Phase::VehicleHold => {
                self.pending = None;
                self.hold_confirmed = Some(now);
            }
            _ => {}
        }
    }

    pub(super) fn request_arm(&mut self, now: SimTime) {
        self.phase = Phase::Arming;
        self.send_pending(now, VehicleCommand::Arm, 1);
    }

    pub(super) fn request_fly_mode(&mut self, now: SimTime) {
        self.phase = Phase::Offboarding;
        let mode = self.state.dialect().fly_mode();
        self.send_pending(now, mode, 1);
    }

    pub(super) fn send_pending(&mut self, now: SimTime, command: VehicleCommand, attempt: u8) {
        self.send_command(command, attempt - 1);
        self.pending = Some(Pending {
            command,
            attempt,
            deadline: now + self.cfg.ack_timeout,
            accepted: false,
        });
    }

    /// Sends `command`; `confirmation` counts its resends before this one.
    pub(super) fn send_command(&mut self, command: VehicleCommand, confirmation: u8) {
        let target_system = self.cfg.system_id;
        self.queue(Outgoing::Command {
            command,
            target_system,
            confirmation,
        });
    }
}
