//! Every setpoint kind MAVSDK and PX4 use, each frame, and what PX4 refuses.

use std::f64::consts::FRAC_PI_2;

use nalgebra::{UnitQuaternion, Vector3};

use super::*;
use crate::world::World;

const NAN: f64 = f64::NAN;

fn target(frame: u8, type_mask: u16) -> PositionTarget {
    PositionTarget {
        frame,
        type_mask,
        position: [1.0, 2.0, -3.0],
        velocity: [0.5, -0.5, -1.0],
        acceleration: [0.1, 0.2, 0.3],
        yaw_rad: 0.25,
        yaw_rate_rps: 0.5,
    }
}

fn trajectory(r: Result<OffboardTarget, Refusal>) -> TrajectorySetpoint {
    match r {
        Ok(OffboardTarget::Trajectory(sp)) => sp,
        other => panic!("not a trajectory: {other:?}"),
    }
}

/// NaN-aware equality of a vector with the expected one.
fn same(v: Vector3<f64>, expected: [f64; 3]) -> bool {
    v.iter()
        .zip(expected)
        .all(|(a, b)| (a.is_nan() && b.is_nan()) || (a - b).abs() < 1e-9)
}

#[test]
fn mavsdk_masks_in_local_ned_set_exactly_their_fields() {
    let level = UnitQuaternion::identity();
    // (MAVSDK call, type_mask, position, velocity, acceleration, yaw set, yaw rate set)
    type Case = (&'static str, u16, [f64; 3], [f64; 3], [f64; 3], bool, bool);
    let cases: [Case; 5] = [
        (
            "velocity_ned",
            0x9C7,
            [NAN; 3],
            [0.5, -0.5, -1.0],
            [NAN; 3],
            true,
            false,
        ),
        (
            "position_ned",
            0x9F8,
            [1.0, 2.0, -3.0],
            [NAN; 3],
            [NAN; 3],
            true,
            false,
        ),
        (
            "position_velocity_ned",
            0x9C0,
            [1.0, 2.0, -3.0],
            [0.5, -0.5, -1.0],
            [NAN; 3],
            true,
            false,
        ),
        (
            "position_velocity_acceleration_ned",
            0x800,
            [1.0, 2.0, -3.0],
            [0.5, -0.5, -1.0],
            [0.1, 0.2, 0.3],
            true,
            false,
        ),
        (
            "acceleration_ned",
            0xC3F,
            [NAN; 3],
            [NAN; 3],
            [0.1, 0.2, 0.3],
            false,
            false,
        ),
    ];
    for (name, mask, pos, vel, acc, yaw, yaw_rate) in cases {
        let sp = trajectory(local_ned(&target(frame::LOCAL_NED, mask), &level));
        assert!(
            same(sp.pos_ned_m, pos),
            "{name}: position {:?}",
            sp.pos_ned_m
        );
        assert!(
            same(sp.vel_ned_mps, vel),
            "{name}: velocity {:?}",
            sp.vel_ned_mps
        );
        assert!(
            same(sp.acc_ned_mps2, acc),
            "{name}: acceleration {:?}",
            sp.acc_ned_mps2
        );
        assert_eq!(sp.yaw_rad.is_finite(), yaw, "{name}: yaw");
        assert_eq!(sp.yawspeed_rps.is_finite(), yaw_rate, "{name}: yaw rate");
    }
}

#[test]
fn every_single_axis_combination_of_position_velocity_acceleration_is_taken() {
    // All 2⁹ ignore patterns of the nine axes: everything but "all ignored" is a
    // setpoint; half a horizontal pair is dropped as PX4 flies x and y together.
    let level = UnitQuaternion::identity();
    for bits in 0u16..512 {
        let mask = bits; // bits 0..8 are the nine ignore flags
        let result = local_ned(&target(frame::LOCAL_NED, mask), &level);
        if bits == 511 {
            assert_eq!(result, Err(Refusal::NothingSet));
            continue;
        }
        let sp = trajectory(result);
        for (i, value) in [1.0, 2.0, -3.0].iter().enumerate() {
            let ignored = mask & (1 << i) != 0;
            let pair_broken = i < 2 && (mask & 1 != 0) != (mask & 2 != 0);
            let expect = if ignored || pair_broken { NAN } else { *value };
            assert!(
                same(Vector3::repeat(sp.pos_ned_m[i]), [expect; 3]),
                "mask {mask:#x} axis {i}"
            );
        }
    }
}

#[test]
fn body_ned_rotates_velocity_by_heading_and_acceleration_by_attitude() {
    // Heading east (yaw 90°), pitched 10° nose down.
    let attitude = UnitQuaternion::from_euler_angles(0.0, -10f64.to_radians(), FRAC_PI_2);
    let mut t = target(frame::BODY_NED, 0x5C7); // MAVSDK's velocity_body
    t.velocity = [5.0, 0.0, -1.0]; // forward 5 m/s, up 1 m/s
    let sp = trajectory(local_ned(&t, &attitude));
    // Forward is east whatever the pitch; down stays down.
    assert!(
        same(sp.vel_ned_mps, [0.0, 5.0, -1.0]),
        "{:?}",
        sp.vel_ned_mps
    );
    assert!(sp.pos_ned_m.iter().all(|x| x.is_nan()));
    assert!(sp.yaw_rad.is_nan() && (sp.yawspeed_rps - 0.5).abs() < 1e-12);
    // Acceleration uses the full attitude: body forward 1 m/s² tilts with the pitch.
    let mut t = target(frame::BODY_NED, 0x3F); // only ax, ay, az
    t.acceleration = [1.0, 0.0, 0.0];
    let sp = trajectory(local_ned(&t, &attitude));
    let expected = attitude * Vector3::new(1.0, 0.0, 0.0);
    assert!((sp.acc_ned_mps2 - expected).norm() < 1e-9);
    assert!(
        sp.acc_ned_mps2.z > 0.17 - 0.01,
        "nose down: forward has a down part"
    );
}

#[test]
fn body_ned_takes_a_velocity_only_with_all_three_axes() {
    let level = UnitQuaternion::identity();
    let t = target(frame::BODY_NED, 0x5C7 | 32); // vz ignored too
    assert_eq!(local_ned(&t, &level), Err(Refusal::NothingSet));
}

#[test]
fn offset_frames_and_unknown_frames_are_refused_as_current_px4_does() {
    let level = UnitQuaternion::identity();
    for f in [frame::LOCAL_OFFSET_NED, frame::BODY_OFFSET_NED, 0, 12] {
        assert_eq!(
            local_ned(&target(f, 0x9F8), &level),
            Err(Refusal::UnsupportedFrame(f))
        );
    }
}

#[test]
fn force_with_an_acceleration_and_yaw_alone_are_refused() {
    let level = UnitQuaternion::identity();
    let force = target(frame::LOCAL_NED, 0xC3F | mask::FORCE);
    assert_eq!(local_ned(&force, &level), Err(Refusal::ForceNotSupported));
    // The force bit without an acceleration is harmless.
    let vel = target(frame::LOCAL_NED, 0x9C7 | mask::FORCE);
    assert!(local_ned(&vel, &level).is_ok());
    let yaw_only = target(frame::LOCAL_NED, 0x1FF);
    assert_eq!(local_ned(&yaw_only, &level), Err(Refusal::NothingSet));
}

#[test]
fn infinite_values_are_refused() {
    let level = UnitQuaternion::identity();
    let mut t = target(frame::LOCAL_NED, 0x9C7);
    t.velocity[0] = f64::INFINITY;
    assert_eq!(local_ned(&t, &level), Err(Refusal::BadValue));
}

#[test]
fn global_positions_project_around_the_origin_with_relative_altitude_above_home() {
    let world = World::default();
    // A vehicle whose origin is 100 m north of the reference, home 488 m AMSL.
    let origin = Vector3::new(100.0, 0.0, 0.0);
    let gf = GlobalFrame {
        world,
        origin_world_ned_m: origin,
        home_alt_amsl_m: 488.0,
    };
    let goal = world.to_geodetic(&Vector3::new(150.0, 30.0, 0.0));
    let mut t = target(frame::GLOBAL_RELATIVE_ALT_INT, 0x9F8);
    t.position = [goal.lat_deg, goal.lon_deg, 20.0];
    let sp = trajectory(global_int(&t, &gf));
    assert!(
        (sp.pos_ned_m - Vector3::new(50.0, 30.0, -20.0)).norm() < 1e-6,
        "{:?}",
        sp.pos_ned_m
    );
    t.frame = frame::GLOBAL_INT;
    t.position[2] = 498.0; // AMSL: 10 m above home
    let sp = trajectory(global_int(&t, &gf));
    assert!((sp.pos_ned_m.z + 10.0).abs() < 1e-9);
    t.frame = 3; // GLOBAL_RELATIVE_ALT (not _INT): PX4 refuses it here
    assert_eq!(global_int(&t, &gf), Err(Refusal::UnsupportedFrame(3)));
}

#[test]
fn attitude_target_with_thrust_or_rates_and_nothing_without_thrust() {
    let level = [1.0, 0.0, 0.0, 0.0];
    let base = AttitudeTarget {
        type_mask: 7,
        q: level,
        body_rates_rps: [0.1, 0.2, 0.3],
        thrust: 0.6,
        thrust_body: [0.0; 3],
    };
    assert!(matches!(
        attitude_target(&base),
        Ok(OffboardTarget::Attitude { thrust, yawspeed_ff_rps, .. }) if thrust == 0.6 && yawspeed_ff_rps.is_nan()
    ));
    // Attitude with a yaw-rate feed-forward (bit 4 clear).
    let ff = AttitudeTarget {
        type_mask: 3,
        ..base
    };
    assert!(matches!(
        attitude_target(&ff),
        Ok(OffboardTarget::Attitude { yawspeed_ff_rps, .. }) if (yawspeed_ff_rps - 0.3).abs() < 1e-12
    ));
    // Rates (MAVSDK's set_attitude_rate: attitude ignored).
    let rates = AttitudeTarget {
        type_mask: 128,
        ..base
    };
    assert_eq!(
        attitude_target(&rates),
        Ok(OffboardTarget::Rates {
            rates_frd_rps: Vector3::new(0.1, 0.2, 0.3),
            thrust: 0.6
        })
    );
    // Yaw rate alone is nothing; thrust ignored is nothing.
    let yaw_rate_only = AttitudeTarget {
        type_mask: 128 | 3,
        ..base
    };
    assert_eq!(attitude_target(&yaw_rate_only), Err(Refusal::NothingSet));
    let no_thrust = AttitudeTarget {
        type_mask: 7 | 64,
        ..base
    };
    assert_eq!(attitude_target(&no_thrust), Err(Refusal::NothingSet));
    // thrust_body (bit 32): collective is −z.
    let body = AttitudeTarget {
        type_mask: 7 | 64 | 32,
        thrust_body: [0.0, 0.0, -0.55],
        ..base
    };
    assert!(matches!(
        attitude_target(&body),
        Ok(OffboardTarget::Attitude { thrust, .. }) if (thrust - 0.55).abs() < 1e-12
    ));
    let bad_q = AttitudeTarget {
        q: [0.5, 0.0, 0.0, 0.0],
        ..base
    };
    assert_eq!(attitude_target(&bad_q), Err(Refusal::BadValue));
    let bad_thrust = AttitudeTarget {
        thrust: 1.5,
        ..base
    };
    assert_eq!(attitude_target(&bad_thrust), Err(Refusal::BadValue));
}
