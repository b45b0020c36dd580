//! The controller's algebra, then closed-loop steps on the emulated airframes.

use nalgebra::{Vector2, Vector3, Vector4};

use super::*;
use crate::control::{AttitudeCommand, AttitudeController};
use crate::physics::{Airframe, BodyState, Environment};
use crate::profile::{GRAVITY_MPS2, Profile};

#[test]
fn hover_needs_hover_thrust_and_a_level_attitude() {
    let p = MpcParams::px4_defaults(0.5);
    let thrust = acceleration_to_thrust(&p, &Vector3::zeros());
    assert!((thrust - Vector3::new(0.0, 0.0, -0.5)).norm() < 1e-12);
    let sp = thrust_to_attitude(&thrust, 0.3);
    assert!((sp.thrust_norm - 0.5).abs() < 1e-12);
    let (roll, pitch, yaw) = sp.attitude.euler_angles();
    assert!(roll.abs() < 1e-12 && pitch.abs() < 1e-12 && (yaw - 0.3).abs() < 1e-12);
}

#[test]
fn north_acceleration_pitches_nose_down_and_east_rolls_right() {
    let p = MpcParams::px4_defaults(0.5);
    // 2 m/s² north: tilt atan(2/g) nose down; thrust hover/cos(tilt).
    let thrust = acceleration_to_thrust(&p, &Vector3::new(2.0, 0.0, 0.0));
    let sp = thrust_to_attitude(&thrust, 0.0);
    let (roll, pitch, _) = sp.attitude.euler_angles();
    let tilt = (2.0 / GRAVITY_MPS2).atan();
    assert!(
        (pitch + tilt).abs() < 1e-9 && roll.abs() < 1e-9,
        "pitch {pitch}"
    );
    assert!((sp.thrust_norm - 0.5 / tilt.cos()).abs() < 1e-9);
    let thrust = acceleration_to_thrust(&p, &Vector3::new(0.0, 2.0, 0.0));
    let (roll, _, _) = thrust_to_attitude(&thrust, 0.0).attitude.euler_angles();
    assert!((roll - tilt).abs() < 1e-9, "roll {roll}");
}

#[test]
fn tilt_is_limited_to_tiltmax() {
    let p = MpcParams::px4_defaults(0.5);
    let thrust = acceleration_to_thrust(&p, &Vector3::new(50.0, 0.0, 0.0));
    let tilt = (-thrust.z / thrust.norm()).acos();
    assert!((tilt - 45f64.to_radians()).abs() < 1e-9, "tilt {tilt}");
}

#[test]
fn constrain_xy_keeps_the_position_part_first() {
    // Position part 3 m/s north, feed-forward 10 m/s east, limit 5: 3 north + 4 east.
    let v = constrain_xy(Vector2::new(3.0, 0.0), Vector2::new(0.0, 10.0), 5.0);
    assert!((v - Vector2::new(3.0, 4.0)).norm() < 1e-9, "{v:?}");
    // A position part above the limit is scaled alone.
    let v = constrain_xy(Vector2::new(8.0, 6.0), Vector2::new(0.0, 10.0), 5.0);
    assert!((v - Vector2::new(4.0, 3.0)).norm() < 1e-9);
    // Under the limit nothing changes.
    let v = constrain_xy(Vector2::new(1.0, 0.0), Vector2::new(0.0, 1.0), 5.0);
    assert!((v - Vector2::new(1.0, 1.0)).norm() < 1e-12);
}

#[test]
fn velocity_setpoint_is_clamped_to_the_vertical_limits() {
    let p = MpcParams::px4_defaults(0.5);
    let kin = Kinematics {
        pos_ned_m: Vector3::zeros(),
        vel_ned_mps: Vector3::zeros(),
        yaw_rad: 0.0,
    };
    let up = TrajectorySetpoint::hold(Vector3::new(0.0, 0.0, -100.0), 0.0);
    assert!((velocity_setpoint(&p, &up, &kin).z + 3.0).abs() < 1e-12);
    let down = TrajectorySetpoint::hold(Vector3::new(0.0, 0.0, 100.0), 0.0);
    assert!((velocity_setpoint(&p, &down, &kin).z - 1.5).abs() < 1e-12);
    let far = TrajectorySetpoint::hold(Vector3::new(1000.0, 0.0, 0.0), 0.0);
    assert!((velocity_setpoint(&p, &far, &kin).x - 12.0).abs() < 1e-12);
}

/// Flies `sp` from a hover at 50 m for `seconds` on `profile` and records the position
/// and velocity every millisecond.
fn fly(
    profile: Profile,
    sp: &TrajectorySetpoint,
    seconds: f64,
) -> Vec<(Vector3<f64>, Vector3<f64>)> {
    const DT: f64 = 1e-3;
    let mut frame = Airframe::new(profile.clone());
    let params = MpcParams::px4_defaults(profile.hover_throttle());
    let mut state = BodyState::at_rest(Vector3::new(0.0, 0.0, -50.0));
    state.motor_thrust_n = Vector4::repeat(profile.mass_kg * GRAVITY_MPS2 / 4.0);
    let env = Environment {
        ground_z_ned_m: 0.0,
        ..Default::default()
    };
    let (mut att, mut pos) = (AttitudeController::default(), PositionController::default());
    let mut trace = Vec::new();
    for _ in 0..(seconds / DT) as usize {
        let kin = Kinematics {
            pos_ned_m: state.pos_ned_m,
            vel_ned_mps: state.vel_ned_mps,
            yaw_rad: state.attitude.euler_angles().2,
        };
        let out = pos.update(&params, sp, &kin, DT);
        let command = AttitudeCommand::Attitude {
            setpoint: out.attitude,
            yawspeed_ff_rps: out.yawspeed_ff_rps,
        };
        let motors = att.update_command(&frame, &state, &command, DT);
        state = frame.step(&state, &motors, &env, DT);
        trace.push((state.pos_ned_m, state.vel_ned_mps));
    }
    trace
}

/// Rise time 10 %→90 %, overshoot (fraction of the step) and 2 %-settling time of one
/// signal stepping from 0 to `step`.
fn step_metrics(signal: &[f64], step: f64) -> (f64, f64, f64) {
    let t = |i: usize| (i + 1) as f64 * 1e-3;
    let first = |f: f64| {
        signal
            .iter()
            .position(|x| x / step >= f)
            .map_or(f64::INFINITY, t)
    };
    let rise = first(0.9) - first(0.1);
    let peak = signal.iter().fold(0.0_f64, |m, x| m.max(x / step));
    let settle = signal
        .iter()
        .rposition(|x| (x / step - 1.0).abs() > 0.02)
        .map_or(0.0, t);
    (rise, peak - 1.0, settle)
}

/// The same loops on a perfect double integrator, integrated independently of the
/// controller's code: `(1 + D)·v̇ = P·(v_sp − v) + I·∫(v_sp − v)`, with
/// `v_sp = P_pos·(x_sp − x)` when `position` is set. Returns the peak of the output
/// (position or velocity) over the step.
fn linear_model_peak(position: bool, step: f64) -> f64 {
    let (kp, ki, kd, kx) = (1.8, 0.4, 0.2, 0.95);
    let dt = 1e-4;
    let (mut x, mut v, mut integral, mut peak) = (0.0_f64, 0.0_f64, 0.0, 0.0_f64);
    for _ in 0..(30.0 / dt) as usize {
        let v_sp = if position { kx * (step - x) } else { step };
        let e = v_sp - v;
        let a = (kp * e + ki * integral) / (1.0 + kd);
        integral += e * dt;
        v += a * dt;
        x += v * dt;
        peak = peak.max(if position { x } else { v });
    }
    peak / step - 1.0
}

#[test]
fn five_metre_position_step_rises_overshoots_and_settles_as_documented() {
    // PX4's gains overshoot a position step: the velocity integrator (I 0.4) winds up
    // during the move. Measured (rise 10→90 %, overshoot, settling to 2 % = ±0.1 m,
    // altitude): x500 1.35 s, 11.2 %, 6.5 s, ±0.07 m; ideal 1.44 s, 11.3 %, 7.1 s,
    // ±0.02 m. Documented bounds: rise ≤ 1.6 s, overshoot ≤ 13 %, settle ≤ 8 s,
    // altitude ±0.1 m; and the ideal vehicle within 1.5 points of the linear model's.
    let model = linear_model_peak(true, 5.0);
    for profile in [Profile::x500(), Profile::ideal()] {
        let name = profile.name;
        let sp = TrajectorySetpoint::hold(Vector3::new(5.0, 0.0, -50.0), 0.0);
        let trace = fly(profile, &sp, 12.0);
        let north: Vec<f64> = trace.iter().map(|(p, _)| p.x).collect();
        let (rise, overshoot, settle) = step_metrics(&north, 5.0);
        let alt_err = trace
            .iter()
            .map(|(p, _)| (p.z + 50.0).abs())
            .fold(0.0, f64::max);
        println!(
            "{name}: 5 m step rise {rise:.3} s overshoot {:.2} % (model {:.2} %) settle {settle:.3} s altitude ±{alt_err:.4} m",
            overshoot * 100.0,
            model * 100.0
        );
        assert!(rise <= 1.6, "{name}: rise {rise}");
        assert!(overshoot <= 0.13, "{name}: overshoot {overshoot}");
        assert!(settle <= 8.0, "{name}: settle {settle}");
        assert!(alt_err <= 0.1, "{name}: altitude error {alt_err}");
        if name == "ideal" {
            assert!(
                (overshoot - model).abs() <= 0.015,
                "ideal {overshoot} vs model {model}"
            );
        }
    }
}

#[test]
fn two_metre_per_second_velocity_step_rises_overshoots_and_settles_as_documented() {
    // The velocity PID's slow zero (I/P = 0.22 1/s) overshoots a velocity step too.
    // Measured: x500 rise 0.97 s, 5.9 %, settle 8.0 s; ideal 1.07 s, 9.6 %, 9.8 s.
    // Documented bounds: rise ≤ 1.2 s, overshoot ≤ 11 %, settle ≤ 11 s, within
    // 1.5 cm/s of 2 m/s after 15 s (the integrator removes the x500's drag); the ideal
    // vehicle within 1 point of the linear model's overshoot.
    let model = linear_model_peak(false, 2.0);
    for profile in [Profile::x500(), Profile::ideal()] {
        let name = profile.name;
        let sp = TrajectorySetpoint {
            vel_ned_mps: Vector3::new(0.0, 2.0, 0.0),
            pos_ned_m: Vector3::new(f64::NAN, f64::NAN, -50.0),
            yaw_rad: 0.0,
            ..TrajectorySetpoint::UNSET
        };
        let trace = fly(profile, &sp, 15.0);
        let east: Vec<f64> = trace.iter().map(|(_, v)| v.y).collect();
        let (rise, overshoot, settle) = step_metrics(&east, 2.0);
        let last = east[east.len() - 1];
        println!(
            "{name}: 2 m/s step rise {rise:.3} s overshoot {:.2} % (model {:.2} %) settle {settle:.3} s final {last:.4}",
            overshoot * 100.0,
            model * 100.0
        );
        assert!(rise <= 1.2, "{name}: rise {rise}");
        assert!(overshoot <= 0.11, "{name}: overshoot {overshoot}");
        assert!(settle <= 11.0, "{name}: settle {settle}");
        assert!((last - 2.0).abs() <= 0.015, "{name}: final {last}");
        if name == "ideal" {
            assert!(
                (overshoot - model).abs() <= 0.01,
                "ideal {overshoot} vs model {model}"
            );
        }
    }
}
