//! Model evaluation with finiteness checks: every model output that a solver
//! uses goes through one of these, so a NaN or infinity from generated code is
//! reported as [`ErrorKind::NonFiniteModelOutput`] instead of propagating.

use crate::error::{Error, ErrorKind, Quantity};
use crate::linalg::all_finite;
use crate::model::{Equations, Sizes};
use crate::scalar::Scalar;
use nalgebra::allocator::Allocator;
use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector};

#[inline]
pub(crate) fn check<T: Scalar, R: Dim, C: Dim>(
    m: &OMatrix<T, R, C>,
    quantity: Quantity,
    t: T,
) -> Result<(), Error>
where
    DefaultAllocator: Allocator<R, C>,
{
    if all_finite(m) {
        Ok(())
    } else {
        Err(Error::new(ErrorKind::NonFiniteModelOutput { quantity }, t))
    }
}

/// `M(q, t)`.
pub(crate) fn mass<M, T: Scalar, Q: Dim, C: Dim, U: Dim>(
    model: &M,
    q: &OVector<T, Q>,
    t: T,
) -> Result<OMatrix<T, Q, Q>, Error>
where
    M: Equations<Q, C, U, T> + ?Sized,
    DefaultAllocator: Sizes<Q, C, U>,
{
    let (nq, _, _) = model.sizes();
    let mut m = OMatrix::<T, Q, Q>::zeros_generic(nq, nq);
    model.mass_matrix(q, t, &mut m);
    check(&m, Quantity::MassMatrix, t)?;
    Ok(m)
}

/// `M qdd + h` at `(q, qd, qdd, t)`, from the model's
/// [`crate::Model::inverse_dynamics`], written into `r`.
pub(crate) fn inverse_dynamics_into<M, T: Scalar, Q: Dim, C: Dim, U: Dim>(
    model: &M,
    q: &OVector<T, Q>,
    qd: &OVector<T, Q>,
    qdd: &OVector<T, Q>,
    t: T,
    r: &mut OVector<T, Q>,
) -> Result<(), Error>
where
    M: Equations<Q, C, U, T> + ?Sized,
    DefaultAllocator: Sizes<Q, C, U>,
{
    model.inverse_dynamics(q, qd, qdd, t, r);
    check(r, Quantity::InverseDynamics, t)
}

/// `gamma(q, qd, t)`.
pub(crate) fn constraint_rhs<M, T: Scalar, Q: Dim, C: Dim, U: Dim>(
    model: &M,
    q: &OVector<T, Q>,
    qd: &OVector<T, Q>,
    t: T,
) -> Result<OVector<T, C>, Error>
where
    M: Equations<Q, C, U, T> + ?Sized,
    DefaultAllocator: Sizes<Q, C, U>,
{
    let (_, nc, _) = model.sizes();
    let mut gamma = OVector::<T, C>::zeros_generic(nc, nalgebra::U1);
    model.constraint_rhs(q, qd, t, &mut gamma);
    check(&gamma, Quantity::ConstraintRhs, t)?;
    Ok(gamma)
}

/// `M`, `h`, `Phi_q` and `gamma` at one state, from the model's fused
/// [`crate::Model::dynamics_terms`] (one program sharing every common
/// subexpression in generated models).
pub(crate) struct Terms<T: Scalar, Q: Dim, C: Dim>
where
    DefaultAllocator: Allocator<Q, Q> + Allocator<Q> + Allocator<C, Q> + Allocator<C>,
{
    pub m: OMatrix<T, Q, Q>,
    pub h: OVector<T, Q>,
    pub phi_q: OMatrix<T, C, Q>,
    pub gamma: OVector<T, C>,
}

impl<T: Scalar, Q: Dim, C: Dim> Terms<T, Q, C>
where
    DefaultAllocator: Allocator<Q, Q> + Allocator<Q> + Allocator<C, Q> + Allocator<C>,
{
    /// All zero, for `nq` coordinates and `nc` constraints.
    pub(crate) fn zeros(nq: Q, nc: C) -> Self {
        Terms {
            m: OMatrix::zeros_generic(nq, nq),
            h: OVector::zeros_generic(nq, nalgebra::U1),
            phi_q: OMatrix::zeros_generic(nc, nq),
            gamma: OVector::zeros_generic(nc, nalgebra::U1),
        }
    }
}

/// [`Terms`] with every output checked.
pub(crate) fn dynamics_terms<M, T: Scalar, Q: Dim, C: Dim, U: Dim>(
    model: &M,
    q: &OVector<T, Q>,
    qd: &OVector<T, Q>,
    t: T,
) -> Result<Terms<T, Q, C>, Error>
where
    M: Equations<Q, C, U, T> + ?Sized,
    DefaultAllocator: Sizes<Q, C, U>,
{
    let (nq, nc, _) = model.sizes();
    let mut o = Terms::zeros(nq, nc);
    dynamics_terms_into(model, q, qd, t, &mut o)?;
    Ok(o)
}

/// [`dynamics_terms`] written into `o` (no copy of the terms on return).
pub(crate) fn dynamics_terms_into<M, T: Scalar, Q: Dim, C: Dim, U: Dim>(
    model: &M,
    q: &OVector<T, Q>,
    qd: &OVector<T, Q>,
    t: T,
    o: &mut Terms<T, Q, C>,
) -> Result<(), Error>
where
    M: Equations<Q, C, U, T> + ?Sized,
    DefaultAllocator: Sizes<Q, C, U>,
{
    model.dynamics_terms(q, qd, t, &mut o.m, &mut o.h, &mut o.phi_q, &mut o.gamma);
    check_terms(o, t)
}

/// Checks every term of `o` (evaluated at time `t`).
pub(crate) fn check_terms<T: Scalar, Q: Dim, C: Dim>(o: &Terms<T, Q, C>, t: T) -> Result<(), Error>
where
    DefaultAllocator: Allocator<Q, Q> + Allocator<Q> + Allocator<C, Q> + Allocator<C>,
{
    check(&o.m, Quantity::MassMatrix, t)?;
    check(&o.h, Quantity::Bias, t)?;
    check(&o.phi_q, Quantity::ConstraintJacobian, t)?;
    check(&o.gamma, Quantity::ConstraintRhs, t)
}

/// `B`.
pub(crate) fn actuator_map<M, T: Scalar, Q: Dim, C: Dim, U: Dim>(
    model: &M,
    t: T,
) -> Result<OMatrix<T, Q, U>, Error>
where
    M: Equations<Q, C, U, T> + ?Sized,
    DefaultAllocator: Sizes<Q, C, U>,
{
    let b = written_actuator_map(model);
    check(&b, Quantity::ActuatorMap, t)?;
    Ok(b)
}

/// `B` as the model writes it, unchecked (inlined: built where it is used).
#[inline(always)]
fn written_actuator_map<M, T: Scalar, Q: Dim, C: Dim, U: Dim>(model: &M) -> OMatrix<T, Q, U>
where
    M: Equations<Q, C, U, T> + ?Sized,
    DefaultAllocator: Sizes<Q, C, U>,
{
    let (nq, _, nu) = model.sizes();
    let mut b = OMatrix::<T, Q, U>::zeros_generic(nq, nu);
    model.actuator_map(&mut b);
    b
}

/// `B tau`: the model's generated [`Equations::actuator_forces`] where it
/// has it (it costs what the non-zero entries of `B` do; TALOS's `B tau`
/// was 11 % of its forward dynamics as a dense product), else `B` formed
/// where it is used (not returned, which copied it) and multiplied. `B` is
/// checked only when the forces are not finite, to name it if it is the
/// cause (a non-finite entry of `B` makes its row's force non-finite
/// whatever `tau` is).
pub(crate) fn actuator_forces<M, T: Scalar, Q: Dim, C: Dim, U: Dim>(
    model: &M,
    tau: &OVector<T, U>,
    t: T,
) -> Result<OVector<T, Q>, Error>
where
    M: Equations<Q, C, U, T> + ?Sized,
    DefaultAllocator: Sizes<Q, C, U>,
{
    let (nq, _, _) = model.sizes();
    let mut f = OVector::<T, Q>::zeros_generic(nq, nalgebra::U1);
    if model.actuator_forces(tau, &mut f) && all_finite(&f) {
        return Ok(f);
    }
    let b = written_actuator_map(model);
    let f = &b * tau;
    if !all_finite(&f) {
        check(&b, Quantity::ActuatorMap, t)?;
    }
    Ok(f)
}

/// `Phi(q, t)`.
pub(crate) fn constraints<M, T: Scalar, Q: Dim, C: Dim, U: Dim>(
    model: &M,
    q: &OVector<T, Q>,
    t: T,
) -> Result<OVector<T, C>, Error>
where
    M: Equations<Q, C, U, T> + ?Sized,
    DefaultAllocator: Sizes<Q, C, U>,
{
    let (_, nc, _) = model.sizes();
    let mut phi = OVector::<T, C>::zeros_generic(nc, nalgebra::U1);
    if nc.value() > 0 {
        model.constraints(q, t, &mut phi);
        check(&phi, Quantity::Constraints, t)?;
    }
    Ok(phi)
}

/// `Phi_q(q, t)`.
pub(crate) fn constraint_jacobian<M, T: Scalar, Q: Dim, C: Dim, U: Dim>(
    model: &M,
    q: &OVector<T, Q>,
    t: T,
) -> Result<OMatrix<T, C, Q>, Error>
where
    M: Equations<Q, C, U, T> + ?Sized,
    DefaultAllocator: Sizes<Q, C, U>,
{
    let (nq, nc, _) = model.sizes();
    let mut j = OMatrix::<T, C, Q>::zeros_generic(nc, nq);
    constraint_jacobian_into(model, q, t, &mut j)?;
    Ok(j)
}

/// [`constraint_jacobian`] written into `phi_q`.
pub(crate) fn constraint_jacobian_into<M, T: Scalar, Q: Dim, C: Dim, U: Dim>(
    model: &M,
    q: &OVector<T, Q>,
    t: T,
    phi_q: &mut OMatrix<T, C, Q>,
) -> Result<(), Error>
where
    M: Equations<Q, C, U, T> + ?Sized,
    DefaultAllocator: Sizes<Q, C, U>,
{
    phi_q.as_mut_slice().fill(T::zero());
    if phi_q.nrows() > 0 {
        model.constraint_jacobian(q, t, phi_q);
        check(phi_q, Quantity::ConstraintJacobian, t)?;
    }
    Ok(())
}

/// `Phi(q, t)` and `Phi_q(q, t)` from the model's fused
/// [`crate::Model::constraints_and_jacobian`], written into `phi` and `phi_q`.
pub(crate) fn constraints_and_jacobian<M, T: Scalar, Q: Dim, C: Dim, U: Dim>(
    model: &M,
    q: &OVector<T, Q>,
    t: T,
    phi: &mut OVector<T, C>,
    phi_q: &mut OMatrix<T, C, Q>,
) -> Result<(), Error>
where
    M: Equations<Q, C, U, T> + ?Sized,
    DefaultAllocator: Sizes<Q, C, U>,
{
    phi.as_mut_slice().fill(T::zero());
    phi_q.as_mut_slice().fill(T::zero());
    if phi.nrows() > 0 {
        model.constraints_and_jacobian(q, t, phi, phi_q);
        check(phi, Quantity::Constraints, t)?;
        check(phi_q, Quantity::ConstraintJacobian, t)?;
    }
    Ok(())
}

/// `Phi_t(q, t)`.
pub(crate) fn constraint_time_derivative<M, T: Scalar, Q: Dim, C: Dim, U: Dim>(
    model: &M,
    q: &OVector<T, Q>,
    t: T,
) -> Result<OVector<T, C>, Error>
where
    M: Equations<Q, C, U, T> + ?Sized,
    DefaultAllocator: Sizes<Q, C, U>,
{
    let (_, nc, _) = model.sizes();
    let mut p = OVector::<T, C>::zeros_generic(nc, nalgebra::U1);
    if nc.value() > 0 {
        model.constraint_time_derivative(q, t, &mut p);
        check(&p, Quantity::ConstraintTimeDerivative, t)?;
    }
    Ok(p)
}

/// Checks an actuator input vector.
pub(crate) fn check_input<T: Scalar, U: Dim>(tau: &OVector<T, U>, t: T) -> Result<(), Error>
where
    DefaultAllocator: Allocator<U>,
{
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
pub(crate) fn check_result<T: Scalar, R: Dim, C: Dim>(
    m: &OMatrix<T, R, C>,
    quantity: Quantity,
    t: T,
) -> Result<(), Error>
where
    DefaultAllocator: Allocator<R, C>,
{
    if all_finite(m) {
        Ok(())
    } else {
        Err(Error::new(ErrorKind::NonFiniteResult { quantity }, t))
    }
}
