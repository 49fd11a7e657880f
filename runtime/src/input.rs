//! Actuator inputs as functions of time over a step.
//!
//! Integrators evaluate the input at the times their stages need. A plain
//! vector is a zero-order hold; [`Linear`] interpolates between two samples;
//! [`FromFn`] wraps any `Fn(f64) -> SVector` (e.g. a controller or a lookup
//! table).

use crate::scalar::Scalar;
use nalgebra::SVector;

/// Actuator input `tau(t)`.
pub trait Input<const NU: usize, T: Scalar = f64> {
    /// The input at time `t`.
    fn at(&self, t: T) -> SVector<T, NU>;
}

/// A constant vector: zero-order hold over the step.
impl<T: Scalar, const NU: usize> Input<NU, T> for SVector<T, NU> {
    #[inline]
    fn at(&self, _t: T) -> SVector<T, NU> {
        *self
    }
}

/// Linear interpolation between `(t0, tau0)` and `(t1, tau1)`; constant
/// extrapolation outside `[t0, t1]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Linear<const NU: usize, T: Scalar = f64> {
    /// Start time.
    pub t0: T,
    /// Input at `t0`.
    pub tau0: SVector<T, NU>,
    /// End time.
    pub t1: T,
    /// Input at `t1`.
    pub tau1: SVector<T, NU>,
}

impl<T: Scalar, const NU: usize> Input<NU, T> for Linear<NU, T> {
    fn at(&self, t: T) -> SVector<T, NU> {
        let span = self.t1 - self.t0;
        if !(span > T::zero()) || t <= self.t0 {
            return self.tau0;
        }
        if t >= self.t1 {
            return self.tau1;
        }
        let s = (t - self.t0) / span;
        self.tau0 * (T::one() - s) + self.tau1 * s
    }
}

/// Input given by a closure of time.
#[derive(Clone, Copy, Debug)]
pub struct FromFn<F>(pub F);

impl<F, T: Scalar, const NU: usize> Input<NU, T> for FromFn<F>
where
    F: Fn(T) -> SVector<T, NU>,
{
    #[inline]
    fn at(&self, t: T) -> SVector<T, NU> {
        (self.0)(t)
    }
}
