//! The mission transfer machine alone: the steps it asks for, message by message.

use mavlink::dialects::common::{
    MISSION_COUNT_DATA, MISSION_ITEM_INT_DATA, MavCmd, MavFrame, MavMessage, MavMissionResult,
    MavMissionType,
};

use super::{MissionTransfer, StoredPlans, TransferStep};
use crate::autopilot::LinkId;
use crate::autopilot::mission_item::MissionItem;
use crate::time::SimTime;

const GCS: (u8, u8) = (255, 190);
const OTHER: (u8, u8) = (254, 190);
const MISSION: MavMissionType = MavMissionType::MAV_MISSION_TYPE_MISSION;

fn at_ms(v: u64) -> SimTime {
    SimTime::ZERO + std::time::Duration::from_millis(v)
}

fn nothing_stored() -> StoredPlans<'static> {
    StoredPlans {
        mission: &[],
        mission_crc: 0,
        current_seq: 0,
        fence: &[],
        fence_crc: 0,
    }
}

fn count(n: u16) -> MISSION_COUNT_DATA {
    MISSION_COUNT_DATA {
        count: n,
        target_system: 1,
        target_component: 1,
        mission_type: MISSION,
        opaque_id: 0,
    }
}

/// A waypoint at 47.39° N, 8.54° E, `seq` metres above home.
fn waypoint(seq: u16) -> MISSION_ITEM_INT_DATA {
    MISSION_ITEM_INT_DATA {
        param1: 0.0,
        param2: 0.0,
        param3: 0.0,
        param4: f32::NAN,
        x: 473_977_000,
        y: 85_456_000,
        z: f32::from(seq),
        seq,
        command: MavCmd::MAV_CMD_NAV_WAYPOINT,
        target_system: 1,
        target_component: 1,
        frame: MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT,
        current: 0,
        autocontinue: 1,
        mission_type: MISSION,
    }
}

fn steps(t: &mut MissionTransfer) -> Vec<TransferStep> {
    std::iter::from_fn(|| t.poll_step()).collect()
}

/// The sequence numbers of the item requests among `steps`, and whether each was legacy.
fn requests(steps: &[TransferStep]) -> Vec<(u16, bool)> {
    #[allow(deprecated)]
    steps
        .iter()
        .filter_map(|s| match s {
            TransferStep::Send(_, m) => match m.as_ref() {
                MavMessage::MISSION_REQUEST_INT(r) => Some((r.seq, false)),
                MavMessage::MISSION_REQUEST(r) => Some((r.seq, true)),
                _ => None,
            },
            _ => None,
        })
        .collect()
}

fn ack(result: MavMissionResult) -> TransferStep {
    TransferStep::Ack {
        link: LinkId::Gcs,
        to: GCS,
        result,
        mission_type: MISSION,
    }
}

#[test]
fn an_upload_asks_each_item_then_stores_before_it_acknowledges() {
    let mut t = MissionTransfer::new(1, false);
    let plans = nothing_stored();
    t.on_count(at_ms(0), LinkId::Gcs, GCS, &count(2));
    assert_eq!(requests(&steps(&mut t)), vec![(0, false)]);
    t.on_item(at_ms(10), LinkId::Gcs, GCS, &waypoint(0), false, &plans);
    assert_eq!(requests(&steps(&mut t)), vec![(1, false)]);
    assert!(!t.is_idle());
    let mut last = waypoint(1);
    last.current = 1;
    t.on_item(at_ms(20), LinkId::Gcs, GCS, &last, false, &plans);
    let done = steps(&mut t);
    assert_eq!(done.len(), 2);
    let TransferStep::Store {
        mission_type,
        items,
        current,
    } = &done[0]
    else {
        panic!("the plan is stored first: {done:?}");
    };
    assert_eq!(*mission_type, MISSION);
    assert_eq!(
        items.iter().map(|i| i.z).collect::<Vec<_>>(),
        vec![0.0, 1.0]
    );
    assert_eq!(*current, Some(1));
    assert_eq!(done[1], ack(MavMissionResult::MAV_MISSION_ACCEPTED));
    assert!(t.is_idle());
}

#[test]
fn an_item_out_of_sequence_waits_for_the_retry_and_silence_ends_the_upload() {
    let mut t = MissionTransfer::new(1, false);
    let plans = nothing_stored();
    t.on_count(at_ms(0), LinkId::Gcs, GCS, &count(3));
    steps(&mut t);
    t.on_item(at_ms(10), LinkId::Gcs, GCS, &waypoint(2), false, &plans);
    assert!(steps(&mut t).is_empty());
    // The request goes again 250 ms after the last one, not before.
    t.handle_timeout(at_ms(249), &plans);
    assert!(steps(&mut t).is_empty());
    t.handle_timeout(at_ms(250), &plans);
    assert_eq!(requests(&steps(&mut t)), vec![(0, false)]);
    // 5 s after the partner was last heard (at 10 ms): dropped, with no ack.
    for ms in (500..=5010).step_by(250) {
        t.handle_timeout(at_ms(ms), &plans);
    }
    steps(&mut t);
    assert!(!t.is_idle());
    t.handle_timeout(at_ms(5011), &plans);
    assert!(t.is_idle());
    assert!(steps(&mut t).is_empty());
}

#[test]
fn a_second_partner_is_refused_while_an_upload_runs_and_a_bad_item_ends_it() {
    let mut t = MissionTransfer::new(1, false);
    let plans = nothing_stored();
    t.on_count(at_ms(0), LinkId::Gcs, GCS, &count(2));
    steps(&mut t);
    t.on_count(at_ms(5), LinkId::Gcs, OTHER, &count(1));
    assert_eq!(
        steps(&mut t),
        vec![TransferStep::Ack {
            link: LinkId::Gcs,
            to: OTHER,
            result: MavMissionResult::MAV_MISSION_ERROR,
            mission_type: MISSION,
        }]
    );
    let mut bad = waypoint(0);
    bad.x = 910_000_000; // 91° N
    t.on_item(at_ms(10), LinkId::Gcs, GCS, &bad, false, &plans);
    assert_eq!(
        steps(&mut t),
        vec![ack(MavMissionResult::MAV_MISSION_INVALID_PARAM5_X)]
    );
    assert!(t.is_idle());
}

#[test]
fn a_download_sends_the_count_with_the_checksum_then_items_until_the_ack() {
    let stored = [MissionItem {
        command: 16,
        frame: 6,
        params: [0.0; 4],
        x: 473_977_000,
        y: 85_456_000,
        z: 12.0,
        autocontinue: 1,
    }];
    let plans = StoredPlans {
        mission: &stored,
        mission_crc: 0xdead_beef,
        current_seq: 0,
        fence: &[],
        fence_crc: 0,
    };
    let mut t = MissionTransfer::new(1, false);
    t.on_request_list(at_ms(0), LinkId::Offboard, GCS, MISSION, &plans);
    let sent = steps(&mut t);
    let [TransferStep::Send(LinkId::Offboard, msg)] = &sent[..] else {
        panic!("one count: {sent:?}");
    };
    let MavMessage::MISSION_COUNT(c) = msg.as_ref() else {
        panic!("a count: {msg:?}");
    };
    assert_eq!((c.count, c.opaque_id), (1, 0xdead_beef));
    // The count is repeated until the first request.
    t.handle_timeout(at_ms(250), &plans);
    assert_eq!(steps(&mut t).len(), 1);
    t.on_request(at_ms(300), LinkId::Offboard, GCS, 0, false, &plans);
    let sent = steps(&mut t);
    let [TransferStep::Send(_, msg)] = &sent[..] else {
        panic!("one item: {sent:?}");
    };
    let MavMessage::MISSION_ITEM_INT(item) = msg.as_ref() else {
        panic!("an item: {msg:?}");
    };
    assert_eq!((item.seq, item.current, item.z), (0, 1, 12.0));
    t.handle_timeout(at_ms(600), &plans);
    assert!(steps(&mut t).is_empty());
    t.on_ack(OTHER);
    assert!(!t.is_idle());
    t.on_ack(GCS);
    assert!(t.is_idle());
}

#[test]
fn clearing_all_stores_two_empty_plans_and_ardupilot_asks_in_legacy_form() {
    let mut t = MissionTransfer::new(1, true);
    t.on_clear(LinkId::Gcs, GCS, MavMissionType::MAV_MISSION_TYPE_ALL);
    let kinds: Vec<_> = steps(&mut t)
        .into_iter()
        .map(|s| match s {
            TransferStep::Store {
                mission_type,
                items,
                ..
            } => format!("store {mission_type:?} {}", items.len()),
            TransferStep::Ack { result, .. } => format!("ack {result:?}"),
            TransferStep::Send(..) => "send".into(),
        })
        .collect();
    assert_eq!(
        kinds,
        vec![
            "store MAV_MISSION_TYPE_MISSION 0",
            "store MAV_MISSION_TYPE_FENCE 0",
            "ack MAV_MISSION_ACCEPTED"
        ]
    );
    t.on_count(at_ms(0), LinkId::Gcs, GCS, &count(1));
    assert_eq!(requests(&steps(&mut t)), vec![(0, true)]);
}
