use super::*;
use crate::codec::tests::heartbeat;
use crate::codec::{Encoder, Frame, decode_datagram, decode_datagram_with};
use mavlink::dialects::common::{MavMessage, TIMESYNC_DATA};

fn key(first: u8) -> SigningKey {
    let mut bytes = [0u8; 32];
    for (i, b) in bytes.iter_mut().enumerate() {
        *b = first.wrapping_add(i as u8);
    }
    SigningKey::from_bytes(bytes)
}

/// A TIMESYNC (message id 111), not let through unsigned.
fn ping(ts1: i64) -> MavMessage {
    MavMessage::TIMESYNC(TIMESYNC_DATA {
        tc1: 0,
        ts1,
        ..Default::default()
    })
}

/// A frame from `sys`/1 on link `link_id`, signed at `timestamp`, decoded with `key`.
fn signed_frame(k: &SigningKey, sys: u8, link_id: u8, timestamp: u64) -> Frame {
    let mut signing = Signing::new(k.clone(), timestamp);
    let bytes = Encoder::new(sys, 1).encode_signed(&ping(1), &mut signing, link_id);
    decode_datagram_with(&bytes, Some(k))
        .remove(0)
        .expect("a frame")
}

#[test]
fn golden_signed_heartbeat_matches_pymavlink() {
    // pymavlink 2.4: MAVLink(srcSystem=1, srcComponent=1), signing.secret_key = bytes(0..32),
    // link_id 7, timestamp 0x0102030405, heartbeat_send(quadrotor, PX4, custom mode
    // enabled, 6 << 16, standby), the first frame written.
    let golden = "fd09010000010100000000000600020c0103035ec807050403020100502584133b6e";
    let mut signing = Signing::new(key(0), 0x01_0203_0405);
    let bytes = Encoder::new(1, 1).encode_signed(&heartbeat(), &mut signing, 7);
    let hex: String = bytes.iter().map(|b| format!("{b:02x}")).collect();
    assert_eq!(hex, golden);
    assert_eq!(signing.timestamp(), 0x01_0203_0406, "one unit per frame");
    let frame = decode_datagram_with(&bytes, Some(&key(0)))
        .remove(0)
        .unwrap();
    assert_eq!(
        frame.signature,
        Some(Trailer {
            link_id: 7,
            timestamp: 0x01_0203_0405,
            authentic: true
        })
    );
    let other = decode_datagram_with(&bytes, Some(&key(1)))
        .remove(0)
        .unwrap();
    assert!(!other.signature.unwrap().authentic, "another key");
    let keyless = decode_datagram(&bytes).remove(0).unwrap();
    assert!(!keyless.signature.unwrap().authentic, "no key");
}

#[test]
fn a_flipped_bit_anywhere_in_a_signed_frame_is_not_authentic() {
    let k = key(3);
    let mut signing = Signing::new(k.clone(), 1000);
    let bytes = Encoder::new(1, 1).encode_signed(&heartbeat(), &mut signing, 0);
    // The signature covers header (after the start byte), payload, CRC, link id and
    // timestamp; a flip there either breaks the CRC or the signature.
    for i in 1..bytes.len() {
        let mut bad = bytes.clone();
        bad[i] ^= 0x10;
        let authentic = decode_datagram_with(&bad, Some(&k))
            .into_iter()
            .any(|f| f.is_ok_and(|f| f.signature.is_some_and(|t| t.authentic)));
        assert!(!authentic, "byte {i} flipped still authentic");
    }
}

#[test]
fn unsigned_frames_pass_only_when_allowed() {
    let mut s = Signing::new(key(0), 0);
    let unsigned = decode_datagram(&Encoder::new(1, 1).encode(&heartbeat()))
        .remove(0)
        .unwrap();
    assert_eq!(s.accept(&unsigned.stamp(), &PX4_UNSIGNED_ALLOWED), Ok(()));
    let ping = decode_datagram(&Encoder::new(1, 1).encode(&ping(2)))
        .remove(0)
        .unwrap();
    assert_eq!(
        s.accept(&ping.stamp(), &PX4_UNSIGNED_ALLOWED),
        Err(Rejection::Unsigned { msgid: 111 })
    );
    assert_eq!(s.timestamp(), 0, "a refusal changes nothing");
}

#[test]
fn replays_and_stale_streams_are_refused_and_fresh_ones_move_the_clock() {
    let k = key(9);
    let mut s = Signing::new(k.clone(), 10_000_000);
    let first = signed_frame(&k, 1, 0, 10_000_005);
    assert_eq!(s.accept(&first.stamp(), &[]), Ok(()));
    assert_eq!(
        s.timestamp(),
        10_000_005,
        "the clock follows the newest accepted"
    );
    assert_eq!(
        s.accept(&first.stamp(), &[]),
        Err(Rejection::Replayed {
            timestamp: 10_000_005,
            last: 10_000_005
        })
    );
    let older = signed_frame(&k, 1, 0, 10_000_004);
    assert!(matches!(
        s.accept(&older.stamp(), &[]),
        Err(Rejection::Replayed { .. })
    ));
    // The same timestamp on another link id is another stream, inside the minute.
    let other_link = signed_frame(&k, 1, 1, 10_000_005 - NEW_STREAM_WINDOW);
    assert_eq!(s.accept(&other_link.stamp(), &[]), Ok(()));
    // A new stream one unit beyond the minute is stale.
    let stale = signed_frame(&k, 2, 0, 10_000_005 - NEW_STREAM_WINDOW - 1);
    assert_eq!(
        s.accept(&stale.stamp(), &[]),
        Err(Rejection::Stale {
            timestamp: 10_000_005 - NEW_STREAM_WINDOW - 1,
            newest: 10_000_005
        })
    );
    // Signed with another key, checked against ours.
    let mut theirs = Signing::new(key(10), 20_000_000);
    let bytes = Encoder::new(1, 1).encode_signed(&ping(1), &mut theirs, 0);
    let forged = decode_datagram_with(&bytes, Some(&k)).remove(0).unwrap();
    assert_eq!(
        s.accept(&forged.stamp(), &[]),
        Err(Rejection::BadSignature { msgid: 111 })
    );
    assert_eq!(s.timestamp(), 10_000_005, "refusals leave the clock alone");
}

#[test]
fn the_stream_table_is_bounded() {
    let k = key(1);
    let mut s = Signing::new(k.clone(), 0);
    for sys in 1..=MAX_STREAMS as u8 {
        assert_eq!(
            s.accept(&signed_frame(&k, sys, 0, 100).stamp(), &[]),
            Ok(())
        );
    }
    assert_eq!(
        s.accept(&signed_frame(&k, 200, 0, 100).stamp(), &[]),
        Err(Rejection::TooManyStreams)
    );
    assert_eq!(
        s.accept(&signed_frame(&k, 1, 0, 101).stamp(), &[]),
        Ok(()),
        "known streams still pass"
    );
}

#[test]
fn wall_clock_timestamps_count_10_us_since_2015() {
    use std::time::Duration;
    assert_eq!(
        timestamp_from_unix(Duration::from_secs(1_000)),
        0,
        "before 2015"
    );
    assert_eq!(
        timestamp_from_unix(Duration::from_secs(TIMESTAMP_EPOCH_UNIX_S + 2)),
        200_000
    );
    assert_eq!(
        timestamp_from_unix(Duration::new(TIMESTAMP_EPOCH_UNIX_S, 25_000)),
        2,
        "25 µs is two whole units"
    );
    // 2026-11-29 is about 11.9 years after the epoch: 3.76e13 units, well inside 48 bits.
    let now = timestamp_now();
    assert!(now > 11 * 365 * 86_400 * TIMESTAMP_UNITS_PER_S && now < TIMESTAMP_MAX);
    assert_eq!(
        timestamp_from_unix(Duration::from_secs(u64::MAX / 2)),
        TIMESTAMP_MAX,
        "saturates at 48 bits"
    );
}
