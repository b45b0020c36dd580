//! Inbound messages: one function per message, dispatched from one `match`. Each checks
//! that the message is addressed to this system (or to 0, the broadcast) and that its
//! values are usable before acting.

// SET_MODE is deprecated in favour of DO_SET_MODE, but PX4 still accepts it and older
// ground stations send it, so the emulator does too.
#![allow(deprecated)]

use mavlink::dialects::common::{
    AttitudeTargetTypemask, COMMAND_INT_DATA, COMMAND_LONG_DATA, MavMessage,
    PARAM_REQUEST_READ_DATA, PARAM_SET_DATA, SET_ATTITUDE_TARGET_DATA, SET_MODE_DATA,
    TIMESYNC_DATA,
};
use nalgebra::{Quaternion, UnitQuaternion};

use super::commands::Command;
use super::{LinkId, Vehicle};
use crate::codec::decode_datagram;
use crate::control::AttitudeSetpoint;
use crate::time::SimTime;

/// How far a setpoint quaternion's norm may be from 1.
const UNIT_QUATERNION_TOLERANCE: f64 = 1e-3;

impl Vehicle {
    /// Handles one datagram received on `link` at `now`. Bad frames are counted and
    /// skipped; messages for other systems are counted and ignored.
    pub fn handle_datagram(&mut self, now: SimTime, link: LinkId, bytes: &[u8]) {
        for frame in decode_datagram(bytes) {
            match frame {
                Ok(frame) => {
                    let sender = (frame.header.system_id as u8, frame.header.component_id);
                    self.handle_message(now, link, sender, frame.msg);
                }
                Err(err) => {
                    self.counters.bad_frames += 1;
                    tracing::debug!(sysid = self.cfg.system_id, error = %err, "bad frame");
                }
            }
        }
    }

    fn for_us(&mut self, target_system: u8) -> bool {
        let ours = target_system == 0 || target_system == self.cfg.system_id;
        if !ours {
            self.counters.foreign_target += 1;
        }
        ours
    }

    fn handle_message(&mut self, now: SimTime, link: LinkId, sender: (u8, u8), msg: MavMessage) {
        let heard = match msg {
            MavMessage::HEARTBEAT(_) => true,
            MavMessage::SET_ATTITUDE_TARGET(m) => self.on_set_attitude_target(now, &m),
            MavMessage::COMMAND_LONG(m) => self.on_command_long(now, link, sender, &m),
            MavMessage::COMMAND_INT(m) => self.on_command_int(now, link, sender, &m),
            MavMessage::SET_MODE(m) => self.on_set_mode(now, link, sender, &m),
            MavMessage::PARAM_REQUEST_LIST(m) => {
                let ours = self.for_us(m.target_system);
                if ours {
                    self.send_all_params(link);
                }
                ours
            }
            MavMessage::PARAM_REQUEST_READ(m) => self.on_param_request_read(link, &m),
            MavMessage::PARAM_SET(m) => self.on_param_set(link, &m),
            MavMessage::TIMESYNC(m) => self.on_timesync(now, link, &m),
            _ => true,
        };
        if heard {
            self.links[link as usize].last_heard = Some(now);
        }
    }

    fn on_set_attitude_target(&mut self, now: SimTime, m: &SET_ATTITUDE_TARGET_DATA) -> bool {
        if !self.for_us(m.target_system) {
            return false;
        }
        let ignore_attitude = m
            .type_mask
            .contains(AttitudeTargetTypemask::ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE);
        let ignore_thrust = m
            .type_mask
            .contains(AttitudeTargetTypemask::ATTITUDE_TARGET_TYPEMASK_THROTTLE_IGNORE);
        let q = Quaternion::new(
            f64::from(m.q[0]),
            f64::from(m.q[1]),
            f64::from(m.q[2]),
            f64::from(m.q[3]),
        );
        let thrust = f64::from(m.thrust);
        let attitude_ok = ignore_attitude
            || (q.coords.iter().all(|x| x.is_finite())
                && (q.norm() - 1.0).abs() <= UNIT_QUATERNION_TOLERANCE);
        let thrust_ok = ignore_thrust || (thrust.is_finite() && (0.0..=1.0).contains(&thrust));
        if !attitude_ok || !thrust_ok {
            self.counters.rejected_setpoints += 1;
            tracing::debug!(sysid = self.cfg.system_id, "setpoint rejected");
            return false;
        }
        let mut setpoint: AttitudeSetpoint = self.offboard_setpoint;
        if !ignore_attitude {
            setpoint.attitude = UnitQuaternion::new_normalize(q);
        }
        if !ignore_thrust {
            setpoint.thrust_norm = thrust;
            // Only a setpoint that carries thrust proves the sender is alive.
            self.note_setpoint(now);
        }
        self.offboard_setpoint = setpoint;
        self.counters.setpoints += 1;
        true
    }

    fn on_command_long(
        &mut self,
        now: SimTime,
        link: LinkId,
        sender: (u8, u8),
        m: &COMMAND_LONG_DATA,
    ) -> bool {
        if !self.for_us(m.target_system) {
            return false;
        }
        let params = [
            m.param1, m.param2, m.param3, m.param4, m.param5, m.param6, m.param7,
        ];
        self.run_command(now, link, sender, Command::from_wire(m.command, params));
        true
    }

    fn on_command_int(
        &mut self,
        now: SimTime,
        link: LinkId,
        sender: (u8, u8),
        m: &COMMAND_INT_DATA,
    ) -> bool {
        if !self.for_us(m.target_system) {
            return false;
        }
        let params = [
            m.param1, m.param2, m.param3, m.param4, m.x as f32, m.y as f32, m.z,
        ];
        self.run_command(now, link, sender, Command::from_wire(m.command, params));
        true
    }

    fn on_set_mode(
        &mut self,
        now: SimTime,
        link: LinkId,
        sender: (u8, u8),
        m: &SET_MODE_DATA,
    ) -> bool {
        if !self.for_us(m.target_system) {
            return false;
        }
        let main = (m.custom_mode >> 16) & 0xFF;
        let sub = m.custom_mode >> 24;
        let params = [
            1.0,
            main as f32,
            sub as f32,
            f32::NAN,
            f32::NAN,
            f32::NAN,
            f32::NAN,
        ];
        let command = Command::from_wire(
            mavlink::dialects::common::MavCmd::MAV_CMD_DO_SET_MODE,
            params,
        );
        self.run_command(now, link, sender, command);
        true
    }

    fn on_param_request_read(&mut self, link: LinkId, m: &PARAM_REQUEST_READ_DATA) -> bool {
        if !self.for_us(m.target_system) {
            return false;
        }
        let index = if m.param_index >= 0 {
            Some(m.param_index as usize).filter(|i| *i < self.params.len())
        } else {
            m.param_id.to_str().ok().and_then(|name| {
                self.params
                    .find(name.trim_end_matches('\0'))
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
        if !self.for_us(m.target_system) {
            return false;
        }
        let name = m
            .param_id
            .to_str()
            .unwrap_or("")
            .trim_end_matches('\0')
            .to_owned();
        match self.params.set(&name, m.param_value) {
            Ok(index) => self.send_param(link, index),
            Err(err) => {
                tracing::debug!(sysid = self.cfg.system_id, ?err, "parameter not set");
                // Answer with the current value, as PX4 does, when the name exists.
                if let Some((index, _)) = self.params.find(&name) {
                    self.send_param(link, index);
                }
            }
        }
        true
    }

    fn on_timesync(&mut self, now: SimTime, link: LinkId, m: &TIMESYNC_DATA) -> bool {
        if m.target_system != 0 && !self.for_us(m.target_system) {
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
