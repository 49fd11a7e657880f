//! Exact derivatives of the forward dynamics, for linearization and optimal
//! control, from the model's generated derivatives of the inverse dynamics
//! (and, with constraints, of the acceleration constraint).
//!
//! Unconstrained: with `qdd = FD(q, qd, tau) = M^-1 (B tau - h)` the inverse
//! dynamics `ID(q, qd, qdd) = M qdd + h` equal `B tau` along the solution,
//! so differentiating that identity gives `M d qdd/dx = -d ID/dx` at `qdd`
//! for `x = q, qd`, and `M d qdd/d tau = B`: one factorisation of `M`, no
//! differentiation of `M^-1`. Where the scene has its generated forward
//! dynamics that is one generated program
//! ([`crate::Model::forward_dynamics_derivatives`]); otherwise the
//! saddle-point path below, without constraints.
//!
//! Constrained: `(qdd, lambda)` solve `M qdd - Phi_q^T lambda = B tau - h`,
//! `Phi_q qdd = gamma` (the ideal equations, without Baumgarte
//! stabilisation). Differentiating both at the solution (implicit
//! differentiation of the saddle-point system; it needs `Phi_q` of full
//! rank) gives, per direction `x`, the same saddle-point matrix with
//! right-hand sides `B tau_x - ID_x + (Phi_q^T lambda)_x` and `-a_x`, where
//! `a = Phi_q qdd - gamma` is the acceleration constraint. `(Phi_q^T
//! lambda)_q` contracts the constraints' second derivatives with `lambda`;
//! since `a` is linear in `qdd`, `da/dq` at `qdd = e_i` minus `da/dq` at
//! `qdd = 0` is row `i` of every constraint's Hessian, which gives it from
//! the generated `da/dq` without another generated function.

use crate::dynamics::{solved, Kkt};
use crate::error::{invalid_configuration, Error, Quantity};
use crate::eval;
use crate::linalg::mul_sparse_acc;
use crate::model::{Equations, Sizes};
use crate::scalar::Scalar;
use nalgebra::{Const, DefaultAllocator, Dim, OMatrix, OVector};

/// The forward dynamics (accelerations and constraint forces) and their
/// derivatives at one state: `Q` coordinates, `C` constraints and `U`
/// inputs of fixed or run-time size. Entry `(i, j)` of each matrix is
/// `d y_i / d x_j`.
#[derive(Clone, Debug, PartialEq)]
pub struct ForwardDerivativesOf<T: Scalar, Q: Dim, C: Dim, U: Dim>
where
    DefaultAllocator: Sizes<Q, C, U>,
{
    /// The accelerations `qdd`.
    pub qdd: OVector<T, Q>,
    /// The constraint forces `lambda` (empty without constraints).
    pub lambda: OVector<T, C>,
    /// `d qdd / d q`.
    pub qdd_q: OMatrix<T, Q, Q>,
    /// `d qdd / d qd`.
    pub qdd_qd: OMatrix<T, Q, Q>,
    /// `d qdd / d tau`.
    pub qdd_tau: OMatrix<T, Q, U>,
    /// `d lambda / d q`.
    pub lambda_q: OMatrix<T, C, Q>,
    /// `d lambda / d qd`.
    pub lambda_qd: OMatrix<T, C, Q>,
    /// `d lambda / d tau`.
    pub lambda_tau: OMatrix<T, C, U>,
    /// `d (Phi_q qd + Phi_t) / d q` (`nc x nq`): how the velocity
    /// constraint changes with the positions (what a reduction to
    /// independent coordinates needs).
    pub velocity_constraint_q: OMatrix<T, C, Q>,
    /// Condition estimate of `Phi_q M^-1 Phi_q^T` (1 without constraints).
    pub condition: T,
}

/// The accelerations and constraint forces of a model at `(q, qd, t)` with
/// actuator input `tau`, and their exact derivatives with respect to `q`,
/// `qd` and `tau`, from the model's
/// [`crate::Model::inverse_dynamics_derivatives`] and, with constraints,
/// [`crate::Model::constraint_acceleration_derivatives`] (both generated
/// where a scene asks for `dynamics_derivatives`).
///
/// With constraints these are the derivatives of the ideal constrained
/// dynamics (no Baumgarte terms) as a function of the whole state; they
/// need `Phi_q` of full rank. At a state off the constraint manifold they
/// are still those of the saddle-point solution there.
///
/// Errors: [`crate::ErrorKind::InvalidConfiguration`] for a model without
/// generated derivatives; [`crate::ErrorKind::MassMatrixNotPositiveDefinite`],
/// [`crate::ErrorKind::SingularConstraintJacobian`],
/// [`crate::ErrorKind::NonFiniteModelOutput`] and
/// [`crate::ErrorKind::NonFiniteResult`] as in [`crate::accelerations`].
pub fn forward_dynamics_derivatives<M, T: Scalar, Q: Dim, C: Dim, U: Dim>(
    model: &M,
    q: &OVector<T, Q>,
    qd: &OVector<T, Q>,
    t: T,
    tau: &OVector<T, U>,
) -> Result<ForwardDerivativesOf<T, Q, C, U>, Error>
where
    M: Equations<Q, C, U, T> + ?Sized,
    DefaultAllocator: Sizes<Q, C, U>,
{
    let (nq, nc, nu) = model.sizes();
    if nc.value() == 0 {
        // Written in place: these matrices are large enough that moving
        // them between functions showed in profiles (TALOS: 6 % of the
        // time in `memcpy`).
        let mut out = ForwardDerivativesOf {
            qdd: OVector::<T, Q>::zeros_generic(nq, Const::<1>),
            lambda: OVector::<T, C>::zeros_generic(nc, Const::<1>),
            qdd_q: OMatrix::<T, Q, Q>::zeros_generic(nq, nq),
            qdd_qd: OMatrix::<T, Q, Q>::zeros_generic(nq, nq),
            qdd_tau: OMatrix::<T, Q, U>::zeros_generic(nq, nu),
            lambda_q: OMatrix::<T, C, Q>::zeros_generic(nc, nq),
            lambda_qd: OMatrix::<T, C, Q>::zeros_generic(nc, nq),
            lambda_tau: OMatrix::<T, C, U>::zeros_generic(nc, nu),
            velocity_constraint_q: OMatrix::<T, C, Q>::zeros_generic(nc, nq),
            condition: T::one(),
        };
        if generated(model, q, qd, t, tau, &mut out)? {
            return Ok(out);
        }
    }
    let eval::Terms { m, h, phi_q, gamma } = eval::dynamics_terms(model, q, qd, t)?;
    let b = eval::actuator_map(model, t)?;
    let kkt = Kkt::new(m, &phi_q, T::KKT_MAX_CONDITION, t)?;
    let (qdd, lambda) = kkt.solve(&(b.clone() * tau - h), &gamma);
    eval::check_result(&qdd, Quantity::Acceleration, t)?;
    eval::check_result(&lambda, Quantity::ConstraintForces, t)?;

    let mut id = OVector::<T, Q>::zeros_generic(nq, Const::<1>);
    let mut id_q = OMatrix::<T, Q, Q>::zeros_generic(nq, nq);
    let mut id_qd = OMatrix::<T, Q, Q>::zeros_generic(nq, nq);
    if !model.inverse_dynamics_derivatives(q, qd, &qdd, t, &mut id, &mut id_q, &mut id_qd) {
        return Err(not_generated());
    }
    eval::check(&id_q, Quantity::InverseDynamicsDerivatives, t)?;
    eval::check(&id_qd, Quantity::InverseDynamicsDerivatives, t)?;

    // Right-hand sides of the differentiated saddle-point system.
    let mut a_q = OMatrix::<T, C, Q>::zeros_generic(nc, nq);
    let mut a_qd = OMatrix::<T, C, Q>::zeros_generic(nc, nq);
    if nc.value() > 0 {
        let a = |v: &OVector<T, Q>, a_q: &mut OMatrix<T, C, Q>, a_qd: &mut OMatrix<T, C, Q>| {
            if model.constraint_acceleration_derivatives(q, qd, v, t, a_q, a_qd) {
                eval::check(a_q, Quantity::InverseDynamicsDerivatives, t)?;
                eval::check(a_qd, Quantity::InverseDynamicsDerivatives, t)
            } else {
                Err(not_generated())
            }
        };
        a(&qdd, &mut a_q, &mut a_qd)?;
        // (Phi_q^T lambda)_q, row i: lambda^T (a_q(e_i) - a_q(0)).
        let mut base = OMatrix::<T, C, Q>::zeros_generic(nc, nq);
        let mut row = OMatrix::<T, C, Q>::zeros_generic(nc, nq);
        let mut scratch = OMatrix::<T, C, Q>::zeros_generic(nc, nq);
        let mut v = OVector::<T, Q>::zeros_generic(nq, Const::<1>);
        a(&v, &mut base, &mut scratch)?;
        for i in 0..nq.value() {
            v[i] = T::one();
            a(&v, &mut row, &mut scratch)?;
            v[i] = T::zero();
            row -= &base;
            // id_q - (Phi_q^T lambda)_q.
            let k = row.tr_mul(&lambda);
            for j in 0..nq.value() {
                id_q[(i, j)] -= k[j];
            }
        }
    }
    let mut qdd_q = OMatrix::<T, Q, Q>::zeros_generic(nq, nq);
    let mut qdd_qd = OMatrix::<T, Q, Q>::zeros_generic(nq, nq);
    let mut qdd_tau = OMatrix::<T, Q, U>::zeros_generic(nq, nu);
    let mut lambda_q = OMatrix::<T, C, Q>::zeros_generic(nc, nq);
    let mut lambda_qd = OMatrix::<T, C, Q>::zeros_generic(nc, nq);
    let mut lambda_tau = OMatrix::<T, C, U>::zeros_generic(nc, nu);
    for j in 0..nq.value() {
        let (x, mu) = kkt.solve(&-id_q.column(j), &-a_q.column(j));
        qdd_q.set_column(j, &x);
        lambda_q.set_column(j, &mu);
        let (x, mu) = kkt.solve(&-id_qd.column(j), &-a_qd.column(j));
        qdd_qd.set_column(j, &x);
        lambda_qd.set_column(j, &mu);
    }
    let zero = OVector::<T, C>::zeros_generic(nc, Const::<1>);
    for j in 0..nu.value() {
        let (x, mu) = kkt.solve(&b.column(j).clone_owned(), &zero);
        qdd_tau.set_column(j, &x);
        lambda_tau.set_column(j, &mu);
    }
    for m in [&qdd_q, &qdd_qd] {
        eval::check_result(m, Quantity::Acceleration, t)?;
    }
    eval::check_result(&qdd_tau, Quantity::Acceleration, t)?;
    for m in [&lambda_q, &lambda_qd] {
        eval::check_result(m, Quantity::ConstraintForces, t)?;
    }
    eval::check_result(&lambda_tau, Quantity::ConstraintForces, t)?;
    Ok(ForwardDerivativesOf {
        qdd,
        lambda,
        qdd_q,
        qdd_qd,
        qdd_tau,
        lambda_q,
        lambda_qd,
        lambda_tau,
        velocity_constraint_q: a_qd * T::of(0.5),
        condition: kkt.condition,
    })
}

/// [`forward_dynamics_derivatives`] of an unconstrained model from its
/// generated program ([`crate::Model::forward_dynamics_derivatives`]:
/// `qdd`, `d qdd/dq`, `d qdd/dqd` and `M^-1` on the generated factors of
/// `M`), `d qdd/d tau = M^-1 B`, written into `out` (zeros on entry);
/// `false` where the model has no such program or its pivots say the solve
/// does not hold (then the factorisation of the other paths reports why).
fn generated<M, T: Scalar, Q: Dim, C: Dim, U: Dim>(
    model: &M,
    q: &OVector<T, Q>,
    qd: &OVector<T, Q>,
    t: T,
    tau: &OVector<T, U>,
    out: &mut ForwardDerivativesOf<T, Q, C, U>,
) -> Result<bool, Error>
where
    M: Equations<Q, C, U, T> + ?Sized,
    DefaultAllocator: Sizes<Q, C, U>,
{
    let (nq, _, _) = model.sizes();
    let b = eval::actuator_map(model, t)?;
    let f = &b * tau;
    let mut d = OVector::<T, Q>::zeros_generic(nq, Const::<1>);
    let mut inverse = OMatrix::<T, Q, Q>::zeros_generic(nq, nq);
    let (dq, dqd, qdd) = (&mut out.qdd_q, &mut out.qdd_qd, &mut out.qdd);
    if !(model.forward_dynamics_derivatives(q, qd, &f, t, qdd, &mut d, dq, dqd, &mut inverse)
        && solved(&out.qdd, &d))
    {
        return Ok(false);
    }
    mul_sparse_acc(&inverse, &b, &mut out.qdd_tau);
    for m in [&out.qdd_q, &out.qdd_qd] {
        eval::check_result(m, Quantity::Acceleration, t)?;
    }
    eval::check_result(&out.qdd_tau, Quantity::Acceleration, t)?;
    Ok(true)
}

/// The error for a model without the generated derivatives.
fn not_generated() -> Error {
    invalid_configuration(
        "the model has no generated dynamics derivatives (scene `outputs = [\"dynamics_derivatives\"]`)",
    )
}
