//! Link loss and the end of a flight, in lockstep: the paper's first simulation with one
//! vehicle silenced, and with the flight ended by landing.

use ringswarm::config::Config;
use ringswarm::driver::lockstep::Lockstep;
use ringswarm::swarm::SwarmPhase;
use ringswarm::swarm::VehicleIndex;
use ringswarm::vehicle::Phase;
use ringswarm_sitl::autopilot::{FlightMode, Vehicle};
use ringswarm_wire::time::SimTime;

/// paper-sim1 with `[swarm]` and `[emulator]` lines replaced.
fn build(swarm_lines: &str, ground_below_m: f64) -> Lockstep {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/paper-sim1.toml");
    let text = std::fs::read_to_string(path).unwrap();
    let text = text.replace("duration_s = 60.0\n", swarm_lines).replace(
        "ground_below_m = 100.0",
        &format!("ground_below_m = {ground_below_m}"),
    );
    Lockstep::from_config(&Config::from_toml(&text).unwrap()).unwrap()
}

fn secs(s: f64) -> SimTime {
    SimTime::from_micros((s * 1e6).round() as u64)
}

fn speed(v: &Vehicle) -> f64 {
    v.status().vel_ned_mps.xy().norm()
}

#[test]
fn with_retake_a_lost_vehicle_makes_the_others_hover_and_the_swarm_resumes_when_it_is_back() {
    let mut run = build(
        "duration_s = 60.0\non_link_loss = \"hold\"\nretake_offboard = true\n",
        100.0,
    );
    // Vehicle 3's link goes silent from 10 s to 13 s, both ways.
    run.silence(2, secs(10.0), secs(13.0));
    let mut held_at = None;
    let mut failsafe_at = None;
    let mut resumed_at = None;
    run.run_until(secs(30.0), |r| {
        let t = r.now();
        if held_at.is_none() && matches!(r.swarm().phase(), SwarmPhase::Holding(_)) {
            held_at = Some(t);
        }
        if failsafe_at.is_none() && r.vehicles()[2].status().failsafe {
            failsafe_at = Some(t);
        }
        if held_at.is_some()
            && resumed_at.is_none()
            && matches!(r.swarm().phase(), SwarmPhase::Consensus(_))
        {
            resumed_at = Some(t);
        }
        if t == secs(14.0) {
            // Braking at up to g·tan 45° from about 15 m/s, then holding: 3.7 s into the
            // hold the others are slower than 0.5 m/s.
            for (i, v) in r.vehicles().iter().enumerate().filter(|(i, _)| *i != 2) {
                assert!(speed(v) < 0.5, "vehicle {} at {} m/s", i + 1, speed(v));
            }
        }
    });
    // Its last position arrived just before 10 s; 0.3 s later (the state timeout) it is
    // too old to fly on, seen on the next 4 ms control tick: lost for the swarm, long
    // before the 1.5 s link timeout.
    let held = held_at.expect("never held").as_secs_f64();
    assert!((10.29..10.31).contains(&held), "held at {held} s");
    // The vehicle's own offboard-loss failsafe: COM_OF_LOSS_T = 1 s after its last
    // setpoint, which left on the 9.996 s control tick.
    let failsafe = failsafe_at.expect("no failsafe").as_secs_f64() - 9.996;
    assert!(
        (1.0..1.2).contains(&failsafe),
        "failsafe {failsafe} s after the last setpoint"
    );
    // Heard again at 13 s: 1.2 s of stream, arm (already armed), OFFBOARD, then resume.
    let resumed = resumed_at.expect("never resumed").as_secs_f64();
    assert!((14.2..14.6).contains(&resumed), "resumed at {resumed} s");
    assert!(run.swarm().links().all(|l| l.phase() == Phase::Flying));
    assert!(run.vehicles()[2].status().mode == FlightMode::Offboard);
    // The new consensus starts from a hovering swarm: its predicted velocity is small.
    let predicted = run.swarm().predicted_final_velocity().unwrap();
    assert!(predicted.norm() < 0.5, "{predicted:?}");
}

#[test]
fn by_default_a_vehicle_that_failsafed_is_left_to_its_own_decision() {
    let mut run = build("duration_s = 60.0\non_link_loss = \"hold\"\n", 100.0);
    run.silence(2, secs(10.0), secs(13.0));
    let mut failsafe_mode = None;
    let mut retaken = false;
    let mut overridden_at = None;
    run.run_until(secs(30.0), |r| {
        let v = r.vehicles()[2].status();
        if failsafe_mode.is_none() && v.failsafe {
            failsafe_mode = Some(v.mode);
        }
        if r.now() > secs(13.0) && v.mode == FlightMode::Offboard {
            retaken = true;
        }
        if overridden_at.is_none()
            && r.swarm().link(VehicleIndex(2)).unwrap().phase() == Phase::Overridden
        {
            overridden_at = Some(r.now());
        }
    });
    let mode = failsafe_mode.expect("no failsafe");
    assert_ne!(mode, FlightMode::Offboard);
    assert!(!retaken, "vehicle 3 was taken back into OFFBOARD");
    // Heard again at 13 s (its first heartbeat after the silence, within 1 s): not in
    // OFFBOARD any more, so it is left alone.
    let overridden = overridden_at.expect("never overridden").as_secs_f64();
    assert!(
        (13.0..14.05).contains(&overridden),
        "overridden at {overridden} s"
    );
    let v = run.vehicles()[2].status();
    assert!(v.armed && v.mode == mode, "{v:?}");
    // The others keep holding: the swarm never resumes without it.
    assert!(matches!(run.swarm().phase(), SwarmPhase::Holding(_)));
    for (i, v) in run.vehicles().iter().enumerate().filter(|(i, _)| *i != 2) {
        assert!(speed(v) < 0.2, "vehicle {} at {} m/s", i + 1, speed(v));
    }
    // The operator was told, in words.
    let told: Vec<&str> = run
        .swarm()
        .events()
        .iter()
        .filter(|e| e.system_id == Some(3) && e.warning)
        .map(|e| e.text.as_str())
        .collect();
    assert!(told.contains(&"lost (link timeout)"), "{told:?}");
    assert!(
        told.iter()
            .any(|t| t.starts_with("left OFFBOARD by itself: now in ")),
        "{told:?}"
    );
}

#[test]
fn policy_land_lands_and_disarms_every_vehicle_including_the_lost_one() {
    let mut run = build("duration_s = 60.0\non_link_loss = \"land\"\n", 55.0);
    run.silence(2, secs(10.0), secs(13.0));
    let mut finished_at = None;
    run.run_until(secs(150.0), |r| {
        if finished_at.is_none() && r.swarm().is_finished() {
            finished_at = Some(r.now());
        }
    });
    let finished = finished_at.expect("not finished").as_secs_f64();
    for (i, v) in run.vehicles().iter().enumerate() {
        let s = v.status();
        assert!(s.landed && !s.armed, "vehicle {}: {s:?}", i + 1);
        assert!(
            s.height_m.abs() < 0.05,
            "vehicle {} height {}",
            i + 1,
            s.height_m
        );
    }
    assert!(run.swarm().links().all(|l| l.phase() == Phase::Done));
    // About 105 m to descend at 1.5 m/s, the last 10 m slower: 75-80 s after 11.5 s.
    assert!(
        (80.0..100.0).contains(&finished),
        "finished at {finished} s"
    );
}

#[test]
fn at_the_end_of_the_duration_every_vehicle_lands_where_it_is_and_disarms() {
    let mut run = build("duration_s = 20.0\nend = \"land\"\n", 55.0);
    let mut landing_at = None;
    let mut where_told = Vec::new();
    run.run_until(secs(140.0), |r| {
        if landing_at.is_none() && matches!(r.swarm().phase(), SwarmPhase::Landing(_)) {
            landing_at = Some(r.now());
            where_told = r
                .vehicles()
                .iter()
                .map(|v| v.status().pos_world_ned_m.xy())
                .collect();
        }
    });
    let landing = landing_at.expect("never landed").as_secs_f64();
    let start = run.swarm().consensus_started().unwrap().as_secs_f64();
    assert!(
        (landing - (start + 20.0)).abs() < 0.005,
        "landing at {landing}"
    );
    assert!(run.swarm().is_finished());
    for (i, v) in run.vehicles().iter().enumerate() {
        let s = v.status();
        assert!(s.landed && !s.armed, "vehicle {}: {s:?}", i + 1);
        // Touchdown where it was told to land: AUTO.LAND holds the horizontal position it
        // was entered at (measured 8 µm off).
        let drift = (s.pos_world_ned_m.xy() - where_told[i]).norm();
        assert!(drift < 0.01, "vehicle {} landed {drift} m away", i + 1);
    }
}

/// Every vehicle silenced for good during consensus: the swarm holds, lands at the end
/// of the duration, and the landing stops waiting for the lost vehicles
/// `LOST_LANDING_WAIT` after it was ordered, naming them, instead of landing forever;
/// each vehicle's own failsafe has it by then.
#[test]
fn a_landing_held_up_only_by_lost_vehicles_ends_without_them_and_names_them() {
    let mut run = build("duration_s = 10.0\n", 100.0);
    for i in 0..6 {
        run.silence(i, secs(5.0), secs(1e6));
    }
    let mut landing_at = None;
    let mut finished_at = None;
    run.run_until(secs(60.0), |r| {
        if landing_at.is_none()
            && let SwarmPhase::Landing(since) = r.swarm().phase()
        {
            landing_at = Some(since);
        }
        if finished_at.is_none() && r.swarm().is_finished() {
            finished_at = Some(r.now());
        }
    });
    let landing = landing_at.expect("never landed");
    // Consensus started at 1.3 s and ran its 10 s (held from 5.3 s on): landing at 11.3 s.
    let started = run
        .swarm()
        .consensus_started()
        .expect("consensus")
        .as_secs_f64();
    assert!((landing.as_secs_f64() - (started + 10.0)).abs() < 0.01);
    let finished = finished_at.expect("never finished");
    let waited = finished.saturating_since(landing);
    assert!(
        waited >= ringswarm::swarm::LOST_LANDING_WAIT
            && waited < ringswarm::swarm::LOST_LANDING_WAIT + std::time::Duration::from_millis(5),
        "finished {waited:?} after the landing"
    );
    let names: Vec<String> = (1..=6).map(|id| format!("vehicle {id}")).collect();
    assert_eq!(run.swarm().left_lost(), names.as_slice());
    assert!(run.swarm().links().all(|l| l.phase() == Phase::Lost));
    // Each vehicle's own offboard-loss failsafe took it long before.
    assert!(run.vehicles().iter().all(|v| v.status().failsafe));
    let event = run
        .swarm()
        .events()
        .iter()
        .find(|e| e.text.starts_with("landing ended without"))
        .expect("the event");
    assert!(event.text.starts_with(
        "landing ended without vehicle 1, vehicle 2, vehicle 3, vehicle 4, vehicle 5, vehicle 6: lost"
    ));
}
