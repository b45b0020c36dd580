//! MAVLink 2 signing in lockstep: the paper's first simulation flown with every frame
//! signed on both sides, and vehicles holding another key (or none) left on the ground.

use crate::common;

use ringswarm::driver::Observer;
use ringswarm::driver::lockstep::Lockstep;
use ringswarm::swarm::VehicleIndex;
use ringswarm::vehicle::Phase;
use ringswarm_sitl::autopilot::FlightMode;
use ringswarm_wire::codec::decode_datagram_with;
use ringswarm_wire::signing::SigningKey;
use ringswarm_wire::time::SimTime;

fn build(coordinator: Option<&SigningKey>, vehicle_keys: &[Option<SigningKey>]) -> Lockstep {
    common::signed_paper_sim1(coordinator, vehicle_keys)
}

/// Every datagram in both directions, checked against `key`: (frames, authentic frames).
#[derive(Default)]
struct Census {
    key: Option<SigningKey>,
    frames: u64,
    authentic: u64,
}

impl Observer for Census {
    fn datagram(&mut self, _now: SimTime, _vehicle: VehicleIndex, _to_vehicle: bool, bytes: &[u8]) {
        for frame in decode_datagram_with(bytes, self.key.as_ref())
            .into_iter()
            .flatten()
        {
            self.frames += 1;
            if frame.signature.is_some_and(|t| t.authentic) {
                self.authentic += 1;
            }
        }
    }
}

#[test]
fn signed_flight_is_the_unsigned_flight_bit_for_bit_and_every_frame_is_signed() {
    let key = SigningKey::from_bytes([0x5A; 32]);
    let keys = vec![Some(key.clone()); 6];
    let mut signed = build(Some(&key), &keys);
    let mut census = Census {
        key: Some(key),
        ..Census::default()
    };
    let end = SimTime::from_millis(12_000);
    signed.run_observed(end, &mut census);
    let mut plain = build(None, &[None, None, None, None, None, None]);
    plain.run_until(end, |_| {});
    // Signing changes the bytes, never the flight: the same trajectory to the bit.
    let (a, b) = (
        common::vehicle_states(&signed),
        common::vehicle_states(&plain),
    );
    assert!(
        a.iter()
            .zip(&b)
            .all(|(p, q)| p.iter().zip(q).all(|(x, y)| x.to_bits() == y.to_bits())),
        "signed {a:?}\nunsigned {b:?}"
    );
    assert!(
        signed.swarm().links().all(|l| l.phase() == Phase::Flying),
        "every vehicle flies"
    );
    // 6 links × 12 s × 50 Hz setpoints and 2 × 50 Hz telemetry: well over 20 000 frames.
    assert!(census.frames > 20_000, "{} frames", census.frames);
    assert_eq!(
        census.authentic, census.frames,
        "every frame signed and authentic"
    );
    for (link, vehicle) in signed.swarm().links().zip(signed.vehicles()) {
        assert_eq!(link.refused_frames(), 0);
        let c = vehicle.status().counters;
        assert_eq!((c.unsigned_refused, c.signature_refused), (0, 0));
    }
}

#[test]
fn a_vehicle_with_another_key_or_none_never_obeys_and_is_named() {
    let ours = SigningKey::from_bytes([1; 32]);
    let theirs = SigningKey::from_bytes([2; 32]);
    // Vehicle 2 holds another key; vehicle 4 has no key and so takes our signed frames.
    let keys = vec![
        Some(ours.clone()),
        Some(theirs),
        Some(ours.clone()),
        None,
        Some(ours.clone()),
        Some(ours.clone()),
    ];
    let mut run = build(Some(&ours), &keys);
    run.run_until(SimTime::from_millis(5_000), |_| {});
    // paper-sim1's vehicles start in the air, armed, in Position mode: only OFFBOARD
    // would show that a setpoint was obeyed.
    let offboard = |i: usize| run.vehicles()[i].status().mode == FlightMode::Offboard;
    assert!(
        !offboard(1),
        "vehicle 2 obeyed a frame signed with another key"
    );
    assert!(offboard(0) && offboard(2) && offboard(4) && offboard(5));
    let c = run.vehicles()[1].status().counters;
    // The coordinator never discovers it, so it only sends its 1 Hz heartbeat
    // (t = 0, 1, 2, 3, 4 s): all refused.
    assert!(
        c.signature_refused >= 5,
        "5 heartbeats refused, got {}",
        c.signature_refused
    );
    // The coordinator refuses vehicle 2's frames (signed with its key) and vehicle 4's
    // (unsigned): each named once.
    let links: Vec<_> = run.swarm().links().collect();
    assert_eq!(links[1].phase(), Phase::Discovering);
    assert!(links[1].refused_frames() > 100);
    assert_eq!(links[3].phase(), Phase::Discovering);
    assert!(links[3].refused_frames() > 100);
    let named: Vec<_> = run
        .swarm()
        .events()
        .iter()
        .filter(|e| e.text.contains("refused by signing"))
        .map(|e| e.system_id)
        .collect();
    assert_eq!(named, vec![Some(2), Some(4)]);
    assert!(
        run.swarm()
            .events()
            .iter()
            .any(|e| e.system_id == Some(4) && e.text.contains("unsigned message id")),
        "vehicle 4's unsigned telemetry is the reason given"
    );
}

#[test]
fn the_vehicles_authentic_frames_from_another_link_id_are_refused() {
    // Vehicle 1 talks to us on PX4's offboard instance (link id 1). Its frames to another
    // station (the GCS instance, link id 0), replayed to us, are authentic and fresh, but
    // refused: they are not addressed to us and could feed us old state.
    let key = SigningKey::from_bytes([0x77; 32]);
    let mut run = build(Some(&key), &vec![Some(key.clone()); 6]);
    run.run_until(SimTime::from_millis(2_000), |_| {});
    let before = run.swarm().link(VehicleIndex(0)).unwrap().refused_frames();
    assert_eq!(before, 0);
    let mut gcs_clock =
        ringswarm_wire::signing::Signing::new(key.clone(), common::START + 500_000_000);
    let position = mavlink::dialects::common::MavMessage::LOCAL_POSITION_NED(
        mavlink::dialects::common::LOCAL_POSITION_NED_DATA {
            time_boot_ms: 1_000,
            x: 400.0,
            ..Default::default()
        },
    );
    let mut enc = ringswarm_wire::codec::Encoder::new(1, 1);
    for _ in 0..10 {
        let bytes = enc.encode_signed(&position, &mut gcs_clock, 0);
        run.inject(false, 0, bytes);
    }
    run.run_until(SimTime::from_millis(2_100), |_| {});
    assert_eq!(
        run.swarm().link(VehicleIndex(0)).unwrap().refused_frames(),
        10
    );
    assert!(run.swarm().events().iter().any(|e| {
        e.system_id == Some(1)
            && e.text
                .contains("signed on link id 0, but the vehicle talks to us on link id 1")
    }));
    assert_eq!(
        run.swarm().link(VehicleIndex(0)).unwrap().phase(),
        Phase::Flying
    );
}
