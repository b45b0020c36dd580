//! Prints the attitude step response and hover drift of each profile (the figures the
//! README documents): `cargo run -p ringswarm-sitl --release --example step_response`.

use nalgebra::{UnitQuaternion, Vector3, Vector4};
use ringswarm_sitl::control::{AttitudeController, AttitudeSetpoint};
use ringswarm_sitl::physics::{Airframe, BodyState, Environment};
use ringswarm_sitl::profile::{GRAVITY_MPS2, Profile};

fn main() {
    println!(
        "| profile | 20° roll step: rise 10–90 % (s) | overshoot (%) | settle to 2 % (s) | hover drift over 10 s (mm) |"
    );
    println!("|---|---|---|---|---|");
    for profile in Profile::all() {
        let mut frame = Airframe::new(profile.clone());
        let env = Environment {
            ground_z_ned_m: 0.0,
            ..Default::default()
        };
        let mut s = BodyState::at_rest(Vector3::new(0.0, 0.0, -100.0));
        s.motor_thrust_n = Vector4::repeat(profile.mass_kg * GRAVITY_MPS2 / 4.0);
        let mut ctrl = AttitudeController::default();
        let step = 20f64.to_radians();
        let sp = AttitudeSetpoint {
            attitude: UnitQuaternion::from_euler_angles(step, 0.0, 0.0),
            thrust_norm: profile.hover_throttle(),
        };
        let (mut t10, mut t90, mut peak, mut settle) = (None, None, 0.0_f64, 0.0);
        for i in 0..3000 {
            let t = (i + 1) as f64 * 1e-3;
            let cmd = ctrl.update(&frame, &s, &sp, 1e-3);
            s = frame.step(&s, &cmd, &env, 1e-3);
            let (roll, _, _) = s.attitude.euler_angles();
            if roll >= 0.1 * step && t10.is_none() {
                t10 = Some(t);
            }
            if roll >= 0.9 * step && t90.is_none() {
                t90 = Some(t);
            }
            peak = peak.max(roll);
            if (roll - step).abs() > 0.02 * step {
                settle = t;
            }
        }
        let mut h = BodyState::at_rest(Vector3::new(0.0, 0.0, -10.0));
        let hover = Vector4::repeat(profile.mass_kg * GRAVITY_MPS2 / 4.0);
        h.motor_thrust_n = hover;
        for _ in 0..10_000 {
            h = frame.step(&h, &hover, &env, 1e-3);
        }
        println!(
            "| {} | {:.3} | {:.1} | {:.3} | {:.4} |",
            profile.name,
            t90.unwrap_or(f64::NAN) - t10.unwrap_or(f64::NAN),
            100.0 * (peak - step) / step,
            settle,
            1000.0 * (h.pos_ned_m.z + 10.0).abs()
        );
    }
}
