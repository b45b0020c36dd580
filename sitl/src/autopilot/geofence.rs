//! PX4's geofence: the fence plan a ground station uploads (mission type FENCE), the
//! shapes the navigator takes from it, the breach check and GF_ACTION, as PX4 main's
//! `mavlink_mission.cpp`, `navigator/geofence.cpp`, `navigator_main.cpp`
//! (`geofence_breach_check`) and the commander's failsafe framework do it.
//!
//! Upload rules (per item, as it arrives): at most 64 items (MAV_MISSION_NO_SPACE); a
//! global frame (GLOBAL, GLOBAL_RELATIVE_ALT, and their _INT forms from MISSION_ITEM_INT)
//! or MAV_MISSION_UNSUPPORTED_FRAME (MAV_FRAME_MISSION: MAV_MISSION_UNSUPPORTED); the
//! fence commands 5000–5004 with param2–4 and z zero or NaN (MAV_MISSION_INVALID_PARAMn,
//! PARAM7 for z); a polygon vertex with fewer than 3 vertices is MAV_MISSION_ERROR. Other
//! navigation commands are stored, as PX4 stores them, and skipped when the fence loads.
//!
//! Loading: consecutive vertices form a polygon of the first vertex's count; a shape that
//! does not contain home, or (armed, GF_ACTION not none) the vehicle, is dropped with
//! PX4's STATUSTEXT. The check: every 200 ms, in every mode, armed or not, the vehicle's
//! global position inside every inclusion shape and outside every exclusion shape, within
//! GF_MAX_HOR_DIST of home and GF_MAX_VER_DIST above it (0: off). Fence items carry no
//! altitude band. A breach that begins while armed with GF_ACTION ≠ 0 reports "Geofence:
//! approaching or outside geofence" and acts: 1 warning only; 2 Hold at once; 3 Return
//! and 5 Land after holding COM_FAIL_ACT_T (at once when it is 0.1 s or less); 4
//! terminate (motors off). The vehicle stays in that mode until a mode change or disarm;
//! a new breach acts again. While breached, arming is refused.

use std::time::Duration;

use mavlink::dialects::common::{MavMissionResult, MavSeverity};
use ringswarm_wire::geo::{Geodetic, MapProjection};

use super::mission_item::{MissionItem, cmd};
use super::{FlightMode, Vehicle};
use crate::time::SimTime;

/// Most fence items PX4 stores (`DM_KEY_FENCE_POINTS_MAX`).
pub(super) const MAX_FENCE_ITEMS: usize = 64;
/// The navigator's check interval (`GEOFENCE_CHECK_INTERVAL_US`).
const CHECK_INTERVAL: Duration = Duration::from_millis(200);

/// MAV_CMD numbers of fence items.
pub(super) mod fence_cmd {
    pub const RETURN_POINT: u16 = 5000;
    pub const POLYGON_INCLUSION: u16 = 5001;
    pub const POLYGON_EXCLUSION: u16 = 5002;
    pub const CIRCLE_INCLUSION: u16 = 5003;
    pub const CIRCLE_EXCLUSION: u16 = 5004;
}

/// GF_ACTION values.
mod action {
    pub const NONE: i32 = 0;
    pub const WARN: i32 = 1;
    pub const HOLD: i32 = 2;
    pub const RETURN: i32 = 3;
    pub const TERMINATE: i32 = 4;
    pub const LAND: i32 = 5;
}

/// One shape of the loaded fence (degrees; metres for a radius).
#[derive(Debug, Clone, PartialEq)]
enum Shape {
    Polygon {
        inclusion: bool,
        vertices_deg: Vec<(f64, f64)>,
    },
    Circle {
        inclusion: bool,
        centre_deg: (f64, f64),
        radius_m: f64,
    },
}

impl Shape {
    /// Whether `(lat, lon)` passes this shape (inside an inclusion, outside an exclusion).
    fn passes(&self, lat: f64, lon: f64) -> bool {
        match self {
            Self::Polygon {
                inclusion,
                vertices_deg,
            } => inside_polygon(vertices_deg, lat, lon) == *inclusion,
            Self::Circle {
                inclusion,
                centre_deg,
                radius_m,
            } => {
                let centre = Geodetic {
                    lat_deg: centre_deg.0,
                    lon_deg: centre_deg.1,
                    alt_amsl_m: 0.0,
                };
                let d = MapProjection::new(centre).project(&Geodetic {
                    lat_deg: lat,
                    lon_deg: lon,
                    alt_amsl_m: 0.0,
                });
                (d.x * d.x + d.y * d.y <= radius_m * radius_m) == *inclusion
            }
        }
    }
}

/// PX4's crossing test on latitude and longitude as plane coordinates.
fn inside_polygon(vertices: &[(f64, f64)], lat: f64, lon: f64) -> bool {
    let n = vertices.len();
    let mut inside = false;
    let mut j = n.wrapping_sub(1);
    for i in 0..n {
        let (vi, vj) = (vertices[i], vertices[j]);
        if (vi.1 >= lon) != (vj.1 >= lon)
            && lat <= (vj.0 - vi.0) * (lon - vi.1) / (vj.1 - vi.1) + vi.0
        {
            inside = !inside;
        }
        j = i;
    }
    inside
}

/// The stored fence plan, the shapes loaded from it and the breach state.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Geofence {
    items: Vec<MissionItem>,
    shapes: Vec<Shape>,
    pub(super) crc: u32,
    next_check: Option<SimTime>,
    breached: bool,
    /// Return or Land due at this time (after the failsafe's Hold), if no one takes over.
    delayed: Option<(SimTime, FlightMode)>,
}

impl Geofence {
    /// The stored items.
    pub fn items(&self) -> &[MissionItem] {
        &self.items
    }

    /// Whether the last check found the vehicle outside.
    pub fn breached(&self) -> bool {
        self.breached
    }

    /// Shapes the navigator uses (after the load's checks).
    pub fn shapes(&self) -> usize {
        self.shapes.len()
    }
}

/// Checks one uploaded fence item against PX4's rules; `legacy` for MISSION_ITEM.
pub(super) fn check_fence_item(item: &MissionItem, legacy: bool) -> Result<(), MavMissionResult> {
    use MavMissionResult as R;
    let global = match item.frame {
        0 | 3 => true,
        5 | 6 => !legacy,
        _ => false,
    };
    let fence = (fence_cmd::RETURN_POINT..=fence_cmd::CIRCLE_EXCLUSION).contains(&item.command);
    if !global {
        return Err(if item.frame == 2 && fence {
            R::MAV_MISSION_UNSUPPORTED
        } else {
            R::MAV_MISSION_UNSUPPORTED_FRAME
        });
    }
    let navigation = [
        cmd::NAV_WAYPOINT,
        cmd::NAV_LOITER_UNLIM,
        cmd::NAV_LOITER_TIME,
        cmd::NAV_LAND,
        cmd::NAV_TAKEOFF,
    ];
    if !fence && !navigation.contains(&item.command) {
        return Err(R::MAV_MISSION_UNSUPPORTED);
    }
    let zero = |p: f32| p.is_nan() || p == 0.0;
    if fence {
        // 5001–5004 use param1, x and y; 5000 uses x, y and z.
        let (first, z_free) = if item.command == fence_cmd::RETURN_POINT {
            (0, true)
        } else {
            (1, false)
        };
        let errors = [
            R::MAV_MISSION_INVALID_PARAM1,
            R::MAV_MISSION_INVALID_PARAM2,
            R::MAV_MISSION_INVALID_PARAM3,
            R::MAV_MISSION_INVALID_PARAM4,
        ];
        for (p, error) in item.params.iter().zip(errors).skip(first) {
            if !zero(*p) {
                return Err(error);
            }
        }
        if !z_free && !zero(item.z) {
            return Err(R::MAV_MISSION_INVALID_PARAM7);
        }
    }
    let (lat, lon) = item.lat_lon_deg();
    if lat.abs() > 90.0 {
        return Err(R::MAV_MISSION_INVALID_PARAM5_X);
    }
    if lon.abs() > 180.0 {
        return Err(R::MAV_MISSION_INVALID_PARAM6_Y);
    }
    let vertex = matches!(
        item.command,
        fence_cmd::POLYGON_INCLUSION | fence_cmd::POLYGON_EXCLUSION
    );
    if vertex && (item.params[0] + 0.5) < 3.0 {
        return Err(R::MAV_MISSION_ERROR); // "Fence: too few vertices"
    }
    Ok(())
}

/// The shapes of a plan, as the navigator's `_updateFence` reads it.
fn shapes_of(items: &[MissionItem]) -> Vec<Shape> {
    let mut shapes = Vec::new();
    let mut k = 0;
    while k < items.len() {
        let item = &items[k];
        match item.command {
            fence_cmd::POLYGON_INCLUSION | fence_cmd::POLYGON_EXCLUSION => {
                let count = (item.params[0] + 0.5) as usize;
                let end = (k + count).min(items.len());
                shapes.push(Shape::Polygon {
                    inclusion: item.command == fence_cmd::POLYGON_INCLUSION,
                    vertices_deg: items[k..end].iter().map(MissionItem::lat_lon_deg).collect(),
                });
                k += count.max(1);
            }
            fence_cmd::CIRCLE_INCLUSION | fence_cmd::CIRCLE_EXCLUSION => {
                shapes.push(Shape::Circle {
                    inclusion: item.command == fence_cmd::CIRCLE_INCLUSION,
                    centre_deg: item.lat_lon_deg(),
                    radius_m: f64::from(item.params[0]),
                });
                k += 1;
            }
            other => {
                if other != fence_cmd::RETURN_POINT {
                    tracing::warn!(command = other, "unhandled Fence command");
                }
                k += 1;
            }
        }
    }
    shapes
}

impl Vehicle {
    fn gf_action(&self) -> i32 {
        self.params.value("GF_ACTION") as i32
    }

    fn position_geodetic(&self) -> Geodetic {
        self.world.to_geodetic(&self.world_position())
    }

    /// Stores an uploaded (or cleared) fence plan and loads its shapes, dropping those
    /// that do not contain home, or the vehicle in flight, as PX4's navigator does.
    pub(super) fn replace_fence(&mut self, items: Vec<MissionItem>) {
        self.geofence.crc = if items.is_empty() {
            0
        } else {
            super::mission_item::crc_of(&items)
        };
        let home = self.home_geodetic();
        let here = self.position_geodetic();
        let check_here =
            self.modes.armed() && !self.modes.landed() && self.gf_action() != action::NONE;
        let mut kept = Vec::new();
        for shape in shapes_of(&items) {
            if !shape.passes(home.lat_deg, home.lon_deg) {
                self.send_statustext(
                    MavSeverity::MAV_SEVERITY_CRITICAL,
                    "Geofence invalid, doesn't contain Home position\t",
                );
            } else if check_here && !shape.passes(here.lat_deg, here.lon_deg) {
                self.send_statustext(
                    MavSeverity::MAV_SEVERITY_CRITICAL,
                    "Geofence invalid, doesn't contain current vehicle position\t",
                );
            } else {
                kept.push(shape);
            }
        }
        tracing::info!(
            sysid = self.cfg.system_id,
            items = items.len(),
            shapes = kept.len(),
            "fence stored"
        );
        self.geofence.items = items;
        self.geofence.shapes = kept;
    }

    /// Whether the vehicle's position passes every fence: the shapes, GF_MAX_HOR_DIST and
    /// GF_MAX_VER_DIST (from home; 0 is off).
    fn inside_geofence(&self) -> bool {
        let here = self.position_geodetic();
        let home = self.home_geodetic();
        let max_hor = self.params.value("GF_MAX_HOR_DIST");
        if max_hor > 0.0 && MapProjection::new(home).project(&here).xy().norm() >= max_hor {
            return false;
        }
        let max_ver = self.params.value("GF_MAX_VER_DIST");
        if max_ver > 0.0 && here.alt_amsl_m - home.alt_amsl_m >= max_ver {
            return false;
        }
        self.geofence
            .shapes
            .iter()
            .all(|s| s.passes(here.lat_deg, here.lon_deg))
    }

    /// The navigator's breach check (every 200 ms) and the commander's GF_ACTION.
    pub(super) fn check_geofence(&mut self, t: SimTime) {
        if let Some((at, mode)) = self.geofence.delayed
            && t >= at
        {
            self.geofence.delayed = None;
            // Still in the failsafe's Hold: no one took over.
            if self.modes.armed() && self.modes.failsafe && self.modes.mode == FlightMode::Hold {
                self.enter_mode(mode);
            }
        }
        if self.geofence.next_check.is_some_and(|next| t < next) {
            return;
        }
        self.geofence.next_check = Some(t + CHECK_INTERVAL);
        let breached = !self.inside_geofence();
        let began = breached && !self.geofence.breached;
        self.geofence.breached = breached;
        let gf_action = self.gf_action();
        if !began || gf_action == action::NONE {
            return;
        }
        self.send_statustext(
            MavSeverity::MAV_SEVERITY_CRITICAL,
            "Geofence: approaching or outside geofence",
        );
        if !self.modes.armed() || gf_action == action::WARN {
            return;
        }
        tracing::warn!(sysid = self.cfg.system_id, gf_action, "geofence breached");
        self.modes.failsafe = true;
        let delay = Duration::from_secs_f64(self.params.value("COM_FAIL_ACT_T").max(0.0));
        match gf_action {
            action::HOLD => {
                self.send_statustext(MavSeverity::MAV_SEVERITY_CRITICAL, "Failsafe activated\t");
                self.enter_mode(FlightMode::Hold);
            }
            action::RETURN | action::LAND => {
                let mode = if gf_action == action::RETURN {
                    FlightMode::Return
                } else {
                    FlightMode::Land
                };
                if delay > Duration::from_millis(100) {
                    self.send_statustext(
                        MavSeverity::MAV_SEVERITY_CRITICAL,
                        &format!(
                            "Failsafe activated: entering Hold for {} seconds\t",
                            delay.as_secs()
                        ),
                    );
                    self.enter_mode(FlightMode::Hold);
                    self.geofence.delayed = Some((t + delay, mode));
                } else {
                    self.send_statustext(
                        MavSeverity::MAV_SEVERITY_CRITICAL,
                        "Failsafe activated\t",
                    );
                    self.enter_mode(mode);
                }
            }
            action::TERMINATE => {
                self.send_statustext(MavSeverity::MAV_SEVERITY_CRITICAL, "Failsafe activated\t");
                self.disarm("geofence: flight termination");
            }
            _ => {} // unknown values warn, as PX4's fromGfActParam
        }
    }

    /// PX4's geofence arming check: refused while breached with GF_ACTION not none.
    pub(super) fn geofence_denies_arming(&self) -> bool {
        self.geofence.breached && self.gf_action() != action::NONE
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn item(command: u16, frame: u8, p1: f32, lat: f64, lon: f64) -> MissionItem {
        MissionItem {
            command,
            frame,
            params: [p1, 0.0, 0.0, 0.0],
            x: (lat * 1e7).round() as i32,
            y: (lon * 1e7).round() as i32,
            z: 0.0,
            autocontinue: 0,
        }
    }

    #[test]
    fn fence_items_follow_px4s_rules() {
        use MavMissionResult as R;
        let ok = item(fence_cmd::POLYGON_INCLUSION, 0, 4.0, 47.0, 8.0);
        assert_eq!(check_fence_item(&ok, false), Ok(()));
        assert_eq!(
            check_fence_item(
                &item(fence_cmd::POLYGON_INCLUSION, 0, 2.0, 47.0, 8.0),
                false
            ),
            Err(R::MAV_MISSION_ERROR)
        );
        assert_eq!(
            check_fence_item(
                &item(fence_cmd::CIRCLE_INCLUSION, 2, 50.0, 47.0, 8.0),
                false
            ),
            Err(R::MAV_MISSION_UNSUPPORTED)
        );
        assert_eq!(
            check_fence_item(
                &item(fence_cmd::CIRCLE_INCLUSION, 1, 50.0, 47.0, 8.0),
                false
            ),
            Err(R::MAV_MISSION_UNSUPPORTED_FRAME)
        );
        // A legacy MISSION_ITEM may not use the _INT frames.
        assert_eq!(
            check_fence_item(&item(fence_cmd::CIRCLE_INCLUSION, 5, 50.0, 47.0, 8.0), true),
            Err(R::MAV_MISSION_UNSUPPORTED_FRAME)
        );
        let mut high = item(fence_cmd::CIRCLE_INCLUSION, 0, 50.0, 47.0, 8.0);
        high.z = 30.0;
        assert_eq!(
            check_fence_item(&high, false),
            Err(R::MAV_MISSION_INVALID_PARAM7)
        );
        let mut p3 = ok;
        p3.params[2] = 1.0;
        assert_eq!(
            check_fence_item(&p3, false),
            Err(R::MAV_MISSION_INVALID_PARAM3)
        );
        assert_eq!(
            check_fence_item(&item(183, 0, 0.0, 47.0, 8.0), false),
            Err(R::MAV_MISSION_UNSUPPORTED)
        );
        // A waypoint parses, as PX4's fence branch lets it; loading skips it.
        assert_eq!(
            check_fence_item(&item(cmd::NAV_WAYPOINT, 0, 0.0, 47.0, 8.0), false),
            Ok(())
        );
    }

    #[test]
    fn the_polygon_test_is_the_crossing_number_on_latitude_and_longitude() {
        let square = [(0.0, 0.0), (0.0, 1.0), (1.0, 1.0), (1.0, 0.0)];
        assert!(inside_polygon(&square, 0.5, 0.5));
        assert!(!inside_polygon(&square, 1.5, 0.5));
        assert!(!inside_polygon(&square, 0.5, -0.1));
        // An L: the notch is outside.
        let l = [
            (0.0, 0.0),
            (0.0, 2.0),
            (1.0, 2.0),
            (1.0, 1.0),
            (2.0, 1.0),
            (2.0, 0.0),
        ];
        assert!(inside_polygon(&l, 1.5, 0.5));
        assert!(!inside_polygon(&l, 1.5, 1.5));
    }

    #[test]
    fn vertices_group_by_the_first_vertex_count_and_a_circle_is_one_item() {
        let items = [
            item(fence_cmd::POLYGON_INCLUSION, 0, 3.0, 0.0, 0.0),
            item(fence_cmd::POLYGON_INCLUSION, 0, 3.0, 0.0, 1.0),
            item(fence_cmd::POLYGON_INCLUSION, 0, 3.0, 1.0, 0.0),
            item(fence_cmd::CIRCLE_EXCLUSION, 0, 100.0, 0.2, 0.2),
            item(cmd::NAV_WAYPOINT, 0, 0.0, 0.5, 0.5),
        ];
        let shapes = shapes_of(&items);
        assert_eq!(shapes.len(), 2);
        assert!(
            matches!(&shapes[0], Shape::Polygon { inclusion: true, vertices_deg } if vertices_deg.len() == 3)
        );
        // 100 m about (0.2, 0.2): a point 90 m north is inside the exclusion (fails), 110 m
        // north outside (passes). One degree of latitude is R·π/180 m on PX4's sphere.
        let m_per_deg = ringswarm_wire::geo::EARTH_RADIUS_M.to_radians();
        assert!(!shapes[1].passes(0.2 + 90.0 / m_per_deg, 0.2));
        assert!(shapes[1].passes(0.2 + 110.0 / m_per_deg, 0.2));
    }
}
