//! The actuator envelope and the two ways of saturating the swarm's commands.
//!
//! Each vehicle's vertical command comes first (altitude has priority, as in PX4): the
//! specific thrust's vertical part `u_z + g` is clamped to the thrust limits, the upper
//! one lowered to `√(max² − margin²)` so that a horizontal margin of thrust always remains
//! (PX4's `MPC_THR_XY_MARG`; without it a vehicle climbing at full thrust has no authority
//! left to hold its velocity against drag, and `w·v` drifts). What is left bounds the
//! horizontal command: its magnitude may not exceed
//! `a_h = min((u_z + g)·tan θ_max, √(f_max² − (u_z + g)²))`, which keeps both the tilt and
//! the total thrust inside the envelope.
//!
//! - [`SaturationMode::Clip`]: every vehicle scales its own horizontal command into its
//!   disc. Simple, but it changes `Σ wᵢ uᵢ`, so the swarm drifts to another final velocity.
//! - [`SaturationMode::Conserve`] (default): per horizontal axis,
//!   `ũᵢ = clip(uᵢ − λ·wᵢ, −bᵢ, bᵢ)` with one `λ` for the whole swarm chosen by bisection
//!   so that `Σ wᵢ ũᵢ = Σ wᵢ uᵢ`, which is zero for the consensus law (`w·L = 0`). The sum is continuous and non-increasing in `λ` and changes
//!   sign over `[−λ_max, λ_max]`, so the root exists; `w·v` is then conserved exactly and
//!   the predicted final velocity still holds under limits. The per-axis box `bᵢ` is the
//!   largest box inside the vehicle's disc aligned with its nominal command
//!   (`bᵢ = a_h·|uᵢ,axis|/|uᵢ|`), so an unsaturated command is left untouched and a
//!   saturated one keeps its full authority along its own direction.
//!
//! Pure, synchronous and allocation-free.

use nalgebra::{Vector2, Vector3};
use serde::{Deserialize, Serialize};

use super::vehicle::{GRAVITY_MPS2, VehicleModel, check_finite};
use crate::error::ControlError;

/// How the swarm's horizontal commands are brought inside the envelope.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SaturationMode {
    /// Keep `Σ wᵢ uᵢ = 0` (and with it the consensus value).
    #[default]
    Conserve,
    /// Scale each vehicle's command on its own.
    Clip,
}

impl SaturationMode {
    /// The name used in configuration files (`conserve`, `clip`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Conserve => "conserve",
            Self::Clip => "clip",
        }
    }
}

/// Tilt and thrust limits shared by the swarm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Envelope {
    max_tilt_rad: f64,
    /// `tan(max_tilt_rad)`, computed once.
    tan_max_tilt: f64,
    min_thrust_norm: f64,
    max_thrust_norm: f64,
    xy_margin_norm: f64,
}

impl Envelope {
    /// Validates `0 < max_tilt_rad < π/2` and `0 ≤ min_thrust_norm < max_thrust_norm ≤ 1`.
    ///
    /// # Errors
    /// [`ControlError`] naming the limit that is out of range or not finite.
    pub fn new(
        max_tilt_rad: f64,
        min_thrust_norm: f64,
        max_thrust_norm: f64,
    ) -> Result<Self, ControlError> {
        check_finite("max_tilt_rad", max_tilt_rad)?;
        check_finite("min_thrust_norm", min_thrust_norm)?;
        check_finite("max_thrust_norm", max_thrust_norm)?;
        if !(max_tilt_rad > 0.0 && max_tilt_rad < std::f64::consts::FRAC_PI_2) {
            return Err(ControlError::OutOfRange {
                name: "max_tilt_rad",
                value: max_tilt_rad,
                expected: "strictly between 0 and π/2",
            });
        }
        if !(0.0..1.0).contains(&min_thrust_norm) {
            return Err(ControlError::OutOfRange {
                name: "min_thrust_norm",
                value: min_thrust_norm,
                expected: "in [0, 1)",
            });
        }
        if !(max_thrust_norm > min_thrust_norm && max_thrust_norm <= 1.0) {
            return Err(ControlError::OutOfRange {
                name: "max_thrust_norm",
                value: max_thrust_norm,
                expected: "above min_thrust_norm and at most 1",
            });
        }
        Ok(Self {
            max_tilt_rad,
            tan_max_tilt: max_tilt_rad.tan(),
            min_thrust_norm,
            max_thrust_norm,
            xy_margin_norm: 0.0,
        })
    }

    /// The same envelope keeping `margin` (normalised thrust, `0 ≤ margin < max`) for
    /// horizontal control when the vertical command saturates.
    ///
    /// # Errors
    /// [`ControlError::OutOfRange`] for a margin outside `[0, max_thrust)`.
    pub fn with_xy_margin(self, margin: f64) -> Result<Self, ControlError> {
        check_finite("xy_margin", margin)?;
        if !(0.0..self.max_thrust_norm).contains(&margin) {
            return Err(ControlError::OutOfRange {
                name: "xy_margin",
                value: margin,
                expected: "in [0, max_thrust)",
            });
        }
        Ok(Self {
            xy_margin_norm: margin,
            ..self
        })
    }

    /// The highest normalised thrust the vertical command may take.
    fn vertical_max_norm(&self) -> f64 {
        (self.max_thrust_norm.powi(2) - self.xy_margin_norm.powi(2))
            .sqrt()
            .max(self.min_thrust_norm)
    }

    /// The largest tilt (rad).
    pub fn max_tilt_rad(&self) -> f64 {
        self.max_tilt_rad
    }

    /// The lower thrust limit (normalised).
    pub fn min_thrust_norm(&self) -> f64 {
        self.min_thrust_norm
    }

    /// The upper thrust limit (normalised).
    pub fn max_thrust_norm(&self) -> f64 {
        self.max_thrust_norm
    }

    /// Checks that a vehicle can hover inside the envelope.
    ///
    /// # Errors
    /// [`ControlError::OutOfRange`] when the thrust limits exclude the hover throttle.
    pub fn check_hover(&self, model: &VehicleModel) -> Result<(), ControlError> {
        let hover = model.hover_throttle();
        if hover >= self.max_thrust_norm || hover <= self.min_thrust_norm {
            return Err(ControlError::OutOfRange {
                name: "hover_throttle",
                value: hover,
                expected: "strictly between the envelope's min and max thrust",
            });
        }
        Ok(())
    }

    /// The vertical command (m/s², z up) clamped to the thrust limits.
    /// A command already inside the limits is returned bit for bit.
    pub fn limit_vertical(&self, u_z_mps2: f64, model: &VehicleModel) -> f64 {
        let f_max = model.max_specific_thrust_mps2();
        let (lo, hi) = (
            self.min_thrust_norm * f_max,
            self.vertical_max_norm() * f_max,
        );
        let f_z = u_z_mps2 + GRAVITY_MPS2;
        if f_z < lo {
            lo - GRAVITY_MPS2
        } else if f_z > hi {
            hi - GRAVITY_MPS2
        } else {
            u_z_mps2
        }
    }

    /// The largest horizontal acceleration (m/s²) once the vertical command is `u_z_mps2`
    /// (already limited).
    pub fn horizontal_limit_mps2(&self, u_z_mps2: f64, model: &VehicleModel) -> f64 {
        let f_z = u_z_mps2 + GRAVITY_MPS2;
        let f_max = self.max_thrust_norm * model.max_specific_thrust_mps2();
        let by_thrust = (f_max * f_max - f_z * f_z).max(0.0).sqrt();
        (f_z * self.tan_max_tilt).max(0.0).min(by_thrust)
    }
}

/// What a saturation pass did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SaturationSummary {
    /// How many vehicles had their vertical command clamped to the thrust limits.
    pub vertical_limited: usize,
    /// How many vehicles had their horizontal command changed.
    pub horizontal_limited: usize,
    /// The shift `λ` per horizontal axis (zero in `clip` mode or when nothing saturated).
    pub lambda: Vector2<f64>,
}

/// Brings every vehicle's acceleration command (m/s², paper frame, z up) inside the
/// envelope, in place. `w` is the ring's left null vector.
///
/// # Errors
/// [`ControlError::WrongLength`] when `models`, `w` and `accel_enu_mps2` differ in length;
/// [`ControlError::NonFinite`] when a command or a weight is not finite (nothing is
/// changed then: one bad number must not spread to the whole swarm through `λ`).
pub fn saturate(
    mode: SaturationMode,
    envelope: &Envelope,
    models: &[VehicleModel],
    w: &[f64],
    accel_enu_mps2: &mut [Vector3<f64>],
) -> Result<SaturationSummary, ControlError> {
    saturate_with(mode, envelope, models, w, accel_enu_mps2, &mut Vec::new())
}

/// [`saturate`] with a buffer for each vehicle's horizontal box, kept between calls so
/// that a control tick allocates nothing.
///
/// # Errors
/// As [`saturate`].
pub fn saturate_with(
    mode: SaturationMode,
    envelope: &Envelope,
    models: &[VehicleModel],
    w: &[f64],
    accel_enu_mps2: &mut [Vector3<f64>],
    boxes: &mut Vec<Vector2<f64>>,
) -> Result<SaturationSummary, ControlError> {
    let n = accel_enu_mps2.len();
    for (what, got) in [("vehicle models", models.len()), ("weights w", w.len())] {
        if got != n {
            return Err(ControlError::WrongLength {
                what,
                expected: n,
                got,
            });
        }
    }
    for u in accel_enu_mps2.iter() {
        if let Some(&bad) = u.iter().find(|x| !x.is_finite()) {
            return Err(ControlError::NonFinite {
                name: "acceleration command",
                value: bad,
            });
        }
    }
    if let Some(&bad) = w.iter().find(|x| !x.is_finite()) {
        return Err(ControlError::NonFinite {
            name: "weight w",
            value: bad,
        });
    }
    let mut summary = SaturationSummary::default();
    // Vertical first: it sets how much authority is left horizontally.
    for (u, model) in accel_enu_mps2.iter_mut().zip(models) {
        let limited = envelope.limit_vertical(u.z, model);
        if limited != u.z {
            summary.vertical_limited += 1;
        }
        u.z = limited;
    }
    let radius = |i: usize, u: &Vector3<f64>| envelope.horizontal_limit_mps2(u.z, &models[i]);
    match mode {
        SaturationMode::Clip => {
            for (i, u) in accel_enu_mps2.iter_mut().enumerate() {
                let a_h = radius(i, u);
                let horizontal = u.xy().norm();
                if horizontal > a_h {
                    let scale = a_h / horizontal;
                    u.x *= scale;
                    u.y *= scale;
                    summary.horizontal_limited += 1;
                }
            }
        }
        SaturationMode::Conserve => {
            // The boxes do not depend on the shift: computed once, not per bisection step.
            boxes.clear();
            boxes.extend(
                accel_enu_mps2
                    .iter()
                    .enumerate()
                    .map(|(i, u)| axis_box(u.xy(), radius(i, u))),
            );
            for axis in 0..2 {
                summary.lambda[axis] = conserving_shift(accel_enu_mps2, w, axis, boxes);
            }
            for (i, u) in accel_enu_mps2.iter_mut().enumerate() {
                let b = boxes[i];
                let shifted = Vector2::new(
                    (u.x - summary.lambda.x * w[i]).clamp(-b.x, b.x),
                    (u.y - summary.lambda.y * w[i]).clamp(-b.y, b.y),
                );
                if (shifted - u.xy()).norm() > 1e-12 * (1.0 + u.xy().norm()) {
                    summary.horizontal_limited += 1;
                }
                u.x = shifted.x;
                u.y = shifted.y;
            }
        }
    }
    Ok(summary)
}

/// The largest box inside the disc of radius `a_h` aligned with the command `u`.
fn axis_box(u: Vector2<f64>, a_h: f64) -> Vector2<f64> {
    let n = u.norm();
    if n > 0.0 {
        Vector2::new(a_h * u.x.abs() / n, a_h * u.y.abs() / n)
    } else {
        Vector2::repeat(a_h * std::f64::consts::FRAC_1_SQRT_2)
    }
}

/// The `λ` with `Σ wᵢ clip(uᵢ − λwᵢ, ±bᵢ) = Σ wᵢ uᵢ` on one axis, by bisection and a final
/// exact step on the linear piece that holds the root.
fn conserving_shift(accel: &[Vector3<f64>], w: &[f64], axis: usize, boxes: &[Vector2<f64>]) -> f64 {
    let sum = |lambda: f64| -> f64 {
        accel
            .iter()
            .zip(boxes)
            .zip(w)
            .map(|((u, b), wi)| wi * (u[axis] - lambda * wi).clamp(-b[axis], b[axis]))
            .sum()
    };
    // The nominal law gives Σ wᵢuᵢ = 0 up to rounding; keeping the nominal sum (rather
    // than forcing an exact zero) leaves unsaturated commands untouched.
    let nominal: f64 = accel.iter().zip(w).map(|(u, wi)| wi * u[axis]).sum();
    let sum = |lambda: f64| sum(lambda) - nominal;
    if sum(0.0) == 0.0 {
        return 0.0;
    }
    let reach = accel
        .iter()
        .enumerate()
        .filter(|(i, _)| w[*i] != 0.0)
        .map(|(i, u)| (u[axis].abs() + boxes[i][axis]) / w[i].abs())
        .fold(0.0, f64::max);
    let (mut lo, mut hi) = (-reach, reach);
    let (mut s_lo, mut s_hi) = (sum(lo), sum(hi));
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if mid <= lo || mid >= hi {
            break;
        }
        let s = sum(mid);
        if s == 0.0 {
            return mid;
        }
        if s > 0.0 {
            (lo, s_lo) = (mid, s);
        } else {
            (hi, s_hi) = (mid, s);
        }
    }
    if s_lo == s_hi {
        return 0.5 * (lo + hi);
    }
    (lo + s_lo * (hi - lo) / (s_lo - s_hi)).clamp(lo, hi)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hover_model() -> VehicleModel {
        VehicleModel::from_hover_throttle(2.0, 0.5).unwrap()
    }

    #[test]
    fn a_non_finite_command_is_refused_and_nothing_changes() {
        let env = Envelope::new(35f64.to_radians(), 0.1, 1.0).unwrap();
        let models = [hover_model(); 3];
        let mut u = [
            Vector3::new(30.0, 0.0, 0.0),
            Vector3::new(f64::NAN, 0.0, 0.0),
            Vector3::new(-30.0, 0.0, 0.0),
        ];
        let before = u;
        let err = saturate(SaturationMode::Conserve, &env, &models, &[1.0; 3], &mut u);
        assert!(matches!(
            err,
            Err(ControlError::NonFinite {
                name: "acceleration command",
                ..
            })
        ));
        assert_eq!(u[0], before[0]);
        assert_eq!(u[2], before[2]);
    }

    #[test]
    fn horizontal_limit_at_hover_is_g_tan_tilt_when_thrust_allows() {
        let env = Envelope::new(35f64.to_radians(), 0.1, 1.0).unwrap();
        let a_h = env.horizontal_limit_mps2(0.0, &hover_model());
        assert!((a_h - GRAVITY_MPS2 * 35f64.to_radians().tan()).abs() < 1e-12);
    }

    #[test]
    fn the_xy_margin_caps_the_vertical_command_and_leaves_that_much_horizontally() {
        // Max specific thrust 2g (hover 0.5); max 0.9, margin 0.3: the vertical part may
        // reach √(0.81 − 0.09) = 0.8485 of full thrust, and a full climb still leaves
        // √(0.9² − 0.8485²)·2g = 0.3·2g horizontally (tilt 80° does not bind).
        let env = Envelope::new(80f64.to_radians(), 0.1, 0.9)
            .unwrap()
            .with_xy_margin(0.3)
            .unwrap();
        let model = hover_model();
        let u_z = env.limit_vertical(100.0, &model);
        let f_max = 2.0 * GRAVITY_MPS2;
        assert!((u_z + GRAVITY_MPS2 - 0.72f64.sqrt() * f_max).abs() < 1e-12);
        let a_h = env.horizontal_limit_mps2(u_z, &model);
        assert!((a_h - 0.3 * f_max).abs() < 1e-9, "{a_h}");
        assert!(env.with_xy_margin(0.95).is_err());
    }

    #[test]
    fn horizontal_limit_is_bounded_by_thrust_when_tilt_allows_more() {
        // Max specific thrust 2g; at hover the thrust circle leaves √3·g horizontally,
        // less than g·tan 80°.
        let env = Envelope::new(80f64.to_radians(), 0.1, 1.0).unwrap();
        let a_h = env.horizontal_limit_mps2(0.0, &hover_model());
        assert!((a_h - 3f64.sqrt() * GRAVITY_MPS2).abs() < 1e-12);
    }

    #[test]
    fn unsaturated_commands_are_left_alone_in_both_modes() {
        let env = Envelope::new(0.5, 0.1, 1.0).unwrap();
        let models = [hover_model(); 4];
        let w = [1.0, 1.5, 1.0, 1.5];
        let nominal = [
            Vector3::new(0.3, -0.2, 0.1),
            Vector3::new(-0.1, 0.4, 0.0),
            Vector3::new(1.0, 1.0, -0.5),
            Vector3::new(0.0, 0.0, 0.0),
        ];
        for mode in [SaturationMode::Conserve, SaturationMode::Clip] {
            let mut u = nominal;
            let summary = saturate(mode, &env, &models, &w, &mut u).unwrap();
            assert_eq!(summary.horizontal_limited + summary.vertical_limited, 0);
            assert_eq!(u, nominal);
        }
    }

    #[test]
    fn vertical_command_is_clamped_to_the_thrust_limits() {
        let env = Envelope::new(0.5, 0.2, 0.9).unwrap();
        let model = hover_model(); // f_max = 2g
        assert!((env.limit_vertical(100.0, &model) - (1.8 - 1.0) * GRAVITY_MPS2).abs() < 1e-12);
        assert!((env.limit_vertical(-100.0, &model) - (0.4 - 1.0) * GRAVITY_MPS2).abs() < 1e-12);
    }

    #[test]
    fn envelope_limits_are_validated() {
        assert!(matches!(
            Envelope::new(2.0, 0.1, 1.0),
            Err(ControlError::OutOfRange {
                name: "max_tilt_rad",
                ..
            })
        ));
        assert!(matches!(
            Envelope::new(0.5, 0.6, 0.5),
            Err(ControlError::OutOfRange {
                name: "max_thrust_norm",
                ..
            })
        ));
        assert!(matches!(
            Envelope::new(f64::NAN, 0.1, 1.0),
            Err(ControlError::NonFinite { .. })
        ));
        let env = Envelope::new(0.5, 0.1, 0.45).unwrap();
        assert!(env.check_hover(&hover_model()).is_err());
    }

    #[test]
    fn mismatched_lengths_are_refused() {
        let env = Envelope::new(0.5, 0.1, 1.0).unwrap();
        let mut u = [Vector3::zeros(); 2];
        assert!(matches!(
            saturate(
                SaturationMode::Conserve,
                &env,
                &[hover_model()],
                &[1.0, 1.0],
                &mut u
            ),
            Err(ControlError::WrongLength {
                what: "vehicle models",
                ..
            })
        ));
    }
}
