//! What the attitude controller tracks each step, and the offboard signal: raw offboard
//! attitude or body rates go straight to it; an offboard trajectory or the navigator's
//! setpoint goes through the position controller; a vehicle on the ground idles unless
//! its mode climbs. PX4's `offboardCheck` decides whether OFFBOARD can run; the offboard
//! loss failsafe follows COM_OBL_RC_ACT.

use super::flight::Nav;
use super::offboard::OffboardTarget;
use super::{FlightMode, Vehicle, VehicleEvent};
use crate::control::{AttitudeCommand, AttitudeSetpoint};
use crate::position_control::{Kinematics, TrajectorySetpoint};
use crate::time::SimTime;

impl Vehicle {
    /// What the attitude controller tracks this step; `None` spins the motors down
    /// (disarmed).
    pub(super) fn attitude_command(&mut self, t: SimTime, dt: f64) -> Option<AttitudeCommand> {
        if !self.modes.armed() || !self.motors_started(t) {
            self.navigator.pos_ctrl_active = false;
            return None;
        }
        // Level at idle thrust, holding the heading (computed only when flown: the
        // heading costs three inverse trigonometric functions).
        let idle = |v: &Self| AttitudeCommand::Attitude {
            setpoint: AttitudeSetpoint::idle(v.yaw_rad()),
            yawspeed_ff_rps: f64::NAN,
        };
        let trajectory = if self.modes.mode == FlightMode::Offboard {
            match self.offboard {
                Some(OffboardTarget::Attitude {
                    attitude,
                    thrust,
                    yawspeed_ff_rps,
                }) => {
                    self.navigator.pos_ctrl_active = false;
                    return Some(AttitudeCommand::Attitude {
                        setpoint: AttitudeSetpoint {
                            attitude,
                            thrust_norm: thrust,
                        },
                        yawspeed_ff_rps,
                    });
                }
                Some(OffboardTarget::AttitudeClimb {
                    attitude,
                    climb_up_mps,
                    yawspeed_ff_rps,
                }) => {
                    self.navigator.pos_ctrl_active = false;
                    if self.modes.landed() && climb_up_mps <= 0.0 {
                        self.climb_integral_mps2 = 0.0;
                        return Some(idle(self));
                    }
                    return Some(AttitudeCommand::Attitude {
                        setpoint: AttitudeSetpoint {
                            attitude,
                            thrust_norm: self.climb_thrust(&attitude, climb_up_mps, dt),
                        },
                        yawspeed_ff_rps,
                    });
                }
                Some(OffboardTarget::Rates {
                    rates_frd_rps,
                    thrust,
                }) => {
                    self.navigator.pos_ctrl_active = false;
                    return Some(AttitudeCommand::Rates {
                        rates_frd_rps,
                        thrust_norm: thrust,
                    });
                }
                Some(OffboardTarget::Trajectory(sp)) => {
                    let wants_up = sp.pos_ned_m.z < self.plant.state.pos_ned_m.z - 0.1
                        || sp.vel_ned_mps.z < -0.1
                        || sp.acc_ned_mps2.z < -0.1;
                    (!self.modes.landed() || wants_up).then_some(sp)
                }
                None => None,
            }
        } else {
            match self.nav_setpoint(t, dt) {
                Some(sp) => (!self.modes.landed() || self.nav_wants_climb()).then_some(sp),
                // Never idle in the air: a mode with nothing to fly holds where it is.
                None if !self.modes.landed() => Some(TrajectorySetpoint::hold(
                    self.plant.state.pos_ned_m,
                    self.navigator.yaw_rad,
                )),
                None => None,
            }
        };
        let Some(sp) = trajectory else {
            self.navigator.pos_ctrl_active = false;
            return Some(idle(self));
        };
        if !self.navigator.pos_ctrl_active {
            self.navigator.pos_ctrl.reset();
            self.navigator.pos_ctrl_active = true;
        }
        let kin = Kinematics {
            pos_ned_m: self.plant.state.pos_ned_m,
            vel_ned_mps: self.plant.state.vel_ned_mps,
            yaw_rad: self.yaw_rad(),
        };
        let mut mpc = self.tuning.mpc;
        if let Nav::Velocity { vel_ned_mps } = self.navigator.nav {
            // The pilot of a vehicle started in the air holds its start velocity, however
            // fast: an emulator's fiction, not bound by MPC_XY_VEL_MAX / MPC_Z_VEL_MAX_*.
            mpc.xy_vel_max_mps = mpc.xy_vel_max_mps.max(vel_ned_mps.xy().norm());
            mpc.z_vel_max_up_mps = mpc.z_vel_max_up_mps.max(-vel_ned_mps.z);
            mpc.z_vel_max_dn_mps = mpc.z_vel_max_dn_mps.max(vel_ned_mps.z);
        }
        let out = self.navigator.pos_ctrl.update(&mpc, &sp, &kin, dt);
        Some(AttitudeCommand::Attitude {
            setpoint: out.attitude,
            yawspeed_ff_rps: out.yawspeed_ff_rps,
        })
    }

    /// The thrust that makes `climb_up_mps` at `attitude`: the hover thrust times the
    /// vertical acceleration asked for, a PI of the climb-rate error (MPC_Z_VEL_P_ACC,
    /// MPC_Z_VEL_I_ACC, the integral within ±g/2), over the cosine of the tilt: a
    /// climb-rate loop like ArduPilot's guided angle mode runs (its integral makes the
    /// climb asked for, drag or not).
    fn climb_thrust(
        &mut self,
        attitude: &nalgebra::UnitQuaternion<f64>,
        climb_up_mps: f64,
        dt: f64,
    ) -> f64 {
        let p = self.tuning.mpc;
        let g = crate::profile::GRAVITY_MPS2;
        let error = climb_up_mps - (-self.plant.state.vel_ned_mps.z);
        self.climb_integral_mps2 =
            (self.climb_integral_mps2 + p.z_vel_pid[1] * error * dt).clamp(-0.5 * g, 0.5 * g);
        let accel_up = p.z_vel_pid[0] * error + self.climb_integral_mps2;
        let cos_tilt = (attitude * nalgebra::Vector3::z()).z.clamp(0.1, 1.0);
        (p.thr_hover * (g + accel_up) / g / cos_tilt).clamp(p.thr_min, p.thr_max)
    }

    pub(super) fn check_offboard_loss(&mut self, t: SimTime) {
        // PX4's failsafes act on armed vehicles only.
        if !self.modes.armed() || self.modes.mode != FlightMode::Offboard || self.modes.failsafe {
            return;
        }
        let timeout = self.tuning.offboard_loss;
        let last = self.offboard_signal.unwrap_or(SimTime::ZERO);
        if t.saturating_since(last) <= timeout {
            return;
        }
        self.modes.failsafe = true;
        self.events.push_back(VehicleEvent::OffboardLost {
            at: t,
            last_setpoint: last,
        });
        tracing::warn!(
            sysid = self.cfg.system_id,
            silent_ms = t.saturating_since(last).as_millis() as u64,
            "offboard setpoints lost"
        );
        match self.tuning.offboard_loss_action {
            3 => self.enter_mode(FlightMode::Return),
            4 => self.enter_mode(FlightMode::Land),
            5 => self.enter_mode(FlightMode::Hold),
            6 | 7 => self.disarm("offboard loss failsafe"),
            _ => self.enter_mode(FlightMode::Position),
        }
    }

    /// PX4's `offboardCheck`: an offboard setpoint arrived within COM_OF_LOSS_T.
    pub(super) fn offboard_available(&self, t: SimTime) -> bool {
        let timeout = self.tuning.offboard_loss;
        self.offboard_signal
            .is_some_and(|last| t.saturating_since(last) <= timeout)
    }

    /// Whether `mode` can run now (PX4's `canRun`).
    pub(super) fn can_run(&self, t: SimTime, mode: FlightMode) -> bool {
        match mode {
            FlightMode::Offboard => self.offboard_available(t),
            FlightMode::Mission => self.navigator.mission.is_valid(),
            _ => true,
        }
    }

    /// Records an accepted offboard setpoint at `t`: it is flown in OFFBOARD and keeps
    /// the offboard signal alive.
    pub(super) fn note_offboard(&mut self, t: SimTime, target: OffboardTarget) {
        self.offboard = Some(target);
        self.offboard_signal = Some(t);
        self.counters.setpoints += 1;
    }
}
