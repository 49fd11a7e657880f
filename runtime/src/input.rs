//! Actuator inputs as functions of time over a step.
//!
//! Integrators evaluate the input at the times their stages need. A plain
//! vector is a zero-order hold; [`Linear`] interpolates between two samples;
//! [`FromFn`] wraps any `Fn(f64) -> SVector` (e.g. a controller or a lookup
//! table). `U` is the number of inputs, fixed (`Const<NU>`) or known at run
//! time (`Dyn`).

use crate::scalar::Scalar;
use nalgebra::allocator::Allocator;
use nalgebra::{Const, DefaultAllocator, Dim, OVector};

/// Actuator input `tau(t)` of `U` inputs, fixed (`Const<NU>`, see
/// [`Input`]) or known at run time (`Dyn`).
pub trait InputOf<U: Dim, T: Scalar = f64>
where
    DefaultAllocator: Allocator<U>,
{
    /// The input at time `t`.
    fn at(&self, t: T) -> OVector<T, U>;
}

/// [`InputOf`] of `NU` inputs (fixed size): what firmware code names.
/// Implemented for every [`InputOf`] of that size.
pub trait Input<const NU: usize, T: Scalar = f64>: InputOf<Const<NU>, T> {}

impl<I, T: Scalar, const NU: usize> Input<NU, T> for I where I: InputOf<Const<NU>, T> + ?Sized {}

/// A constant vector: zero-order hold over the step.
impl<T: Scalar, U: Dim> InputOf<U, T> for OVector<T, U>
where
    DefaultAllocator: Allocator<U>,
{
    #[inline]
    fn at(&self, _t: T) -> OVector<T, U> {
        self.clone()
    }
}

/// Linear interpolation between `(t0, tau0)` and `(t1, tau1)`; constant
/// extrapolation outside `[t0, t1]`. `U` inputs, fixed or known at run
/// time ([`Linear`]: fixed).
#[derive(Clone, Debug, PartialEq)]
pub struct LinearOf<T: Scalar, U: Dim>
where
    DefaultAllocator: Allocator<U>,
{
    /// Start time.
    pub t0: T,
    /// Input at `t0`.
    pub tau0: OVector<T, U>,
    /// End time.
    pub t1: T,
    /// Input at `t1`.
    pub tau1: OVector<T, U>,
}

impl<T: Scalar, const NU: usize> Copy for LinearOf<T, Const<NU>> {}

/// [`LinearOf`] of `NU` inputs (fixed).
pub type Linear<const NU: usize, T = f64> = LinearOf<T, Const<NU>>;

impl<T: Scalar, U: Dim> InputOf<U, T> for LinearOf<T, U>
where
    DefaultAllocator: Allocator<U>,
{
    fn at(&self, t: T) -> OVector<T, U> {
        let span = self.t1 - self.t0;
        if !(span > T::zero()) || t <= self.t0 {
            return self.tau0.clone();
        }
        if t >= self.t1 {
            return self.tau1.clone();
        }
        let s = (t - self.t0) / span;
        &self.tau0 * (T::one() - s) + &self.tau1 * s
    }
}

/// Input given by a closure of time.
#[derive(Clone, Copy, Debug)]
pub struct FromFn<F>(pub F);

impl<F, T: Scalar, U: Dim> InputOf<U, T> for FromFn<F>
where
    F: Fn(T) -> OVector<T, U>,
    DefaultAllocator: Allocator<U>,
{
    #[inline]
    fn at(&self, t: T) -> OVector<T, U> {
        (self.0)(t)
    }
}
