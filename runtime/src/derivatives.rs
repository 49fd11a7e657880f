//! Exact derivatives of the forward dynamics of an unconstrained model, for
//! linearization and optimal control, from the model's generated
//! derivatives of the inverse dynamics.
//!
//! With `qdd = FD(q, qd, tau) = M^-1 (B tau - h)` the inverse dynamics
//! `ID(q, qd, qdd) = M qdd + h` equals `B tau` along the solution, so
//! differentiating that identity gives `M d qdd/dx = -d ID/dx` at `qdd`
//! for `x = q, qd`, and `M d qdd/d tau = B`: one factorisation of `M`,
//! three solves, no differentiation of `M^-1`.

use crate::dynamics::Kkt;
use crate::error::{invalid_configuration, Error, Quantity};
use crate::eval;
use crate::model::{Equations, Sizes};
use crate::scalar::Scalar;
use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};

/// The forward dynamics and their derivatives at one state: `Q`
/// coordinates and `U` inputs of fixed or run-time size. Entry `(i, j)` of
/// each matrix is `d qdd_i / d x_j`.
#[derive(Clone, Debug, PartialEq)]
pub struct ForwardDerivativesOf<T: Scalar, Q: Dim, U: Dim>
where
    DefaultAllocator: nalgebra::allocator::Allocator<Q>
        + nalgebra::allocator::Allocator<Q, Q>
        + nalgebra::allocator::Allocator<Q, U>,
{
    /// The accelerations `qdd = M^-1 (B tau - h)`.
    pub qdd: OVector<T, Q>,
    /// `d qdd / d q`.
    pub qdd_q: OMatrix<T, Q, Q>,
    /// `d qdd / d qd`.
    pub qdd_qd: OMatrix<T, Q, Q>,
    /// `d qdd / d tau` (`M^-1 B`).
    pub qdd_tau: OMatrix<T, Q, U>,
}

/// The accelerations of an unconstrained model at `(q, qd, t)` with
/// actuator input `tau`, and their exact derivatives with respect to `q`,
/// `qd` and `tau`, from the model's
/// [`crate::Model::inverse_dynamics_derivatives`] (generated where a scene
/// asks for `dynamics_derivatives`).
///
/// Errors: [`crate::ErrorKind::InvalidConfiguration`] for a model with
/// constraints or without generated inverse-dynamics derivatives;
/// [`crate::ErrorKind::MassMatrixNotPositiveDefinite`],
/// [`crate::ErrorKind::NonFiniteModelOutput`] and
/// [`crate::ErrorKind::NonFiniteResult`] as in [`crate::accelerations`].
pub fn forward_dynamics_derivatives<M, T: Scalar, Q: Dim, C: Dim, U: Dim>(
    model: &M,
    q: &OVector<T, Q>,
    qd: &OVector<T, Q>,
    t: T,
    tau: &OVector<T, U>,
) -> Result<ForwardDerivativesOf<T, Q, U>, Error>
where
    M: Equations<Q, C, U, T> + ?Sized,
    DefaultAllocator: Sizes<Q, C, U>,
{
    let (nq, nc, _) = model.sizes();
    if nc.value() != 0 {
        return Err(invalid_configuration(
            "forward-dynamics derivatives are provided for unconstrained models only",
        ));
    }
    let eval::Terms { m, h, phi_q, .. } = eval::dynamics_terms(model, q, qd, t)?;
    let b = eval::actuator_map(model, t)?;
    let kkt = Kkt::new(m, &phi_q, T::KKT_MAX_CONDITION, t)?;
    let mut qdd = b.clone() * tau - h;
    kkt.solve_mass(&mut qdd);
    eval::check_result(&qdd, Quantity::Acceleration, t)?;
    let mut id = OVector::<T, Q>::zeros_generic(nq, nalgebra::Const::<1>);
    let mut qdd_q = OMatrix::<T, Q, Q>::zeros_generic(nq, nq);
    let mut qdd_qd = OMatrix::<T, Q, Q>::zeros_generic(nq, nq);
    if !model.inverse_dynamics_derivatives(q, qd, &qdd, t, &mut id, &mut qdd_q, &mut qdd_qd) {
        return Err(invalid_configuration(
            "the model has no generated inverse-dynamics derivatives (scene `outputs = [\"dynamics_derivatives\"]`)",
        ));
    }
    eval::check(&qdd_q, Quantity::InverseDynamicsDerivatives, t)?;
    eval::check(&qdd_qd, Quantity::InverseDynamicsDerivatives, t)?;
    qdd_q.neg_mut();
    qdd_qd.neg_mut();
    kkt.solve_mass(&mut qdd_q);
    kkt.solve_mass(&mut qdd_qd);
    let mut qdd_tau = b;
    kkt.solve_mass(&mut qdd_tau);
    eval::check_result(&qdd_q, Quantity::Acceleration, t)?;
    eval::check_result(&qdd_qd, Quantity::Acceleration, t)?;
    eval::check_result(&qdd_tau, Quantity::Acceleration, t)?;
    Ok(ForwardDerivativesOf {
        qdd,
        qdd_q,
        qdd_qd,
        qdd_tau,
    })
}
