//! One emulated vehicle: PX4's wire behaviour around the physics, as a sans-IO machine.
//!
//! ```text
//!            arm (400)                 DO_SET_MODE 6 with an offboard signal
//!  DISARMED ───────────► ARMED ──────────────────────────────────────► OFFBOARD
//!     ▲   ◄─────────────  │  ▲                                             │
//!     │  disarm (landed,  │  └── Position / Hold / Land / Takeoff / ◄──────┤ no setpoint for
//!     │  or forced)       │      Return / Mission (DO_SET_MODE, NAV_*,     │ COM_OF_LOSS_T:
//!     └───────────────────┴── landed for COM_DISARM_LAND, or armed         │ COM_OBL_RC_ACT
//!                             without takeoff for COM_DISARM_PRFLT         ▼ (failsafe)
//! ```
//!
//! The *offboard signal* is PX4's: any offboard setpoint PX4 would publish (position,
//! velocity or acceleration in SET_POSITION_TARGET_*, attitude or roll+pitch rates with
//! thrust in SET_ATTITUDE_TARGET; see [`offboard`]) received within COM_OF_LOSS_T. While
//! disarmed any mode is accepted (arming then needs a mode that can run); while armed,
//! OFFBOARD without the signal and AUTO.MISSION without a mission are TEMPORARILY_REJECTED.
//!
//! Every mode but raw offboard attitude and rates flies through one position controller
//! ([`crate::position_control`]); the navigator (`flight`, `mission_run`) turns each
//! mode into its trajectory setpoint.
//!
//! Driving it: call [`Vehicle::handle_datagram`] for every datagram received on a link,
//! [`Vehicle::handle_timeout`] whenever time has advanced (at least every
//! [`PHYSICS_STEP`]; the machine integrates in fixed 1 ms steps up to `now`), then drain
//! [`Vehicle::poll_transmit`]. It never reads a clock or touches a socket.

mod ardupilot;
mod commands;
mod config;
mod datalink;
pub mod estimator;
mod flight;
mod geofence;
mod inbound;
mod io;
mod mission;
mod mission_item;
mod mission_run;
mod mission_transfer;
mod mode;
mod mode_machine;
mod navigator;
pub mod offboard;
mod plant;
mod signing;
mod steer;
mod streams;
mod telemetry;
mod tuning;

use std::collections::VecDeque;
use std::time::Duration;

use nalgebra::{Vector3, Vector4};

pub use config::{BatteryConfig, Personality, StartState, VehicleConfig, WindConfig};
pub use geofence::Geofence;
pub use mission::MissionStore;
pub use mission_item::MissionItem;
pub use mode::FlightMode;

use crate::codec::Encoder;
use crate::control::AttitudeController;
use crate::params::ParamTable;
use crate::physics::{Airframe, BodyState};
use crate::profile::GRAVITY_MPS2;
use crate::time::SimTime;
use crate::world::World;
use flight::Nav;
use io::MavlinkIo;
use navigator::Navigator;
use offboard::{GlobalFrame, OffboardTarget};
use tuning::Tuning;

/// The fixed physics and autopilot step.
pub const PHYSICS_STEP: Duration = Duration::from_millis(1);

/// The two MAVLink links of a PX4 SITL instance.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum LinkId {
    /// The offboard/API link (binds 14580+i, sends to 14540+i).
    Offboard = 0,
    /// The ground-station link (binds 18570+i, sends to 14550).
    Gcs = 1,
}

/// Bytes to send on a link.
#[derive(Debug, Clone, PartialEq)]
pub struct Transmit {
    /// The link.
    pub link: LinkId,
    /// One MAVLink frame.
    pub bytes: Vec<u8>,
}

/// Something the driver or a test may want to know.
#[derive(Debug, Clone, PartialEq)]
pub enum VehicleEvent {
    /// Armed.
    Armed,
    /// Disarmed, and why.
    Disarmed(&'static str),
    /// A new flight mode.
    ModeChanged(FlightMode),
    /// The offboard stream was lost; the failsafe took `FlightMode` (or disarmed).
    OffboardLost {
        /// When the loss was detected.
        at: SimTime,
        /// The last setpoint.
        last_setpoint: SimTime,
    },
    /// SETUP_SIGNING set a key (or removed it): the driver stores it where the vehicle
    /// finds it after a restart.
    SigningChanged(Option<crate::keystore::StoredKey>),
}

/// Counters of what was refused or ignored.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Counters {
    /// Frames that failed to decode (CRC, truncation, unknown id, garbage).
    pub bad_frames: u64,
    /// Messages addressed to another system.
    pub foreign_target: u64,
    /// Offboard setpoints refused (an unsupported frame, nothing set, non-finite values,
    /// a quaternion not of unit length, thrust out of range).
    pub rejected_setpoints: u64,
    /// Commands answered UNSUPPORTED.
    pub unsupported_commands: u64,
    /// Offboard setpoints accepted.
    pub setpoints: u64,
    /// Unsigned frames refused while a signing key is set.
    pub unsigned_refused: u64,
    /// Signed frames refused: a wrong signature, a replay, a stale new stream.
    pub signature_refused: u64,
}

/// A snapshot for status lines and tests.
#[derive(Debug, Clone, PartialEq)]
pub struct VehicleStatus {
    /// The simulated time of this snapshot.
    pub at: SimTime,
    /// System id.
    pub system_id: u8,
    /// Flight mode.
    pub mode: FlightMode,
    /// Armed.
    pub armed: bool,
    /// In the offboard-loss failsafe.
    pub failsafe: bool,
    /// On the ground.
    pub landed: bool,
    /// Height above the ground (m).
    pub height_m: f64,
    /// Position as a NED offset from the world reference (m).
    pub pos_world_ned_m: Vector3<f64>,
    /// Velocity in NED (m/s).
    pub vel_ned_mps: Vector3<f64>,
    /// Battery remaining (%).
    pub battery_pct: f64,
    /// When each link last heard anything valid.
    pub last_heard: [Option<SimTime>; 2],
    /// Counters.
    pub counters: Counters,
}

/// Per-link state.
#[derive(Debug, Clone)]
struct Link {
    encoder: Encoder,
    streams: streams::StreamTable,
    last_heard: Option<SimTime>,
    /// Whether a driver carries this link's frames (see [`Vehicle::set_link_wired`]).
    wired: bool,
}

/// One emulated vehicle.
#[derive(Debug, Clone)]
pub struct Vehicle {
    cfg: VehicleConfig,
    world: World,
    /// The airframe, its state, the wind and ground, the battery.
    plant: plant::Plant,
    controller: AttitudeController,
    params: ParamTable,
    tuning: Tuning,
    /// Armed or not, the flight mode and failsafe, on the ground or not.
    modes: mode_machine::ModeMachine,
    offboard: Option<OffboardTarget>,
    offboard_signal: Option<SimTime>,
    /// What it navigates by: the mode's target, the heading, the mission, the position
    /// controller.
    navigator: Navigator,
    /// The mission protocol's transfer in progress (plans are stored in `navigator` and
    /// `geofence`).
    mission_transfer: mission_transfer::MissionTransfer,
    geofence: Geofence,
    datalink: datalink::DataLink,
    estimator: estimator::Estimator,
    /// The origin shift last reported in GPS_GLOBAL_ORIGIN (m, NED).
    origin_shift_sent_ned_m: Vector3<f64>,
    /// Its MAVLink links, signing, and the frames waiting for the driver.
    io: MavlinkIo,
    events: VecDeque<VehicleEvent>,
    last_step: SimTime,
    boot_at: SimTime,
    counters: Counters,
    /// The ArduPilot personality's own state (`None`: PX4's).
    ap: Option<ardupilot::ApState>,
    /// The climb-rate loop's integral (m/s², up) of guided attitude targets with a climb
    /// rate.
    climb_integral_mps2: f64,
}

impl Vehicle {
    /// Builds a vehicle at time zero.
    ///
    /// # Errors
    /// The message of [`VehicleConfig::validate`].
    pub fn new(cfg: VehicleConfig, world: World) -> Result<Self, String> {
        cfg.validate()?;
        let frame = Airframe::new(cfg.profile.clone());
        let start = &cfg.start;
        let local_start = Vector3::zeros();
        let ground_local_z = world.ground_down_m - start.pos_world_ned_m.z;
        if ground_local_z < -1e-9 {
            return Err(format!(
                "vehicle {}: start position is below the ground",
                cfg.system_id
            ));
        }
        let mut state = BodyState::at_rest(local_start);
        state.attitude = nalgebra::UnitQuaternion::from_euler_angles(0.0, 0.0, start.yaw_rad);
        let in_air = start.in_air && ground_local_z > 1e-9;
        if in_air {
            state.vel_ned_mps = start.vel_ned_mps;
            state.motor_thrust_n = Vector4::repeat(cfg.profile.mass_kg * GRAVITY_MPS2 / 4.0);
        } else {
            state.pos_ned_m.z = ground_local_z;
        }
        let ap = match cfg.personality {
            Personality::Px4 => None,
            Personality::ArduPilot { ekf_settle } => {
                Some(ardupilot::ApState::at_boot(ekf_settle, in_air))
            }
        };
        let mut params = match ap {
            Some(_) => ParamTable::ardupilot(cfg.system_id, &cfg.profile),
            None => ParamTable::new(cfg.system_id, &cfg.profile),
        };
        if let Some(capacity) = cfg.battery.capacity_mah {
            params
                .set("BAT1_CAPACITY", capacity as f32)
                .map_err(|e| format!("vehicle {}: battery capacity: {e:?}", cfg.system_id))?;
        }
        let tuning = Tuning::from_params(&params);
        let links = [LinkId::Offboard, LinkId::Gcs].map(|_| Link {
            encoder: Encoder::new(cfg.system_id, 1),
            // ArduCopter streams nothing until asked (its MAVn_* rates default to 0).
            streams: match ap {
                Some(_) => telemetry::heartbeat_only(),
                None => telemetry::default_streams(cfg.fast_rate_hz),
            },
            last_heard: None,
            wired: true,
        });
        let nav = if in_air {
            Nav::Velocity {
                vel_ned_mps: start.vel_ned_mps,
            }
        } else {
            Nav::Idle
        };
        Ok(Self {
            world,
            plant: plant::Plant::new(
                frame,
                state,
                ground_local_z,
                cfg.wind,
                cfg.battery.sag,
                cfg.seed,
            ),
            controller: AttitudeController::default(),
            params,
            tuning,
            modes: mode_machine::ModeMachine::at_boot(in_air),
            offboard: None,
            offboard_signal: None,
            navigator: Navigator::new(nav, start.yaw_rad),
            mission_transfer: mission_transfer::MissionTransfer::new(cfg.system_id, ap.is_some()),
            geofence: Geofence::default(),
            datalink: datalink::DataLink::default(),
            estimator: estimator::Estimator::new(cfg.estimator.clone(), cfg.seed),
            origin_shift_sent_ned_m: Vector3::zeros(),
            io: MavlinkIo {
                links,
                signing: cfg
                    .signing
                    .as_ref()
                    .map(|s| ringswarm_wire::signing::Signing::new(s.key.clone(), s.timestamp)),
                outbox: VecDeque::new(),
                spare: crate::codec::FramePool::default(),
                statustext_id: 0,
                due_scratch: Vec::new(),
            },
            events: VecDeque::new(),
            last_step: SimTime::ZERO,
            boot_at: SimTime::ZERO,
            counters: Counters::default(),
            ap,
            climb_integral_mps2: 0.0,
            cfg,
        })
    }

    /// Reboots the vehicle at `now`: back to its configured start state, parameters and
    /// telemetry defaults, with `time_boot_ms` counting from zero again (a test's way of
    /// killing and restarting an autopilot).
    pub fn reboot(&mut self, now: SimTime) {
        let fresh = Vehicle::new(self.cfg.clone(), self.world)
            .expect("the configuration was valid at the first boot");
        // The key and its clock are stored, not configured: they survive; the stream
        // table is memory and does not.
        let signing = self.signing_key();
        let wired = self.io.links.each_ref().map(|l| l.wired);
        *self = fresh;
        for (link, wired) in self.io.links.iter_mut().zip(wired) {
            link.wired = wired;
        }
        self.io.signing =
            signing.map(|s| ringswarm_wire::signing::Signing::new(s.key, s.timestamp));
        self.last_step = now;
        self.boot_at = now;
        for link in &mut self.io.links {
            link.streams.restart_at(now);
        }
    }

    /// Milliseconds since boot at `now` (MAVLink's `time_boot_ms`).
    fn boot_ms(&self, now: SimTime) -> u32 {
        now.saturating_since(self.boot_at).as_millis() as u32
    }

    /// System id.
    pub fn system_id(&self) -> u8 {
        self.cfg.system_id
    }

    /// The next time [`Vehicle::handle_timeout`] must be called.
    pub fn poll_timeout(&self) -> SimTime {
        self.last_step + PHYSICS_STEP
    }

    /// The next frame to send, if any.
    pub fn poll_transmit(&mut self) -> Option<Transmit> {
        self.io.outbox.pop_front()
    }

    /// Whether a driver carries `link`'s frames (both links are wired at boot, as in
    /// PX4's SITL layout). A driver that serves only the offboard link unwires the other:
    /// nothing is built or encoded for it, streams or replies (a reboot keeps the wiring).
    pub fn set_link_wired(&mut self, link: LinkId, wired: bool) {
        self.io.links[link as usize].wired = wired;
    }

    /// Gives a sent frame's buffer back for the next one: a driver that does so makes
    /// the vehicle allocate nothing per frame in steady state.
    pub fn recycle(&mut self, bytes: Vec<u8>) {
        self.io.spare.give(bytes);
    }

    /// The next event, if any.
    pub fn poll_event(&mut self) -> Option<VehicleEvent> {
        self.events.pop_front()
    }

    /// Advances physics and the autopilot in fixed steps up to `now` and queues the
    /// telemetry that has come due.
    pub fn handle_timeout(&mut self, now: SimTime) {
        while self.last_step + PHYSICS_STEP <= now {
            let t = self.last_step + PHYSICS_STEP;
            self.step(t);
            self.last_step = t;
            self.emit_due_telemetry(t);
        }
    }

    /// A snapshot of the vehicle.
    pub fn status(&self) -> VehicleStatus {
        VehicleStatus {
            at: self.last_step,
            system_id: self.cfg.system_id,
            mode: self.modes.mode,
            armed: self.modes.armed(),
            failsafe: self.modes.failsafe,
            landed: self.modes.landed(),
            height_m: self.plant.height_m(),
            pos_world_ned_m: self.cfg.start.pos_world_ned_m + self.plant.state.pos_ned_m,
            vel_ned_mps: self.plant.state.vel_ned_mps,
            battery_pct: self.battery_remaining_pct(),
            last_heard: [self.io.links[0].last_heard, self.io.links[1].last_heard],
            counters: self.counters,
        }
    }

    /// The mechanical state (local NED).
    pub fn body(&self) -> &BodyState {
        &self.plant.state
    }

    /// The stored fence and its breach state.
    pub fn geofence(&self) -> &Geofence {
        &self.geofence
    }

    /// The parameter table.
    pub fn params(&self) -> &ParamTable {
        &self.params
    }

    fn dt_s() -> f64 {
        PHYSICS_STEP.as_secs_f64()
    }

    /// One fixed step of autopilot logic, control and physics ending at `t`.
    fn step(&mut self, t: SimTime) {
        if self.is_ardupilot() {
            self.ap_guided_timeout(t);
        } else {
            self.check_offboard_loss(t);
        }
        self.check_datalink(t);
        self.mission_timers(t);
        self.check_geofence(t);
        let dt = Self::dt_s();
        let available = self
            .plant
            .thrust_available(self.tuning.battery_capacity_mah);
        let motors = match self.attitude_command(t, dt) {
            Some(command) => {
                self.controller
                    .update_command(&self.plant.frame, &self.plant.state, &command, dt)
            }
            None => {
                self.controller.reset();
                Vector4::zeros()
            }
        };
        self.plant
            .advance(&motors, available, self.modes.armed(), dt);
        let state = &self.plant.state;
        self.estimator
            .step(t, dt, state.pos_ned_m, state.vel_ned_mps);
        self.update_landed(t);
    }

    /// The heading (rad).
    fn yaw_rad(&self) -> f64 {
        self.plant.state.attitude.euler_angles().2
    }

    /// The vehicle's geodetic frame: its origin (start point) in the world, home on the
    /// ground below it.
    fn global_frame(&self) -> GlobalFrame {
        let origin = self.cfg.start.pos_world_ned_m;
        let home = self.world.to_geodetic(&Vector3::new(
            origin.x,
            origin.y,
            origin.z + self.plant.env.ground_z_ned_m,
        ));
        GlobalFrame {
            world: self.world,
            origin_world_ned_m: origin,
            home_alt_amsl_m: home.alt_amsl_m,
        }
    }

    /// Switches mode and starts what the navigator flies in it (from where the vehicle
    /// is now).
    fn enter_mode(&mut self, mode: FlightMode) {
        if mode == FlightMode::Mission {
            self.navigator.mission.mark_started();
        }
        self.navigator.nav = self.nav_for(mode);
        self.navigator.yaw_rad = self.yaw_rad();
        if self.modes.set_mode(mode) {
            self.events.push_back(VehicleEvent::ModeChanged(mode));
            tracing::info!(
                sysid = self.cfg.system_id,
                mode = mode.name(),
                "mode changed"
            );
            self.report_mission();
        }
    }

    fn arm(&mut self, t: SimTime) {
        if self.modes.arm(t) {
            self.controller.reset();
            self.navigator.pos_ctrl_active = false;
            self.events.push_back(VehicleEvent::Armed);
            tracing::info!(sysid = self.cfg.system_id, "armed");
        }
    }

    fn disarm(&mut self, why: &'static str) {
        if self.modes.disarm() {
            self.controller.reset();
            self.events.push_back(VehicleEvent::Disarmed(why));
            tracing::info!(sysid = self.cfg.system_id, reason = why, "disarmed");
        }
    }

    fn update_landed(&mut self, t: SimTime) {
        self.modes.observe_ground(self.plant.on_ground(), t);
        if self.is_ardupilot() {
            self.ap_landed_disarm(t);
            return;
        }
        if !(self.modes.armed() && self.modes.landed()) {
            // Nothing to disarm (and the step is not worth the two durations below).
            return;
        }
        // COM_DISARM_LAND: negative never disarms; COM_DISARM_PRFLT: zero or less never.
        let after_landing =
            (self.tuning.disarm_land_s >= 0.0).then(|| tuning::seconds(self.tuning.disarm_land_s));
        let before_takeoff = (self.tuning.disarm_preflight_s > 0.0)
            .then(|| tuning::seconds(self.tuning.disarm_preflight_s));
        if let Some(why) = self
            .modes
            .ground_disarm_due(t, after_landing, before_takeoff)
        {
            let flew = self.modes.took_off();
            self.disarm(why);
            if flew {
                // PX4 goes back to Hold after a landing disarm.
                self.enter_mode(FlightMode::Hold);
            }
        }
    }

    fn battery_remaining_pct(&self) -> f64 {
        self.plant
            .battery_remaining_pct(self.tuning.battery_capacity_mah)
    }
}

#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests_geofence;
#[cfg(test)]
mod tests_mission;
#[cfg(test)]
mod tests_modes;
