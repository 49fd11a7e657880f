//! Actuator inputs as functions of time over a step.
//!
//! Integrators evaluate the input at the times their stages need. A plain
//! vector is a zero-order hold; [`Linear`] interpolates between two samples;
//! [`FromFn`] wraps any `Fn(f64) -> SVector` (e.g. a controller or a lookup
//! table).

use nalgebra::SVector;

/// Actuator input `tau(t)`.
pub trait Input<const NU: usize> {
    /// The input at time `t`.
    fn at(&self, t: f64) -> SVector<f64, NU>;
}

/// A constant vector: zero-order hold over the step.
impl<const NU: usize> Input<NU> for SVector<f64, NU> {
    #[inline]
    fn at(&self, _t: f64) -> SVector<f64, NU> {
        *self
    }
}

/// Linear interpolation between `(t0, tau0)` and `(t1, tau1)`; constant
/// extrapolation outside `[t0, t1]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Linear<const NU: usize> {
    /// Start time.
    pub t0: f64,
    /// Input at `t0`.
    pub tau0: SVector<f64, NU>,
    /// End time.
    pub t1: f64,
    /// Input at `t1`.
    pub tau1: SVector<f64, NU>,
}

impl<const NU: usize> Input<NU> for Linear<NU> {
    fn at(&self, t: f64) -> SVector<f64, NU> {
        let span = self.t1 - self.t0;
        if !(span > 0.0) || t <= self.t0 {
            return self.tau0;
        }
        if t >= self.t1 {
            return self.tau1;
        }
        let s = (t - self.t0) / span;
        self.tau0 * (1.0 - s) + self.tau1 * s
    }
}

/// Input given by a closure of time.
#[derive(Clone, Copy, Debug)]
pub struct FromFn<F>(pub F);

impl<F, const NU: usize> Input<NU> for FromFn<F>
where
    F: Fn(f64) -> SVector<f64, NU>,
{
    #[inline]
    fn at(&self, t: f64) -> SVector<f64, NU> {
        (self.0)(t)
    }
}
