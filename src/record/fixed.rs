//! Fixed-point decimal text for the CSVs, several times faster than `format!("{:.4}")`
//! (whose exact formatting dominated the coordinator's profile at a thousand vehicles).
//!
//! `push(out, x, d)` writes what `format!("{x:.d$}")` writes, except that the value is
//! rounded as `(x·10^d).round()`: in rare ties the last digit may differ by one unit.
//! Values too large for that (|x|·10^d ≥ 2⁵³) and non-finite ones take the standard
//! path.

use std::io::Write;

/// Largest integer a double holds exactly.
const EXACT: f64 = 9_007_199_254_740_992.0;

/// Powers of ten up to the largest precision used (exact as doubles too).
const POW10: [u64; 10] = [
    1,
    10,
    100,
    1_000,
    10_000,
    100_000,
    1_000_000,
    10_000_000,
    100_000_000,
    1_000_000_000,
];

/// Appends `x` with `decimals` digits after the point (at most 9).
pub fn push(out: &mut Vec<u8>, x: f64, decimals: usize) {
    let d = decimals.min(POW10.len() - 1);
    let scaled = (x * POW10[d] as f64).round();
    if !scaled.is_finite() || scaled.abs() >= EXACT {
        let _ = write!(out, "{x:.d$}");
        return;
    }
    if x.is_sign_negative() {
        out.push(b'-');
    }
    // The integer part, then the fraction padded with leading zeros to `d` digits.
    let n = scaled.abs() as u64;
    let mut digits = itoa::Buffer::new();
    out.extend_from_slice(digits.format(n / POW10[d]).as_bytes());
    if d > 0 {
        out.push(b'.');
        let fraction = digits.format(n % POW10[d]).as_bytes();
        out.extend(std::iter::repeat_n(b'0', d - fraction.len()));
        out.extend_from_slice(fraction);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn text(x: f64, d: usize) -> String {
        let mut out = Vec::new();
        push(&mut out, x, d);
        String::from_utf8(out).unwrap()
    }

    #[test]
    fn writes_what_the_standard_formatter_writes() {
        for (x, d) in [
            (0.0, 4),
            (-0.0, 4),
            (1.5, 0),
            (12.345_678, 4),
            (-12.345_678, 4),
            (-0.000_01, 4),
            (0.000_049, 4),
            (123_456.789, 1),
            (1e-9, 5),
            (-3.999_999_9, 3),
            (2.0 * std::f64::consts::PI, 5),
            (f64::NAN, 4),
            (f64::INFINITY, 4),
            (f64::NEG_INFINITY, 1),
            (1e300, 4),
        ] {
            assert_eq!(text(x, d), format!("{x:.d$}"), "{x} with {d} decimals");
        }
    }

    #[test]
    fn agrees_with_the_standard_formatter_on_random_values_but_for_rare_ties() {
        let mut state = 0x9E37_79B9_7F4A_7C15_u64;
        let mut differ = 0;
        for _ in 0..100_000 {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            let x = (state as f64 / u64::MAX as f64 - 0.5) * 2000.0;
            for d in [1, 4, 5] {
                let (ours, std) = (text(x, d), format!("{x:.d$}"));
                if ours != std {
                    differ += 1;
                    // A tie rounded the other way: one unit in the last place.
                    let unit = 10f64.powi(-(d as i32));
                    let gap = (ours.parse::<f64>().unwrap() - std.parse::<f64>().unwrap()).abs();
                    assert!(gap <= unit * 1.000_001, "{x}: {ours} vs {std}");
                }
            }
        }
        assert!(differ < 30, "{differ} of 300 000 differ");
    }
}
