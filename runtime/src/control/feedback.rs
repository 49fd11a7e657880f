//! State feedback: the model with `u = law(q, qd, t)` added to the input,
//!
//! ```text
//! M qdd + h - B (tau + law(q, qd, t)) = Phi_q^T lambda
//! ```
//!
//! i.e. a model whose bias forces are `h - B law(q, qd, t)`, integrated under
//! whatever feed-forward input `tau` the integrator is given.

use crate::model::Model;
use crate::scalar::Scalar;
use nalgebra::{SMatrix, SVector};

/// A state-feedback law `u(q, qd, t)` for `NU` actuator inputs. Any
/// `Fn(&SVector<f64, NQ>, &SVector<f64, NQ>, f64) -> SVector<f64, NU>` is one.
pub trait FeedbackLaw<const NQ: usize, const NU: usize> {
    /// The input at a state.
    fn input(&self, q: &SVector<f64, NQ>, qd: &SVector<f64, NQ>, t: f64) -> SVector<f64, NU>;
}

impl<F, const NQ: usize, const NU: usize> FeedbackLaw<NQ, NU> for F
where
    F: Fn(&SVector<f64, NQ>, &SVector<f64, NQ>, f64) -> SVector<f64, NU>,
{
    #[inline]
    fn input(&self, q: &SVector<f64, NQ>, qd: &SVector<f64, NQ>, t: f64) -> SVector<f64, NU> {
        self(q, qd, t)
    }
}

/// `inner` with the input `law(q, qd, t)` added to whatever input the
/// integrator applies. A non-finite law output makes the bias forces
/// non-finite, which the solvers report
/// ([`crate::ErrorKind::NonFiniteModelOutput`] of the bias).
#[derive(Clone, Copy, Debug)]
pub struct Feedback<'a, M, L> {
    /// The wrapped model.
    pub inner: &'a M,
    /// The feedback law.
    pub law: L,
}

impl<'a, M, L> Feedback<'a, M, L> {
    /// `inner` under the feedback `law`.
    pub fn new(inner: &'a M, law: L) -> Self {
        Feedback { inner, law }
    }
}

/// `h -= B u`.
pub(crate) fn subtract_input<M, T: Scalar, const NQ: usize, const NC: usize, const NU: usize>(
    model: &M,
    u: &SVector<T, NU>,
    h: &mut SVector<T, NQ>,
) where
    M: Model<NQ, NC, NU, T>,
{
    let mut b = SMatrix::<T, NQ, NU>::zeros();
    model.actuator_map(&mut b);
    *h -= b * u;
}

impl<M, L, const NQ: usize, const NC: usize, const NU: usize> Model<NQ, NC, NU>
    for Feedback<'_, M, L>
where
    M: Model<NQ, NC, NU>,
    L: FeedbackLaw<NQ, NU>,
{
    crate::forward_model!(inner: M, NQ, NC, NU);
    fn bias(&self, q: &SVector<f64, NQ>, qd: &SVector<f64, NQ>, t: f64, h: &mut SVector<f64, NQ>) {
        self.inner.bias(q, qd, t, h);
        subtract_input(self.inner, &self.law.input(q, qd, t), h);
    }
    fn dynamics_terms(
        &self,
        q: &SVector<f64, NQ>,
        qd: &SVector<f64, NQ>,
        t: f64,
        m: &mut SMatrix<f64, NQ, NQ>,
        h: &mut SVector<f64, NQ>,
        phi_q: &mut SMatrix<f64, NC, NQ>,
        gamma: &mut SVector<f64, NC>,
    ) {
        self.inner.dynamics_terms(q, qd, t, m, h, phi_q, gamma);
        subtract_input(self.inner, &self.law.input(q, qd, t), h);
    }
}
