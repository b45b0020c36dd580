//! Inbound messages: one function per message, dispatched from one `match`. Each checks
//! that the message is addressed to this system (or to 0, the broadcast) and that its
//! values are usable before acting.

// SET_MODE is deprecated in favour of DO_SET_MODE, but PX4 still accepts it and older
// ground stations send it, so the emulator does too.
#![allow(deprecated)]

use mavlink::dialects::common::{
    COMMAND_INT_DATA, COMMAND_LONG_DATA, HEARTBEAT_DATA, MavFrame, MavMessage, MavType,
    PARAM_REQUEST_READ_DATA, PARAM_SET_DATA, SET_ATTITUDE_TARGET_DATA, SET_MODE_DATA,
    SET_POSITION_TARGET_GLOBAL_INT_DATA, SET_POSITION_TARGET_LOCAL_NED_DATA, TIMESYNC_DATA,
};

use super::commands::ReceivedCommand;
use super::offboard::{self, AttitudeTarget, OffboardTarget, PositionTarget, Refusal};
use super::{LinkId, Vehicle};
use crate::codec::for_each_frame;
use crate::time::SimTime;

impl Vehicle {
    /// Handles one datagram received on `link` at `now`; returns whether it vouches for
    /// its sender: a frame in it was admitted and, once a key is set, signed with it (a
    /// driver lets only such a datagram choose whom the link answers: an unsigned
    /// HEARTBEAT is admitted but proves nothing). Bad frames and frames the signing rules
    /// refuse are counted and skipped; messages for other systems are counted and
    /// ignored.
    pub fn handle_datagram(&mut self, now: SimTime, link: LinkId, bytes: &[u8]) -> bool {
        let key = self.io.signing.as_ref().map(|s| s.key().clone());
        let mut vouched = false;
        for_each_frame(bytes, key.as_ref(), |decoded| match decoded {
            Ok(frame) => {
                if !self.admit(frame, link) {
                    return;
                }
                vouched |= self.io.signing.is_none() || frame.signature.is_some();
                let sender = (frame.system_id(), frame.header.component_id);
                if let MavMessage::SETUP_SIGNING(m) = &frame.msg {
                    self.on_setup_signing(m, frame.signature.is_some());
                    return;
                }
                self.handle_message(now, link, sender, &frame.msg);
            }
            Err(err) => {
                self.counters.bad_frames += 1;
                tracing::debug!(sysid = self.cfg.system_id, error = %err, "bad frame");
            }
        });
        vouched
    }

    /// PX4's rule for commands and offboard setpoints (`evaluate_target_ok`, the setpoint
    /// handlers): this system or broadcast (0), the autopilot component (1) or all (0).
    /// Anything else is ignored, counted, and never answered.
    fn for_us(&mut self, target_system: u8, target_component: u8) -> bool {
        let ours = (target_system == 0 || target_system == self.cfg.system_id)
            && matches!(target_component, 0 | 1);
        if !ours {
            self.counters.foreign_target += 1;
        }
        ours
    }

    /// PX4's rule for the parameter protocol (`mavlink_parameters.cpp`): this system
    /// exactly (no broadcast), the autopilot component or all.
    fn params_for_us(&mut self, target_system: u8, target_component: u8) -> bool {
        let ours = target_system == self.cfg.system_id && matches!(target_component, 0 | 1);
        if !ours {
            self.counters.foreign_target += 1;
        }
        ours
    }

    fn handle_message(&mut self, now: SimTime, link: LinkId, sender: (u8, u8), msg: &MavMessage) {
        let heard = match msg {
            MavMessage::HEARTBEAT(m) => self.on_heartbeat(now, m),
            MavMessage::SET_ATTITUDE_TARGET(m) => self.on_set_attitude_target(now, m),
            MavMessage::SET_POSITION_TARGET_LOCAL_NED(m) => self.on_position_target_local(now, m),
            MavMessage::SET_POSITION_TARGET_GLOBAL_INT(m) => self.on_position_target_global(now, m),
            MavMessage::MISSION_COUNT(_)
            | MavMessage::MISSION_ITEM_INT(_)
            | MavMessage::MISSION_REQUEST_LIST(_)
            | MavMessage::MISSION_REQUEST_INT(_)
            | MavMessage::MISSION_ACK(_)
            | MavMessage::MISSION_CLEAR_ALL(_)
            | MavMessage::MISSION_SET_CURRENT(_) => self.on_mission_message(now, link, sender, msg),
            #[allow(deprecated)]
            MavMessage::MISSION_ITEM(_) | MavMessage::MISSION_REQUEST(_) => {
                self.on_mission_message(now, link, sender, msg)
            }
            MavMessage::COMMAND_LONG(m) => self.on_command_long(now, link, sender, m),
            MavMessage::COMMAND_INT(m) => self.on_command_int(now, link, sender, m),
            MavMessage::SET_MODE(m) => self.on_set_mode(now, link, sender, m),
            MavMessage::PARAM_REQUEST_LIST(m) => {
                let ours = self.params_for_us(m.target_system, m.target_component);
                if ours {
                    self.send_all_params(link);
                }
                ours
            }
            MavMessage::PARAM_REQUEST_READ(m) => self.on_param_request_read(link, m),
            MavMessage::PARAM_SET(m) => self.on_param_set(link, m),
            MavMessage::TIMESYNC(m) => self.on_timesync(now, link, m),
            // ArduPilot's stream groups (MAVProxy asks for them); PX4 has none.
            #[allow(deprecated)]
            MavMessage::REQUEST_DATA_STREAM(m) if self.is_ardupilot() => {
                let ours = self.for_us(m.target_system, m.target_component);
                if ours {
                    self.ap_request_data_stream(
                        now,
                        link,
                        m.req_stream_id as u8,
                        m.req_message_rate,
                        m.start_stop,
                    );
                }
                ours
            }
            _ => true,
        };
        if heard {
            self.io.links[link as usize].last_heard = Some(now);
        }
    }

    /// A ground station's heartbeat (type GCS, from any system) feeds the data-link
    /// check, as PX4's receiver does.
    fn on_heartbeat(&mut self, now: SimTime, m: &HEARTBEAT_DATA) -> bool {
        if m.mavtype == MavType::MAV_TYPE_GCS {
            self.note_gcs_heartbeat(now);
        }
        true
    }

    /// An offboard setpoint read by [`offboard`]: flown and counted as offboard signal,
    /// or refused and counted.
    fn take_offboard(&mut self, now: SimTime, target: Result<OffboardTarget, Refusal>) -> bool {
        match target {
            Ok(target) => {
                self.note_offboard(now, target);
                true
            }
            Err(why) => {
                self.counters.rejected_setpoints += 1;
                tracing::debug!(sysid = self.cfg.system_id, ?why, "setpoint refused");
                false
            }
        }
    }

    fn on_set_attitude_target(&mut self, now: SimTime, m: &SET_ATTITUDE_TARGET_DATA) -> bool {
        if !self.for_us(m.target_system, m.target_component) {
            return false;
        }
        if self.is_ardupilot() {
            self.ap_attitude_target(now, m);
            return true;
        }
        let target = offboard::attitude_target(&AttitudeTarget {
            type_mask: m.type_mask.bits(),
            q: m.q.map(f64::from),
            body_rates_rps: [m.body_roll_rate, m.body_pitch_rate, m.body_yaw_rate].map(f64::from),
            thrust: f64::from(m.thrust),
            thrust_body: m.thrust_body.map(f64::from),
        });
        self.take_offboard(now, target)
    }

    fn on_position_target_local(
        &mut self,
        now: SimTime,
        m: &SET_POSITION_TARGET_LOCAL_NED_DATA,
    ) -> bool {
        if !self.for_us(m.target_system, m.target_component) {
            return false;
        }
        let t = PositionTarget {
            frame: m.coordinate_frame as u8,
            type_mask: m.type_mask.bits(),
            position: [m.x, m.y, m.z].map(f64::from),
            velocity: [m.vx, m.vy, m.vz].map(f64::from),
            acceleration: [m.afx, m.afy, m.afz].map(f64::from),
            yaw_rad: f64::from(m.yaw),
            yaw_rate_rps: f64::from(m.yaw_rate),
        };
        let target = offboard::local_ned(&t, &self.plant.state.attitude);
        self.take_offboard(now, target)
    }

    fn on_position_target_global(
        &mut self,
        now: SimTime,
        m: &SET_POSITION_TARGET_GLOBAL_INT_DATA,
    ) -> bool {
        if !self.for_us(m.target_system, m.target_component) {
            return false;
        }
        let t = PositionTarget {
            frame: m.coordinate_frame as u8,
            type_mask: m.type_mask.bits(),
            position: [
                f64::from(m.lat_int) * 1e-7,
                f64::from(m.lon_int) * 1e-7,
                f64::from(m.alt),
            ],
            velocity: [m.vx, m.vy, m.vz].map(f64::from),
            acceleration: [m.afx, m.afy, m.afz].map(f64::from),
            yaw_rad: f64::from(m.yaw),
            yaw_rate_rps: f64::from(m.yaw_rate),
        };
        let target = offboard::global_int(&t, &self.global_frame());
        self.take_offboard(now, target)
    }

    fn on_command_long(
        &mut self,
        now: SimTime,
        link: LinkId,
        sender: (u8, u8),
        m: &COMMAND_LONG_DATA,
    ) -> bool {
        if !self.for_us(m.target_system, m.target_component) {
            return false;
        }
        let params = [
            m.param1, m.param2, m.param3, m.param4, m.param5, m.param6, m.param7,
        ];
        self.run_wire_command(
            now,
            link,
            sender,
            ReceivedCommand::from_wire(m.command, params),
        );
        true
    }

    fn on_command_int(
        &mut self,
        now: SimTime,
        link: LinkId,
        sender: (u8, u8),
        m: &COMMAND_INT_DATA,
    ) -> bool {
        if !self.for_us(m.target_system, m.target_component) {
            return false;
        }
        let global = matches!(
            m.frame,
            MavFrame::MAV_FRAME_GLOBAL
                | MavFrame::MAV_FRAME_GLOBAL_INT
                | MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT
                | MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
                | MavFrame::MAV_FRAME_GLOBAL_TERRAIN_ALT
                | MavFrame::MAV_FRAME_GLOBAL_TERRAIN_ALT_INT
        );
        let params = [m.param1, m.param2, m.param3, m.param4];
        let command = ReceivedCommand::from_int(m.command, params, m.x, m.y, m.z, global);
        self.run_wire_command(now, link, sender, command);
        true
    }

    fn on_set_mode(
        &mut self,
        now: SimTime,
        link: LinkId,
        sender: (u8, u8),
        m: &SET_MODE_DATA,
    ) -> bool {
        if !self.for_us(m.target_system, 0) {
            return false;
        }
        // ArduPilot's custom mode is the plain mode number; PX4's packs main and sub.
        let (main, sub) = if self.is_ardupilot() {
            (m.custom_mode, 0)
        } else {
            ((m.custom_mode >> 16) & 0xFF, m.custom_mode >> 24)
        };
        let params = [
            1.0,
            main as f32,
            sub as f32,
            f32::NAN,
            f32::NAN,
            f32::NAN,
            f32::NAN,
        ];
        let command = ReceivedCommand::from_wire(
            mavlink::dialects::common::MavCmd::MAV_CMD_DO_SET_MODE,
            params,
        );
        self.run_command(now, link, sender, command);
        true
    }

    fn on_param_request_read(&mut self, link: LinkId, m: &PARAM_REQUEST_READ_DATA) -> bool {
        if !self.params_for_us(m.target_system, m.target_component) {
            return false;
        }
        let index = if m.param_index >= 0 {
            Some(m.param_index as usize).filter(|i| *i < self.params.len())
        } else {
            m.param_id.to_str().ok().and_then(|name| {
                self.params
                    .find_on_wire(name.trim_end_matches('\0'))
                    .map(|(i, _)| i)
            })
        };
        match index {
            Some(i) => self.send_param(link, i),
            None => tracing::debug!(sysid = self.cfg.system_id, "unknown parameter requested"),
        }
        true
    }

    fn on_param_set(&mut self, link: LinkId, m: &PARAM_SET_DATA) -> bool {
        if !self.params_for_us(m.target_system, m.target_component) {
            return false;
        }
        let name = m
            .param_id
            .to_str()
            .unwrap_or("")
            .trim_end_matches('\0')
            .to_owned();
        match self.params.set_on_wire(&name, m.param_value) {
            Ok(index) => {
                self.tuning = super::tuning::Tuning::from_params(&self.params);
                self.send_param(link, index);
            }
            Err(err) => {
                tracing::debug!(sysid = self.cfg.system_id, ?err, "parameter not set");
                // Answer with the current value, as PX4 does, when the name exists.
                if let Some((index, _)) = self.params.find_on_wire(&name) {
                    self.send_param(link, index);
                }
            }
        }
        true
    }

    fn on_timesync(&mut self, now: SimTime, link: LinkId, m: &TIMESYNC_DATA) -> bool {
        if m.target_system != 0 && !self.for_us(m.target_system, 0) {
            return false;
        }
        if m.tc1 == 0 {
            let reply = MavMessage::TIMESYNC(TIMESYNC_DATA {
                tc1: (now.as_micros() * 1000) as i64,
                ts1: m.ts1,
                target_system: 0,
                target_component: 0,
            });
            self.send(link, &reply);
        }
        true
    }
}
