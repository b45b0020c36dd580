//! The swarm over real UDP sockets against emulated vehicles in the same process, on two
//! MAVLink networks whose system ids overlap.

use std::time::Duration;

use nalgebra::Vector2;
use ringswarm::consensus::{CouplingGains, RingDigraph};
use ringswarm::control::{AltitudeGains, Envelope, SaturationMode, VehicleModel};
use ringswarm::driver::udp::{DriverCommand, Port, run_swarm};
use ringswarm::frame::{CommonFrame, Geodetic};
use ringswarm::index::SystemId;
use ringswarm::link::router::{Endpoint, Router, SocketLayout, TransportLayout, VehicleRoute};
use ringswarm::swarm::{EndAction, LossPolicy, Swarm, SwarmSetup};
use ringswarm::vehicle::{LinkConfig, Phase};
use ringswarm_sitl::autopilot::{LinkId, Vehicle, VehicleConfig};
use ringswarm_sitl::fleet::{FleetVehicle, spawn_workers};
use ringswarm_sitl::profile::Profile;
use ringswarm_sitl::udp::{LinkFaults, LinkPort, LinkSocket, SimClock};
use ringswarm_sitl::world::World;
use ringswarm_wire::time::SimTime;
use tokio::net::UdpSocket;
use tokio::sync::watch;

/// Two networks, system ids 1 and 2 on each. Vehicle 3 (network b, id 1) sends first, as
/// PX4 does; vehicle 4 (network b, id 2) sends to a port nobody reads until someone talks
/// to it: the coordinator knows its address from the config and must contact it first.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_vehicle_reaches_offboard_and_setpoints_arrive_at_the_configured_rate() {
    const N: usize = 4;
    let world = World::default();
    let (stop_tx, stop_rx) = watch::channel(false);
    let clock = SimClock::new(1.0);
    let networks = [
        UdpSocket::bind("127.0.0.1:0").await.unwrap(),
        UdpSocket::bind("127.0.0.1:0").await.unwrap(),
    ];
    let nowhere = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let mut plan = TransportLayout {
        sockets: ["a", "b"]
            .iter()
            .zip(&networks)
            .map(|(name, s)| SocketLayout {
                endpoint: Endpoint::Udp(s.local_addr().unwrap()),
                network: Some((*name).to_owned()),
            })
            .collect(),
        routes: Vec::new(),
    };
    let mut statuses = Vec::new();
    let mut fleet = Vec::new();
    for i in 0..N {
        let (network, system_id) = (i / 2, (i % 2) as u8 + 1);
        let socket = UdpSocket::bind("127.0.0.1:0").await.unwrap();
        let quiet = i == 3;
        plan.routes.push(VehicleRoute {
            socket: network,
            address: quiet.then(|| socket.local_addr().unwrap()),
            system_id: SystemId(system_id),
        });
        let default_peer = if quiet {
            nowhere.local_addr().unwrap()
        } else {
            plan.sockets[network].udp_bind().unwrap()
        };
        let mut cfg = VehicleConfig::new(system_id, Profile::x500());
        cfg.start.pos_world_ned_m.y = 5.0 * i as f64;
        let vehicle = Vehicle::new(cfg, world).unwrap();
        let (status, status_rx) = watch::channel(vehicle.status());
        statuses.push(status_rx);
        fleet.push(FleetVehicle {
            vehicle,
            links: vec![LinkSocket {
                id: LinkId::Offboard,
                port: LinkPort::Udp(socket),
                default_peer,
                faults: LinkFaults::default(),
            }],
            seed: i as u64,
            key_file: None,
            status,
        });
    }
    let workers = spawn_workers(fleet, 2, clock, &stop_rx);
    let model = VehicleModel::from_hover_throttle(2.0, 0.5).unwrap();
    let setup = SwarmSetup {
        ring: RingDigraph::for_agents(N, 1.0).unwrap(),
        gains: CouplingGains::new(0.2, 1.0).unwrap(),
        altitude_gains: AltitudeGains::new(1.0, 2.0).unwrap(),
        altitude_m: 5.0,
        offsets_m: (0..N).map(|i| Vector2::new(5.0 * i as f64, 0.0)).collect(),
        assign_places: false,
        assign_off_tick: false,
        models: vec![model; N],
        drag_per_s: vec![0.1; N],
        envelope: Envelope::new(35f64.to_radians(), 0.1, 0.9).unwrap(),
        saturation: SaturationMode::Conserve,
        control_interval: Duration::from_millis(20),
        frame: CommonFrame::new(Geodetic {
            lat_deg: world.reference.lat_deg,
            lon_deg: world.reference.lon_deg,
            alt_amsl_m: world.reference.alt_amsl_m,
        }),
        links: (0..N).map(|i| LinkConfig::new((i % 2) as u8 + 1)).collect(),
        duration: None,
        handshake_timeout: Duration::from_secs(30),
        estimate_hover: true,
        estimate_drag: true,
        disturbance_time_constant_s: 0.5,
        mean_velocity_gain: 0.2,
        setpoint: ringswarm::swarm::SetpointKind::Attitude,
        bandwidth: None,
        end_action: EndAction::Land,
        loss_policy: LossPolicy::Hold,
        target: None,
        guard: None,
        safety: None,
        fence: None,
    };
    let mut all_flying_at = None;
    let (command_tx, command_rx) = watch::channel(DriverCommand::Fly);
    let swarm_task = tokio::spawn(run_swarm(
        Swarm::new(setup),
        networks.into_iter().map(Port::from).collect(),
        Router::new(&plan),
        command_rx,
        move |swarm: &Swarm, now: SimTime| {
            if all_flying_at.is_none() && swarm.links().all(|l| l.phase() == Phase::Flying) {
                all_flying_at = Some(now);
                eprintln!("all flying at {:.3} s", now.as_secs_f64());
            }
        },
        None,
    ));
    // Every vehicle armed in OFFBOARD within 5 s (the handshake needs 1.2 s of stream).
    let deadline = tokio::time::Instant::now() + Duration::from_secs(5);
    loop {
        let all = statuses.iter().all(|s| {
            let s = s.borrow();
            s.armed && s.mode == ringswarm_sitl::autopilot::FlightMode::Offboard
        });
        if all {
            break;
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "not all vehicles in OFFBOARD within 5 s"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    // Setpoint rate seen by each vehicle over 2 s of its own clock: 50 Hz ± 5 %.
    let snapshot = |s: &watch::Receiver<ringswarm_sitl::autopilot::VehicleStatus>| {
        let s = s.borrow();
        (s.counters.setpoints, s.at.as_secs_f64())
    };
    let first: Vec<(u64, f64)> = statuses.iter().map(snapshot).collect();
    tokio::time::sleep(Duration::from_secs(2)).await;
    for (i, s) in statuses.iter().enumerate() {
        let (count, t) = snapshot(s);
        let rate = (count - first[i].0) as f64 / (t - first[i].1);
        eprintln!(
            "vehicle {}: {rate:.2} Hz over {:.2} s",
            i + 1,
            t - first[i].1
        );
        assert!(
            (rate - 50.0).abs() <= 2.5,
            "vehicle {}: {rate:.2} Hz",
            i + 1
        );
    }
    command_tx.send_replace(DriverCommand::Stop);
    stop_tx.send_replace(true);
    let (swarm, _) = swarm_task.await.unwrap().unwrap();
    assert!(swarm.links().all(|l| l.phase() == Phase::Flying));
    workers.join().await.unwrap();
    // Vehicle 4's first frames went to its default peer, not to the coordinator: it was
    // found only because the coordinator spoke first.
    nowhere.set_nonblocking(true).unwrap();
    let mut buf = [0u8; 512];
    assert!(
        nowhere.recv_from(&mut buf).is_ok(),
        "vehicle 4 never sent to its default peer"
    );
}
