//! Model evaluation with finiteness checks: every model output that a solver
//! uses goes through one of these, so a NaN or infinity from generated code is
//! reported as [`ErrorKind::NonFiniteModelOutput`] instead of propagating.

use crate::error::{Error, ErrorKind, Quantity};
use crate::linalg::all_finite;
use crate::model::Model;
use crate::scalar::Scalar;
use nalgebra::{SMatrix, SVector};

#[inline]
pub(crate) fn check<T: Scalar, const R: usize, const C: usize>(
    m: &SMatrix<T, R, C>,
    quantity: Quantity,
    t: T,
) -> Result<(), Error> {
    if all_finite(m) {
        Ok(())
    } else {
        Err(Error::new(ErrorKind::NonFiniteModelOutput { quantity }, t))
    }
}

/// `M(q, t)`.
pub(crate) fn mass<
    M: Model<NQ, NC, NU, T>,
    T: Scalar,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>(
    model: &M,
    q: &SVector<T, NQ>,
    t: T,
) -> Result<SMatrix<T, NQ, NQ>, Error> {
    let mut m = SMatrix::<T, NQ, NQ>::zeros();
    model.mass_matrix(q, t, &mut m);
    check(&m, Quantity::MassMatrix, t)?;
    Ok(m)
}

/// `M qdd + h` at `(q, qd, qdd, t)`, from the model's
/// [`Model::inverse_dynamics`], written into `r`.
pub(crate) fn inverse_dynamics_into<
    M: Model<NQ, NC, NU, T>,
    T: Scalar,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>(
    model: &M,
    q: &SVector<T, NQ>,
    qd: &SVector<T, NQ>,
    qdd: &SVector<T, NQ>,
    t: T,
    r: &mut SVector<T, NQ>,
) -> Result<(), Error> {
    model.inverse_dynamics(q, qd, qdd, t, r);
    check(r, Quantity::InverseDynamics, t)
}

/// `gamma(q, qd, t)`.
pub(crate) fn constraint_rhs<
    M: Model<NQ, NC, NU, T>,
    T: Scalar,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>(
    model: &M,
    q: &SVector<T, NQ>,
    qd: &SVector<T, NQ>,
    t: T,
) -> Result<SVector<T, NC>, Error> {
    let mut gamma = SVector::<T, NC>::zeros();
    model.constraint_rhs(q, qd, t, &mut gamma);
    check(&gamma, Quantity::ConstraintRhs, t)?;
    Ok(gamma)
}

/// `M`, `h`, `Phi_q` and `gamma` at one state, from the model's fused
/// [`Model::dynamics_terms`] (one program sharing every common
/// subexpression in generated models).
pub(crate) struct Terms<const NQ: usize, const NC: usize, T: Scalar = f64> {
    pub m: SMatrix<T, NQ, NQ>,
    pub h: SVector<T, NQ>,
    pub phi_q: SMatrix<T, NC, NQ>,
    pub gamma: SVector<T, NC>,
}

impl<const NQ: usize, const NC: usize, T: Scalar> Terms<NQ, NC, T> {
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
    M: Model<NQ, NC, NU, T>,
    T: Scalar,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>(
    model: &M,
    q: &SVector<T, NQ>,
    qd: &SVector<T, NQ>,
    t: T,
) -> Result<Terms<NQ, NC, T>, Error> {
    let mut o = Terms::zeros();
    dynamics_terms_into(model, q, qd, t, &mut o)?;
    Ok(o)
}

/// [`dynamics_terms`] written into `o` (no copy of the terms on return).
pub(crate) fn dynamics_terms_into<
    M: Model<NQ, NC, NU, T>,
    T: Scalar,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>(
    model: &M,
    q: &SVector<T, NQ>,
    qd: &SVector<T, NQ>,
    t: T,
    o: &mut Terms<NQ, NC, T>,
) -> Result<(), Error> {
    model.dynamics_terms(q, qd, t, &mut o.m, &mut o.h, &mut o.phi_q, &mut o.gamma);
    check_terms(o, t)
}

/// Checks every term of `o` (evaluated at time `t`).
pub(crate) fn check_terms<T: Scalar, const NQ: usize, const NC: usize>(
    o: &Terms<NQ, NC, T>,
    t: T,
) -> Result<(), Error> {
    check(&o.m, Quantity::MassMatrix, t)?;
    check(&o.h, Quantity::Bias, t)?;
    check(&o.phi_q, Quantity::ConstraintJacobian, t)?;
    check(&o.gamma, Quantity::ConstraintRhs, t)
}

/// `B`.
pub(crate) fn actuator_map<
    M: Model<NQ, NC, NU, T>,
    T: Scalar,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>(
    model: &M,
    t: T,
) -> Result<SMatrix<T, NQ, NU>, Error> {
    let mut b = SMatrix::<T, NQ, NU>::zeros();
    model.actuator_map(&mut b);
    check(&b, Quantity::ActuatorMap, t)?;
    Ok(b)
}

/// `Phi(q, t)`.
pub(crate) fn constraints<
    M: Model<NQ, NC, NU, T>,
    T: Scalar,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>(
    model: &M,
    q: &SVector<T, NQ>,
    t: T,
) -> Result<SVector<T, NC>, Error> {
    let mut phi = SVector::<T, NC>::zeros();
    if NC > 0 {
        model.constraints(q, t, &mut phi);
        check(&phi, Quantity::Constraints, t)?;
    }
    Ok(phi)
}

/// `Phi_q(q, t)`.
pub(crate) fn constraint_jacobian<
    M: Model<NQ, NC, NU, T>,
    T: Scalar,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>(
    model: &M,
    q: &SVector<T, NQ>,
    t: T,
) -> Result<SMatrix<T, NC, NQ>, Error> {
    let mut j = SMatrix::<T, NC, NQ>::zeros();
    constraint_jacobian_into(model, q, t, &mut j)?;
    Ok(j)
}

/// [`constraint_jacobian`] written into `phi_q`.
pub(crate) fn constraint_jacobian_into<
    M: Model<NQ, NC, NU, T>,
    T: Scalar,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>(
    model: &M,
    q: &SVector<T, NQ>,
    t: T,
    phi_q: &mut SMatrix<T, NC, NQ>,
) -> Result<(), Error> {
    phi_q.as_mut_slice().fill(T::zero());
    if NC > 0 {
        model.constraint_jacobian(q, t, phi_q);
        check(phi_q, Quantity::ConstraintJacobian, t)?;
    }
    Ok(())
}

/// `Phi(q, t)` and `Phi_q(q, t)` from the model's fused
/// [`Model::constraints_and_jacobian`], written into `phi` and `phi_q`.
pub(crate) fn constraints_and_jacobian<
    M: Model<NQ, NC, NU, T>,
    T: Scalar,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>(
    model: &M,
    q: &SVector<T, NQ>,
    t: T,
    phi: &mut SVector<T, NC>,
    phi_q: &mut SMatrix<T, NC, NQ>,
) -> Result<(), Error> {
    phi.as_mut_slice().fill(T::zero());
    phi_q.as_mut_slice().fill(T::zero());
    if NC > 0 {
        model.constraints_and_jacobian(q, t, phi, phi_q);
        check(phi, Quantity::Constraints, t)?;
        check(phi_q, Quantity::ConstraintJacobian, t)?;
    }
    Ok(())
}

/// `Phi_t(q, t)`.
pub(crate) fn constraint_time_derivative<
    M: Model<NQ, NC, NU, T>,
    T: Scalar,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>(
    model: &M,
    q: &SVector<T, NQ>,
    t: T,
) -> Result<SVector<T, NC>, Error> {
    let mut p = SVector::<T, NC>::zeros();
    if NC > 0 {
        model.constraint_time_derivative(q, t, &mut p);
        check(&p, Quantity::ConstraintTimeDerivative, t)?;
    }
    Ok(p)
}

/// Checks an actuator input vector.
pub(crate) fn check_input<T: Scalar, const NU: usize>(
    tau: &SVector<T, NU>,
    t: T,
) -> Result<(), Error> {
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
pub(crate) fn check_result<T: Scalar, const R: usize, const C: usize>(
    m: &SMatrix<T, R, C>,
    quantity: Quantity,
    t: T,
) -> Result<(), Error> {
    if all_finite(m) {
        Ok(())
    } else {
        Err(Error::new(ErrorKind::NonFiniteResult { quantity }, t))
    }
}
