//! `[formation]` and `[target]`: the offsets `dᵢ` each vehicle keeps from the formation's
//! centre, and the target velocity the planner flies for.

use std::f64::consts::PI;
use std::time::Duration;

use nalgebra::Vector2;

use super::Config;
use super::problems::Problems;
use super::validate::{MAX_DISTANCE_M, MAX_GAIN, MAX_SPEED_MPS};
use crate::swarm::TargetVelocity;

impl Config {
    /// `[target]`, if any.
    pub(super) fn target(&self, p: &mut Problems) -> Option<TargetVelocity> {
        let t = self.target.as_ref()?;
        let mut ok = p.vector(
            "target.velocity_enu_mps",
            &t.velocity_enu_mps,
            MAX_SPEED_MPS,
            " m/s",
        );
        ok &= p.within("target.k_margin", t.k_margin, 0.0, MAX_GAIN, "");
        ok &= p.positive("target.k_max", t.k_max, MAX_GAIN, "");
        ok &= p.positive("target.tolerance_mps", t.tolerance_mps, 10.0, " m/s");
        ok &= p.positive("target.timeout_s", t.timeout_s, 3600.0, " s");
        if let Some(max) = t.max_speed_mps {
            ok &= p.positive("target.max_speed_mps", max, MAX_SPEED_MPS, " m/s");
        }
        ok.then(|| TargetVelocity {
            velocity_mps: Vector2::from(t.velocity_enu_mps),
            k_margin: t.k_margin,
            k_max: t.k_max,
            max_speed_mps: t.max_speed_mps,
            tolerance_mps: t.tolerance_mps,
            timeout: Duration::from_secs_f64(t.timeout_s),
            wait_for_altitude: t.wait_for_altitude,
        })
    }

    /// Whether the formation's places are assigned (`[formation] assign`).
    pub(super) fn assign_places(&self, p: &mut Problems) -> bool {
        let f = &self.formation;
        match f.assign.as_deref() {
            None => f.kind != "line",
            Some("optimal") => true,
            Some("fixed") => false,
            Some(other) => {
                p.push(format!(
                    "formation.assign \"{other}\" is not one of optimal, fixed"
                ));
                false
            }
        }
    }

    /// The formation offsets `dᵢ` (ENU, m).
    pub(super) fn offsets(&self, n: usize, p: &mut Problems) -> Option<Vec<Vector2<f64>>> {
        let f = &self.formation;
        match f.kind.as_str() {
            "polygon" => {
                let Some(r) = f.radius_m else {
                    p.push("formation.radius_m is required for kind = \"polygon\"".to_owned());
                    return None;
                };
                p.positive("formation.radius_m", r, MAX_DISTANCE_M, " m")
                    .then(|| {
                        (0..n)
                            .map(|l| {
                                let angle = 2.0 * PI * l as f64 / n as f64;
                                Vector2::new(angle.cos(), angle.sin()) * r
                            })
                            .collect()
                    })
            }
            "line" => {
                let Some(d) = f.spacing_m else {
                    p.push("formation.spacing_m is required for kind = \"line\"".to_owned());
                    return None;
                };
                p.positive(
                    "formation.spacing_m",
                    d,
                    MAX_DISTANCE_M / n.max(1) as f64,
                    " m",
                )
                .then(|| (0..n).map(|i| Vector2::new(d * i as f64, 0.0)).collect())
            }
            "offsets" => {
                let Some(list) = f.offsets_m.as_ref() else {
                    p.push("formation.offsets_m is required for kind = \"offsets\"".to_owned());
                    return None;
                };
                if list.len() != n {
                    p.push(format!(
                        "formation.offsets_m has {} entries for {n} vehicles",
                        list.len()
                    ));
                    return None;
                }
                let mut ok = true;
                for (j, o) in list.iter().enumerate() {
                    ok &= p.vector(
                        &format!("formation.offsets_m[{j}]"),
                        o,
                        MAX_DISTANCE_M,
                        " m",
                    );
                }
                ok.then(|| list.iter().map(|o| Vector2::new(o[0], o[1])).collect())
            }
            other => {
                p.push(format!(
                    "formation.kind \"{other}\" is not one of polygon, line, offsets"
                ));
                None
            }
        }
    }
}
