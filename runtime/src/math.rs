//! Scalar functions used by generated code.
//!
//! With the `std` feature these call the platform's math library; without it
//! they call the pure-Rust `libm` crate, so generated code builds for
//! `no_std` targets unchanged. [`sin_cos`], the most frequent call in
//! generated code, is `libm`'s in both cases (see its documentation).

#[cfg(feature = "std")]
extern crate std;

macro_rules! unary {
    ($($(#[$doc:meta])* $name:ident => $libm:ident;)*) => {$(
        $(#[$doc])*
        #[inline(always)]
        pub fn $name(x: f64) -> f64 {
            #[cfg(feature = "std")]
            { x.$name() }
            #[cfg(not(feature = "std"))]
            { libm::$libm(x) }
        }
    )*};
}

unary! {
    /// Sine.
    sin => sin;
    /// Cosine.
    cos => cos;
    /// Tangent.
    tan => tan;
    /// Exponential.
    exp => exp;
    /// Natural logarithm.
    ln => log;
    /// Square root.
    sqrt => sqrt;
}

/// Sine and cosine of one argument, computed together (one argument
/// reduction). Always `libm`'s `sincos`, also with `std`: the standard
/// library's `sin_cos` makes two separate platform calls, measured 1.4x slower
/// on the rigid robot's terms (`benches/casadi_c`).
#[inline(always)]
pub fn sin_cos(x: f64) -> (f64, f64) {
    libm::sincos(x)
}

/// The same functions in `f32`, for modules generated with
/// `precision = "f32"` (which import them as `math`), the same with or
/// without `std` so that an `f32` model computes the same on a host as on a
/// microcontroller.
///
/// `sin`, `cos` and `sin_cos` are computed in `f32` arithmetic only (the
/// `libm` crate's `sincosf` evaluates in `f64`, which a Cortex-M4F emulates
/// in software at about 1,800 instructions per call): `x = k pi/2 + r` with
/// `k` the nearest integer to `2 x / pi` and `r` in `[-pi/4, pi/4]`, `pi/2`
/// split into three `f32` parts (the first two with few enough bits that
/// their products with `k` are exact for `|x| <= 6000`), then the Taylor
/// polynomials of `sin r` (to `r^9`) and `cos r` (to `r^10`), whose
/// truncation errors (below `2e-9`) are far below `f32`'s resolution, and the
/// quadrant of `k`. Larger or non-finite arguments go to `libm`'s `sincosf`.
/// Within 2 units in the last place of the exact values (tested against
/// `f64`). The others are `libm`'s single-precision routines.
pub mod f32 {
    macro_rules! unary_f32 {
        ($($(#[$doc:meta])* $name:ident => $libm:ident;)*) => {$(
            $(#[$doc])*
            #[inline(always)]
            pub fn $name(x: f32) -> f32 {
                libm::$libm(x)
            }
        )*};
    }

    unary_f32! {
        /// Tangent.
        tan => tanf;
        /// Exponential.
        exp => expf;
        /// Natural logarithm.
        ln => logf;
        /// Square root.
        sqrt => sqrtf;
    }

    /// Largest `|x|` reduced in `f32` (see the module docs).
    const REDUCED: f32 = 6000.0;
    /// `pi/2 = PIO2_1 + PIO2_2 + PIO2_3`; `PIO2_1` has 8 significant bits,
    /// `PIO2_2` 12.
    const PIO2_1: f32 = 1.5703125;
    const PIO2_2: f32 = 4.838_705e-4;
    const PIO2_3: f32 = -4.371_139e-8;

    /// Sine and cosine of `r` in `[-pi/4, pi/4]`.
    #[inline(always)]
    fn kernel(r: f32) -> (f32, f32) {
        let z = r * r;
        let s = r + r
            * z
            * (-1.0 / 6.0 + z * (1.0 / 120.0 + z * (-1.0 / 5040.0 + z * (1.0 / 362_880.0))));
        let c = 1.0
            + z * (-0.5
                + z * (1.0 / 24.0
                    + z * (-1.0 / 720.0 + z * (1.0 / 40_320.0 + z * (-1.0 / 3_628_800.0)))));
        (s, c)
    }

    /// Sine and cosine of one argument, computed together.
    #[inline]
    pub fn sin_cos(x: f32) -> (f32, f32) {
        if !(x.abs() <= REDUCED) {
            return libm::sincosf(x);
        }
        let kf = x * core::f32::consts::FRAC_2_PI;
        let k = if kf >= 0.0 {
            (kf + 0.5) as i32
        } else {
            (kf - 0.5) as i32
        };
        let kf = k as f32;
        let r = ((x - kf * PIO2_1) - kf * PIO2_2) - kf * PIO2_3;
        let (s, c) = kernel(r);
        match k & 3 {
            0 => (s, c),
            1 => (c, -s),
            2 => (-s, -c),
            _ => (-c, s),
        }
    }

    /// Sine.
    #[inline(always)]
    pub fn sin(x: f32) -> f32 {
        sin_cos(x).0
    }

    /// Cosine.
    #[inline(always)]
    pub fn cos(x: f32) -> f32 {
        sin_cos(x).1
    }

    /// Four-quadrant arctangent of `y / x`.
    #[inline(always)]
    pub fn atan2(y: f32, x: f32) -> f32 {
        libm::atan2f(y, x)
    }

    #[cfg(test)]
    mod tests {
        use super::*;

        /// Distance in units in the last place of `f32` near `exact`.
        fn ulps(got: f32, exact: f64) -> f64 {
            let ulp = f64::from(f32::EPSILON) * exact.abs().max(f64::from(f32::MIN_POSITIVE));
            // Near zero the absolute error counts against f32's resolution at 1.
            (f64::from(got) - exact).abs() / ulp.max(f64::from(f32::EPSILON) * 2f64.powi(-8))
        }

        #[test]
        fn sin_cos_is_within_two_ulps_of_the_f64_values() {
            let mut worst = 0.0f64;
            let mut x = -REDUCED;
            while x <= REDUCED {
                for x in [x, x * 1e-3, x * 1e-6] {
                    let (s, c) = sin_cos(x);
                    let (es, ec) = libm::sincos(f64::from(x));
                    worst = worst.max(ulps(s, es)).max(ulps(c, ec));
                }
                x += 0.0137;
            }
            assert!(worst <= 2.0, "worst error {worst} ulp");
        }

        #[test]
        fn large_and_non_finite_arguments_go_to_libm() {
            for x in [1e5f32, -3e7, f32::MAX] {
                assert_eq!(sin_cos(x), libm::sincosf(x));
            }
            assert!(sin_cos(f32::NAN).0.is_nan() && sin_cos(f32::INFINITY).1.is_nan());
            assert_eq!(sin_cos(0.0), (0.0, 1.0));
        }
    }
}

/// Four-quadrant arctangent of `y / x`.
#[inline(always)]
pub fn atan2(y: f64, x: f64) -> f64 {
    #[cfg(feature = "std")]
    {
        y.atan2(x)
    }
    #[cfg(not(feature = "std"))]
    {
        libm::atan2(y, x)
    }
}
