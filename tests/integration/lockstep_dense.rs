//! Dense blocks in lockstep: x500s in a square block 4 m apart (3 m enforced), sent to a
//! circle of the same spacing. Measured on the emulator's truth: the smallest distance
//! between two vehicles on every control tick, and, when consensus ends, the formation
//! error (the largest distance of `pᵢ − placeᵢ` from their mean, with the places the swarm
//! flew to) and the mean velocity against the prediction.

use nalgebra::Vector2;
use ringswarm::config::Config;
use ringswarm::consensus::formation_error_m;
use ringswarm::control::ned_to_enu;
use ringswarm::driver::lockstep::Lockstep;
use ringswarm::swarm::{SwarmPhase, VehicleIndex};
use ringswarm_wire::time::SimTime;

fn block_circle() -> String {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/block-circle.toml");
    std::fs::read_to_string(path).unwrap()
}

/// The shipped 4 × 4 file with its block widened to `side` × `side` (4 m apart, about the
/// origin) and its circle to the same spacing (chord 4 m), the start velocities as the
/// file's rule gives them.
fn block_of(side: usize) -> String {
    let text = block_circle();
    let head = &text[..text.find("[[vehicle]]").unwrap()];
    let n = side * side;
    let radius = 2.0 / (std::f64::consts::PI / n as f64).sin();
    let mut out = String::new();
    for line in head.lines() {
        if line.starts_with("radius_m") {
            out.push_str(&format!("radius_m = {radius}\n"));
        } else {
            out.push_str(line);
            out.push('\n');
        }
    }
    let half = 2.0 * (side - 1) as f64;
    for i in 0..n {
        let (x, y) = (
            4.0 * (i % side) as f64 - half,
            4.0 * (i / side) as f64 - half,
        );
        let (vx, vy) = (1.0 + 0.2 * (i % 3) as f64, 0.5 - 0.25 * (i % 2) as f64);
        out.push_str(&format!(
            "[[vehicle]]\nsystem_id = {}\nprofile = \"x500\"\nmass_kg = 2.0\n\
             hover_throttle = 0.5\ndrag_per_s = 0.1\nstart_enu_m = [{x}, {y}, 50.0]\n\
             start_velocity_enu_mps = [{vx}, {vy}, 0.0]\nin_air = true\n\n",
            i + 1
        ));
    }
    out
}

#[derive(Debug)]
struct Flight {
    /// Smallest horizontal-equivalent distance between two vehicles, every tick (m).
    min_separation_m: f64,
    /// Formation error when consensus ended (m).
    formation_m: f64,
    /// `|mean velocity − prediction| / |prediction|` when consensus ended.
    velocity_off: f64,
    /// The same for the w-weighted mean velocity (what the law and the filter keep).
    weighted_off: f64,
    filtered_ticks: u64,
    fallbacks: u64,
    /// Jams found and broken.
    jams: u64,
    /// Times a vehicle left for the jam layer.
    layer_climbs: u64,
    /// The highest and lowest altitude a vehicle reached during consensus (m, up).
    altitude_range_m: (f64, f64),
}

/// What the vehicles are at a control tick: formation error, and the mean and w-weighted
/// mean velocity off the prediction (fractions of its speed).
fn measure(run: &Lockstep, w: &[f64]) -> Option<(f64, f64, f64)> {
    let swarm = run.swarm();
    let predicted = swarm.predicted_final_velocity()?;
    let (pos, vel): (Vec<Vector2<f64>>, Vec<Vector2<f64>>) = run
        .vehicles()
        .iter()
        .map(|v| {
            let s = v.status();
            (
                ned_to_enu(s.pos_world_ned_m).xy(),
                ned_to_enu(s.vel_ned_mps).xy(),
            )
        })
        .unzip();
    let formation = formation_error_m(
        pos.iter()
            .enumerate()
            .map(|(i, p)| p - swarm.place_m(VehicleIndex(i))),
    );
    let mean = vel.iter().sum::<Vector2<f64>>() / vel.len() as f64;
    let weighted =
        vel.iter().zip(w).map(|(v, w)| v * *w).sum::<Vector2<f64>>() / w.iter().sum::<f64>();
    let speed = predicted.norm();
    Some((
        formation,
        (mean - predicted).norm() / speed,
        (weighted - predicted).norm() / speed,
    ))
}

/// Flies `config` until consensus has run `consensus_s` (the file's duration at least),
/// measuring at its last control tick.
fn fly(config: &Config, consensus_s: f64) -> Flight {
    let sep = ringswarm::safety::Separation {
        horizontal_m: config.safety.horizontal_m,
        vertical_m: config.safety.vertical_m,
        gamma: 1.0,
    };
    let mut run = Lockstep::from_config(config).unwrap();
    let n = run.vehicles().len();
    let w: Vec<f64> = (0..n).map(|i| run.swarm().setup().ring.w(i)).collect();
    let (mut min_sep, mut tick) = (f64::INFINITY, 0);
    let mut altitude_range_m = (f64::INFINITY, f64::NEG_INFINITY);
    let mut last: Option<(f64, f64, f64)> = None;
    let mut done = false;
    // Consensus starts within seconds; the file's duration bounds the rest.
    let end = SimTime::from_micros(((consensus_s + 30.0) * 1e6) as u64);
    let mut until = SimTime::ZERO;
    while !done && until < end {
        until = until + std::time::Duration::from_secs(1);
        run.run_until(until, |r| {
            if done || r.swarm().control_ticks() == tick {
                return;
            }
            tick = r.swarm().control_ticks();
            let p: Vec<_> = r
                .vehicles()
                .iter()
                .map(|v| ned_to_enu(v.status().pos_world_ned_m))
                .collect();
            for (i, a) in p.iter().enumerate() {
                for b in &p[i + 1..] {
                    min_sep = min_sep.min(sep.distance_m(*a, *b));
                }
            }
            match r.swarm().phase() {
                SwarmPhase::Consensus(t0)
                    if r.now().saturating_since(t0).as_secs_f64() <= consensus_s =>
                {
                    last = measure(r, &w);
                    for z in p.iter().map(|p| p.z) {
                        altitude_range_m.0 = altitude_range_m.0.min(z);
                        altitude_range_m.1 = altitude_range_m.1.max(z);
                    }
                }
                SwarmPhase::Handshake | SwarmPhase::Consensus(_) => {}
                _ => done = true,
            }
            if let SwarmPhase::Consensus(t0) = r.swarm().phase() {
                done |= r.now().saturating_since(t0).as_secs_f64() > consensus_s;
            }
        });
    }
    let (formation_m, velocity_off, weighted_off) = last.expect("consensus ran");
    let stats = run.swarm().safety_stats();
    Flight {
        min_separation_m: min_sep,
        formation_m,
        velocity_off,
        weighted_off,
        filtered_ticks: stats.filtered_ticks,
        fallbacks: stats.fallbacks,
        jams: stats.jams,
        layer_climbs: stats.layer_climbs,
        altitude_range_m,
    }
}

fn config(text: &str) -> Config {
    Config::from_toml(text).unwrap()
}

/// Assigned, the block reaches its circle, and the jam watch finds no jam there: the
/// filter trims the commands without holding anybody. In vehicle order every path
/// crosses the block: without breaking jams the filter keeps them apart and the formation
/// does not finish; breaking them on the layer gets most of the way.
#[test]
fn a_four_by_four_block_assigned_to_a_circle_finishes_apart() {
    let assigned = fly(&config(&block_circle()), 90.0);
    let mut fixed = config(&block_circle());
    fixed.formation.assign = Some("fixed".into());
    let broken = fly(&fixed, 90.0);
    fixed.safety.resolve_jams = false;
    let in_order = fly(&fixed, 90.0);
    eprintln!("assigned {assigned:?}\nin vehicle order {in_order:?}\nits jams broken {broken:?}");
    assert!(assigned.formation_m < 1.0, "{assigned:?}");
    assert!(assigned.min_separation_m >= 0.95 * 3.0, "{assigned:?}");
    assert!(assigned.velocity_off < 1e-3, "{assigned:?}");
    assert_eq!(assigned.fallbacks, 0);
    assert_eq!(
        (assigned.jams, assigned.layer_climbs),
        (0, 0),
        "{assigned:?}"
    );
    assert!(in_order.min_separation_m >= 0.95 * 3.0, "{in_order:?}");
    assert!(in_order.formation_m > 5.0, "{in_order:?}");
    assert!(in_order.filtered_ticks > assigned.filtered_ticks);
    assert!(broken.min_separation_m >= 0.95 * 3.0, "{broken:?}");
    assert!(broken.jams > 0 && broken.layer_climbs > 0, "{broken:?}");
    assert!(broken.formation_m < 4.0, "{broken:?}");
    assert!(broken.weighted_off < 1e-3, "{broken:?}");
}

/// A ring of 36 converges slowly (its smallest non-zero eigenvalue is 0.008, and at the
/// gate's time scale the slowest mode decays over about half an hour): after 90 s the law
/// alone is still metres off. Assigned, the filter costs it nothing: the formation is no
/// worse than the law's alone (filter off) and the w-weighted mean velocity, which the
/// law and the filter keep, is the prediction.
#[test]
fn a_six_by_six_block_assigned_does_no_worse_than_the_law_alone() {
    // Yu's bound for m = 18 is β²/α > 117.4: α = 0.2 with the file's β = 5 gives 125.
    let text = block_of(6).replace("alpha = 1.0", "alpha = 0.2");
    let with_filter = fly(&config(&text), 90.0);
    let mut off = config(&text);
    off.safety.enabled = false;
    let alone = fly(&off, 90.0);
    eprintln!("with the filter {with_filter:?}\nthe law alone {alone:?}");
    assert!(alone.min_separation_m < 0.95 * 3.0, "{alone:?}");
    assert!(
        with_filter.min_separation_m >= 0.95 * 3.0,
        "{with_filter:?}"
    );
    assert!(
        with_filter.formation_m <= alone.formation_m,
        "{with_filter:?}"
    );
    assert!(with_filter.weighted_off < 1e-3, "{with_filter:?}");
    // The jam watch sees a slow ring, not a jam.
    assert_eq!(with_filter.jams, 0, "{with_filter:?}");
    assert!(
        with_filter.velocity_off <= alone.velocity_off + 1e-3,
        "{with_filter:?}"
    );
}

/// The 4 × 4 mirror swap with the places kept in vehicle order (`config/block-swap.toml`):
/// every path crosses the centre and the pairwise filter jams. The law alone (filter and
/// guard off, flying through each other) is itself still metres off after 240 s: the
/// swap excites the ring's slow modes. Passing jams on the layer (the file's
/// `resolve_jams`, `jam_break = "layer"` by default) keeps the separation and the
/// weighted sum, ends no further off than the law alone, and for this file under 1 m;
/// without breaking, the filter holds the block metres off.
#[test]
fn a_mirror_swap_in_vehicle_order_passes_its_jams_on_the_layer() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/block-swap.toml");
    let text = std::fs::read_to_string(path).unwrap();
    let layered = fly(&config(&text), 240.0);
    let mut alone = config(&text);
    alone.safety.enabled = false;
    alone.guard.enabled = false;
    let alone = fly(&alone, 240.0);
    let mut off = config(&text);
    off.safety.resolve_jams = false;
    let jammed = fly(&off, 240.0);
    eprintln!("on the layer {layered:?}\nlaw alone {alone:?}\nwithout breaking {jammed:?}");
    // The separation in three dimensions, the weighted mean velocity the law promises
    // (the layer changes altitudes only), no further off than the law alone.
    assert!(layered.min_separation_m >= 0.95 * 3.0, "{layered:?}");
    assert!(layered.weighted_off < 1e-3, "{layered:?}");
    assert!(
        layered.formation_m <= alone.formation_m,
        "{layered:?} {alone:?}"
    );
    assert!(layered.formation_m < 1.0, "{layered:?}");
    assert!(alone.formation_m > 1.0, "{alone:?}");
    // Some vehicles climbed, to the layer 12 m up (9 m + 3 m) and not past it by more
    // than the altitude loop's overshoot; none went below the formation by more than the
    // overshoot of coming back down.
    assert!(layered.jams > 0 && layered.layer_climbs > 0, "{layered:?}");
    assert!(layered.altitude_range_m.1 > 50.0 + 11.0, "{layered:?}");
    assert!(layered.altitude_range_m.1 < 50.0 + 13.0, "{layered:?}");
    assert!(layered.altitude_range_m.0 > 50.0 - 1.0, "{layered:?}");
    assert!(jammed.formation_m > 5.0, "{jammed:?}");
    assert!(jammed.min_separation_m >= 0.95 * 3.0, "{jammed:?}");
    assert_eq!(jammed.jams, 0);
}

/// In real time (`fly`) the places are assigned off the control loop: at the start of
/// consensus the swarm hands out the job and keeps its places until the answer; the
/// answer gives the places the solve inside the tick gives (lockstep's way), and an
/// answer to another job is dropped.
#[test]
fn an_assignment_solved_off_the_tick_gives_the_places_solved_in_it() {
    let config = config(&block_circle());
    let mut inline = Lockstep::from_config(&config).unwrap();
    inline.run_until(SimTime::from_secs_f64(2.0), |_| {});
    let assigned: Vec<Vector2<f64>> = inline.swarm().places_m().collect();
    let configured = config.validate().unwrap().offsets_m;
    assert_ne!(assigned, configured);

    let mut setup = config.validate().unwrap();
    setup.assign_off_tick = true;
    let (world, vehicles) = config.emulator().unwrap();
    let vehicles = vehicles
        .into_iter()
        .map(|v| ringswarm_sitl::autopilot::Vehicle::new(v, world).unwrap())
        .collect();
    let faults = config.lockstep_faults().unwrap();
    let mut off = Lockstep::new(
        ringswarm::swarm::Swarm::new(setup),
        vehicles,
        faults.conditions,
    )
    .with_transport(&config.transport_layout().unwrap());
    off.run_until(SimTime::from_secs_f64(2.0), |_| {});
    assert!(matches!(off.swarm().phase(), SwarmPhase::Consensus(_)));
    // Consensus flies the configured places while the job is out.
    let places = |run: &Lockstep| run.swarm().places_m().collect::<Vec<_>>();
    assert_eq!(places(&off), configured);
    let job = off.swarm_mut().take_assignment_job().expect("a job");
    assert!(
        off.swarm_mut().take_assignment_job().is_none(),
        "handed out once"
    );
    assert_eq!(job.places_m, configured);
    let now = off.now();
    off.swarm_mut()
        .finish_assignment(now, job.id + 1, job.solve());
    assert_eq!(places(&off), configured, "another job's answer");
    off.swarm_mut().finish_assignment(now, job.id, job.solve());
    // The same places: the positions at the start are the same in both flights.
    assert_eq!(places(&off), assigned);
    let events = off.swarm().events();
    assert_eq!(
        events
            .iter()
            .filter(|e| e.text.starts_with("places assigned: "))
            .count(),
        1
    );
}

/// Landing with vehicles on the jam layer: the mirror swap stopped 20 s into consensus,
/// jams still being passed, with the ground at z = 0 (the formation 50 m up). Coming
/// straight down, a vehicle on the layer lands on or beside the one below it (0.55 m
/// apart on the ground, measured before the landing was ordered this way). Each such
/// vehicle now first flies clear at its altitude: in the air and on the ground every
/// pair keeps 0.95 × the 3 m separation.
#[test]
fn a_vehicle_on_the_jam_layer_lands_clear_of_the_one_below_it() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/block-swap.toml");
    let text = std::fs::read_to_string(path)
        .unwrap()
        .replace("duration_s = 240.0", "duration_s = 20.0")
        .replace("ground_below_m = 100.0", "ground_below_m = 0.0");
    let config = config(&text);
    let sep = ringswarm::safety::Separation {
        horizontal_m: 3.0,
        vertical_m: config.safety.vertical_m,
        gamma: 1.0,
    };
    let mut run = Lockstep::from_config(&config).unwrap();
    let (mut min_landing_m, mut tick) = (f64::INFINITY, 0);
    // The closest two horizontally, and the most vehicles on the layer, when the landing
    // was ordered.
    let mut at_order: Option<(f64, usize)> = None;
    let mut until = SimTime::ZERO;
    while !run.swarm().is_finished() && until < SimTime::from_secs_f64(300.0) {
        until = until + std::time::Duration::from_secs(1);
        run.run_until(until, |r| {
            if r.swarm().control_ticks() == tick {
                return;
            }
            tick = r.swarm().control_ticks();
            if !matches!(r.swarm().phase(), SwarmPhase::Landing(_)) {
                return;
            }
            let p: Vec<_> = r
                .vehicles()
                .iter()
                .map(|v| ned_to_enu(v.status().pos_world_ned_m))
                .collect();
            let mut closest_xy = f64::INFINITY;
            for (i, a) in p.iter().enumerate() {
                for b in &p[i + 1..] {
                    min_landing_m = min_landing_m.min(sep.distance_m(*a, *b));
                    closest_xy = closest_xy.min((a.xy() - b.xy()).norm());
                }
            }
            let up = p.iter().filter(|q| q.z > 50.0 + 6.0).count();
            at_order.get_or_insert((closest_xy, up));
        });
    }
    assert!(run.swarm().is_finished(), "every vehicle landed");
    let (closest_xy, up) = at_order.expect("the landing was ordered");
    let ground: Vec<Vector2<f64>> = run
        .vehicles()
        .iter()
        .map(|v| ned_to_enu(v.status().pos_world_ned_m).xy())
        .collect();
    let mut min_ground_m = f64::INFINITY;
    for (i, a) in ground.iter().enumerate() {
        for b in &ground[i + 1..] {
            min_ground_m = min_ground_m.min((a - b).norm());
        }
    }
    let events = |text: &str| {
        let events = run.swarm().events().iter();
        events.filter(|e| e.text.contains(text)).count()
    };
    let waited = events("waits to land");
    let landed_clear = events("lands: nobody within 3.6 m");
    eprintln!(
        "closest at the order {closest_xy:.3} m with {up} on the layer; waited {waited}, \
         in the air {min_landing_m:.3} m, on the ground {min_ground_m:.3} m"
    );
    // The case is the one to guard: vehicles on the layer, one of them over another
    // closer than the separation.
    assert!(up > 0 && closest_xy < 3.0, "{closest_xy} {up}");
    assert!(waited > 0 && waited <= up, "{waited} {up}");
    assert_eq!(run.swarm().safety_stats().landing_moves, waited as u64);
    // Each came clear and landed without waiting out its time.
    assert_eq!(landed_clear, waited);
    assert!(min_landing_m >= 0.95 * 3.0, "{min_landing_m}");
    assert!(min_ground_m >= 0.95 * 3.0, "{min_ground_m}");
}

/// A vehicle inside the drifting block goes quiet (no position from 12 s on, its heartbeat
/// going on): it is handed to its own Hold, which brakes it at PX4's gentler rate, while
/// the swarm holds and the others brake at up to their envelopes. The filter keeps the
/// others clear of the path it may take until its Hold has stopped it
/// (`ringswarm_core::safety::lost`), so the vehicles ahead of it, braking harder, are
/// not run into: measured on the emulator's truth, every pair keeps 0.95 × the
/// separation, and the quiet vehicle is named once.
#[test]
fn a_quiet_vehicle_inside_the_block_is_not_run_into_while_everyone_brakes() {
    let fault = "[[emulator.fault]]\nvehicle = 6\nfrom_s = 12.0\nuntil_s = 1000.0\n\
                 kind = \"no_position\"\n\n[[vehicle]]";
    let text = block_of(4).replacen("[[vehicle]]", fault, 1);
    let config = config(&text.replace("duration_s = 90.0", "duration_s = 60.0"));
    let sep = ringswarm::safety::Separation {
        horizontal_m: 3.0,
        vertical_m: config.safety.vertical_m,
        gamma: 1.0,
    };
    let mut run = Lockstep::from_config(&config).unwrap();
    let (mut closest, mut closest_to_quiet, mut tick) = (f64::INFINITY, f64::INFINITY, 0);
    run.run_until(SimTime::from_secs_f64(30.0), |r| {
        if r.swarm().control_ticks() == tick {
            return;
        }
        tick = r.swarm().control_ticks();
        let p: Vec<_> = r
            .vehicles()
            .iter()
            .map(|v| ned_to_enu(v.status().pos_world_ned_m))
            .collect();
        for (i, a) in p.iter().enumerate() {
            for (j, b) in p.iter().enumerate().skip(i + 1) {
                let d = sep.distance_m(*a, *b);
                closest = closest.min(d);
                if i == 5 || j == 5 {
                    closest_to_quiet = closest_to_quiet.min(d);
                }
            }
        }
    });
    let named = run
        .swarm()
        .events()
        .iter()
        .filter(|e| e.system_id == Some(6) && e.text.starts_with("no fresh state"))
        .count();
    eprintln!("closest {closest:.3} m, to the quiet vehicle {closest_to_quiet:.3} m");
    assert_eq!(named, 1);
    assert_eq!(run.swarm().safety_stats().quiet_paths, 1);
    assert!(matches!(run.swarm().phase(), SwarmPhase::Holding(_)));
    assert!(closest >= 0.95 * 3.0, "{closest}");
}
