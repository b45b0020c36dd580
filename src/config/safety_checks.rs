//! `[safety]`, `[fence]` and `[guard]` checked: each problem named by its key, every one
//! reported.

use super::Config;
use super::problems::Problems;
use super::validate::MAX_DISTANCE_M;
use crate::safety::layers::LAYER_CLEAR_SHARE;
use crate::swarm::{GuardLimits, MAX_SPEED_MPS};

impl Config {
    /// `[safety]`: every key checked by name, and no two formation places closer than the
    /// horizontal separation; `None` when the filter is off.
    pub(super) fn safety(
        &self,
        offsets: Option<&[nalgebra::Vector2<f64>]>,
        p: &mut Problems,
    ) -> Option<crate::swarm::SafetySetup> {
        let s = &self.safety;
        let mut ok = p.within("safety.horizontal_m", s.horizontal_m, 0.5, 100.0, " m");
        ok &= p.within(
            "safety.vertical_m",
            s.vertical_m,
            s.horizontal_m.max(0.5),
            300.0,
            " m (at least safety.horizontal_m)",
        );
        ok &= p.positive("safety.braking_share", s.braking_share, 1.0, "");
        ok &= p.positive("safety.jam_hold_s", s.jam_hold_s, 600.0, " s");
        ok &= p.positive("safety.jam_turn_mps2", s.jam_turn_mps2, 20.0, " m/s²");
        ok &= p.positive("safety.jam_layer_s", s.jam_layer_s, 3600.0, " s");
        let layer_m = s.jam_layer_m.unwrap_or(s.vertical_m + s.horizontal_m);
        ok &= p.within(
            "safety.jam_layer_m",
            layer_m,
            s.vertical_m,
            300.0,
            " m (at least safety.vertical_m)",
        );
        ok &= p.positive(
            "safety.budget_share",
            s.budget_share,
            0.9,
            " of the control period",
        );
        if !(ok && s.enabled) {
            return None;
        }
        if let Some(offsets) = offsets {
            for i in 0..offsets.len() {
                for j in i + 1..offsets.len() {
                    let d = (offsets[i] - offsets[j]).norm();
                    if d < s.horizontal_m {
                        p.push(format!(
                            "formation.offsets_m[{i}] and formation.offsets_m[{j}] are {d:.3} m apart, closer than safety.horizontal_m = {} m: no formation can hold them",
                            s.horizontal_m
                        ));
                    }
                }
            }
        }
        let layer = if s.resolve_jams && s.jam_break == super::JamBreak::Layer {
            Some(self.jam_layer(layer_m, p)?)
        } else {
            None
        };
        Some(crate::swarm::SafetySetup {
            separation: crate::safety::Separation {
                horizontal_m: s.horizontal_m,
                vertical_m: s.vertical_m,
                gamma: crate::swarm::SAFETY_GAMMA,
            },
            braking_share: s.braking_share,
            action: s.action,
            jams: s.resolve_jams.then(|| crate::safety::jam::JamSettings {
                hold_s: s.jam_hold_s,
                bias_mps2: s.jam_turn_mps2,
                layer,
                ..crate::safety::jam::JamSettings::default()
            }),
            budget_share: s.budget_share,
            wall_clock_budget: false,
        })
    }

    /// The jam layer `layer_m` from the formation's altitude: above it, or below it when
    /// the fence's band has no room above (by the fence's margin), or a problem when it
    /// has room on neither side.
    fn jam_layer(
        &self,
        layer_m: f64,
        p: &mut Problems,
    ) -> Option<crate::safety::layers::LayerRule> {
        let altitude = self.formation.altitude_m;
        let above = match &self.fence {
            None => true,
            Some(f) if altitude + layer_m <= f.max_altitude_m - f.margin_m => true,
            Some(f) if altitude - layer_m >= f.min_altitude_m + f.margin_m => false,
            Some(f) => {
                p.push(format!(
                    "safety.jam_break = \"layer\": a jam layer {layer_m} m above or below formation.altitude_m = {altitude} m leaves the fence's altitudes [{}, {}] m (margin {} m): lower safety.jam_layer_m (at least safety.vertical_m = {} m), widen the band, set safety.jam_break = \"turn\", or stop breaking jams with safety.resolve_jams = false",
                    f.min_altitude_m, f.max_altitude_m, f.margin_m, self.safety.vertical_m
                ));
                return None;
            }
        };
        Some(crate::safety::layers::LayerRule {
            height_m: layer_m,
            above,
            clear_m: LAYER_CLEAR_SHARE * self.safety.horizontal_m,
            dwell_s: self.safety.jam_layer_s,
        })
    }

    /// `[fence]`: the shape, the band and the margin checked by name; the formation's
    /// altitude inside the band and every vehicle's start inside the shape.
    pub(super) fn fence(&self, p: &mut Problems) -> Option<crate::swarm::FenceSetup> {
        use crate::config::FenceKind;
        use crate::safety::{Fence, FenceShape, fence::polygon_self_intersects};
        use nalgebra::{Vector2, Vector3};
        let f = self.fence.as_ref()?;
        let mut ok = p.within(
            "fence.min_altitude_m",
            f.min_altitude_m,
            -MAX_DISTANCE_M,
            MAX_DISTANCE_M,
            " m",
        );
        ok &= p.within(
            "fence.max_altitude_m",
            f.max_altitude_m,
            f.min_altitude_m.max(-MAX_DISTANCE_M),
            MAX_DISTANCE_M,
            " m (above fence.min_altitude_m)",
        );
        ok &= p.within("fence.margin_m", f.margin_m, 0.0, 1000.0, " m");
        let shape = match f.kind {
            FenceKind::Circle => {
                let (Some(c), Some(r)) = (f.centre_enu_m, f.radius_m) else {
                    p.push(
                        "fence.centre_enu_m and fence.radius_m are required for kind = \"circle\""
                            .to_owned(),
                    );
                    return None;
                };
                ok &= p.vector("fence.centre_enu_m", &c, MAX_DISTANCE_M, " m");
                ok &= p.positive("fence.radius_m", r, MAX_DISTANCE_M, " m");
                FenceShape::Circle {
                    centre_m: Vector2::from(c),
                    radius_m: r,
                }
            }
            FenceKind::Polygon => {
                let Some(list) = f.vertices_enu_m.as_ref() else {
                    p.push("fence.vertices_enu_m is required for kind = \"polygon\"".to_owned());
                    return None;
                };
                if list.len() < 3 {
                    p.push(format!(
                        "fence.vertices_enu_m needs at least 3 vertices, got {}",
                        list.len()
                    ));
                    return None;
                }
                for (k, v) in list.iter().enumerate() {
                    ok &= p.vector(
                        &format!("fence.vertices_enu_m[{k}]"),
                        v,
                        MAX_DISTANCE_M,
                        " m",
                    );
                }
                let vertices_m: Vec<Vector2<f64>> =
                    list.iter().map(|v| Vector2::from(*v)).collect();
                if ok && polygon_self_intersects(&vertices_m) {
                    p.push("fence.vertices_enu_m: the polygon's edges cross each other (a fence must be a simple polygon)".to_owned());
                    ok = false;
                }
                FenceShape::Polygon { vertices_m }
            }
        };
        if !ok {
            return None;
        }
        let fence = Fence {
            shape,
            min_altitude_m: f.min_altitude_m,
            max_altitude_m: f.max_altitude_m,
        };
        let altitude = self.formation.altitude_m;
        if fence.vertical_margin_m(altitude) < f.margin_m {
            p.push(format!(
                "formation.altitude_m = {altitude} m is not inside the fence's altitudes [{}, {}] m by its margin of {} m",
                f.min_altitude_m, f.max_altitude_m, f.margin_m
            ));
        }
        for (k, v) in self.vehicle.iter().enumerate() {
            let start = Vector3::from(v.start_enu_m);
            if fence.horizontal_margin_m(start.xy()) < 0.0 {
                p.push(format!(
                    "vehicle[{k}] (system id {}) starts at ({}, {}) m, outside the fence",
                    v.system_id, start.x, start.y
                ));
            }
        }
        Some(crate::swarm::FenceSetup {
            fence,
            margin_m: f.margin_m,
            action: f.action,
        })
    }

    /// `[guard]`: every bound checked by name; `None` when the guard is off.
    pub(super) fn guard(&self, p: &mut Problems) -> Option<GuardLimits> {
        let g = &self.guard;
        let ok = p.positive(
            "guard.velocity_error_mps",
            g.velocity_error_mps,
            MAX_SPEED_MPS,
            " m/s",
        ) & p.positive("guard.velocity_error_s", g.velocity_error_s, 3600.0, " s")
            & p.positive(
                "guard.velocity_error_fraction",
                g.velocity_error_fraction,
                10.0,
                "",
            )
            & p.positive(
                "guard.formation_growth_fraction",
                g.formation_growth_fraction,
                100.0,
                "",
            )
            & p.positive(
                "guard.formation_growth_m",
                g.formation_growth_m,
                MAX_DISTANCE_M,
                " m",
            )
            & p.positive(
                "guard.formation_growth_s",
                g.formation_growth_s,
                3600.0,
                " s",
            );
        if !(ok && g.enabled) {
            return None;
        }
        GuardLimits::new(
            (
                g.velocity_error_mps,
                g.velocity_error_fraction,
                g.velocity_error_s,
            ),
            (
                g.formation_growth_m,
                g.formation_growth_fraction,
                g.formation_growth_s,
            ),
        )
        .map_err(|e| p.push(format!("guard: {e}")))
        .ok()
    }
}
