//! State feedback: the model with `u = law(q, qd, t)` added to the input,
//!
//! ```text
//! M qdd + h - B (tau + law(q, qd, t)) = Phi_q^T lambda
//! ```
//!
//! i.e. a model whose bias forces are `h - B law(q, qd, t)`, integrated under
//! whatever feed-forward input `tau` the integrator is given.

use crate::model::{Equations, Sizes};
use crate::scalar::Scalar;
use nalgebra::allocator::Allocator;
use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};

/// A state-feedback law `u(q, qd, t)` for `U` actuator inputs of `Q`
/// coordinates (fixed, `Const<N>`, or run-time, `Dyn`). Any
/// `Fn(&OVector<f64, Q>, &OVector<f64, Q>, f64) -> OVector<f64, U>` is one
/// (e.g. `Fn(&SVector<f64, NQ>, ..) -> SVector<f64, NU>`).
pub trait FeedbackLaw<Q: Dim, U: Dim>
where
    DefaultAllocator: Allocator<Q> + Allocator<U>,
{
    /// The input at a state.
    fn input(&self, q: &OVector<f64, Q>, qd: &OVector<f64, Q>, t: f64) -> OVector<f64, U>;
}

impl<F, Q: Dim, U: Dim> FeedbackLaw<Q, U> for F
where
    F: Fn(&OVector<f64, Q>, &OVector<f64, Q>, f64) -> OVector<f64, U>,
    DefaultAllocator: Allocator<Q> + Allocator<U>,
{
    #[inline]
    fn input(&self, q: &OVector<f64, Q>, qd: &OVector<f64, Q>, t: f64) -> OVector<f64, U> {
        self(q, qd, t)
    }
}

/// `inner` with the input `law(q, qd, t)` added to whatever input the
/// integrator applies. A non-finite law output makes the bias forces
/// non-finite, which the solvers report
/// ([`crate::ErrorKind::NonFiniteModelOutput`] of the bias).
#[derive(Clone, Copy, Debug)]
pub struct Feedback<'a, M: ?Sized, L> {
    /// The wrapped model.
    pub inner: &'a M,
    /// The feedback law.
    pub law: L,
}

impl<'a, M: ?Sized, L> Feedback<'a, M, L> {
    /// `inner` under the feedback `law`.
    pub fn new(inner: &'a M, law: L) -> Self {
        Feedback { inner, law }
    }
}

/// `h -= B u`.
pub(crate) fn subtract_input<M, T: Scalar, Q: Dim, C: Dim, U: Dim>(
    model: &M,
    u: &OVector<T, U>,
    h: &mut OVector<T, Q>,
) where
    M: Equations<Q, C, U, T> + ?Sized,
    DefaultAllocator: Sizes<Q, C, U>,
{
    let (nq, _, nu) = model.sizes();
    let mut b = OMatrix::<T, Q, U>::zeros_generic(nq, nu);
    model.actuator_map(&mut b);
    *h -= b * u;
}

impl<M, L, Q: Dim, C: Dim, U: Dim> Equations<Q, C, U> for Feedback<'_, M, L>
where
    M: Equations<Q, C, U> + ?Sized,
    L: FeedbackLaw<Q, U>,
    DefaultAllocator: Sizes<Q, C, U>,
{
    crate::model::forward_equations!(inner, Q, C, U, f64);
    fn bias(&self, q: &OVector<f64, Q>, qd: &OVector<f64, Q>, t: f64, h: &mut OVector<f64, Q>) {
        self.inner.bias(q, qd, t, h);
        subtract_input(self.inner, &self.law.input(q, qd, t), h);
    }
    /// Not provided (the law's derivatives are unknown).
    fn bias_jacobians(
        &self,
        _: &OVector<f64, Q>,
        _: &OVector<f64, Q>,
        _: f64,
        _: &mut OMatrix<f64, Q, Q>,
        _: &mut OMatrix<f64, Q, Q>,
    ) -> bool {
        false
    }
    fn dynamics_terms(
        &self,
        q: &OVector<f64, Q>,
        qd: &OVector<f64, Q>,
        t: f64,
        m: &mut OMatrix<f64, Q, Q>,
        h: &mut OVector<f64, Q>,
        phi_q: &mut OMatrix<f64, C, Q>,
        gamma: &mut OVector<f64, C>,
    ) {
        self.inner.dynamics_terms(q, qd, t, m, h, phi_q, gamma);
        subtract_input(self.inner, &self.law.input(q, qd, t), h);
    }
    /// `M qdd + h - B law(q, qd, t)`.
    fn inverse_dynamics(
        &self,
        q: &OVector<f64, Q>,
        qd: &OVector<f64, Q>,
        qdd: &OVector<f64, Q>,
        t: f64,
        tau: &mut OVector<f64, Q>,
    ) {
        self.inner.inverse_dynamics(q, qd, qdd, t, tau);
        subtract_input(self.inner, &self.law.input(q, qd, t), tau);
    }
}
