//! The parameters the control loop reads every step, looked up once from the parameter
//! table (and again after every PARAM_SET), in SI units.

use std::time::Duration;

use crate::params::ParamTable;
use crate::position_control::MpcParams;
use crate::trajectory::Limits;

/// Parameter values in the units the controllers use (m, m/s, m/s², rad, s).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Tuning {
    pub mpc: MpcParams,
    /// Auto-mode leg limits at cruise speed (MPC_XY_CRUISE, MPC_Z_V_AUTO_UP/DN,
    /// MPC_ACC_HOR, MPC_ACC_UP_MAX/DOWN_MAX).
    pub auto: Limits,
    /// Takeoff climb (MPC_TKO_SPEED) and its acceleration
    /// `min(MPC_ACC_UP_MAX, MPC_TKO_SPEED / MPC_TKO_RAMP_T)`.
    pub takeoff_speed_mps: f64,

    pub takeoff_acc_mps2: f64,
    pub takeoff_alt_m: f64,
    pub land_speed_mps: f64,
    pub land_alt1_m: f64,
    pub land_alt2_m: f64,
    pub z_auto_dn_mps: f64,
    pub yaw_rate_auto_rps: f64,
    pub acceptance_radius_m: f64,
    pub altitude_radius_m: f64,
    pub rtl_return_alt_m: f64,
    pub rtl_descend_alt_m: f64,
    pub rtl_land_delay_s: f64,
    /// COM_OF_LOSS_T, COM_DL_LOSS_T, COM_DISARM_LAND, COM_DISARM_PRFLT (s).
    pub offboard_loss: Duration,
    pub datalink_loss: Duration,
    pub disarm_land_s: f64,
    pub disarm_preflight_s: f64,
    /// COM_OBL_RC_ACT and NAV_DLL_ACT.
    pub offboard_loss_action: i64,
    pub datalink_loss_action: i64,
    /// BAT1_CAPACITY (mAh).
    pub battery_capacity_mah: f64,
}

impl Tuning {
    /// Reads the table.
    pub fn from_params(p: &ParamTable) -> Self {
        let v = |name: &str| p.value(name);
        let mpc = MpcParams {
            xy_p: v("MPC_XY_P"),
            z_p: v("MPC_Z_P"),
            xy_vel_pid: [
                v("MPC_XY_VEL_P_ACC"),
                v("MPC_XY_VEL_I_ACC"),
                v("MPC_XY_VEL_D_ACC"),
            ],
            z_vel_pid: [
                v("MPC_Z_VEL_P_ACC"),
                v("MPC_Z_VEL_I_ACC"),
                v("MPC_Z_VEL_D_ACC"),
            ],
            xy_vel_max_mps: v("MPC_XY_VEL_MAX"),
            z_vel_max_up_mps: v("MPC_Z_VEL_MAX_UP"),
            z_vel_max_dn_mps: v("MPC_Z_VEL_MAX_DN"),
            tilt_max_rad: v("MPC_TILTMAX_AIR").to_radians(),
            thr_min: v("MPC_THR_MIN"),
            thr_max: v("MPC_THR_MAX"),
            // PX4 keeps the hover thrust within [THR_MIN, THR_MAX] (never panicking when
            // someone sets MIN above MAX: then MAX wins).
            thr_hover: v("MPC_THR_HOVER")
                .max(v("MPC_THR_MIN"))
                .min(v("MPC_THR_MAX")),
            thr_xy_margin: v("MPC_THR_XY_MARG"),
        };
        // PX4 keeps the auto speeds within the manual limits.
        let z_up = v("MPC_Z_V_AUTO_UP").min(mpc.z_vel_max_up_mps);
        let z_dn = v("MPC_Z_V_AUTO_DN").min(mpc.z_vel_max_dn_mps);
        let takeoff_speed = v("MPC_TKO_SPEED").min(mpc.z_vel_max_up_mps);
        let ramp = v("MPC_TKO_RAMP_T");
        let acc_up = v("MPC_ACC_UP_MAX");
        Self {
            mpc,
            auto: Limits {
                speed_xy_mps: v("MPC_XY_CRUISE").min(mpc.xy_vel_max_mps),
                speed_up_mps: z_up,
                speed_down_mps: z_dn,
                acc_xy_mps2: v("MPC_ACC_HOR"),
                acc_z_mps2: acc_up.min(v("MPC_ACC_DOWN_MAX")),
            },
            takeoff_speed_mps: takeoff_speed,

            takeoff_acc_mps2: if ramp > 0.0 {
                acc_up.min(takeoff_speed / ramp)
            } else {
                acc_up
            },
            takeoff_alt_m: v("MIS_TAKEOFF_ALT"),
            land_speed_mps: v("MPC_LAND_SPEED").min(mpc.z_vel_max_dn_mps),
            land_alt1_m: v("MPC_LAND_ALT1"),
            land_alt2_m: v("MPC_LAND_ALT2"),
            z_auto_dn_mps: z_dn,
            yaw_rate_auto_rps: v("MPC_YAWRAUTO_MAX").to_radians(),
            acceptance_radius_m: v("NAV_ACC_RAD"),
            altitude_radius_m: v("NAV_MC_ALT_RAD"),
            rtl_return_alt_m: v("RTL_RETURN_ALT"),
            rtl_descend_alt_m: v("RTL_DESCEND_ALT"),
            rtl_land_delay_s: v("RTL_LAND_DELAY"),
            offboard_loss: seconds(v("COM_OF_LOSS_T")),
            datalink_loss: seconds(v("COM_DL_LOSS_T")),
            disarm_land_s: v("COM_DISARM_LAND"),
            disarm_preflight_s: v("COM_DISARM_PRFLT"),
            offboard_loss_action: v("COM_OBL_RC_ACT") as i64,
            datalink_loss_action: v("NAV_DLL_ACT") as i64,
            battery_capacity_mah: v("BAT1_CAPACITY").max(1.0),
        }
    }

    /// PX4's landing descent speed at `height_m` above the ground: MPC_Z_V_AUTO_DN above
    /// MPC_LAND_ALT1, MPC_LAND_SPEED below MPC_LAND_ALT2, linear in between (m/s, down).
    pub fn land_speed_at(&self, height_m: f64) -> f64 {
        let (fast, slow) = (self.z_auto_dn_mps, self.land_speed_mps);
        let (alt1, alt2) = (self.land_alt1_m, self.land_alt2_m);
        if height_m >= alt1 {
            fast
        } else if height_m <= alt2 || alt1 <= alt2 {
            slow
        } else {
            slow + (fast - slow) * (height_m - alt2) / (alt1 - alt2)
        }
    }

    /// The auto-mode limits with another horizontal speed (a goto's or DO_CHANGE_SPEED's).
    pub fn auto_at(&self, speed_xy_mps: f64) -> Limits {
        Limits {
            speed_xy_mps: speed_xy_mps.min(self.mpc.xy_vel_max_mps),
            ..self.auto
        }
    }
}

/// A duration from seconds that never panics: negative or NaN is zero, anything beyond
/// what a `Duration` holds is the largest one.
pub(super) fn seconds(s: f64) -> Duration {
    if s.is_nan() || s <= 0.0 {
        Duration::ZERO
    } else {
        Duration::try_from_secs_f64(s).unwrap_or(Duration::MAX)
    }
}
