//! Model evaluation with finiteness checks: every model output that a solver
//! uses goes through one of these, so a NaN or infinity from generated code is
//! reported as [`ErrorKind::NonFiniteModelOutput`] instead of propagating.

use crate::error::{Error, ErrorKind, Quantity};
use crate::linalg::all_finite;
use crate::model::Model;
use nalgebra::{SMatrix, SVector};

#[inline]
fn check<const R: usize, const C: usize>(
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

/// `h(q, qd, t)`.
pub(crate) fn bias<M: Model<NQ, NC, NU>, const NQ: usize, const NC: usize, const NU: usize>(
    model: &M,
    q: &SVector<f64, NQ>,
    qd: &SVector<f64, NQ>,
    t: f64,
) -> Result<SVector<f64, NQ>, Error> {
    let mut h = SVector::<f64, NQ>::zeros();
    model.bias(q, qd, t, &mut h);
    check(&h, Quantity::Bias, t)?;
    Ok(h)
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
    if NC > 0 {
        model.constraint_jacobian(q, t, &mut j);
        check(&j, Quantity::ConstraintJacobian, t)?;
    }
    Ok(j)
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
    let mut g = SVector::<f64, NC>::zeros();
    if NC > 0 {
        model.constraint_rhs(q, qd, t, &mut g);
        check(&g, Quantity::ConstraintRhs, t)?;
    }
    Ok(g)
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
