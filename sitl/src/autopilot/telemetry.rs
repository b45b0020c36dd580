//! Outgoing messages: one builder per message, and sending what each link's stream table
//! (`streams`) finds due. Every field is set explicitly (the crate's defaults for bitflag
//! fields are not empty).

use std::time::Duration;

use mavlink::dialects::common::{
    ATTITUDE_DATA, ATTITUDE_QUATERNION_DATA, AUTOPILOT_VERSION_DATA, BATTERY_STATUS_DATA,
    ESTIMATOR_STATUS_DATA, EXTENDED_SYS_STATE_DATA, EstimatorStatusFlags, GLOBAL_POSITION_INT_DATA,
    GPS_GLOBAL_ORIGIN_DATA, GPS_RAW_INT_DATA, GpsFixType, HEARTBEAT_DATA, HOME_POSITION_DATA,
    LOCAL_POSITION_NED_DATA, MavAutopilot, MavBatteryChargeState, MavBatteryFault,
    MavBatteryFunction, MavBatteryMode, MavBatteryType, MavLandedState, MavMessage, MavModeFlag,
    MavParamType, MavProtocolCapability, MavSeverity, MavState, MavSysStatusSensor,
    MavSysStatusSensorExtended, MavType, MavVtolState, PARAM_VALUE_DATA, STATUSTEXT_DATA,
    SYS_STATUS_DATA,
};
use nalgebra::Vector3;

use super::mode::FlightMode;
use super::streams::StreamTable;
use super::{LinkId, Transmit, Vehicle};
use crate::params::ParamKind;
use crate::time::SimTime;

const HEARTBEAT: u32 = 0;
const SYS_STATUS: u32 = 1;
const GPS_RAW_INT: u32 = 24;
const ATTITUDE: u32 = 30;
const ATTITUDE_QUATERNION: u32 = 31;
const LOCAL_POSITION_NED: u32 = 32;
const GLOBAL_POSITION_INT: u32 = 33;
const GPS_GLOBAL_ORIGIN: u32 = 49;
const BATTERY_STATUS: u32 = 147;
const AUTOPILOT_VERSION: u32 = 148;
const EXTENDED_SYS_STATE: u32 = 245;
const HOME_POSITION: u32 = 242;
const ESTIMATOR_STATUS: u32 = 230;

/// The streams every link starts with: `(message id, rate in Hz)`.
pub(super) fn default_streams(fast_rate_hz: f64) -> StreamTable {
    StreamTable::at_rates(&[
        (HEARTBEAT, 1.0),
        (SYS_STATUS, 2.0),
        (EXTENDED_SYS_STATE, 5.0),
        (BATTERY_STATUS, 1.0),
        (GPS_RAW_INT, 5.0),
        (HOME_POSITION, 0.5),
        (GPS_GLOBAL_ORIGIN, 0.2),
        // PX4's onboard and normal modes stream it at 1 and 0.5 Hz (mavlink_main.cpp).
        (ESTIMATOR_STATUS, 1.0),
        (ATTITUDE, fast_rate_hz),
        (ATTITUDE_QUATERNION, fast_rate_hz),
        (LOCAL_POSITION_NED, fast_rate_hz),
        (GLOBAL_POSITION_INT, fast_rate_hz),
    ])
}

/// The ArduPilot personality's streams at boot: the heartbeat, nothing else until asked.
pub(super) fn heartbeat_only() -> StreamTable {
    StreamTable::at_rates(&[(HEARTBEAT, 1.0)])
}

/// Messages that can be streamed or requested once.
fn is_known(msg_id: u32) -> bool {
    matches!(
        msg_id,
        HEARTBEAT
            | SYS_STATUS
            | GPS_RAW_INT
            | ATTITUDE
            | ATTITUDE_QUATERNION
            | LOCAL_POSITION_NED
            | GLOBAL_POSITION_INT
            | GPS_GLOBAL_ORIGIN
            | BATTERY_STATUS
            | AUTOPILOT_VERSION
            | EXTENDED_SYS_STATE
            | HOME_POSITION
            | ESTIMATOR_STATUS
    )
}

impl Vehicle {
    /// Encodes `msg` for `link` and queues it.
    pub(super) fn send(&mut self, link: LinkId, msg: &MavMessage) {
        if !self.io.links[link as usize].wired {
            return;
        }
        let link_id = self.signing_link_id(link);
        let signing = self.io.signing.as_mut().map(|s| (s, link_id));
        let mut bytes = self.io.spare.take();
        self.io.links[link as usize]
            .encoder
            .encode_into(msg, signing, &mut bytes);
        self.io.outbox.push_back(Transmit { link, bytes });
    }

    /// A STATUSTEXT on both links, as PX4's `mavlink_log` reaches every ground station.
    /// A text longer than the field's 50 bytes goes in chunks of one nonzero `id`
    /// (`chunk_seq` 0, 1, …; the last one shorter, or an empty one after a full last
    /// chunk), as PX4's STATUSTEXT stream splits it.
    pub(super) fn send_statustext(&mut self, severity: MavSeverity, text: &str) {
        const FIELD: usize = 50;
        let bytes = text.as_bytes();
        let (id, chunks) = if bytes.len() <= FIELD {
            (0, 1)
        } else {
            self.io.statustext_id = self.io.statustext_id.wrapping_add(1).max(1);
            (self.io.statustext_id, bytes.len() / FIELD + 1)
        };
        for k in 0..chunks {
            let chunk = &bytes[(k * FIELD).min(bytes.len())..((k + 1) * FIELD).min(bytes.len())];
            let mut field = [0u8; FIELD];
            field[..chunk.len()].copy_from_slice(chunk);
            let msg = MavMessage::STATUSTEXT(STATUSTEXT_DATA {
                severity,
                text: field.into(),
                id,
                chunk_seq: k as u8,
            });
            for link in [LinkId::Offboard, LinkId::Gcs] {
                self.send(link, &msg);
            }
        }
    }

    pub(super) fn emit_due_telemetry(&mut self, now: SimTime) {
        // An estimator origin that moved is reported at once, as PX4 does on a reset.
        let shift = self.estimator.origin_shift_ned_m(now);
        if shift != self.origin_shift_sent_ned_m {
            self.origin_shift_sent_ned_m = shift;
            if let Some(msg) = self.build(now, GPS_GLOBAL_ORIGIN) {
                for link in [LinkId::Offboard, LinkId::Gcs] {
                    self.send(link, &msg);
                }
            }
        }
        let mut due = std::mem::take(&mut self.io.due_scratch);
        for link in [LinkId::Offboard, LinkId::Gcs] {
            if !self.io.links[link as usize].wired {
                continue;
            }
            due.clear();
            self.io.links[link as usize].streams.take_due(now, &mut due);
            for &msg_id in &due {
                if let Some(msg) = self.build(now, msg_id) {
                    self.send(link, &msg);
                }
            }
        }
        self.io.due_scratch = due;
    }

    /// Sets a stream's interval on one link: `Some(None)` stops it, `None` restores its
    /// default. Returns false for a message the emulator cannot stream.
    pub(super) fn set_interval(
        &mut self,
        now: SimTime,
        link: LinkId,
        msg_id: u32,
        interval: Option<Option<Duration>>,
    ) -> bool {
        if !is_known(msg_id) || msg_id == AUTOPILOT_VERSION {
            return false;
        }
        self.io.links[link as usize]
            .streams
            .set_interval(now, msg_id, interval);
        true
    }

    /// Sends one message now (MAV_CMD_REQUEST_MESSAGE). Returns false if unknown.
    pub(super) fn send_message_now(&mut self, now: SimTime, link: LinkId, msg_id: u32) -> bool {
        match self.build(now, msg_id) {
            Some(msg) if is_known(msg_id) => {
                self.send(link, &msg);
                true
            }
            _ => false,
        }
    }

    pub(super) fn send_param(&mut self, link: LinkId, index: usize) {
        let Some(param) = self.params.get(index) else {
            return;
        };
        let msg = MavMessage::PARAM_VALUE(PARAM_VALUE_DATA {
            param_value: param.wire_value(),
            param_count: self.params.len() as u16,
            param_index: index as u16,
            param_id: param.name.into(),
            param_type: match param.kind {
                ParamKind::Int32 | ParamKind::Int32Cast => MavParamType::MAV_PARAM_TYPE_INT32,
                ParamKind::Real32 => MavParamType::MAV_PARAM_TYPE_REAL32,
            },
        });
        self.send(link, &msg);
    }

    pub(super) fn send_all_params(&mut self, link: LinkId) {
        for i in 0..self.params.len() {
            self.send_param(link, i);
        }
    }

    fn build(&self, now: SimTime, msg_id: u32) -> Option<MavMessage> {
        if self.is_ardupilot() {
            match msg_id {
                HEARTBEAT => return Some(self.ap_heartbeat()),
                // Not until its EKF has an origin (GCS_Common.cpp skips them).
                LOCAL_POSITION_NED | GPS_GLOBAL_ORIGIN | HOME_POSITION if !self.ekf_ready(now) => {
                    return None;
                }
                // PX4's message; ArduPilot sends EKF_STATUS_REPORT instead.
                ESTIMATOR_STATUS => return None,
                _ => {}
            }
        }
        Some(match msg_id {
            HEARTBEAT => self.heartbeat(),
            SYS_STATUS => self.sys_status(now),
            EXTENDED_SYS_STATE => MavMessage::EXTENDED_SYS_STATE(EXTENDED_SYS_STATE_DATA {
                vtol_state: MavVtolState::MAV_VTOL_STATE_UNDEFINED,
                landed_state: self.landed_state(),
            }),
            BATTERY_STATUS => self.battery_status(),
            ESTIMATOR_STATUS => MavMessage::ESTIMATOR_STATUS(ESTIMATOR_STATUS_DATA {
                time_usec: now.as_micros(),
                vel_ratio: 0.0,
                pos_horiz_ratio: 0.0,
                pos_vert_ratio: 0.0,
                mag_ratio: 0.0,
                hagl_ratio: 0.0,
                tas_ratio: 0.0,
                pos_horiz_accuracy: 0.0,
                pos_vert_accuracy: 0.0,
                flags: EstimatorStatusFlags::from_bits_truncate(self.estimator.solution_flags(
                    now,
                    self.landed_state() == MavLandedState::MAV_LANDED_STATE_ON_GROUND,
                )),
            }),
            GPS_RAW_INT => self.gps_raw_int(now),
            HOME_POSITION => self.home_position(now),
            GPS_GLOBAL_ORIGIN => {
                let origin = self.world.to_geodetic(
                    &(self.cfg.start.pos_world_ned_m + self.estimator.origin_shift_ned_m(now)),
                );
                MavMessage::GPS_GLOBAL_ORIGIN(GPS_GLOBAL_ORIGIN_DATA {
                    latitude: origin.lat_e7(),
                    longitude: origin.lon_e7(),
                    altitude: origin.alt_mm(),
                    time_usec: now.as_micros(),
                })
            }
            ATTITUDE => {
                let (roll, pitch, yaw) = self.plant.state.attitude.euler_angles();
                let w = self.plant.state.rate_frd_rps;
                MavMessage::ATTITUDE(ATTITUDE_DATA {
                    time_boot_ms: self.boot_ms(now),
                    roll: roll as f32,
                    pitch: pitch as f32,
                    yaw: yaw as f32,
                    rollspeed: w.x as f32,
                    pitchspeed: w.y as f32,
                    yawspeed: w.z as f32,
                })
            }
            ATTITUDE_QUATERNION => {
                let q = self.plant.state.attitude;
                let w = self.plant.state.rate_frd_rps;
                MavMessage::ATTITUDE_QUATERNION(ATTITUDE_QUATERNION_DATA {
                    time_boot_ms: self.boot_ms(now),
                    q1: q.w as f32,
                    q2: q.i as f32,
                    q3: q.j as f32,
                    q4: q.k as f32,
                    rollspeed: w.x as f32,
                    pitchspeed: w.y as f32,
                    yawspeed: w.z as f32,
                    repr_offset_q: [0.0; 4],
                })
            }
            LOCAL_POSITION_NED => {
                let (p, v) = self.estimator.report(
                    now,
                    self.plant.state.pos_ned_m,
                    self.plant.state.vel_ned_mps,
                )?;
                MavMessage::LOCAL_POSITION_NED(LOCAL_POSITION_NED_DATA {
                    time_boot_ms: self.boot_ms(now),
                    x: p.x as f32,
                    y: p.y as f32,
                    z: p.z as f32,
                    vx: v.x as f32,
                    vy: v.y as f32,
                    vz: v.z as f32,
                })
            }
            GLOBAL_POSITION_INT => self.global_position_int(now),
            AUTOPILOT_VERSION => self.autopilot_version(),
            _ => return None,
        })
    }

    fn heartbeat(&self) -> MavMessage {
        let mut base_mode = MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED;
        if self.modes.armed() {
            base_mode |= MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED;
        }
        let system_status = match (self.modes.failsafe, self.modes.armed()) {
            (true, _) => MavState::MAV_STATE_CRITICAL,
            (false, true) => MavState::MAV_STATE_ACTIVE,
            (false, false) => MavState::MAV_STATE_STANDBY,
        };
        MavMessage::HEARTBEAT(HEARTBEAT_DATA {
            custom_mode: self.modes.mode.custom_mode(),
            mavtype: MavType::MAV_TYPE_QUADROTOR,
            autopilot: MavAutopilot::MAV_AUTOPILOT_PX4,
            base_mode,
            system_status,
            mavlink_version: 3,
        })
    }

    fn landed_state(&self) -> MavLandedState {
        match (self.modes.landed(), self.modes.mode) {
            (true, _) => MavLandedState::MAV_LANDED_STATE_ON_GROUND,
            (false, FlightMode::Takeoff) => MavLandedState::MAV_LANDED_STATE_TAKEOFF,
            (false, FlightMode::Land) => MavLandedState::MAV_LANDED_STATE_LANDING,
            (false, _) => MavLandedState::MAV_LANDED_STATE_IN_AIR,
        }
    }

    fn battery_voltage_v(&self) -> f64 {
        let remaining = self.battery_remaining_pct() / 100.0;
        4.0 * (3.5 + 0.7 * remaining) - 0.01 * self.plant.battery.current_a
    }

    fn sys_status(&self, now: SimTime) -> MavMessage {
        let sensors = MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_3D_GYRO
            | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_3D_ACCEL
            | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_3D_MAG
            | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
            | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_GPS
            | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
            | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION
            | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
            | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_BATTERY
            | MavSysStatusSensor::MAV_SYS_STATUS_PREARM_CHECK;
        // The pre-arm bit is healthy once the EKF has a position (ArduPilot; always PX4's).
        let mut health = sensors;
        if !self.ekf_ready(now) {
            health.remove(MavSysStatusSensor::MAV_SYS_STATUS_PREARM_CHECK);
        }
        let mut sensors = sensors;
        if self.is_ardupilot() {
            // ArduPilot's geofence bit: present and enabled with FENCE_ENABLE, healthy
            // unless breached (MAVProxy's fence module reads it).
            let fence = MavSysStatusSensor::MAV_SYS_STATUS_GEOFENCE;
            if self.params.value("FENCE_ENABLE") != 0.0 {
                sensors |= fence;
            }
            if !self.geofence.breached() {
                health |= fence;
            }
        }
        MavMessage::SYS_STATUS(SYS_STATUS_DATA {
            onboard_control_sensors_present: sensors,
            onboard_control_sensors_enabled: sensors,
            onboard_control_sensors_health: health,
            load: 250,
            voltage_battery: (self.battery_voltage_v() * 1000.0) as u16,
            current_battery: (self.plant.battery.current_a * 100.0) as i16,
            drop_rate_comm: 0,
            errors_comm: 0,
            errors_count1: 0,
            errors_count2: 0,
            errors_count3: 0,
            errors_count4: 0,
            battery_remaining: self.battery_remaining_pct().round() as i8,
            onboard_control_sensors_present_extended: MavSysStatusSensorExtended::empty(),
            onboard_control_sensors_enabled_extended: MavSysStatusSensorExtended::empty(),
            onboard_control_sensors_health_extended: MavSysStatusSensorExtended::empty(),
        })
    }

    fn battery_status(&self) -> MavMessage {
        let cell_mv = (self.battery_voltage_v() / 4.0 * 1000.0) as u16;
        let mut voltages = [u16::MAX; 10];
        voltages[..4].fill(cell_mv);
        MavMessage::BATTERY_STATUS(BATTERY_STATUS_DATA {
            current_consumed: self.plant.battery.consumed_mah as i32,
            energy_consumed: -1,
            temperature: i16::MAX,
            voltages,
            current_battery: (self.plant.battery.current_a * 100.0) as i16,
            id: 0,
            battery_function: MavBatteryFunction::MAV_BATTERY_FUNCTION_ALL,
            mavtype: MavBatteryType::MAV_BATTERY_TYPE_LIPO,
            battery_remaining: self.battery_remaining_pct().round() as i8,
            time_remaining: 0,
            charge_state: MavBatteryChargeState::MAV_BATTERY_CHARGE_STATE_OK,
            voltages_ext: [0; 4],
            mode: MavBatteryMode::MAV_BATTERY_MODE_UNKNOWN,
            fault_bitmask: MavBatteryFault::empty(),
        })
    }

    pub(super) fn world_position(&self) -> Vector3<f64> {
        self.cfg.start.pos_world_ned_m + self.plant.state.pos_ned_m
    }

    fn global_position_int(&self, now: SimTime) -> MavMessage {
        let geo = self.world.to_geodetic(&self.world_position());
        let home_amsl = self.world.reference.alt_amsl_m - self.world.ground_down_m;
        let v = self.plant.state.vel_ned_mps;
        let (_, _, yaw) = self.plant.state.attitude.euler_angles();
        MavMessage::GLOBAL_POSITION_INT(GLOBAL_POSITION_INT_DATA {
            time_boot_ms: self.boot_ms(now),
            lat: geo.lat_e7(),
            lon: geo.lon_e7(),
            alt: geo.alt_mm(),
            relative_alt: ((geo.alt_amsl_m - home_amsl) * 1000.0).round() as i32,
            vx: (v.x * 100.0).round() as i16,
            vy: (v.y * 100.0).round() as i16,
            vz: (v.z * 100.0).round() as i16,
            hdg: (yaw.to_degrees().rem_euclid(360.0) * 100.0) as u16,
        })
    }

    fn gps_raw_int(&self, now: SimTime) -> MavMessage {
        let geo = self.world.to_geodetic(&self.world_position());
        let v = self.plant.state.vel_ned_mps;
        MavMessage::GPS_RAW_INT(GPS_RAW_INT_DATA {
            time_usec: now.as_micros(),
            lat: geo.lat_e7(),
            lon: geo.lon_e7(),
            alt: geo.alt_mm(),
            eph: 70,
            epv: 100,
            vel: (v.xy().norm() * 100.0) as u16,
            cog: (v.y.atan2(v.x).to_degrees().rem_euclid(360.0) * 100.0) as u16,
            fix_type: GpsFixType::GPS_FIX_TYPE_3D_FIX,
            satellites_visible: 16,
            alt_ellipsoid: geo.alt_mm(),
            h_acc: 500,
            v_acc: 800,
            vel_acc: 200,
            hdg_acc: 0,
            yaw: 0,
        })
    }

    /// Home: the start point projected on the ground, in local coordinates.
    pub(super) fn home_local_ned_m(&self) -> Vector3<f64> {
        Vector3::new(0.0, 0.0, self.plant.env.ground_z_ned_m)
    }

    /// Home as latitude, longitude and altitude.
    pub(super) fn home_geodetic(&self) -> ringswarm_wire::geo::Geodetic {
        self.world
            .to_geodetic(&(self.cfg.start.pos_world_ned_m + self.home_local_ned_m()))
    }

    fn home_position(&self, now: SimTime) -> MavMessage {
        let home_local = self.home_local_ned_m();
        let geo = self.home_geodetic();
        MavMessage::HOME_POSITION(HOME_POSITION_DATA {
            latitude: geo.lat_e7(),
            longitude: geo.lon_e7(),
            altitude: geo.alt_mm(),
            x: home_local.x as f32,
            y: home_local.y as f32,
            z: home_local.z as f32,
            q: [1.0, 0.0, 0.0, 0.0],
            approach_x: 0.0,
            approach_y: 0.0,
            approach_z: 0.0,
            time_usec: now.as_micros(),
        })
    }

    fn autopilot_version(&self) -> MavMessage {
        // What the emulator implements (MAVSDK refuses to upload a mission without
        // MISSION_INT); no fence or rally plans, no FTP.
        let capabilities = MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_MAVLINK2
            | MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_SET_ATTITUDE_TARGET
            | MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
            | MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT
            | MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_COMMAND_INT
            | MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_MISSION_INT
            | MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT
            | MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE;
        MavMessage::AUTOPILOT_VERSION(AUTOPILOT_VERSION_DATA {
            capabilities,
            uid: 0x5249_4E47_0000_0000 | u64::from(self.cfg.system_id),
            flight_sw_version: (1 << 24) | (15 << 16) | 0xFF, // reads as PX4 1.15 release
            middleware_sw_version: 0,
            os_sw_version: 0,
            board_version: 0,
            vendor_id: 0,
            product_id: 0,
            flight_custom_version: [0; 8],
            middleware_custom_version: [0; 8],
            os_custom_version: [0; 8],
            uid2: [0; 18],
        })
    }
}
