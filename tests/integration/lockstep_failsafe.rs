//! What the coordinator does when a vehicle's reports go wrong or a vehicle never
//! answers, in lockstep on the paper's first simulation (six ideal vehicles, 250 Hz,
//! telemetry every 4 ms, state timeout 300 ms, link timeout 1.5 s). The faults are the
//! emulator's (`[[emulator.fault]]`, `[[emulator.silence]]`); the numbers are read on the
//! emulator's truth and the coordinator's events.

use ringswarm::config::Config;
use ringswarm::driver::lockstep::Lockstep;
use ringswarm::swarm::VehicleIndex;
use ringswarm::swarm::{SwarmFailure, SwarmPhase};
use ringswarm::vehicle::Phase;
use ringswarm_sitl::autopilot::{FlightMode, Vehicle};
use ringswarm_wire::time::SimTime;

/// paper-sim1 with extra `[swarm]` lines and extra tables before the vehicles.
fn build(swarm_lines: &str, tables: &str) -> Lockstep {
    build_over(swarm_lines, tables, 100.0)
}

/// The same, with the paper's z = 0 `ground_below_m` above the ground.
fn build_over(swarm_lines: &str, tables: &str, ground_below_m: f64) -> Lockstep {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/paper-sim1.toml");
    let text = std::fs::read_to_string(path).unwrap().replace(
        "ground_below_m = 100.0",
        &format!("ground_below_m = {ground_below_m}"),
    );
    let text = text.replace(
        "duration_s = 60.0\n",
        &format!("duration_s = 60.0\n{swarm_lines}"),
    );
    let text = text.replace("[[vehicle]]", &format!("{tables}\n[[vehicle]]"));
    Lockstep::from_config(&Config::from_toml(&text).unwrap()).unwrap()
}

fn secs(s: f64) -> SimTime {
    SimTime::from_micros((s * 1e6).round() as u64)
}

fn speed(v: &Vehicle) -> f64 {
    v.status().vel_ned_mps.xy().norm()
}

/// Warnings about system id `id`, in order.
fn warnings(run: &Lockstep, id: u8) -> Vec<String> {
    run.swarm()
        .events()
        .iter()
        .filter(|e| e.warning && e.system_id == Some(id))
        .map(|e| e.text.clone())
        .collect()
}

/// When the swarm first entered Holding and resumed, the lowest thrust it streamed to
/// vehicle `i` while that vehicle flew in OFFBOARD, and the largest drop of any vehicle
/// below its own highest point since 9 s (the altitude loop has no overshoot: k_pz = 1,
/// k_vz = 4 is overdamped, so any drop is a fall).
struct Watch {
    held_at: Option<SimTime>,
    resumed_at: Option<SimTime>,
    min_thrust: f64,
    max_height_loss_m: f64,
}

fn watch(run: &mut Lockstep, until_s: f64, i: usize) -> Watch {
    let mut w = Watch {
        held_at: None,
        resumed_at: None,
        min_thrust: f64::INFINITY,
        max_height_loss_m: 0.0,
    };
    let mut last_tick = 0;
    let mut peak = vec![f64::NEG_INFINITY; run.vehicles().len()];
    run.run_until(secs(until_s), |r| {
        match r.swarm().phase() {
            SwarmPhase::Holding(since) => {
                w.held_at.get_or_insert(since);
            }
            SwarmPhase::Consensus(since) if w.held_at.is_some() => {
                w.resumed_at.get_or_insert(since);
            }
            _ => {}
        }
        if r.swarm().control_ticks() != last_tick {
            last_tick = r.swarm().control_ticks();
            if r.swarm().link(VehicleIndex(i)).unwrap().phase() == Phase::Flying {
                w.min_thrust = w.min_thrust.min(r.swarm().setpoints()[i].thrust_norm);
            }
        }
        if r.now() >= secs(9.0) {
            for (v, top) in r.vehicles().iter().zip(&mut peak) {
                let h = v.status().height_m;
                *top = top.max(h);
                w.max_height_loss_m = w.max_height_loss_m.max(*top - h);
            }
        }
    });
    w
}

#[test]
fn nan_telemetry_from_one_vehicle_leaves_the_others_flying_and_that_vehicle_holding() {
    let fault =
        "[[emulator.fault]]\nvehicle = 3\nfrom_s = 10.0\nuntil_s = 14.0\nkind = \"nan_position\"\n";
    let mut run = build("", fault);
    let w = watch(&mut run, 14.0, 2);
    // The last good report of vehicle 3 arrived just before 10 s; 0.3 s later it is too
    // old: vehicle 3 is handed to its own Hold and the swarm holds, on the 4 ms tick.
    let held = w.held_at.expect("never held").as_secs_f64();
    assert!((10.29..10.31).contains(&held), "held at {held} s");
    let v3 = run.vehicles()[2].status();
    assert_eq!(v3.mode, FlightMode::Hold, "{v3:?}");
    assert!(v3.armed && !v3.failsafe);
    assert_eq!(
        run.swarm().link(VehicleIndex(2)).unwrap().phase(),
        Phase::VehicleHold
    );
    // The others brake at up to g·tan 45° from ~15 m/s and hover 3.7 s later; vehicle 3
    // brakes in its own Hold, more gently (PX4's MPC_ACC_HOR-limited braking).
    for (i, v) in run.vehicles().iter().enumerate().filter(|(i, _)| *i != 2) {
        assert!(speed(v) < 0.5, "vehicle {} at {} m/s", i + 1, speed(v));
    }
    assert!(
        speed(&run.vehicles()[2]) < 5.0,
        "{}",
        speed(&run.vehicles()[2])
    );
    // Nobody fell and the coordinator never cut vehicle 3's thrust: the lowest setpoint
    // it streamed is the envelope's 0.1, or more.
    assert!(w.max_height_loss_m < 1.0, "fell {} m", w.max_height_loss_m);
    assert!(w.min_thrust >= 0.1 - 1e-9, "thrust {}", w.min_thrust);
    let told = warnings(&run, 3);
    assert_eq!(
        told.first().map(String::as_str),
        Some("telemetry refused: LOCAL_POSITION_NED.x is NaN"),
        "{told:?}"
    );
    assert!(
        told.iter().any(|t| t.starts_with(
            "handed to its own Hold: no usable position within the 300 ms state timeout"
        )),
        "{told:?}"
    );
    // The reports are good again at 14 s: it was our Hold, so the vehicle is taken back
    // (1.2 s of stream, OFFBOARD) and consensus resumes with all six.
    let w = watch(&mut run, 18.0, 2);
    let resumed = w.resumed_at.expect("never resumed").as_secs_f64();
    assert!((15.2..15.6).contains(&resumed), "resumed at {resumed} s");
    assert_eq!(run.vehicles()[2].status().mode, FlightMode::Offboard);
}

#[test]
fn a_vehicle_whose_position_stops_while_its_heartbeat_goes_on_is_lost_within_the_timeout() {
    let fault = "[[emulator.fault]]\nvehicle = 3\nfrom_s = 10.0\nuntil_s = 1000.0\nkind = \"no_position\"\n";
    let mut run = build("", fault);
    let w = watch(&mut run, 16.0, 2);
    let held = w.held_at.expect("never held").as_secs_f64();
    assert!((10.29..10.31).contains(&held), "held at {held} s");
    // Its heartbeat goes on: never lost, but in its own Hold, and the others hover.
    let link = &run.swarm().link(VehicleIndex(2)).unwrap();
    assert_eq!(link.phase(), Phase::VehicleHold);
    // The link hands it over on its own timer, just before the swarm's tick holds; the
    // Hold was acknowledged at once (no latency here), and no setpoint went after the
    // hand-over: what bounds where it may coast (`safety::lost`). Measured: confirmed at
    // 10.299 s, the swarm holding at 10.300 s.
    let confirmed = link.hold_confirmed_at().expect("confirmed").as_secs_f64();
    assert!(
        (held - 0.01..held + 0.05).contains(&confirmed),
        "confirmed at {confirmed} s"
    );
    let last_setpoint = link.last_setpoint_sent().expect("streamed").as_secs_f64();
    assert!(
        (held - 0.01..=held).contains(&last_setpoint),
        "last setpoint at {last_setpoint} s"
    );
    assert!(
        link.state().last_heartbeat.is_some_and(
            |t| secs(16.0).saturating_since(t) < std::time::Duration::from_millis(1100)
        )
    );
    assert!(!warnings(&run, 3).iter().any(|t| t == "lost (link timeout)"));
    assert_eq!(run.vehicles()[2].status().mode, FlightMode::Hold);
    assert!(matches!(run.swarm().phase(), SwarmPhase::Holding(_)));
    assert!(w.max_height_loss_m < 1.0, "fell {} m", w.max_height_loss_m);
    // The others keep clear of where vehicle 3 may stop (its last state, 13.2 m/s, and
    // what was on its way to it): named once.
    let told = warnings(&run, 3);
    assert_eq!(
        told.iter()
            .filter(|t| t.starts_with("no fresh state: the others keep clear of where it may be"))
            .count(),
        1,
        "{told:?}"
    );
    // Vehicle 4, held beside where vehicle 3 was last seen, inside the separation from
    // that path, is moved out of it at about 0.2 m/s; by 20 s every vehicle hovers.
    run.run_until(secs(20.0), |_| {});
    for (i, v) in run.vehicles().iter().enumerate() {
        let limit = if i == 2 { 0.5 } else { 0.2 };
        assert!(speed(v) < limit, "vehicle {} at {} m/s", i + 1, speed(v));
    }
}

#[test]
fn a_vehicle_whose_estimator_loses_its_position_is_not_flown_on_its_dead_reckoning() {
    // From 10.5 s vehicle 3's estimator keeps only its attitude (ESTIMATOR_STATUS flags
    // 0x001, sent at 1 Hz on the whole seconds) while its LOCAL_POSITION_NED goes on, 1 m/s
    // off north and drifting: fresh, plausible, and wrong. The status at 11 s arrives on
    // the coordinator's first 4 ms tick after it: vehicle 3 goes to its own Hold then.
    let fault = "[[emulator.fault]]\nvehicle = 3\nfrom_s = 10.5\nuntil_s = 13.5\nkind = \"position_lost\"\n";
    let mut run = build("", fault);
    let w = watch(&mut run, 13.0, 2);
    let held = w.held_at.expect("never held").as_secs_f64();
    assert!((11.0..=11.004).contains(&held), "held at {held} s");
    assert_eq!(
        run.swarm().link(VehicleIndex(2)).unwrap().phase(),
        Phase::VehicleHold
    );
    assert_eq!(run.vehicles()[2].status().mode, FlightMode::Hold);
    let told = warnings(&run, 3);
    assert_eq!(
        told.first().map(String::as_str),
        Some(
            "estimator reports no good position and velocity (ESTIMATOR_STATUS flags 0x001): not flown on"
        ),
        "{told:?}"
    );
    assert!(
        told.iter()
            .any(|t| t == "handed to its own Hold: its estimator lost its position (flags 0x001)"),
        "{told:?}"
    );
    // Before the status the coordinator flew 0.5 s on the drifting report: 1 m/s of
    // velocity error for at most 0.5 s. Nobody fell, nobody's thrust was cut.
    assert!(w.max_height_loss_m < 1.0, "fell {} m", w.max_height_loss_m);
    assert!(w.min_thrust >= 0.1 - 1e-9, "thrust {}", w.min_thrust);
    // Good again from the 14 s status: our Hold, so vehicle 3 is taken back (1.2 s of
    // stream, then OFFBOARD).
    let w = watch(&mut run, 18.0, 2);
    let resumed = w.resumed_at.expect("never resumed").as_secs_f64();
    assert!((15.2..15.6).contains(&resumed), "resumed at {resumed} s");
    assert_eq!(run.vehicles()[2].status().mode, FlightMode::Offboard);
}

/// The common-frame position the coordinator flies vehicle `i` on, against the truth.
fn common_error_m(run: &Lockstep, i: usize) -> f64 {
    let truth = ringswarm::control::ned_to_enu(run.vehicles()[i].status().pos_world_ned_m);
    let seen = run.swarm().common_state(VehicleIndex(i)).unwrap().pos_enu_m;
    (seen - truth).norm()
}

#[test]
fn an_origin_moved_with_its_positions_is_re_anchored_and_the_flight_goes_on() {
    let fault = "[[emulator.fault]]\nvehicle = 3\nfrom_s = 10.0\nuntil_s = 1000.0\n\
                 kind = \"origin_shift\"\nshift_ned_m = [100.0, 50.0, 0.0]\n";
    let mut run = build("", fault);
    let w = watch(&mut run, 12.0, 2);
    assert!(w.held_at.is_none(), "held at {:?}", w.held_at);
    assert!(matches!(run.swarm().phase(), SwarmPhase::Consensus(_)));
    // √(100² + 50²) = 111.80 m.
    let told = warnings(&run, 3);
    assert_eq!(
        told,
        ["GPS_GLOBAL_ORIGIN moved 111.80 m: re-anchored"],
        "{told:?}"
    );
    // Still placed where it truly is (float32 telemetry, projection round trip: cm).
    assert!(
        common_error_m(&run, 2) < 0.05,
        "{} m",
        common_error_m(&run, 2)
    );
}

#[test]
fn an_origin_moved_without_its_positions_is_a_jump_the_swarm_holds_for() {
    let fault = "[[emulator.fault]]\nvehicle = 3\nfrom_s = 10.0\nuntil_s = 1000.0\n\
                 kind = \"origin_shift\"\nshift_ned_m = [100.0, 50.0, 0.0]\npositions_follow = false\n";
    let mut run = build("", fault);
    let w = watch(&mut run, 12.0, 2);
    // Its reports now put it 111.8 m away: refused as a jump, stale 0.3 s after the last
    // good one, the swarm holds; the new track, followed for 0.3 s, is then taken with a
    // warning (the estimate says the vehicle is there now).
    let held = w.held_at.expect("never held").as_secs_f64();
    assert!((10.29..10.31).contains(&held), "held at {held} s");
    let told = warnings(&run, 3);
    assert!(
        told.iter()
            .any(|t| t == "telemetry refused: LOCAL_POSITION_NED jumped 111.8 m from where its velocity put it"),
        "{told:?}"
    );
    assert!(
        told.iter().any(|t| t.starts_with("position jump of 111.")),
        "{told:?}"
    );
    assert!(w.max_height_loss_m < 1.0, "fell {} m", w.max_height_loss_m);
}

#[test]
fn a_vehicle_never_heard_is_named_after_the_handshake_timeout_and_the_others_land() {
    let silence = "[[emulator.silence]]\nvehicle = 4\nfrom_s = 0.0\nuntil_s = 10000.0\n";
    // Started 5 m up: the others land within a minute.
    let mut run = build_over("handshake_timeout_s = 5.0\n", silence, 5.0);
    let mut gave_up_at = None;
    run.run_until(secs(120.0), |r| {
        if gave_up_at.is_none() && r.swarm().failure().is_some() {
            gave_up_at = Some(r.now());
        }
    });
    let at = gave_up_at.expect("never gave up").as_secs_f64();
    assert!((5.0..5.005).contains(&at), "gave up at {at} s");
    let Some(SwarmFailure::Handshake { not_flying, .. }) = run.swarm().failure() else {
        panic!("no failure")
    };
    assert_eq!(not_flying.len(), 1);
    assert_eq!(
        (not_flying[0].system_id, not_flying[0].phase.as_str()),
        (4, "discovering")
    );
    assert_eq!(
        run.swarm().failure().unwrap().to_string(),
        "handshake not complete after 5.0 s: vehicle 4 not flying (never heard); the vehicles that flew were landed"
    );
    assert!(run.swarm().is_finished());
    for (i, v) in run.vehicles().iter().enumerate().filter(|(i, _)| *i != 3) {
        let s = v.status();
        assert!(s.landed && !s.armed, "vehicle {}: {s:?}", i + 1);
    }
}

#[test]
fn a_stall_of_the_coordinator_is_not_taken_for_its_vehicles_going_silent() {
    // The coordinator's host stops scheduling it for 0.8 s mid-consensus: more than the
    // 300 ms state timeout, less than the vehicles' own 1 s offboard-loss timeout. The
    // vehicles fly on their last setpoints; their reports wait unread.
    let mut run = build("", "");
    run.stall_coordinator(secs(10.0), secs(10.8));
    let w = watch(&mut run, 30.0, 2);
    assert_eq!(w.held_at, None, "the swarm held");
    for id in 1..=6u8 {
        let told = warnings(&run, id);
        assert!(told.is_empty(), "vehicle {id}: {told:?}");
        assert_eq!(
            run.swarm()
                .link(VehicleIndex(usize::from(id) - 1))
                .unwrap()
                .phase(),
            Phase::Flying
        );
    }
    assert!(matches!(run.swarm().phase(), SwarmPhase::Consensus(_)));
    // 0.8 s on its last setpoint costs 0.091 m of height, and nothing else.
    assert!(w.max_height_loss_m < 0.1, "fell {} m", w.max_height_loss_m);
}
