//! MAVLink networks in lockstep: the paper's first simulation with its six vehicles on two
//! networks whose system ids overlap (1, 2, 3 on each), routed by the same router as over
//! UDP, flies exactly as with one socket per vehicle.

use crate::common;

use ringswarm::config::Config;
use ringswarm::driver::lockstep::Lockstep;
use ringswarm::vehicle::Phase;
use ringswarm_wire::time::SimTime;

fn paper_sim1_text() -> String {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/paper-sim1.toml");
    std::fs::read_to_string(path).unwrap()
}

/// paper-sim1 with vehicles 1–3 on network "a" and 4–6 on network "b" as system ids 1–3.
fn on_two_networks() -> String {
    let mut text = paper_sim1_text();
    for (old, new) in [
        ("system_id = 1\n", "system_id = 1\nnetwork = \"a\"\n"),
        ("system_id = 2\n", "system_id = 2\nnetwork = \"a\"\n"),
        ("system_id = 3\n", "system_id = 3\nnetwork = \"a\"\n"),
        ("system_id = 4\n", "system_id = 1\nnetwork = \"b\"\n"),
        ("system_id = 5\n", "system_id = 2\nnetwork = \"b\"\n"),
        ("system_id = 6\n", "system_id = 3\nnetwork = \"b\"\n"),
    ] {
        assert!(text.contains(old), "paper-sim1 has {old:?}");
        text = text.replacen(old, new, 1);
    }
    text.push_str(
        "\n[[network]]\nname = \"a\"\nbind = \"0.0.0.0:14550\"\n\n\
         [[network]]\nname = \"b\"\nbind = \"0.0.0.0:14551\"\n",
    );
    text
}

fn run(text: &str, seconds: u64) -> Lockstep {
    let config = Config::from_toml(text).unwrap();
    let mut run = Lockstep::from_config(&config).unwrap();
    run.run_until(SimTime::from_millis(seconds * 1000), |_| {});
    run
}

fn states(run: &Lockstep) -> Vec<[u64; 6]> {
    common::vehicle_states(run)
        .into_iter()
        .map(|s| s.map(f64::to_bits))
        .collect()
}

#[test]
fn two_networks_with_overlapping_ids_fly_the_own_socket_flight_bit_for_bit() {
    let networked = run(&on_two_networks(), 12);
    let own = run(&paper_sim1_text(), 12);
    assert!(
        networked
            .swarm()
            .links()
            .all(|l| l.phase() == Phase::Flying),
        "every vehicle flies"
    );
    // A datagram routed to the wrong vehicle with the same system id would have doubled
    // one vehicle's setpoints and starved the other: the flights would differ.
    assert_eq!(states(&networked), states(&own));
    let setpoints: Vec<u64> = networked
        .vehicles()
        .iter()
        .map(|v| v.status().counters.setpoints)
        .collect();
    let own_setpoints: Vec<u64> = own
        .vehicles()
        .iter()
        .map(|v| v.status().counters.setpoints)
        .collect();
    assert_eq!(setpoints, own_setpoints);
    // The vehicles send first (as PX4 does): nothing waited for an address for long.
    // Before a vehicle's first frame the coordinator's heartbeat has nowhere to go: at
    // most its first one per vehicle.
    assert!(
        networked.unsent() <= 6,
        "{} datagrams unsent",
        networked.unsent()
    );
}

#[test]
fn events_name_the_network_of_a_vehicle_whose_id_repeats() {
    let networked = run(&on_two_networks(), 3);
    let own = run(&paper_sim1_text(), 3);
    // Every vehicle event of the network flight carries its network: system id 1 on "a"
    // is vehicle 1, on "b" vehicle 4.
    let vehicle_events: Vec<_> = networked
        .swarm()
        .events()
        .iter()
        .filter(|e| e.system_id.is_some())
        .collect();
    assert!(!vehicle_events.is_empty());
    for e in &vehicle_events {
        assert!(matches!(e.network.as_deref(), Some("a" | "b")), "{e:?}");
    }
    for net in ["a", "b"] {
        assert!(
            vehicle_events
                .iter()
                .any(|e| e.system_id == Some(1) && e.network.as_deref() == Some(net)),
            "no event of vehicle 1 on {net}"
        );
    }
    // On their own sockets the vehicles have no network; the swarm's events never do.
    assert!(own.swarm().events().iter().all(|e| e.network.is_none()));
    assert!(
        networked
            .swarm()
            .events()
            .iter()
            .filter(|e| e.system_id.is_none())
            .all(|e| e.network.is_none())
    );
}

#[test]
fn stepping_the_vehicles_on_every_core_flies_the_same_flight_bit_for_bit() {
    // config/ring-500.toml: 500 vehicles on two networks, stepped in parallel by default.
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/ring-500.toml");
    let config = Config::from_toml(&std::fs::read_to_string(path).unwrap()).unwrap();
    let fly = |parallel: bool| {
        let mut run = Lockstep::from_config(&config).unwrap();
        run.set_parallel(parallel);
        run.run_until(SimTime::from_millis(2_000), |_| {});
        run
    };
    let (parallel, sequential) = (fly(true), fly(false));
    assert_eq!(states(&parallel), states(&sequential));
    let setpoints = |run: &Lockstep| -> Vec<u64> {
        run.vehicles()
            .iter()
            .map(|v| v.status().counters.setpoints)
            .collect()
    };
    assert_eq!(setpoints(&parallel), setpoints(&sequential));
    // Not a flight that did nothing: the handshake is under way.
    assert!(setpoints(&parallel).iter().sum::<u64>() > 0);
}
