//! The force solve `Phi_q^T lambda + B tau = M qdd + h` at a known motion:
//! the square fast path and the SVD path (module docs of the parent).

use super::{ForceReport, InverseConfig, SolvePath};
use crate::error::{Error, ErrorKind, Quantity};
use crate::eval;
use crate::linalg::{invert_in_place, mul_vec_acc, norm_squared, tr_mul_vec_acc, Svd};
use crate::model::{Equations, Sizes};
use crate::scalar::Scalar;
use crate::state::inf_norm;
use nalgebra::allocator::Allocator;
use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector, U1};

/// Inputs, multipliers and the report of a force solve.
pub(crate) type ForceSolution<T, C, U> = (OVector<T, U>, OVector<T, C>, ForceReport<T>);

/// Solves `Phi_q^T lambda + B tau = M qdd + h` at a known `(q, qd, qdd, t)`
/// (minimum-norm least squares, see the module docs). Returns
/// `(tau, lambda, report)`.
///
/// When [`InverseConfig::fast_path`] is set and `[Phi_q^T B]` is square
/// (`NC + NU = NQ`), it is inverted in place (as `J_f` is) and the
/// result is used if `Phi_q` has full rank and the actuation is well
/// conditioned by the bounds of the module docs (here: `|Phi_q|_F |S|_F <
/// 1 / rank_tolerance` and `|B|_F |T|_F <= max_condition`, with `S` and `T`
/// the `lambda` and `tau` rows of the inverse, `|T|_2` being exactly the
/// norm of the inverse of the projected actuation matrix); otherwise the SVDs
/// decide.
///
/// Errors: non-finite model outputs, [`ErrorKind::DecompositionNotConverged`],
/// [`ErrorKind::SingularActuation`], [`ErrorKind::NonFiniteResult`].
pub fn forces<M, T: Scalar, Q: Dim, C: Dim, U: Dim>(
    model: &M,
    config: &InverseConfig<T>,
    q: &OVector<T, Q>,
    qd: &OVector<T, Q>,
    qdd: &OVector<T, Q>,
    t: T,
) -> Result<ForceSolution<T, C, U>, Error>
where
    M: Equations<Q, C, U, T> + ?Sized,
    DefaultAllocator: Sizes<Q, C, U>,
{
    let mut r = OVector::<T, Q>::zeros_generic(q.shape_generic().0, U1);
    eval::inverse_dynamics_into(model, q, qd, qdd, t, &mut r)?;
    let b = eval::actuator_map(model, t)?;
    let phi_q = eval::constraint_jacobian(model, q, t)?;
    forces_from(config, &phi_q, &b, &r, t)
}

/// [`forces`] from evaluated `Phi_q`, `B` and `r = M qdd + h`.
pub(crate) fn forces_from<T: Scalar, Q: Dim, C: Dim, U: Dim>(
    config: &InverseConfig<T>,
    phi_q: &OMatrix<T, C, Q>,
    b: &OMatrix<T, Q, U>,
    r: &OVector<T, Q>,
    t: T,
) -> Result<ForceSolution<T, C, U>, Error>
where
    DefaultAllocator: Sizes<Q, C, U>,
{
    if config.fast_path && phi_q.nrows() + b.ncols() == r.nrows() {
        if let Some(solution) = forces_square(config, phi_q, b, r, t)? {
            return Ok(solution);
        }
    }
    forces_svd(config, phi_q, b, r, t)
}

/// Fast path of [`forces`] for `NC + NU = NQ`; `Ok(None)` when its
/// assumptions do not hold.
fn forces_square<T: Scalar, Q: Dim, C: Dim, U: Dim>(
    config: &InverseConfig<T>,
    phi_q: &OMatrix<T, C, Q>,
    b: &OMatrix<T, Q, U>,
    r: &OVector<T, Q>,
    t: T,
) -> Result<Option<ForceSolution<T, C, U>>, Error>
where
    DefaultAllocator: Sizes<Q, C, U>,
{
    let (nc, nq) = phi_q.shape_generic();
    let nu = b.shape_generic().1;
    let (c, n, u) = (nc.value(), nq.value(), nu.value());
    // [Phi_q^T B], inverted in place.
    let mut inv = OMatrix::<T, Q, Q>::zeros_generic(nq, nq);
    for j in 0..c {
        for i in 0..n {
            inv[(i, j)] = phi_q[(j, i)];
        }
    }
    for j in 0..u {
        for i in 0..n {
            inv[(i, c + j)] = b[(i, j)];
        }
    }
    if !invert_in_place(&mut inv) {
        return Ok(None);
    }
    let (mut s2, mut t2) = (T::zero(), T::zero());
    for j in 0..n {
        for i in 0..n {
            let x = inv[(i, j)] * inv[(i, j)];
            if i < c {
                s2 += x;
            } else {
                t2 += x;
            }
        }
    }
    let full_rank =
        Scalar::square_root(norm_squared(phi_q) * s2) * config.rank_tolerance < T::one();
    let actuation_condition = if u == 0 {
        T::one()
    } else {
        Scalar::square_root(norm_squared(b) * t2)
    };
    if !full_rank || !(actuation_condition <= config.max_condition) {
        return Ok(None);
    }
    let x = inv * r;
    let lambda = OVector::<T, C>::from_fn_generic(nc, U1, |i, _| x[i]);
    let tau = OVector::<T, U>::from_fn_generic(nu, U1, |j, _| x[c + j]);
    finish_forces(
        phi_q,
        b,
        r,
        (tau, lambda),
        c,
        actuation_condition,
        SolvePath::Elimination,
        t,
    )
    .map(Some)
}

/// Checks the results `(tau, lambda)` and computes the residual of a force
/// solve.
#[allow(clippy::too_many_arguments)]
pub(crate) fn finish_forces<T: Scalar, Q: Dim, C: Dim, U: Dim>(
    phi_q: &OMatrix<T, C, Q>,
    b: &OMatrix<T, Q, U>,
    r: &OVector<T, Q>,
    (tau, lambda): (OVector<T, U>, OVector<T, C>),
    constraint_rank: usize,
    actuation_condition: T,
    path: SolvePath,
    t: T,
) -> Result<ForceSolution<T, C, U>, Error>
where
    DefaultAllocator: Sizes<Q, C, U>,
{
    eval::check_result(&tau, Quantity::Input, t)?;
    eval::check_result(&lambda, Quantity::ConstraintForces, t)?;
    let mut res = -r;
    tr_mul_vec_acc(phi_q, lambda.as_slice(), res.as_mut_slice());
    mul_vec_acc(b, tau.as_slice(), res.as_mut_slice());
    let residual = inf_norm(&res);
    Ok((
        tau,
        lambda,
        ForceReport {
            constraint_rank,
            actuation_condition,
            residual,
            path,
        },
    ))
}

/// SVD path of [`forces`].
fn forces_svd<T: Scalar, Q: Dim, C: Dim, U: Dim>(
    config: &InverseConfig<T>,
    phi_q: &OMatrix<T, C, Q>,
    b: &OMatrix<T, Q, U>,
    r: &OVector<T, Q>,
    t: T,
) -> Result<ForceSolution<T, C, U>, Error>
where
    DefaultAllocator: Sizes<Q, C, U>,
{
    let (nc, nq) = phi_q.shape_generic();
    let nu = b.shape_generic().1;
    let p_svd = svd(&phi_q.transpose(), config.max_sweeps, t)?;
    let rank_c = p_svd.rank(config.rank_tolerance);
    // Components of r and B outside the range of Phi_q^T, i.e. along the
    // free motion directions.
    let mut r_free = r.clone();
    p_svd.remove_range(&mut r_free, rank_c);
    let mut b_free = b.clone();
    for j in 0..nu.value() {
        let mut col: OVector<T, Q> = b.column(j).into_owned();
        p_svd.remove_range(&mut col, rank_c);
        b_free.set_column(j, &col);
    }
    let b_svd = svd(&b_free, config.max_sweeps, t)?;
    let needed = nu.value().min(nq.value().saturating_sub(rank_c));
    let actuation_condition = b_svd.condition_of_leading(needed);
    if !(actuation_condition <= config.max_condition) {
        return Err(Error::new(
            ErrorKind::SingularActuation {
                condition: actuation_condition.into(),
                limit: config.max_condition.into(),
            },
            t,
        ));
    }
    let mut tau = OVector::<T, U>::zeros_generic(nu, U1);
    b_svd.solve(&r_free, needed, &mut tau);
    let mut lambda = OVector::<T, C>::zeros_generic(nc, U1);
    p_svd.solve(&(r - b * &tau), rank_c, &mut lambda);
    finish_forces(
        phi_q,
        b,
        r,
        (tau, lambda),
        rank_c,
        actuation_condition,
        SolvePath::Svd,
        t,
    )
}

/// The SVD of `a`, or [`ErrorKind::DecompositionNotConverged`] at `t`.
pub(crate) fn svd<T: Scalar, R: Dim, C: Dim>(
    a: &OMatrix<T, R, C>,
    max_sweeps: u32,
    t: T,
) -> Result<Svd<T, R, C>, Error>
where
    DefaultAllocator: Allocator<R, C> + Allocator<C, C> + Allocator<C> + Allocator<R>,
{
    Svd::new(a, max_sweeps)
        .map_err(|sweeps| Error::new(ErrorKind::DecompositionNotConverged { sweeps }, t))
}
