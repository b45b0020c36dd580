//! The swarm's common frame.
//!
//! Every PX4 vehicle reports LOCAL_POSITION_NED relative to its own origin (where its
//! estimator started), so local positions of two vehicles are not comparable. The
//! coordinator places every origin in one frame: it projects each vehicle's
//! GPS_GLOBAL_ORIGIN onto the tangent plane at a common reference with PX4's own map
//! projection (azimuthal equidistant on a sphere of radius 6 371 000 m, as in PX4's
//! `MapProjection`), and adds the vehicle's local position. The result is expressed in
//! NED about the reference and, for the laws, in the paper's ENU frame.

use nalgebra::Vector3;

use crate::control::ned_to_enu;

use ringswarm_wire::geo::MapProjection;
pub use ringswarm_wire::geo::{EARTH_RADIUS_M as PX4_EARTH_RADIUS_M, Geodetic};

/// The common frame: a tangent plane at `reference`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CommonFrame {
    reference: Geodetic,
}

impl CommonFrame {
    /// A frame whose origin is `reference`.
    pub fn new(reference: Geodetic) -> Self {
        Self { reference }
    }

    /// The reference point.
    pub fn reference(&self) -> Geodetic {
        self.reference
    }

    /// The NED offset (m) of a geodetic point from the reference (PX4's azimuthal
    /// equidistant projection; altitude as the negative height difference).
    pub fn offset_ned_m(&self, point: &Geodetic) -> Vector3<f64> {
        MapProjection::new(self.reference).project(point)
    }

    /// The geodetic point at a NED offset (m) from the reference: the inverse of
    /// [`CommonFrame::offset_ned_m`] (altitude from the down offset).
    pub fn geodetic_of_ned_m(&self, offset_ned_m: &Vector3<f64>) -> Geodetic {
        MapProjection::new(self.reference).reproject(offset_ned_m)
    }

    /// A vehicle's position in the common frame (NED, m) from its origin and its local
    /// NED position.
    pub fn to_common_ned(&self, origin: &Geodetic, local_ned_m: &Vector3<f64>) -> Vector3<f64> {
        self.offset_ned_m(origin) + local_ned_m
    }

    /// The same in the paper's ENU frame (x east, y north, z up).
    pub fn to_common_enu(&self, origin: &Geodetic, local_ned_m: &Vector3<f64>) -> Vector3<f64> {
        ned_to_enu(self.to_common_ned(origin, local_ned_m))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn zurich() -> Geodetic {
        Geodetic {
            lat_deg: 47.397742,
            lon_deg: 8.545594,
            alt_amsl_m: 488.0,
        }
    }

    #[test]
    fn east_offset_shrinks_with_the_cosine_of_latitude() {
        let frame = CommonFrame::new(zurich());
        let mut p = zurich();
        p.lon_deg += 0.001;
        let d = frame.offset_ned_m(&p);
        let expected = PX4_EARTH_RADIUS_M * 0.001f64.to_radians() * 47.397742f64.to_radians().cos();
        assert!((d.y - expected).abs() < 1e-3, "{} vs {expected}", d.y);
        assert!(d.x.abs() < 1e-2); // the small northward bulge of the projection
    }

    #[test]
    fn two_vehicles_with_different_origins_share_one_frame() {
        // Vehicle B's origin is 30 m north, 40 m east and 2 m higher than A's; both hover
        // over the same point, so their common positions agree.
        let frame = CommonFrame::new(zurich());
        let origin_a = zurich();
        let origin_b = Geodetic {
            lat_deg: zurich().lat_deg + (30.0 / PX4_EARTH_RADIUS_M).to_degrees(),
            lon_deg: zurich().lon_deg
                + (40.0 / (PX4_EARTH_RADIUS_M * 47.397742f64.to_radians().cos())).to_degrees(),
            alt_amsl_m: 490.0,
        };
        let a = frame.to_common_ned(&origin_a, &Vector3::new(30.0, 40.0, -12.0));
        let b = frame.to_common_ned(&origin_b, &Vector3::new(0.0, 0.0, -10.0));
        assert!((a - b).norm() < 1e-3, "{a:?} vs {b:?}");
        let enu = frame.to_common_enu(&origin_a, &Vector3::new(30.0, 40.0, -12.0));
        assert!((enu - Vector3::new(40.0, 30.0, 12.0)).norm() < 1e-9);
    }
}
