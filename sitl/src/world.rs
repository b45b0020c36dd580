//! The shared world: one geodetic reference, each vehicle's own local origin, the ground.
//!
//! Positions in the world are NED offsets from the reference point (m). Each vehicle's
//! LOCAL_POSITION_NED is relative to its own origin, its start point, as with PX4, so two
//! vehicles' local positions are not comparable; GLOBAL_POSITION_INT, GPS_GLOBAL_ORIGIN
//! and HOME_POSITION place everything around the one reference, with PX4's own projection
//! (`ringswarm_wire::geo`, azimuthal equidistant), the one the coordinator uses too.

use nalgebra::Vector3;

use ringswarm_wire::geo::MapProjection;
pub use ringswarm_wire::geo::{EARTH_RADIUS_M, Geodetic};

/// The world every emulated vehicle shares.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct World {
    /// The reference point (NED offset zero).
    pub reference: Geodetic,
    /// The ground as a NED z offset from the reference (m; positive is below it).
    pub ground_down_m: f64,
}

impl Default for World {
    fn default() -> Self {
        // PX4 SITL's default home (Zurich), ground at the reference.
        Self {
            reference: Geodetic {
                lat_deg: 47.397_742,
                lon_deg: 8.545_594,
                alt_amsl_m: 488.0,
            },
            ground_down_m: 0.0,
        }
    }
}

impl World {
    /// The geodetic position of a NED offset from the reference.
    pub fn to_geodetic(&self, offset_ned_m: &Vector3<f64>) -> Geodetic {
        MapProjection::new(self.reference).reproject(offset_ned_m)
    }

    /// The NED offset from the reference of a geodetic position.
    pub fn to_offset_ned(&self, position: &Geodetic) -> Vector3<f64> {
        MapProjection::new(self.reference).project(position)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn north_offset_raises_latitude_and_east_raises_longitude() {
        let world = World::default();
        let g = world.to_geodetic(&Vector3::new(100.0, 50.0, -20.0));
        assert!(g.lat_deg > world.reference.lat_deg && g.lon_deg > world.reference.lon_deg);
        assert!((g.alt_amsl_m - 508.0).abs() < 1e-9);
        // One degree of latitude is R·π/180 m.
        let one_deg = world.to_geodetic(&Vector3::new(EARTH_RADIUS_M.to_radians() * 1.0, 0.0, 0.0));
        assert!((one_deg.lat_deg - world.reference.lat_deg - 1.0).abs() < 1e-12);
        let back = world.to_offset_ned(&g);
        assert!((back - Vector3::new(100.0, 50.0, -20.0)).norm() < 1e-9);
    }
}
