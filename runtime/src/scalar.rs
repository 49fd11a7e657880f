//! The floating-point type the solvers compute in: `f64` (the default
//! everywhere) or `f32` (single-precision FPUs, e.g. a Cortex-M4F).
//!
//! Every solver is generic over `T:` [`Scalar`]; the model trait, the state
//! and the configurations take it as a defaulted parameter, so `Model<NQ,
//! NC, NU>` means `Model<NQ, NC, NU, f64>`. Errors keep their numbers as
//! `f64` whatever `T` is (exact for `f32`).
//!
//! The configuration defaults depend on the precision. With machine epsilon
//! `eps` (2.2e-16 for `f64`, 1.2e-7 for `f32`), a linear solve with condition
//! `kappa` loses about `kappa * eps` in relative accuracy, so the largest
//! accepted condition ([`Scalar::MAX_CONDITION`]) is where that loss reaches
//! 1e-8 in `f64` and 1e-3 in `f32` (`1e4 * 1.2e-7`); beyond it an `f32`
//! result would carry no trustworthy digit worth reporting and the solvers
//! refuse with a conditioning error instead.

use nalgebra::RealField;

/// A floating-point type the runtime computes in (`f32` or `f64`).
pub trait Scalar: RealField + Copy + Default + Into<f64> + core::iter::Sum {
    /// Machine epsilon (`f64::EPSILON` or `f32::EPSILON`).
    const EPSILON: Self;
    /// Positive infinity.
    const INFINITY: Self;
    /// Not a number.
    const NAN: Self;
    /// Default target `max |Phi|` of position solves (Newton on the
    /// constraints), in model units: `1e-12` (`f64`), `1e-5` (`f32`).
    const POSITION_TOLERANCE: Self;
    /// Default relative tolerance for the numerical rank of a matrix
    /// (singular values below it times the largest count as zero): `1e-10`
    /// (`f64`), `1e-4` (`f32`).
    const RANK_TOLERANCE: Self;
    /// Default largest accepted condition of the systems the solvers
    /// invert: `1e8` (`f64`), `1e4` (`f32`); see the module docs.
    const MAX_CONDITION: Self;
    /// Default largest accepted condition estimate of the constrained
    /// forward dynamics (the equilibrated Schur complement of the KKT
    /// system): `1e12` (`f64`), `1e6` (`f32`, about `1 / (8 eps)`: beyond it
    /// not one significant digit of the accelerations is certain).
    const KKT_MAX_CONDITION: Self;
    /// Default largest accepted condition estimate of an implicit
    /// integrator's Newton iteration matrix (generalized-α): `1e14`
    /// (`f64`), `1e6` (`f32`). Newton tolerates an inexact matrix (it slows
    /// down, the residual it drives to zero is evaluated exactly), so the
    /// limit sits where the correction would keep no significant digit:
    /// `kappa * eps` about `0.02` (`f64`) and `0.1` (`f32`).
    const ITERATION_MAX_CONDITION: Self;

    /// `x` rounded to this type (exact for `f64`).
    fn of(x: f64) -> Self;

    /// True for a value that is neither infinite nor NaN.
    fn finite(self) -> bool;

    /// Square root (the runtime's [`crate::math`] function of this type).
    fn square_root(self) -> Self;
}

impl Scalar for f64 {
    const EPSILON: Self = f64::EPSILON;
    const INFINITY: Self = f64::INFINITY;
    const NAN: Self = f64::NAN;
    const POSITION_TOLERANCE: Self = 1e-12;
    const RANK_TOLERANCE: Self = 1e-10;
    const MAX_CONDITION: Self = 1e8;
    const KKT_MAX_CONDITION: Self = 1e12;
    const ITERATION_MAX_CONDITION: Self = 1e14;

    #[inline]
    fn of(x: f64) -> Self {
        x
    }

    #[inline]
    fn finite(self) -> bool {
        self.is_finite()
    }

    #[inline]
    fn square_root(self) -> Self {
        crate::math::sqrt(self)
    }
}

impl Scalar for f32 {
    const EPSILON: Self = f32::EPSILON;
    const INFINITY: Self = f32::INFINITY;
    const NAN: Self = f32::NAN;
    const POSITION_TOLERANCE: Self = 1e-5;
    const RANK_TOLERANCE: Self = 1e-4;
    const MAX_CONDITION: Self = 1e4;
    const KKT_MAX_CONDITION: Self = 1e6;
    const ITERATION_MAX_CONDITION: Self = 1e6;

    #[inline]
    fn of(x: f64) -> Self {
        x as f32
    }

    #[inline]
    fn finite(self) -> bool {
        self.is_finite()
    }

    #[inline]
    fn square_root(self) -> Self {
        crate::math::f32::sqrt(self)
    }
}
