//! Giving the fence to a vehicle: the client side of the mission protocol for mission
//! type FENCE, as QGroundControl and MAVSDK speak it to PX4, so that the vehicle's own
//! geofence backs the coordinator's.
//!
//! ```text
//!  start ──► Counting: MISSION_COUNT n (FENCE) sent; sent again every `retry`
//!  Counting/Sending ──MISSION_REQUEST(_INT) seq < n──► Sending: item seq sent (any seq is
//!                     answered: PX4 asks again for an item it did not get)
//!  Sending ──MISSION_ACK ACCEPTED, once the last item was asked for──► Done
//!  Counting/Sending ──MISSION_ACK with an error──► Failed (the result named)
//!  Counting/Sending ──nothing for `retry`──► the last message again, up to `max_attempts`
//!                     sends in a row, then Failed
//! ```
//!
//! The items are the fence's boundary itself, in geodetic coordinates: the coordinator
//! acts `margin_m` inside it, the vehicle's geofence only at it. A circle is one
//! MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION item (centre, radius); a polygon is one
//! MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION item per vertex, each carrying the vertex
//! count. PX4's fence items carry no altitude; the altitude band stays the coordinator's.
//!
//! Pure: the MAVLink messages are built and read in `crate::link`.

use std::sync::Arc;
use std::time::Duration;

use nalgebra::Vector3;
use ringswarm_wire::time::SimTime;

use crate::frame::{CommonFrame, Geodetic};
use crate::safety::{Fence, FenceItem, FenceItemKind, FenceShape};

/// The fence as the vehicles get it.
#[derive(Debug, Clone, PartialEq)]
pub struct FencePlan {
    items: Vec<FenceItem>,
}

impl FencePlan {
    /// The items for `fence` (common frame, ENU) about `frame`'s reference, projected back
    /// with PX4's own map projection.
    pub fn new(fence: &Fence, frame: &CommonFrame) -> Result<Self, String> {
        let geodetic = |east_m: f64, north_m: f64| {
            frame.geodetic_of_ned_m(&Vector3::new(north_m, east_m, 0.0))
        };
        let items = match &fence.shape {
            FenceShape::Circle { centre_m, radius_m } => {
                let Geodetic {
                    lat_deg, lon_deg, ..
                } = geodetic(centre_m.x, centre_m.y);
                vec![FenceItem {
                    kind: FenceItemKind::Circle {
                        radius_m: *radius_m,
                    },
                    lat_deg,
                    lon_deg,
                }]
            }
            FenceShape::Polygon { vertices_m } => {
                let vertex_count = u16::try_from(vertices_m.len()).map_err(|_| {
                    format!(
                        "fence: {} vertices, more than a vehicle takes",
                        vertices_m.len()
                    )
                })?;
                vertices_m
                    .iter()
                    .map(|v| {
                        let g = geodetic(v.x, v.y);
                        FenceItem {
                            kind: FenceItemKind::PolygonVertex { vertex_count },
                            lat_deg: g.lat_deg,
                            lon_deg: g.lon_deg,
                        }
                    })
                    .collect()
            }
        };
        Ok(Self { items })
    }

    /// The items in upload order.
    pub fn items(&self) -> &[FenceItem] {
        &self.items
    }
}

/// A message the upload wants sent.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum UploadSend {
    /// MISSION_COUNT (FENCE) with this count.
    Count(u16),
    /// MISSION_ITEM_INT (FENCE) number `seq`.
    Item {
        /// Its sequence number.
        seq: u16,
        /// The item.
        item: FenceItem,
    },
}

/// Where the upload is.
#[derive(Debug, Clone, PartialEq)]
pub enum UploadState {
    /// Not started.
    Idle,
    /// The count was sent; no item asked for yet.
    Counting,
    /// Items are being asked for; the highest asked so far.
    Sending {
        /// Highest sequence number asked for.
        highest: u16,
    },
    /// The vehicle acknowledged the whole fence.
    Done,
    /// The vehicle refused it or never answered; why.
    Failed(String),
}

/// What an answer did to the upload.
#[derive(Debug, Clone, PartialEq)]
pub enum UploadAnswer {
    /// Send this.
    Send(UploadSend),
    /// The vehicle holds the fence now.
    Done,
    /// The upload failed; why.
    Failed(String),
    /// Nothing to do (not ours, stale or out of range).
    Ignored,
}

/// The upload machine of one vehicle.
#[derive(Debug, Clone)]
pub struct FenceUpload {
    plan: Arc<FencePlan>,
    state: UploadState,
    last_sent: Option<UploadSend>,
    deadline: SimTime,
    sends: u8,
    retry: Duration,
    max_attempts: u8,
}

impl FenceUpload {
    /// An idle upload of `plan`, resending after `retry` up to `max_attempts` times.
    pub fn new(plan: Arc<FencePlan>, retry: Duration, max_attempts: u8) -> Self {
        Self {
            plan,
            state: UploadState::Idle,
            last_sent: None,
            deadline: SimTime::MAX,
            sends: 0,
            retry,
            max_attempts: max_attempts.max(1),
        }
    }

    /// Where it is.
    pub fn state(&self) -> &UploadState {
        &self.state
    }

    /// Whether the vehicle holds the fence.
    pub fn done(&self) -> bool {
        self.state == UploadState::Done
    }

    /// Items in the plan.
    pub fn len(&self) -> usize {
        self.plan.items().len()
    }

    /// Whether the plan is empty (never: a fence has at least one item).
    pub fn is_empty(&self) -> bool {
        self.plan.items().is_empty()
    }

    /// Starts (or, after a loss, starts over) an upload that is not done: the count.
    /// `None` once done or failed.
    pub fn start(&mut self, now: SimTime) -> Option<UploadSend> {
        if matches!(self.state, UploadState::Done | UploadState::Failed(_)) {
            return None;
        }
        self.state = UploadState::Counting;
        self.sends = 0;
        let count = u16::try_from(self.plan.items().len()).unwrap_or(u16::MAX);
        Some(self.send(now, UploadSend::Count(count)))
    }

    fn send(&mut self, now: SimTime, what: UploadSend) -> UploadSend {
        self.sends += 1;
        self.last_sent = Some(what);
        self.deadline = now + self.retry;
        what
    }

    /// The vehicle asks for item `seq`.
    pub fn on_request(&mut self, now: SimTime, seq: u16) -> UploadAnswer {
        let highest = match self.state {
            UploadState::Counting => seq,
            UploadState::Sending { highest } => highest.max(seq),
            _ => return UploadAnswer::Ignored,
        };
        let Some(item) = self.plan.items().get(usize::from(seq)).copied() else {
            return UploadAnswer::Ignored;
        };
        self.state = UploadState::Sending { highest };
        self.sends = 0;
        UploadAnswer::Send(self.send(now, UploadSend::Item { seq, item }))
    }

    /// The vehicle's MISSION_ACK for a fence, with its MAV_MISSION_RESULT and that result's
    /// name.
    pub fn on_ack(&mut self, result: u8, result_name: &str) -> UploadAnswer {
        let last = u16::try_from(self.plan.items().len().saturating_sub(1)).unwrap_or(u16::MAX);
        match (&self.state, result) {
            (UploadState::Sending { highest }, 0) if *highest >= last => {
                self.finish(UploadState::Done);
                UploadAnswer::Done
            }
            // An ACCEPTED before the last item was asked for answers someone else.
            (UploadState::Counting | UploadState::Sending { .. }, 0) => UploadAnswer::Ignored,
            (UploadState::Counting | UploadState::Sending { .. }, _) => {
                let why = format!("the vehicle refused the fence: MISSION_ACK {result_name}");
                self.finish(UploadState::Failed(why.clone()));
                UploadAnswer::Failed(why)
            }
            _ => UploadAnswer::Ignored,
        }
    }

    fn finish(&mut self, state: UploadState) {
        self.state = state;
        self.deadline = SimTime::MAX;
        self.last_sent = None;
    }

    /// When [`FenceUpload::handle_timeout`] is next due.
    pub fn poll_timeout(&self) -> SimTime {
        self.deadline
    }

    /// Resends what the vehicle did not answer, or gives up.
    pub fn handle_timeout(&mut self, now: SimTime) -> UploadAnswer {
        if now < self.deadline {
            return UploadAnswer::Ignored;
        }
        let Some(last) = self.last_sent else {
            return UploadAnswer::Ignored;
        };
        if self.sends >= self.max_attempts {
            let what = match last {
                UploadSend::Count(n) => format!("MISSION_COUNT {n}"),
                UploadSend::Item { seq, .. } => format!("fence item {seq}"),
            };
            let why = format!(
                "the vehicle did not answer the fence upload ({what} sent {} times, {} ms apart)",
                self.sends,
                self.retry.as_millis()
            );
            self.finish(UploadState::Failed(why.clone()));
            return UploadAnswer::Failed(why);
        }
        UploadAnswer::Send(self.send(now, last))
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::Vector2;

    use super::*;

    fn frame() -> CommonFrame {
        CommonFrame::new(Geodetic {
            lat_deg: 47.397742,
            lon_deg: 8.545594,
            alt_amsl_m: 488.0,
        })
    }

    fn square() -> Fence {
        Fence {
            shape: FenceShape::Polygon {
                vertices_m: vec![
                    Vector2::new(-100.0, -100.0),
                    Vector2::new(100.0, -100.0),
                    Vector2::new(100.0, 100.0),
                    Vector2::new(-100.0, 100.0),
                ],
            },
            min_altitude_m: 2.0,
            max_altitude_m: 50.0,
        }
    }

    fn ms(t: u64) -> SimTime {
        SimTime::ZERO + Duration::from_millis(t)
    }

    #[test]
    fn a_polygon_is_one_vertex_item_per_corner_projected_back_to_where_it_was() {
        let plan = FencePlan::new(&square(), &frame()).unwrap();
        assert_eq!(plan.items().len(), 4);
        for (item, v) in plan.items().iter().zip([(-100.0, -100.0), (100.0, -100.0)]) {
            assert_eq!(item.kind, FenceItemKind::PolygonVertex { vertex_count: 4 });
            // Independently: north 1 m is 1/R rad of latitude; east 1 m is 1/(R cos φ) rad
            // of longitude at the point's own latitude φ (the east offset runs along its
            // parallel, to second order in the offset).
            let r = crate::frame::PX4_EARTH_RADIUS_M;
            let lat: f64 = 47.397742 + (v.1 / r).to_degrees();
            let lon = 8.545594 + (v.0 / (r * lat.to_radians().cos())).to_degrees();
            assert!(
                (item.lat_deg - lat).abs() < 2e-8,
                "{} vs {lat}",
                item.lat_deg
            );
            assert!(
                (item.lon_deg - lon).abs() < 2e-8,
                "{} vs {lon}",
                item.lon_deg
            );
        }
        // And the frame maps each item back onto its vertex to a millimetre.
        let f = frame();
        let back = f.offset_ned_m(&Geodetic {
            lat_deg: plan.items()[2].lat_deg,
            lon_deg: plan.items()[2].lon_deg,
            alt_amsl_m: 488.0,
        });
        assert!((back.x - 100.0).abs() < 1e-3 && (back.y - 100.0).abs() < 1e-3);
    }

    #[test]
    fn a_circle_is_one_item_with_its_radius() {
        let fence = Fence {
            shape: FenceShape::Circle {
                centre_m: Vector2::new(0.0, 0.0),
                radius_m: 400.0,
            },
            ..square()
        };
        let plan = FencePlan::new(&fence, &frame()).unwrap();
        assert_eq!(plan.items().len(), 1);
        assert_eq!(
            plan.items()[0].kind,
            FenceItemKind::Circle { radius_m: 400.0 }
        );
        assert!((plan.items()[0].lat_deg - 47.397742).abs() < 1e-12);
    }

    fn upload() -> FenceUpload {
        let plan = Arc::new(FencePlan::new(&square(), &frame()).unwrap());
        FenceUpload::new(plan, Duration::from_millis(1000), 3)
    }

    #[test]
    fn the_count_then_each_asked_item_then_the_ack_is_done() {
        let mut up = upload();
        assert_eq!(up.start(ms(0)), Some(UploadSend::Count(4)));
        for seq in 0..4u16 {
            let UploadAnswer::Send(UploadSend::Item { seq: s, .. }) = up.on_request(ms(10), seq)
            else {
                panic!("item {seq} not sent")
            };
            assert_eq!(s, seq);
        }
        assert_eq!(up.on_ack(0, "ACCEPTED"), UploadAnswer::Done);
        assert!(up.done());
        assert_eq!(up.poll_timeout(), SimTime::MAX);
        assert_eq!(up.start(ms(20)), None, "a done upload is not repeated");
    }

    #[test]
    fn an_accepted_before_the_last_item_is_not_the_fence_accepted() {
        let mut up = upload();
        up.start(ms(0));
        up.on_request(ms(1), 0);
        assert_eq!(up.on_ack(0, "ACCEPTED"), UploadAnswer::Ignored);
        assert!(!up.done());
    }

    #[test]
    fn a_refusal_names_the_result() {
        let mut up = upload();
        up.start(ms(0));
        let UploadAnswer::Failed(why) = up.on_ack(3, "UNSUPPORTED") else {
            panic!("not failed")
        };
        assert!(why.contains("MISSION_ACK UNSUPPORTED"), "{why}");
    }

    #[test]
    fn silence_resends_the_last_message_then_gives_up() {
        let mut up = upload();
        up.start(ms(0));
        assert_eq!(up.poll_timeout(), ms(1000));
        assert_eq!(up.handle_timeout(ms(999)), UploadAnswer::Ignored);
        assert_eq!(
            up.handle_timeout(ms(1000)),
            UploadAnswer::Send(UploadSend::Count(4))
        );
        // An item asked for restarts the count of sends.
        assert!(matches!(up.on_request(ms(1500), 1), UploadAnswer::Send(_)));
        assert!(matches!(
            up.handle_timeout(ms(2500)),
            UploadAnswer::Send(UploadSend::Item { seq: 1, .. })
        ));
        assert!(matches!(up.handle_timeout(ms(3500)), UploadAnswer::Send(_)));
        let UploadAnswer::Failed(why) = up.handle_timeout(ms(4500)) else {
            panic!("did not give up")
        };
        assert!(why.contains("fence item 1 sent 3 times"), "{why}");
        assert_eq!(up.on_request(ms(4600), 2), UploadAnswer::Ignored);
    }

    #[test]
    fn a_request_beyond_the_plan_is_ignored() {
        let mut up = upload();
        up.start(ms(0));
        assert_eq!(up.on_request(ms(1), 4), UploadAnswer::Ignored);
    }
}
