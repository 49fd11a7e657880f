//! Model evaluation with finiteness checks: every model output that a solver
//! uses goes through one of these, so a NaN or infinity from generated code is
//! reported as [`ErrorKind::NonFiniteModelOutput`] instead of propagating.

use crate::error::{Error, ErrorKind, Quantity};
use crate::linalg::all_finite;
use crate::model::Model;
use nalgebra::{SMatrix, SVector};

#[inline]
pub(crate) fn check<const R: usize, const C: usize>(
    m: &SMatrix<f64, R, C>,
    quantity: Quantity,
    t: f64,
) -> Result<(), Error> {
    if all_finite(m) {
        Ok(())
    } else {
        Err(Error::new(ErrorKind::NonFiniteModelOutput { quantity }, t))
    }
}

/// `M(q, t)`.
pub(crate) fn mass<M: Model<NQ, NC, NU>, const NQ: usize, const NC: usize, const NU: usize>(
    model: &M,
    q: &SVector<f64, NQ>,
    t: f64,
) -> Result<SMatrix<f64, NQ, NQ>, Error> {
    let mut m = SMatrix::<f64, NQ, NQ>::zeros();
    model.mass_matrix(q, t, &mut m);
    check(&m, Quantity::MassMatrix, t)?;
    Ok(m)
}

/// `M qdd + h` at `(q, qd, qdd, t)`, from the model's
/// [`Model::inverse_dynamics`], written into `r`.
pub(crate) fn inverse_dynamics_into<
    M: Model<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>(
    model: &M,
    q: &SVector<f64, NQ>,
    qd: &SVector<f64, NQ>,
    qdd: &SVector<f64, NQ>,
    t: f64,
    r: &mut SVector<f64, NQ>,
) -> Result<(), Error> {
    model.inverse_dynamics(q, qd, qdd, t, r);
    check(r, Quantity::InverseDynamics, t)
}

/// `gamma(q, qd, t)`.
pub(crate) fn constraint_rhs<
    M: Model<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>(
    model: &M,
    q: &SVector<f64, NQ>,
    qd: &SVector<f64, NQ>,
    t: f64,
) -> Result<SVector<f64, NC>, Error> {
    let mut gamma = SVector::<f64, NC>::zeros();
    model.constraint_rhs(q, qd, t, &mut gamma);
    check(&gamma, Quantity::ConstraintRhs, t)?;
    Ok(gamma)
}

/// `M`, `h`, `Phi_q` and `gamma` at one state, from the model's fused
/// [`Model::dynamics_terms`] (one program sharing every common
/// subexpression in generated models).
pub(crate) struct Terms<const NQ: usize, const NC: usize> {
    pub m: SMatrix<f64, NQ, NQ>,
    pub h: SVector<f64, NQ>,
    pub phi_q: SMatrix<f64, NC, NQ>,
    pub gamma: SVector<f64, NC>,
}

impl<const NQ: usize, const NC: usize> Terms<NQ, NC> {
    /// All zero.
    pub(crate) fn zeros() -> Self {
        Terms {
            m: SMatrix::zeros(),
            h: SVector::zeros(),
            phi_q: SMatrix::zeros(),
            gamma: SVector::zeros(),
        }
    }
}

/// [`Terms`] with every output checked.
pub(crate) fn dynamics_terms<
    M: Model<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>(
    model: &M,
    q: &SVector<f64, NQ>,
    qd: &SVector<f64, NQ>,
    t: f64,
) -> Result<Terms<NQ, NC>, Error> {
    let mut o = Terms::zeros();
    dynamics_terms_into(model, q, qd, t, &mut o)?;
    Ok(o)
}

/// [`dynamics_terms`] written into `o` (no copy of the terms on return).
pub(crate) fn dynamics_terms_into<
    M: Model<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>(
    model: &M,
    q: &SVector<f64, NQ>,
    qd: &SVector<f64, NQ>,
    t: f64,
    o: &mut Terms<NQ, NC>,
) -> Result<(), Error> {
    model.dynamics_terms(q, qd, t, &mut o.m, &mut o.h, &mut o.phi_q, &mut o.gamma);
    check_terms(o, t)
}

/// Checks every term of `o` (evaluated at time `t`).
pub(crate) fn check_terms<const NQ: usize, const NC: usize>(
    o: &Terms<NQ, NC>,
    t: f64,
) -> Result<(), Error> {
    check(&o.m, Quantity::MassMatrix, t)?;
    check(&o.h, Quantity::Bias, t)?;
    check(&o.phi_q, Quantity::ConstraintJacobian, t)?;
    check(&o.gamma, Quantity::ConstraintRhs, t)
}

/// `B`.
pub(crate) fn actuator_map<
    M: Model<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>(
    model: &M,
    t: f64,
) -> Result<SMatrix<f64, NQ, NU>, Error> {
    let mut b = SMatrix::<f64, NQ, NU>::zeros();
    model.actuator_map(&mut b);
    check(&b, Quantity::ActuatorMap, t)?;
    Ok(b)
}

/// `Phi(q, t)`.
pub(crate) fn constraints<
    M: Model<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>(
    model: &M,
    q: &SVector<f64, NQ>,
    t: f64,
) -> Result<SVector<f64, NC>, Error> {
    let mut phi = SVector::<f64, NC>::zeros();
    if NC > 0 {
        model.constraints(q, t, &mut phi);
        check(&phi, Quantity::Constraints, t)?;
    }
    Ok(phi)
}

/// `Phi_q(q, t)`.
pub(crate) fn constraint_jacobian<
    M: Model<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>(
    model: &M,
    q: &SVector<f64, NQ>,
    t: f64,
) -> Result<SMatrix<f64, NC, NQ>, Error> {
    let mut j = SMatrix::<f64, NC, NQ>::zeros();
    constraint_jacobian_into(model, q, t, &mut j)?;
    Ok(j)
}

/// [`constraint_jacobian`] written into `phi_q`.
pub(crate) fn constraint_jacobian_into<
    M: Model<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>(
    model: &M,
    q: &SVector<f64, NQ>,
    t: f64,
    phi_q: &mut SMatrix<f64, NC, NQ>,
) -> Result<(), Error> {
    phi_q.as_mut_slice().fill(0.0);
    if NC > 0 {
        model.constraint_jacobian(q, t, phi_q);
        check(phi_q, Quantity::ConstraintJacobian, t)?;
    }
    Ok(())
}

/// `Phi(q, t)` and `Phi_q(q, t)` from the model's fused
/// [`Model::constraints_and_jacobian`], written into `phi` and `phi_q`.
pub(crate) fn constraints_and_jacobian<
    M: Model<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>(
    model: &M,
    q: &SVector<f64, NQ>,
    t: f64,
    phi: &mut SVector<f64, NC>,
    phi_q: &mut SMatrix<f64, NC, NQ>,
) -> Result<(), Error> {
    phi.as_mut_slice().fill(0.0);
    phi_q.as_mut_slice().fill(0.0);
    if NC > 0 {
        model.constraints_and_jacobian(q, t, phi, phi_q);
        check(phi, Quantity::Constraints, t)?;
        check(phi_q, Quantity::ConstraintJacobian, t)?;
    }
    Ok(())
}

/// `Phi_t(q, t)`.
pub(crate) fn constraint_time_derivative<
    M: Model<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>(
    model: &M,
    q: &SVector<f64, NQ>,
    t: f64,
) -> Result<SVector<f64, NC>, Error> {
    let mut p = SVector::<f64, NC>::zeros();
    if NC > 0 {
        model.constraint_time_derivative(q, t, &mut p);
        check(&p, Quantity::ConstraintTimeDerivative, t)?;
    }
    Ok(p)
}

/// Checks an actuator input vector.
pub(crate) fn check_input<const NU: usize>(tau: &SVector<f64, NU>, t: f64) -> Result<(), Error> {
    match crate::linalg::first_non_finite(tau) {
        None => Ok(()),
        Some(index) => Err(Error::new(
            ErrorKind::NonFiniteInput {
                quantity: Quantity::Input,
                index,
            },
            t,
        )),
    }
}

/// Checks a solver result.
pub(crate) fn check_result<const R: usize, const C: usize>(
    m: &SMatrix<f64, R, C>,
    quantity: Quantity,
    t: f64,
) -> Result<(), Error> {
    if all_finite(m) {
        Ok(())
    } else {
        Err(Error::new(ErrorKind::NonFiniteResult { quantity }, t))
    }
}
