//! [`Problems`]: what a validation found wrong, one line each, naming the key and the
//! value, and the range checks every section's numbers go through.

/// Collects problems, one line each.
#[derive(Debug, Default)]
pub(super) struct Problems(pub(super) Vec<String>);

impl Problems {
    /// Requires `lo <= value <= hi` (so also finite); `unit` is printed after the range.
    pub(super) fn within(&mut self, key: &str, value: f64, lo: f64, hi: f64, unit: &str) -> bool {
        let good = value.is_finite() && value >= lo && value <= hi;
        if !good {
            self.0.push(format!(
                "{key} must be a finite number in [{lo}, {hi}]{unit}, got {}",
                show(value)
            ));
        }
        good
    }

    /// Requires `0 < value <= hi`.
    pub(super) fn positive(&mut self, key: &str, value: f64, hi: f64, unit: &str) -> bool {
        let good = value.is_finite() && value > 0.0 && value <= hi;
        if !good {
            self.0.push(format!(
                "{key} must be a finite number in (0, {hi}]{unit}, got {}",
                show(value)
            ));
        }
        good
    }

    /// Requires every element finite with magnitude at most `hi`.
    pub(super) fn vector(&mut self, key: &str, values: &[f64], hi: f64, unit: &str) -> bool {
        let bad = values
            .iter()
            .position(|v| !(v.is_finite() && v.abs() <= hi));
        if let Some(j) = bad {
            self.0.push(format!(
                "{key}[{j}] must be a finite number in [-{hi}, {hi}]{unit}, got {}",
                show(values[j])
            ));
        }
        bad.is_none()
    }

    pub(super) fn push(&mut self, problem: String) {
        self.0.push(problem);
    }
}

/// A value as a person would write it: `1e20`, not twenty-one digits.
pub(crate) fn show(value: f64) -> String {
    let a = value.abs();
    if value.is_finite() && (a >= 1e7 || (a > 0.0 && a < 1e-4)) {
        format!("{value:e}")
    } else {
        value.to_string()
    }
}
