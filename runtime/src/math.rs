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
