//! Exact folding of constants: what keeps round-off of zeros out of the
//! generated code.
//!
//! Two rules, applied wherever the graph folds constants (so to every
//! scene):
//!
//! * **Sines and cosines of multiples of `pi/12`.** A constant angle `x`
//!   with `|x| <= 1e6` that lies within `8 eps |x|` of `n pi/12` for an
//!   integer `n` (`eps = 2^-52`: a few ulps, the round-off of writing
//!   `pi/2`, `3*pi/2`, `-pi/6` or `1.5707963267948966` in `f64`) is taken
//!   to be exactly `n pi/12`: its sine and cosine are the correctly rounded
//!   values of the exact ones, so multiples of `pi/2` give exact `0` and
//!   `+-1`, multiples of `pi/6` exact `+-0.5`, and `tan` is their quotient
//!   (`tan(pi/4) = 1`). Any other angle goes to the library `sin`/`cos`.
//!   An angle that is deliberately close to, but not at, a multiple of
//!   `pi/12` (`1.57079632679`, 4.9e-12 from `pi/2`) is not moved.
//! * **Cancellation.** When constants are added (the constant of a sum, or
//!   the coefficients of like terms being collected), a result within
//!   `4 eps` of the sum of the magnitudes of its parts is zero: it is the
//!   round-off of a cancellation (`0.5 - (sqrt(2)/2)^2`), not a value.
//!
//! Both move a value by at most a few ulps of the quantities involved,
//! i.e. no more than evaluating the same expression in `f64` would.

use std::f64::consts::{FRAC_1_SQRT_2, PI};

/// `sin(k pi/12)` for `k = 0..=6`, correctly rounded.
const SIN_TWELFTHS: [f64; 7] = [
    0.0,
    0.258_819_045_102_520_74, // (sqrt 6 - sqrt 2) / 4
    0.5,
    FRAC_1_SQRT_2,
    0.866_025_403_784_438_6, // sqrt 3 / 2
    0.965_925_826_289_068_3, // (sqrt 6 + sqrt 2) / 4
    1.0,
];

/// Relative distance (in units of `eps`) within which an angle counts as a
/// multiple of `pi/12`.
const ANGLE_ULPS: f64 = 8.0;

/// Relative size (in units of `eps`) below which a sum of constants is the
/// round-off of a cancellation.
const CANCEL_ULPS: f64 = 4.0;

/// `n` when `x` is `n pi/12` up to round-off (see the module docs).
fn twelfths_of_pi(x: f64) -> Option<i64> {
    if !x.is_finite() || x.abs() > 1e6 {
        return None;
    }
    let n = (x * 12.0 / PI).round();
    let off = (x - n * (PI / 12.0)).abs();
    (off <= ANGLE_ULPS * f64::EPSILON * x.abs()).then_some(n as i64)
}

/// `sin(n pi/12)`, exactly rounded.
fn sin_twelfths(n: i64) -> f64 {
    let k = n.rem_euclid(24) as usize;
    // sin is symmetric about 6 (pi/2) and antisymmetric about 12 (pi).
    let (k, sign) = if k < 12 { (k, 1.0) } else { (k - 12, -1.0) };
    let k = if k > 6 { 12 - k } else { k };
    sign * SIN_TWELFTHS[k]
}

/// `(sin x, cos x)` with the exact values at multiples of `pi/12`.
pub fn sin_cos(x: f64) -> (f64, f64) {
    match twelfths_of_pi(x) {
        Some(n) => (sin_twelfths(n), sin_twelfths(n + 6)),
        None => x.sin_cos(),
    }
}

/// `sum` set to zero when it is the round-off of cancelling parts whose
/// magnitudes add up to `magnitude`; a sum that is not finite is kept (an
/// overflow, which the graph records, is not a cancellation).
pub fn cancel(sum: f64, magnitude: f64) -> f64 {
    if sum.is_finite() && sum.abs() <= CANCEL_ULPS * f64::EPSILON * magnitude {
        0.0
    } else {
        sum
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn multiples_of_half_pi_are_exact() {
        for (x, s, c) in [
            (0.0, 0.0, 1.0),
            (PI / 2.0, 1.0, 0.0),
            (PI, 0.0, -1.0),
            (3.0 * PI / 2.0, -1.0, 0.0),
            (-PI / 2.0, -1.0, 0.0),
            (2.0 * PI, 0.0, 1.0),
        ] {
            assert_eq!(sin_cos(x), (s, c), "angle {x}");
        }
        // As written in a URDF file.
        let read = |s: &str| s.parse::<f64>().expect("a number");
        assert_eq!(sin_cos(read("1.5707963267948966")), (1.0, 0.0));
        assert_eq!(sin_cos(read("-3.141592653589793")), (0.0, -1.0));
    }

    #[test]
    fn multiples_of_pi_over_twelve_match_the_library_closely() {
        for n in -48..=48 {
            let x = n as f64 * PI / 12.0;
            let (s, c) = sin_cos(x);
            // The library's values carry the round-off of `x` itself.
            let tol = 4.0 * f64::EPSILON * x.abs().max(1.0);
            assert!((s - x.sin()).abs() < tol, "sin {n} pi/12");
            assert!((c - x.cos()).abs() < tol, "cos {n} pi/12");
            assert!(s.abs() <= 1.0 && c.abs() <= 1.0);
        }
        assert_eq!(sin_cos(PI / 6.0).0, 0.5);
        assert_eq!(sin_cos(PI / 3.0).1, 0.5);
        assert_eq!(sin_cos(-2.0 * PI / 3.0).1, -0.5);
    }

    #[test]
    fn angles_near_but_not_at_a_multiple_are_kept() {
        let x: f64 = "1.57079632679".parse().expect("a number");
        assert_eq!(sin_cos(x), x.sin_cos());
        assert!(sin_cos(x).1 > 4e-12);
        let y = 0.3;
        assert_eq!(sin_cos(y), y.sin_cos());
    }

    #[test]
    fn cancellation_round_off_is_zero() {
        let h = FRAC_1_SQRT_2 * FRAC_1_SQRT_2;
        assert_ne!(h - 0.5, 0.0);
        assert_eq!(cancel(h - 0.5, h + 0.5), 0.0);
        assert_eq!(cancel(1e-10, 1.0), 1e-10);
        assert_eq!(cancel(-1.0, 1.0), -1.0);
    }
}
