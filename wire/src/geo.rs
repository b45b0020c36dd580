//! One geodetic projection for both sides: PX4's own (`MapProjection` in PX4's
//! `lib/geo`): the azimuthal equidistant projection on a sphere of radius
//! [`EARTH_RADIUS_M`] about a reference point. Both the emulator (placing its vehicles
//! and reporting GPS_GLOBAL_ORIGIN) and the coordinator (placing every vehicle's origin in
//! the common frame) use it, so a round trip between them is exact to rounding.

use nalgebra::Vector3;

/// Standard gravity (m/s², PX4's CONSTANTS_ONE_G), the one value both sides use.
pub const GRAVITY_MPS2: f64 = 9.806_65;

/// PX4's Earth radius for its local projection (m).
pub const EARTH_RADIUS_M: f64 = 6_371_000.0;

/// A geodetic position.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Geodetic {
    /// Latitude (deg).
    pub lat_deg: f64,
    /// Longitude (deg).
    pub lon_deg: f64,
    /// Altitude above mean sea level (m).
    pub alt_amsl_m: f64,
}

impl Geodetic {
    /// From MAVLink's integer fields: degE7 and millimetres.
    pub fn from_mavlink(lat_e7: i32, lon_e7: i32, alt_mm: i32) -> Self {
        Self {
            lat_deg: f64::from(lat_e7) * 1e-7,
            lon_deg: f64::from(lon_e7) * 1e-7,
            alt_amsl_m: f64::from(alt_mm) * 1e-3,
        }
    }

    /// MAVLink's `degE7` latitude.
    pub fn lat_e7(&self) -> i32 {
        (self.lat_deg * 1e7).round() as i32
    }

    /// MAVLink's `degE7` longitude.
    pub fn lon_e7(&self) -> i32 {
        (self.lon_deg * 1e7).round() as i32
    }

    /// Altitude in millimetres.
    pub fn alt_mm(&self) -> i32 {
        (self.alt_amsl_m * 1000.0).round() as i32
    }
}

/// The projection about one reference point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapProjection {
    reference: Geodetic,
}

impl MapProjection {
    /// A projection about `reference`.
    pub fn new(reference: Geodetic) -> Self {
        Self { reference }
    }

    /// The reference point.
    pub fn reference(&self) -> Geodetic {
        self.reference
    }

    /// The NED offset (m) of a point from the reference; down is the negative height
    /// difference.
    pub fn project(&self, point: &Geodetic) -> Vector3<f64> {
        let (lat0, lon0) = (
            self.reference.lat_deg.to_radians(),
            self.reference.lon_deg.to_radians(),
        );
        let (lat, lon) = (point.lat_deg.to_radians(), point.lon_deg.to_radians());
        let cos_d_lon = (lon - lon0).cos();
        let cos_c = (lat0.sin() * lat.sin() + lat0.cos() * lat.cos() * cos_d_lon).clamp(-1.0, 1.0);
        let c = cos_c.acos();
        let k = if c.abs() < f64::EPSILON {
            1.0
        } else {
            c / c.sin()
        };
        let north =
            k * (lat0.cos() * lat.sin() - lat0.sin() * lat.cos() * cos_d_lon) * EARTH_RADIUS_M;
        let east = k * lat.cos() * (lon - lon0).sin() * EARTH_RADIUS_M;
        Vector3::new(north, east, self.reference.alt_amsl_m - point.alt_amsl_m)
    }

    /// The point at a NED offset (m) from the reference: the inverse of
    /// [`MapProjection::project`].
    pub fn reproject(&self, offset_ned_m: &Vector3<f64>) -> Geodetic {
        let (lat0, lon0) = (
            self.reference.lat_deg.to_radians(),
            self.reference.lon_deg.to_radians(),
        );
        let x = offset_ned_m.x / EARTH_RADIUS_M;
        let y = offset_ned_m.y / EARTH_RADIUS_M;
        let c = x.hypot(y);
        let (lat, lon) = if c.abs() < f64::EPSILON {
            (lat0, lon0)
        } else {
            let (sin_c, cos_c) = c.sin_cos();
            let lat = (cos_c * lat0.sin() + x * sin_c * lat0.cos() / c)
                .clamp(-1.0, 1.0)
                .asin();
            let lon = lon0 + (y * sin_c).atan2(c * lat0.cos() * cos_c - x * lat0.sin() * sin_c);
            (lat, lon)
        };
        Geodetic {
            lat_deg: lat.to_degrees(),
            lon_deg: lon.to_degrees(),
            alt_amsl_m: self.reference.alt_amsl_m - offset_ned_m.z,
        }
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
    fn north_is_r_times_the_angle_and_round_trips_are_exact() {
        let p = MapProjection::new(zurich());
        let mut north = zurich();
        north.lat_deg += 1.0 / 3600.0;
        let d = p.project(&north);
        let expected = EARTH_RADIUS_M * (1.0f64 / 3600.0).to_radians();
        assert!((d.x - expected).abs() < 1e-6 && d.y.abs() < 1e-6 && d.z == 0.0);
        for offset in [
            Vector3::new(100.0, 50.0, -20.0),
            Vector3::new(-3000.0, 4000.0, 5.0),
            Vector3::new(0.0, 0.0, 0.0),
        ] {
            let back = p.project(&p.reproject(&offset));
            assert!((back - offset).norm() < 1e-6, "{offset:?} → {back:?}");
        }
    }

    #[test]
    fn east_shrinks_with_the_cosine_of_latitude() {
        let p = MapProjection::new(zurich());
        let g = p.reproject(&Vector3::new(0.0, 1000.0, 0.0));
        let expected = (1000.0 / (EARTH_RADIUS_M * 47.397742f64.to_radians().cos())).to_degrees();
        assert!((g.lon_deg - zurich().lon_deg - expected).abs() < 1e-9);
        // The azimuthal projection bends a little towards the pole: 1 km east at 47° is
        // 0.085 m south of the reference's parallel in latitude terms.
        assert!(g.lat_deg > zurich().lat_deg - 1e-6);
    }

    #[test]
    fn mavlink_integer_fields_convert_with_their_units() {
        let g = Geodetic::from_mavlink(473_977_420, 85_455_940, 488_000);
        assert!((g.lat_deg - 47.397742).abs() < 1e-12 && (g.alt_amsl_m - 488.0).abs() < 1e-12);
        assert_eq!(
            (g.lat_e7(), g.lon_e7(), g.alt_mm()),
            (473_977_420, 85_455_940, 488_000)
        );
    }
}
