//! What the link makes of each message from its vehicle: one handler per inbound
//! message, dispatched from [`VehicleLink::apply`]'s single match (the heartbeat drives
//! the phases; telemetry goes through the gate; answers to the handshake's parameters
//! and fence go to their sessions).

use std::time::Duration;

use nalgebra::{UnitQuaternion, Vector3};
use ringswarm_wire::geo::Geodetic;
use ringswarm_wire::time::SimTime;

use super::super::params::ParamSession;
use super::super::telemetry::{OriginVerdict, PositionVerdict};
use super::super::{LinkEvent, Phase, Setpoint};
use super::VehicleLink;
use crate::link::{Autopilot, AutopilotChoice, Inbound, autopilot_name, mission_result_name};

impl VehicleLink {
    /// Takes one decoded message from the vehicle.
    pub(super) fn apply(&mut self, now: SimTime, update: Inbound) {
        match update {
            Inbound::Heartbeat {
                armed,
                custom_mode,
                autopilot,
                failsafe,
            } => self.on_heartbeat(now, armed, custom_mode, autopilot, failsafe),
            Inbound::LocalPosition {
                sampled_ms,
                pos_ned_m,
                vel_ned_mps,
            } => self.on_local_position(now, sampled_ms, pos_ned_m, vel_ned_mps),
            Inbound::Attitude(q) => self.on_attitude(q),
            Inbound::Origin(origin) => self.on_origin(origin),
            Inbound::Landed(landed) => {
                self.state.landed = landed;
                self.advance_on_state(now);
            }
            Inbound::Estimator { usable, flags } => self.on_estimator(now, usable, flags),
            Inbound::Ack {
                command, result, ..
            } => self.on_ack(now, command, result),
            Inbound::TimesyncReply {
                ts1_ns,
                target_system,
            } => self.on_timesync_reply(now, ts1_ns, target_system),
            Inbound::ParamValue { name, value } => self.on_param_value(now, &name, value),
            Inbound::StatusText { text, .. } => self.on_status_text(text),
            Inbound::Prearm(ok) => self.state.prearm_ok = Some(ok),
            Inbound::FenceRequest { seq, target_system } => {
                if self.fence_answer_is_ours(target_system) {
                    let answer = self.fence.as_mut().map(|f| f.on_request(now, seq));
                    self.on_fence_answer(answer);
                }
            }
            Inbound::FenceAck {
                result,
                target_system,
            } => {
                if self.fence_answer_is_ours(target_system) {
                    let name = mission_result_name(result);
                    let answer = self.fence.as_mut().map(|f| f.on_ack(result, &name));
                    self.on_fence_answer(answer);
                }
            }
        }
    }

    /// HEARTBEAT: the autopilot (on the first), armed state and mode, and what they mean
    /// in this phase.
    fn on_heartbeat(
        &mut self,
        now: SimTime,
        armed: bool,
        custom_mode: u32,
        autopilot: u8,
        failsafe: bool,
    ) {
        if self.phase == Phase::Discovering {
            match self.dialect_of(autopilot) {
                Ok(dialect) => self.state.autopilot = Some(dialect),
                Err(reason) => {
                    self.fail(reason);
                    return;
                }
            }
        }
        self.state.last_heartbeat = Some(now);
        self.state.custom_mode = custom_mode;
        self.state.failsafe = failsafe;
        if armed && !self.state.armed {
            self.events.push_back(LinkEvent::Armed);
        }
        self.state.armed = armed;
        match self.phase {
            Phase::Discovering => {
                let autopilot = self.state.dialect();
                self.events.push_back(LinkEvent::Discovered { autopilot });
                let steps = autopilot.setup_params(self.cfg.own_ids.0, self.fence.is_some());
                self.params = Some(ParamSession::new(
                    steps,
                    self.cfg.ack_timeout,
                    self.cfg.max_attempts,
                ));
                self.start_streaming(now);
            }
            Phase::Lost => self.recover(now),
            Phase::Flying => {
                // Two in a row: a heartbeat sent just before the switch may still
                // arrive after the acknowledgement.
                if self.state.in_fly_mode() && armed {
                    self.heartbeats_out_of_offboard = 0;
                } else {
                    self.heartbeats_out_of_offboard += 1;
                    if self.heartbeats_out_of_offboard >= 2 {
                        self.left_offboard(now);
                    }
                }
            }
            Phase::VehicleHold => {
                if self.state.in_hold() {
                    self.heartbeats_out_of_offboard = 0;
                    if self.pending.is_some() {
                        self.pending = None;
                        self.hold_confirmed = Some(now);
                    }
                } else if self.hold_confirmed.is_some() {
                    // Out of the Hold we asked for, by itself (a pilot, its
                    // battery failsafe): its decision.
                    self.heartbeats_out_of_offboard += 1;
                    if self.heartbeats_out_of_offboard >= 2 {
                        self.held = None;
                        self.left_offboard(now);
                    }
                }
            }
            _ => self.advance_on_state(now),
        }
    }

    /// LOCAL_POSITION_NED, through the gate.
    fn on_local_position(
        &mut self,
        now: SimTime,
        sampled_ms: u32,
        pos_ned_m: Vector3<f64>,
        vel_ned_mps: Vector3<f64>,
    ) {
        let verdict = self.gate.position_report(
            now,
            Some(sampled_ms),
            pos_ned_m,
            vel_ned_mps,
            self.cfg.state_timeout,
        );
        match verdict {
            PositionVerdict::Refused(why) => self.refuse_report(why),
            accepted => {
                if let PositionVerdict::Reset { jump_m } = accepted {
                    self.events.push_back(LinkEvent::PositionReset { jump_m });
                }
                self.refusing = false;
                self.state.pos_local_ned_m = pos_ned_m;
                self.state.vel_ned_mps = vel_ned_mps;
                self.state.last_position = Some(now);
                // A jump taken or a new origin is no motion: the window starts over.
                let mut restart = matches!(accepted, PositionVerdict::Reset { .. });
                if let Some(origin) = self.next_origin.take() {
                    self.state.origin = Some(origin);
                    restart = true;
                }
                if restart {
                    self.unseen.restart();
                }
                let t_s = self.vehicle_time_s(sampled_ms);
                self.unseen.report(t_s, pos_ned_m.xy(), vel_ned_mps.xy());
                self.take_back_if_usable(now);
            }
        }
    }

    /// The vehicle's time of a report (s, counted from its first report), from its
    /// `time_boot_ms`: forward by the wrapped difference up to a minute; a clock that went
    /// back (a reboot) or leapt is put an hour on, which starts [`crate::control::UnseenMotion`]'s window
    /// over.
    fn vehicle_time_s(&mut self, sampled_ms: u32) -> f64 {
        let t_s = match self.vehicle_clock {
            Some((last_ms, last_s)) => {
                let forward_ms = sampled_ms.wrapping_sub(last_ms);
                if forward_ms <= 60_000 {
                    last_s + f64::from(forward_ms) * 1e-3
                } else {
                    last_s + 3600.0
                }
            }
            None => 0.0,
        };
        self.vehicle_clock = Some((sampled_ms, t_s));
        t_s
    }

    /// ATTITUDE_QUATERNION.
    fn on_attitude(&mut self, q: UnitQuaternion<f64>) {
        self.state.attitude = Some(q);
    }

    /// GPS_GLOBAL_ORIGIN, through the gate.
    fn on_origin(&mut self, origin: Geodetic) {
        match self.gate.origin_report(origin) {
            OriginVerdict::First | OriginVerdict::Same => self.state.origin = Some(origin),
            OriginVerdict::Changed { shift_m } => {
                // The position in hand was reported against the old origin: the new
                // one is taken with the next position the gate accepts.
                self.next_origin = Some(origin);
                self.events.push_back(LinkEvent::OriginChanged { shift_m });
            }
            OriginVerdict::Refused(why) => self.refuse_report(why),
        }
    }

    /// ESTIMATOR_STATUS: a lost position hands a flying vehicle to its own hold.
    fn on_estimator(&mut self, now: SimTime, usable: bool, flags: u16) {
        let was = self.state.estimate_lost;
        self.state.estimate_lost = (!usable).then_some(flags);
        if was.is_none() && !usable {
            self.events.push_back(LinkEvent::EstimateLost { flags });
            if self.phase == Phase::Flying {
                self.hand_to_hold(
                    now,
                    format!("its estimator lost its position (flags 0x{flags:03x})"),
                    true,
                );
            }
        } else if was.is_some() && usable {
            self.events.push_back(LinkEvent::EstimateGood { flags });
            self.take_back_if_usable(now);
        }
    }

    /// TIMESYNC answering ours: the round trip.
    fn on_timesync_reply(&mut self, now: SimTime, ts1_ns: i64, target_system: u8) {
        let ours = target_system == 0 || target_system == self.cfg.own_ids.0;
        if ours && self.timesync_sent_ns == Some(ts1_ns) {
            self.timesync_sent_ns = None;
            let sample =
                Duration::from_nanos((now.as_micros() * 1000).saturating_sub(ts1_ns.max(0) as u64));
            self.round_trip = Some(match self.round_trip {
                Some(rtt) if sample < rtt => rtt.mul_f64(0.9) + sample.mul_f64(0.1),
                _ => sample,
            });
        }
    }

    /// STATUSTEXT of warning or worse, said once while it repeats.
    fn on_status_text(&mut self, text: String) {
        if self.last_warning.as_deref() != Some(text.as_str()) {
            self.events.push_back(LinkEvent::VehicleSays(text.clone()));
            self.last_warning = Some(text);
        }
    }

    pub(super) fn refuse_report(&mut self, why: String) {
        self.refused_reports += 1;
        if !self.refusing {
            self.refusing = true;
            self.events.push_back(LinkEvent::TelemetryRefused(why));
        }
    }

    /// The dialect a first heartbeat's `autopilot` asks for, or why the vehicle is
    /// refused: an autopilot the coordinator does not speak (its mode numbers would mean
    /// something else), or not the one configured. ArduPilot is flown with attitude
    /// setpoints only.
    pub(super) fn dialect_of(&self, autopilot: u8) -> Result<Autopilot, String> {
        let id = self.cfg.system_id;
        let Some(dialect) = Autopilot::from_heartbeat(autopilot) else {
            return Err(format!(
                "vehicle {id}: autopilot is {}: refused (ringswarm speaks PX4 and ArduPilot)",
                autopilot_name(autopilot)
            ));
        };
        if let AutopilotChoice::Only(want) = self.cfg.autopilot
            && want != dialect
        {
            return Err(format!(
                "vehicle {id}: its heartbeat says {}, the configuration autopilot = \"{}\": refused",
                autopilot_name(autopilot),
                want.key()
            ));
        }
        if dialect == Autopilot::ArduPilot && matches!(self.setpoint, Setpoint::Acceleration(_)) {
            return Err(format!(
                "vehicle {id}: ArduPilot is flown with attitude setpoints only (swarm.setpoint = \"attitude\")"
            ));
        }
        Ok(dialect)
    }
}
