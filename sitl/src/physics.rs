//! Rigid-body quadrotor dynamics, pure and fixed-step.
//!
//! Frames: position and velocity in the vehicle's local NED frame (m, m/s); attitude as the
//! rotation from body FRD to NED; body rates in FRD (rad/s). Four motors in PX4's X layout:
//!
//! ```text
//!        front
//!    3 (CW)   1 (CCW)        motor i at (x, y) = (±d, ±d) in FRD
//!         \ /                1: (+d, +d)  2: (−d, −d)  3: (+d, −d)  4: (−d, +d)
//!         / \                CCW props give a positive (nose-right) yaw reaction.
//!    2 (CCW)  4 (CW)
//! ```
//!
//! Each motor's thrust follows its command (`0..1` of full thrust) with a first-order lag.
//! Forces: gravity, thrust along body −z, linear drag on airspeed (`v − wind`). Torques:
//! `τ = Σ rᵢ × Fᵢ` plus the yaw reaction, and `ω̇ = I⁻¹(τ − ω × Iω)`.
//!
//! One step integrates as PX4's SIH simulator does, at four times its 250 Hz: the
//! accelerations are taken at the start of the step, velocity by forward Euler, position by
//! the trapezoid of the old and new velocity (exact under constant acceleration), attitude
//! by the rotation `ω·dt` (first order, then renormalised: the angle is off by `(ω·dt)³/12`,
//! 2·10⁻⁹ rad at 3 rad/s and 1 ms), body rates by forward Euler. The motor lag is
//! integrated exactly (`e^(−dt/τ)`), so a motor time constant shorter than the step stays
//! stable. Then the ground contact is applied as a constraint: the vehicle never goes below
//! the ground, rests on it while the thrust cannot lift it, and lifts off when it can.

use nalgebra::{Matrix4, Quaternion, UnitQuaternion, Vector3, Vector4};

use crate::profile::{GRAVITY_MPS2, Profile};

/// The full mechanical state of one vehicle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BodyState {
    /// Position in the local NED frame (m).
    pub pos_ned_m: Vector3<f64>,
    /// Velocity in NED (m/s).
    pub vel_ned_mps: Vector3<f64>,
    /// Rotation from body FRD to NED.
    pub attitude: UnitQuaternion<f64>,
    /// Body rates in FRD (rad/s).
    pub rate_frd_rps: Vector3<f64>,
    /// Thrust of each motor (N).
    pub motor_thrust_n: Vector4<f64>,
}

impl BodyState {
    /// At rest, level, at `pos_ned_m`.
    pub fn at_rest(pos_ned_m: Vector3<f64>) -> Self {
        Self {
            pos_ned_m,
            vel_ned_mps: Vector3::zeros(),
            attitude: UnitQuaternion::identity(),
            rate_frd_rps: Vector3::zeros(),
            motor_thrust_n: Vector4::zeros(),
        }
    }
}

/// Environment inputs that are not commands.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Environment {
    /// Wind velocity in NED (m/s).
    pub wind_ned_mps: Vector3<f64>,
    /// Height of the ground as a NED z coordinate (m): the vehicle stays at `z ≤ ground`.
    pub ground_z_ned_m: f64,
}

/// A quadrotor airframe: the profile's numbers and its mixing matrices.
#[derive(Debug, Clone)]
pub struct Airframe {
    profile: Profile,
    /// `[T, τx, τy, τz] = allocation · thrusts`.
    allocation: Matrix4<f64>,
    /// Its inverse.
    mixing: Matrix4<f64>,
    /// The motor lag's decay `e^(−dt/τ)` over the last step length `dt` (s), kept so that
    /// fixed steps pay the exponential once: `(dt, decay)`.
    motor_decay: (f64, f64),
    /// `0.3 / I` per axis of the profile's rate gains `I` (at least 1e-9): the scale of
    /// the rate integrator's bound, worked out once rather than on every step.
    rate_integral_scale: Vector3<f64>,
}

/// Motor positions in FRD (x, y) for PX4's quad X, and the yaw reaction sign.
const MOTORS: [(f64, f64, f64); 4] = [
    (1.0, 1.0, 1.0),
    (-1.0, -1.0, 1.0),
    (1.0, -1.0, -1.0),
    (-1.0, 1.0, -1.0),
];

impl Airframe {
    /// Builds the airframe of a profile.
    pub fn new(profile: Profile) -> Self {
        let d = profile.motor_offset_m;
        let mut allocation = Matrix4::zeros();
        for (i, (x, y, spin)) in MOTORS.iter().enumerate() {
            allocation[(0, i)] = 1.0;
            allocation[(1, i)] = -y * d; // τx = −Σ yᵢ Tᵢ (thrust along −z)
            allocation[(2, i)] = x * d; // τy = Σ xᵢ Tᵢ
            allocation[(3, i)] = spin * profile.moment_constant_m;
        }
        let mixing = allocation.try_inverse().expect(
            "the X allocation matrix is invertible for any positive arm and moment constant",
        );
        let rate_integral_scale =
            Vector3::repeat(0.3).component_div(&profile.gains.rate_i.map(|g| g.max(1e-9)));
        Self {
            profile,
            allocation,
            mixing,
            motor_decay: (0.0, 1.0),
            rate_integral_scale,
        }
    }

    /// `0.3 / I` per axis of the profile's rate gains `I`: the rate controller bounds its
    /// integrator at ten times this.
    pub fn rate_integral_scale(&self) -> Vector3<f64> {
        self.rate_integral_scale
    }

    /// The profile.
    pub fn profile(&self) -> &Profile {
        &self.profile
    }

    /// Motor thrusts (N) for a collective thrust (N) and body torques (N·m), desaturated
    /// in PX4's order with airmode off: roll and pitch first, the collective only ever
    /// lowered (never raised) to make room at the top, roll and pitch scaled down when a
    /// motor would go below zero, and yaw last, with whatever headroom is left.
    pub fn mix(&self, thrust_n: f64, torque_frd_nm: Vector3<f64>) -> Vector4<f64> {
        let max = self.profile.max_motor_thrust_n;
        let collective = (thrust_n / 4.0).clamp(0.0, max);
        let (roll, pitch, yaw) = (
            self.mixing.column(1),
            self.mixing.column(2),
            self.mixing.column(3),
        );
        let roll_pitch: [f64; 4] =
            std::array::from_fn(|i| roll[i] * torque_frd_nm.x + pitch[i] * torque_frd_nm.y);
        let (lowest, highest) = roll_pitch
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
                (lo.min(v), hi.max(v))
            });
        // Largest share of roll/pitch that fits between 0 and max once the collective may
        // be lowered: the spread must fit, and no motor may go below zero.
        let spread = highest - lowest;
        let mut scale = if spread > max { max / spread } else { 1.0 };
        if lowest < 0.0 {
            scale = scale.min(collective / -lowest);
        }
        let mut thrusts = roll_pitch.map(|v| v * scale + collective);
        let over = thrusts.iter().fold(f64::NEG_INFINITY, |m, &t| m.max(t)) - max;
        if over > 0.0 {
            thrusts.iter_mut().for_each(|t| *t -= over);
        }
        let yaw: [f64; 4] = std::array::from_fn(|i| yaw[i] * torque_frd_nm.z);
        // The share of the yaw each motor has room for: up to `max` when its yaw adds
        // thrust, down to zero when it takes thrust away; any share without yaw. Every
        // quotient is formed and the unused ones dropped, so that the four divide at once.
        let room: [f64; 4] = std::array::from_fn(|i| {
            let (t, y) = (thrusts[i], yaw[i]);
            let share = if y > 0.0 { (max - t) / y } else { t / -y };
            if y == 0.0 { 1.0 } else { share }
        });
        let yaw_scale = room.into_iter().fold(1.0_f64, f64::min).max(0.0);
        Vector4::from_fn(|i, _| (thrusts[i] + yaw[i] * yaw_scale).clamp(0.0, max))
    }

    /// Collective thrust (N) and torques (N·m) produced by motor thrusts.
    pub fn wrench(&self, motor_thrust_n: &Vector4<f64>) -> (f64, Vector3<f64>) {
        let w = self.allocation * motor_thrust_n;
        (w[0], Vector3::new(w[1], w[2], w[3]))
    }

    /// Linear and angular accelerations (NED m/s², FRD rad/s²) of a state.
    fn accelerations(&self, s: &BodyState, env: &Environment) -> (Vector3<f64>, Vector3<f64>) {
        let p = &self.profile;
        let (thrust, torque) = self.wrench(&s.motor_thrust_n);
        let thrust_ned = s.attitude * Vector3::new(0.0, 0.0, -thrust / p.mass_kg);
        let drag = (s.vel_ned_mps - env.wind_ned_mps) * -p.linear_drag_per_s;
        let accel = thrust_ned + drag + Vector3::new(0.0, 0.0, GRAVITY_MPS2);
        let inertia = p.inertia_kg_m2;
        let w = s.rate_frd_rps;
        let gyro = w.cross(&inertia.component_mul(&w));
        (accel, (torque - gyro).component_div(&inertia))
    }

    /// The state `dt_s` after `s` under motor thrust commands `motor_cmd_n` (held
    /// constant over the step), the ground contact applied: [`Airframe::advance`] on a copy.
    pub fn step(
        &mut self,
        s: &BodyState,
        motor_cmd_n: &Vector4<f64>,
        env: &Environment,
        dt_s: f64,
    ) -> BodyState {
        let mut next = *s;
        self.advance(&mut next, motor_cmd_n, env, dt_s);
        next
    }

    /// Advances the state in place by `dt_s` under motor thrust commands `motor_cmd_n`
    /// (held constant over the step), then applies the ground contact.
    pub fn advance(
        &mut self,
        s: &mut BodyState,
        motor_cmd_n: &Vector4<f64>,
        env: &Environment,
        dt_s: f64,
    ) {
        let cmd = motor_cmd_n.map(|t| t.clamp(0.0, self.profile.max_motor_thrust_n));
        let (accel, rate_dot) = self.accelerations(s, env);
        let vel = s.vel_ned_mps + accel * dt_s;
        let half_turn = Quaternion::from_parts(1.0, s.rate_frd_rps * (0.5 * dt_s));
        let decay = match self.motor_decay {
            (dt, decay) if dt == dt_s => decay,
            _ => {
                let decay = (-dt_s / self.profile.motor_time_constant_s).exp();
                self.motor_decay = (dt_s, decay);
                decay
            }
        };
        s.pos_ned_m += (s.vel_ned_mps + vel) * (0.5 * dt_s);
        s.vel_ned_mps = vel;
        s.attitude = UnitQuaternion::new_normalize(s.attitude.quaternion() * half_turn);
        s.rate_frd_rps += rate_dot * dt_s;
        s.motor_thrust_n = cmd + (s.motor_thrust_n - cmd) * decay;
        self.apply_ground(s, env);
    }

    /// Keeps the vehicle on or above the ground; on the ground and unable to lift off it
    /// rests level at its heading, with no velocity and no rates.
    fn apply_ground(&self, s: &mut BodyState, env: &Environment) {
        if s.pos_ned_m.z < env.ground_z_ned_m {
            return;
        }
        let (thrust, _) = self.wrench(&s.motor_thrust_n);
        let lift_up = (s.attitude * Vector3::new(0.0, 0.0, -thrust)).z; // NED: negative is up
        let can_lift = -lift_up > self.profile.mass_kg * GRAVITY_MPS2;
        s.pos_ned_m.z = env.ground_z_ned_m;
        if can_lift {
            s.vel_ned_mps.z = s.vel_ned_mps.z.min(0.0);
        } else {
            let (_, _, yaw) = s.attitude.euler_angles();
            s.vel_ned_mps = Vector3::zeros();
            s.rate_frd_rps = Vector3::zeros();
            s.attitude = UnitQuaternion::from_euler_angles(0.0, 0.0, yaw);
        }
    }

    /// Whether the state is resting on the ground.
    pub fn on_ground(&self, s: &BodyState, env: &Environment) -> bool {
        s.pos_ned_m.z >= env.ground_z_ned_m - 1e-9
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const DT: f64 = 1e-3;

    #[test]
    fn hover_thrust_holds_altitude_within_a_centimetre_for_ten_seconds() {
        for profile in Profile::all() {
            let mut frame = Airframe::new(profile.clone());
            let hover = profile.mass_kg * GRAVITY_MPS2 / 4.0;
            let mut s = BodyState::at_rest(Vector3::new(0.0, 0.0, -10.0));
            s.motor_thrust_n = Vector4::repeat(hover);
            let env = Environment {
                ground_z_ned_m: 0.0,
                ..Default::default()
            };
            for _ in 0..10_000 {
                s = frame.step(&s, &Vector4::repeat(hover), &env, DT);
            }
            assert!(
                (s.pos_ned_m.z + 10.0).abs() < 0.01,
                "{}: z = {}",
                profile.name,
                s.pos_ned_m.z
            );
            assert!(s.pos_ned_m.xy().norm() < 1e-9);
        }
    }

    #[test]
    fn free_fall_after_motor_cut_matches_g() {
        let mut frame = Airframe::new(Profile::ideal());
        let mut s = BodyState::at_rest(Vector3::new(0.0, 0.0, -100.0));
        let env = Environment {
            ground_z_ned_m: 0.0,
            ..Default::default()
        };
        for _ in 0..2000 {
            s = frame.step(&s, &Vector4::zeros(), &env, DT);
        }
        // After 2 s: v = g·t, z = z0 + g·t²/2.
        assert!((s.vel_ned_mps.z / (GRAVITY_MPS2 * 2.0) - 1.0).abs() < 0.005);
        assert!(((s.pos_ned_m.z + 100.0) / (0.5 * GRAVITY_MPS2 * 4.0) - 1.0).abs() < 0.005);
    }

    #[test]
    fn quaternion_stays_unit_over_a_million_steps() {
        let mut frame = Airframe::new(Profile::x500());
        let mut s = BodyState::at_rest(Vector3::new(0.0, 0.0, -1e6));
        s.rate_frd_rps = Vector3::new(3.0, -2.0, 1.5);
        let env = Environment {
            ground_z_ned_m: 1e9,
            ..Default::default()
        };
        for _ in 0..1_000_000 {
            s = frame.step(&s, &Vector4::zeros(), &env, DT);
        }
        assert!((s.attitude.quaternion().norm() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn ground_holds_a_vehicle_without_thrust_at_zero_height() {
        let mut frame = Airframe::new(Profile::x500());
        let env = Environment {
            ground_z_ned_m: 0.0,
            ..Default::default()
        };
        let mut s = BodyState::at_rest(Vector3::zeros());
        for _ in 0..5000 {
            s = frame.step(&s, &Vector4::zeros(), &env, DT);
        }
        assert_eq!(s.pos_ned_m, Vector3::zeros());
        assert_eq!(s.vel_ned_mps, Vector3::zeros());
        // Dropped from 2 m, it lands and stays on the ground, never below.
        let mut s = BodyState::at_rest(Vector3::new(0.0, 0.0, -2.0));
        for _ in 0..3000 {
            s = frame.step(&s, &Vector4::zeros(), &env, DT);
            assert!(s.pos_ned_m.z <= 0.0);
        }
        assert_eq!(s.pos_ned_m.z, 0.0);
    }

    #[test]
    fn full_thrust_lifts_off_the_ground() {
        let profile = Profile::x500();
        let mut frame = Airframe::new(profile.clone());
        let env = Environment {
            ground_z_ned_m: 0.0,
            ..Default::default()
        };
        let mut s = BodyState::at_rest(Vector3::zeros());
        for _ in 0..1000 {
            s = frame.step(&s, &Vector4::repeat(profile.max_motor_thrust_n), &env, DT);
        }
        assert!(s.pos_ned_m.z < -0.5, "z = {}", s.pos_ned_m.z);
    }

    #[test]
    fn mixer_reproduces_requested_wrench_inside_limits() {
        let frame = Airframe::new(Profile::x500());
        let torque = Vector3::new(0.3, -0.2, 0.05);
        let thrusts = frame.mix(20.0, torque);
        let (t, tau) = frame.wrench(&thrusts);
        assert!((t - 20.0).abs() < 1e-9 && (tau - torque).norm() < 1e-9);
        // A positive roll torque needs more thrust on the left motors (2, 3).
        assert!(thrusts[1] > thrusts[0] && thrusts[2] > thrusts[3]);
    }

    #[test]
    fn mixer_never_raises_the_collective_and_keeps_roll_pitch_before_yaw() {
        let frame = Airframe::new(Profile::ideal());
        // Low collective, a roll torque that needs more than it: roll is scaled down (same
        // sign, smaller), the collective is not raised, pitch stays zero.
        let thrusts = frame.mix(4.0, Vector3::new(2.0, 0.0, 0.0));
        let (t, tau) = frame.wrench(&thrusts);
        assert!(t <= 4.0 + 1e-9, "collective raised to {t}");
        assert!(tau.x > 0.0 && tau.x < 2.0 && tau.y.abs() < 1e-9, "{tau:?}");
        // Exactly: every motor is at 0 or 2 N, so τx = 2·2·d.
        assert!((tau.x - 4.0 * frame.profile().motor_offset_m).abs() < 1e-9);
        // At hover a yaw torque beyond the headroom still gets part of it (same sign),
        // and roll and pitch are delivered in full.
        let hover = GRAVITY_MPS2;
        let thrusts = frame.mix(hover, Vector3::new(0.1, -0.05, 1.0));
        let (t, tau) = frame.wrench(&thrusts);
        assert!(
            (tau.x - 0.1).abs() < 1e-9 && (tau.y + 0.05).abs() < 1e-9,
            "{tau:?}"
        );
        assert!(tau.z > 0.05 && tau.z < 1.0, "yaw {}", tau.z);
        assert!(t <= hover + 1e-9);
    }

    #[test]
    fn drag_pulls_velocity_towards_the_wind() {
        let profile = Profile::x500();
        let mut frame = Airframe::new(profile.clone());
        let hover = profile.mass_kg * GRAVITY_MPS2 / 4.0;
        let mut s = BodyState::at_rest(Vector3::new(0.0, 0.0, -50.0));
        s.motor_thrust_n = Vector4::repeat(hover);
        let env = Environment {
            wind_ned_mps: Vector3::new(3.0, 0.0, 0.0),
            ground_z_ned_m: 0.0,
        };
        for _ in 0..1000 {
            s = frame.step(&s, &Vector4::repeat(hover), &env, DT);
        }
        // dv/dt = c(w − v) with c = 0.1 /s, by forward Euler: v_n = 3·(1 − (1 − c·dt)ⁿ)
        // exactly; the continuous 3·(1 − e^(−0.1)) is within 3·e^(−0.1)·c²·dt·T/2 ≈ 1.4e-5.
        let euler = 3.0 * (1.0 - (1.0 - 0.1 * DT).powi(1000));
        assert!(
            (s.vel_ned_mps.x - euler).abs() < 1e-12,
            "{}",
            s.vel_ned_mps.x
        );
        assert!((s.vel_ned_mps.x - 3.0 * (1.0 - (-0.1f64).exp())).abs() < 1.5e-5);
    }
}
