//! The fence: an inclusion circle or polygon in the common frame (ENU, metres) with a
//! lowest and a highest altitude, and where a vehicle would stop if it braked now.
//!
//! A swarm that flies at a constant final velocity leaves any fence eventually, so the
//! coordinator acts for the whole swarm (hold or land) as soon as one vehicle's stopping
//! point comes within the margin of the fence (docs/math.md, "The fence").
//!
//! Pure: no allocation after construction.

use nalgebra::{Vector2, Vector3};

use super::barrier::{PairRow, Side, barrier_row};

/// The horizontal shape of the fence.
#[derive(Debug, Clone, PartialEq)]
pub enum FenceShape {
    /// Inside a circle.
    Circle {
        /// Centre (m, ENU).
        centre_m: Vector2<f64>,
        /// Radius (m).
        radius_m: f64,
    },
    /// Inside a simple polygon (vertices in order, either sense, at least three).
    Polygon {
        /// Vertices (m, ENU).
        vertices_m: Vec<Vector2<f64>>,
    },
}

/// An inclusion fence.
#[derive(Debug, Clone, PartialEq)]
pub struct Fence {
    /// The horizontal shape.
    pub shape: FenceShape,
    /// Lowest altitude in flight (m, up, common frame).
    pub min_altitude_m: f64,
    /// Highest altitude (m, up, common frame).
    pub max_altitude_m: f64,
}

impl Fence {
    /// How far inside the horizontal shape `p` is (m): positive inside, negative outside.
    pub fn horizontal_margin_m(&self, p: Vector2<f64>) -> f64 {
        match &self.shape {
            FenceShape::Circle { centre_m, radius_m } => radius_m - (p - centre_m).norm(),
            FenceShape::Polygon { vertices_m } => {
                let n = vertices_m.len();
                let mut nearest = f64::INFINITY;
                let mut inside = false;
                for k in 0..n {
                    let (a, b) = (vertices_m[k], vertices_m[(k + 1) % n]);
                    nearest = nearest.min(segment_distance_m(p, a, b));
                    // Crossing number along +x.
                    if (a.y > p.y) != (b.y > p.y) {
                        let x = a.x + (p.y - a.y) * (b.x - a.x) / (b.y - a.y);
                        if p.x < x {
                            inside = !inside;
                        }
                    }
                }
                if inside { nearest } else { -nearest }
            }
        }
    }

    /// The nearest point of the horizontal boundary seen from `p`: the signed margin (m,
    /// positive inside), the unit normal pointing inward there, and, for a circle, the
    /// distance from its centre (the radius of the margin's level curve through `p`).
    /// `None` at the circle's centre, or on the boundary itself (no direction).
    pub fn nearest(&self, p: Vector2<f64>) -> Option<(f64, Vector2<f64>, Option<f64>)> {
        match &self.shape {
            FenceShape::Circle { centre_m, radius_m } => {
                let r = (p - centre_m).norm();
                (r > 1e-9).then(|| (radius_m - r, (centre_m - p) / r, Some(r)))
            }
            FenceShape::Polygon { vertices_m } => {
                let n = vertices_m.len();
                let mut best: Option<(f64, Vector2<f64>)> = None;
                for k in 0..n {
                    let q = segment_nearest(p, vertices_m[k], vertices_m[(k + 1) % n]);
                    let d = (p - q).norm();
                    if best.is_none_or(|b| d < b.0) {
                        best = Some((d, q));
                    }
                }
                let (d, q) = best?;
                if d < 1e-12 {
                    return None;
                }
                let margin = self.horizontal_margin_m(p);
                let inward = if margin > 0.0 {
                    (p - q) / d
                } else {
                    (q - p) / d
                };
                Some((margin, inward, None))
            }
        }
    }

    /// How far inside the altitude band `z_m` is (m).
    pub fn vertical_margin_m(&self, z_m: f64) -> f64 {
        (z_m - self.min_altitude_m).min(self.max_altitude_m - z_m)
    }

    /// How far inside the fence `p` is (m): the smaller of the two margins.
    pub fn margin_m(&self, p: Vector3<f64>) -> f64 {
        self.horizontal_margin_m(p.xy())
            .min(self.vertical_margin_m(p.z))
    }
}

/// Where a vehicle at `pos_m` moving at `vel_mps` stops if it goes on for `age_s` and
/// then brakes at `braking_mps2` (> 0) horizontally and `vertical_braking_mps2` (> 0)
/// vertically: `p + v·τ + v|v|/2a` per part.
pub fn stop_point_m(
    pos_m: Vector3<f64>,
    vel_mps: Vector3<f64>,
    age_s: f64,
    braking_mps2: f64,
    vertical_braking_mps2: f64,
) -> Vector3<f64> {
    let h = vel_mps.xy();
    let h_stop = h * (age_s + h.norm() / (2.0 * braking_mps2));
    let z_stop = vel_mps.z * (age_s + vel_mps.z.abs() / (2.0 * vertical_braking_mps2));
    pos_m + Vector3::new(h_stop.x, h_stop.y, z_stop)
}

/// The distance from `p` to the segment `ab` (m).
pub(crate) fn segment_distance_m(p: Vector2<f64>, a: Vector2<f64>, b: Vector2<f64>) -> f64 {
    (p - segment_nearest(p, a, b)).norm()
}

/// The point of the segment `ab` nearest to `p`.
fn segment_nearest(p: Vector2<f64>, a: Vector2<f64>, b: Vector2<f64>) -> Vector2<f64> {
    let ab = b - a;
    let len2 = ab.norm_squared();
    let t = if len2 > 0.0 {
        ((p - a).dot(&ab) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    a + ab * t
}

/// The barrier row of one vehicle against the fence's horizontal boundary, `aᵀuᵢ ≥ b`:
/// the pair barrier with the margin `m − margin_m` in place of `D − d`, `s = nᵀv` the
/// rate at which the margin grows (`n` the inward normal) and the vehicle's own braking
/// `A`. For a circle the margin's second derivative loses `(|v|² − s²)/r` to tangential
/// motion (`r` the distance from the centre), which the bound adds. Inside the age-grown
/// margin a vehicle moving outward must turn in at `A`.
pub fn fence_row(
    fence: &Fence,
    margin_m: f64,
    side: &Side,
    braking_mps2: f64,
    age_s: f64,
    gamma: f64,
) -> Option<PairRow> {
    let p = side.pos_m.xy();
    let v = side.vel_mps.xy();
    let (m, inward, radius) = fence.nearest(p)?;
    let s = inward.dot(&v);
    let d = margin_m + v.norm() * age_s + 0.5 * braking_mps2 * age_s * age_s;
    let room = m - d;
    let curvature = radius.map_or(0.0, |r| (v.norm_squared() - s * s).max(0.0) / r);
    Some(barrier_row(
        inward,
        (s, m, room),
        braking_mps2,
        gamma,
        -curvature,
    ))
}

/// Whether the polygon's edges cross each other anywhere but at shared vertices of
/// neighbouring edges (a fence must be a simple polygon). O(n²): fences are small.
pub fn polygon_self_intersects(vertices_m: &[Vector2<f64>]) -> bool {
    let n = vertices_m.len();
    let cross = |o: Vector2<f64>, a: Vector2<f64>, b: Vector2<f64>| (a - o).perp(&(b - o));
    for i in 0..n {
        let (a, b) = (vertices_m[i], vertices_m[(i + 1) % n]);
        for j in i + 1..n {
            if j == i + 1 || (i == 0 && j == n - 1) {
                continue;
            }
            let (c, d) = (vertices_m[j], vertices_m[(j + 1) % n]);
            let (d1, d2) = (cross(a, b, c), cross(a, b, d));
            let (d3, d4) = (cross(c, d, a), cross(c, d, b));
            if d1 * d2 <= 0.0 && d3 * d4 <= 0.0 {
                return true;
            }
        }
    }
    false
}

/// What one fence item says.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FenceItemKind {
    /// One vertex of an inclusion polygon of `vertex_count` vertices.
    PolygonVertex {
        /// Vertices of its polygon.
        vertex_count: u16,
    },
    /// The centre of an inclusion circle.
    Circle {
        /// Radius (m).
        radius_m: f64,
    },
}

/// One fence item: a point and what it is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FenceItem {
    /// Vertex or circle.
    pub kind: FenceItemKind,
    /// Latitude (deg).
    pub lat_deg: f64,
    /// Longitude (deg).
    pub lon_deg: f64,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square() -> Fence {
        Fence {
            shape: FenceShape::Polygon {
                vertices_m: vec![
                    Vector2::new(0.0, 0.0),
                    Vector2::new(100.0, 0.0),
                    Vector2::new(100.0, 100.0),
                    Vector2::new(0.0, 100.0),
                ],
            },
            min_altitude_m: 5.0,
            max_altitude_m: 60.0,
        }
    }

    #[test]
    fn margins_inside_and_outside_a_polygon_and_a_circle() {
        let f = square();
        assert_eq!(f.horizontal_margin_m(Vector2::new(30.0, 20.0)), 20.0);
        assert_eq!(f.horizontal_margin_m(Vector2::new(-3.0, 50.0)), -3.0);
        // Outside past a corner: the distance to the corner.
        assert!((f.horizontal_margin_m(Vector2::new(103.0, 104.0)) + 5.0).abs() < 1e-12);
        assert_eq!(f.vertical_margin_m(50.0), 10.0);
        assert_eq!(f.vertical_margin_m(2.0), -3.0);
        assert_eq!(f.margin_m(Vector3::new(30.0, 20.0, 58.0)), 2.0);
        let c = Fence {
            shape: FenceShape::Circle {
                centre_m: Vector2::new(10.0, 0.0),
                radius_m: 50.0,
            },
            ..square()
        };
        assert_eq!(c.horizontal_margin_m(Vector2::new(10.0, 30.0)), 20.0);
        assert_eq!(c.horizontal_margin_m(Vector2::new(70.0, 0.0)), -10.0);
    }

    #[test]
    fn a_vehicle_stops_where_braking_brings_it() {
        // 10 m/s east, 0.3 s late, braking at 5 m/s²: 3 m + 10 m; 2 m/s up at 4 m/s²:
        // 0.6 m + 0.5 m.
        let p = stop_point_m(
            Vector3::new(1.0, 2.0, 20.0),
            Vector3::new(10.0, 0.0, 2.0),
            0.3,
            5.0,
            4.0,
        );
        assert!((p - Vector3::new(14.0, 2.0, 21.1)).norm() < 1e-12, "{p}");
    }

    #[test]
    fn the_fence_rows_derivative_is_the_barriers_along_a_trajectory() {
        // A vehicle inside a circle of radius 100 m moving out and sideways with a given
        // acceleration: ḣ by central differences equals aᵀu − b − γh³.
        let fence = Fence {
            shape: FenceShape::Circle {
                centre_m: Vector2::new(0.0, 0.0),
                radius_m: 100.0,
            },
            min_altitude_m: 0.0,
            max_altitude_m: 100.0,
        };
        let (margin, a_brake, gamma) = (5.0, 3.0, 1.0);
        let u = Vector2::new(0.4, -0.7);
        let at = |t: f64| Side {
            pos_m: Vector3::new(
                60.0 + 4.0 * t + 0.2 * t * t,
                20.0 + 3.0 * t - 0.35 * t * t,
                50.0,
            ),
            vel_mps: Vector3::new(4.0 + 0.4 * t, 3.0 - 0.7 * t, 0.0),
            accel_z_mps2: 0.0,
        };
        let h = |side: &Side| {
            let p = side.pos_m.xy();
            let r = p.norm();
            let s = -(p / r).dot(&side.vel_mps.xy());
            s + (2.0 * a_brake * (100.0 - r - margin)).sqrt()
        };
        let dt = 1e-5;
        let hdot = (h(&at(dt)) - h(&at(-dt))) / (2.0 * dt);
        let row = fence_row(&fence, margin, &at(0.0), a_brake, 0.0, gamma).expect("a row");
        assert!((row.h_mps - h(&at(0.0))).abs() < 1e-12);
        let from_row = row.a.dot(&u) - row.b - gamma * row.h_mps.powi(3);
        assert!((hdot - from_row).abs() < 1e-6, "{hdot} vs {from_row}");
    }

    #[test]
    fn the_nearest_boundary_point_of_a_polygon_gives_the_inward_normal() {
        let f = square();
        let (m, n, r) = f.nearest(Vector2::new(30.0, 20.0)).expect("inside");
        assert_eq!((m, n, r), (20.0, Vector2::new(0.0, 1.0), None));
        let (m, n, _) = f.nearest(Vector2::new(-3.0, 50.0)).expect("outside");
        assert_eq!((m, n), (-3.0, Vector2::new(1.0, 0.0)));
    }

    #[test]
    fn a_bow_tie_is_not_a_fence() {
        let bow = [
            Vector2::new(0.0, 0.0),
            Vector2::new(10.0, 10.0),
            Vector2::new(10.0, 0.0),
            Vector2::new(0.0, 10.0),
        ];
        assert!(polygon_self_intersects(&bow));
        let FenceShape::Polygon { vertices_m } = square().shape else {
            unreachable!()
        };
        assert!(!polygon_self_intersects(&vertices_m));
    }
}
