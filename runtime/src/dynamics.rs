//! Constrained forward dynamics: the KKT system
//!
//! ```text
//! M qdd - Phi_q^T lambda = B tau - h
//! Phi_q qdd              = gamma - 2 alpha (Phi_q qd + Phi_t) - beta^2 Phi
//! ```
//!
//! solved by a Schur complement on the stack: Cholesky `M = L L^T`,
//! `Y = L^-1 Phi_q^T`, `S = Y^T Y = Phi_q M^-1 Phi_q^T` factored by an
//! equilibrated, diagonally pivoted Cholesky whose pivot ratio is the
//! condition estimate reported (and checked) for the constraint Jacobian.

use crate::error::{Error, ErrorKind, Quantity};
use crate::eval;
use crate::linalg::{all_finite, cholesky, solve_lower, solve_lower_transpose, SpdSolver};
use crate::model::{Equations, Sizes};
use crate::scalar::Scalar;
use nalgebra::allocator::Allocator;
use nalgebra::{Const, DefaultAllocator, Dim, OMatrix, OVector};

/// Baumgarte stabilisation gains: the acceleration constraint becomes
/// `Phi_q qdd = gamma - 2 alpha dPhi/dt - beta^2 Phi`, which makes the
/// constraint violation obey `Phi'' + 2 alpha Phi' + beta^2 Phi = 0`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Baumgarte {
    /// Damping gain `alpha` (1/s).
    pub alpha: f64,
    /// Stiffness gain `beta` (1/s).
    pub beta: f64,
}

impl Baumgarte {
    /// No stabilisation (`alpha = beta = 0`): pure index-1 formulation.
    pub const NONE: Baumgarte = Baumgarte {
        alpha: 0.0,
        beta: 0.0,
    };
}

impl Default for Baumgarte {
    /// `alpha = beta = 10 / s` (critically damped violation, time constant 0.1 s).
    fn default() -> Self {
        Baumgarte {
            alpha: 10.0,
            beta: 10.0,
        }
    }
}

/// Configuration of the constrained acceleration solve.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DynamicsConfig<T: Scalar = f64> {
    /// Baumgarte gains.
    pub baumgarte: Baumgarte,
    /// Largest accepted condition estimate of the (equilibrated)
    /// `Phi_q M^-1 Phi_q^T`; above it the solve fails with
    /// [`ErrorKind::SingularConstraintJacobian`].
    pub max_condition: T,
}

impl<T: Scalar> Default for DynamicsConfig<T> {
    fn default() -> Self {
        DynamicsConfig {
            baumgarte: Baumgarte::default(),
            max_condition: T::KKT_MAX_CONDITION,
        }
    }
}

/// Result of a forward-dynamics solve, `Q` coordinates and `C`
/// constraints of fixed or run-time size ([`Accelerations`]: fixed).
#[derive(Clone, Debug, PartialEq)]
pub struct AccelerationsOf<T: Scalar, Q: Dim, C: Dim>
where
    DefaultAllocator: Allocator<Q> + Allocator<C>,
{
    /// Generalized accelerations `qdd`.
    pub qdd: OVector<T, Q>,
    /// Constraint forces (Lagrange multipliers) `lambda`; the generalized
    /// constraint force is `Phi_q^T lambda`.
    pub lambda: OVector<T, C>,
    /// Condition estimate of `Phi_q M^-1 Phi_q^T` (1 when unconstrained).
    pub condition: T,
}

impl<T: Scalar, const NQ: usize, const NC: usize> Copy
    for AccelerationsOf<T, Const<NQ>, Const<NC>>
{
}

/// [`AccelerationsOf`] of a model of fixed size.
pub type Accelerations<const NQ: usize, const NC: usize, T = f64> =
    AccelerationsOf<T, Const<NQ>, Const<NC>>;

/// Factored saddle-point matrix `[[M, Phi_q^T], [Phi_q, 0]]`.
pub(crate) struct Kkt<T: Scalar, Q: Dim, C: Dim>
where
    DefaultAllocator: Allocator<Q, Q> + Allocator<Q, C> + Allocator<C, C> + Allocator<C>,
{
    l: OMatrix<T, Q, Q>,
    y: OMatrix<T, Q, C>,
    s: SpdSolver<T, C>,
    pub(crate) condition: T,
}

impl<T: Scalar, Q: Dim, C: Dim> Kkt<T, Q, C>
where
    DefaultAllocator: Allocator<Q, Q>
        + Allocator<Q, C>
        + Allocator<C, C>
        + Allocator<C>
        + Allocator<C, Q>
        + Allocator<Q>,
{
    /// Factors the KKT matrix; errors are reported at time `t`.
    pub(crate) fn new(
        mut m: OMatrix<T, Q, Q>,
        phi_q: &OMatrix<T, C, Q>,
        max_condition: T,
        t: T,
    ) -> Result<Self, Error> {
        factor_mass(&mut m, t)?;
        let mut y = phi_q.transpose();
        solve_lower(&m, &mut y);
        let s_mat = y.transpose() * &y;
        match SpdSolver::factor(&s_mat, max_condition) {
            Ok((s, condition)) => Ok(Kkt {
                l: m,
                y,
                s,
                condition,
            }),
            Err(condition) => Err(Error::new(
                ErrorKind::SingularConstraintJacobian {
                    condition: condition.into(),
                    limit: max_condition.into(),
                },
                t,
            )),
        }
    }

    /// `sqrt(v^T M^-1 v)`.
    pub(crate) fn inverse_mass_norm(&self, v: &OVector<T, Q>) -> T {
        let mut z = v.clone();
        solve_lower(&self.l, &mut z);
        z.norm()
    }

    /// Solves `M x - Phi_q^T mu = f`, `Phi_q x = c`.
    pub(crate) fn solve(
        &self,
        f: &OVector<T, Q>,
        c: &OVector<T, C>,
    ) -> (OVector<T, Q>, OVector<T, C>) {
        let mut z = f.clone();
        solve_lower(&self.l, &mut z);
        let mut mu = c - self.y.transpose() * &z;
        self.s.solve(&mut mu);
        let mut x = z + &self.y * &mu;
        solve_lower_transpose(&self.l, &mut x);
        (x, mu)
    }
}

/// Overwrites `m` with its Cholesky factor `L` (`M = L L^T`); errors are
/// reported at time `t`.
pub(crate) fn factor_mass<T: Scalar, Q: Dim>(m: &mut OMatrix<T, Q, Q>, t: T) -> Result<(), Error>
where
    DefaultAllocator: Allocator<Q, Q>,
{
    cholesky(m).map_err(|(pivot, value)| {
        Error::new(
            ErrorKind::MassMatrixNotPositiveDefinite {
                pivot,
                value: value.into(),
            },
            t,
        )
    })
}

/// Solves the constrained equations of motion for the accelerations and
/// constraint forces at `(q, qd, t)` with actuator input `tau`.
///
/// The inputs are assumed finite (the integrators check them); model outputs
/// are checked. Errors: [`ErrorKind::NonFiniteModelOutput`],
/// [`ErrorKind::MassMatrixNotPositiveDefinite`],
/// [`ErrorKind::SingularConstraintJacobian`], [`ErrorKind::NonFiniteResult`].
pub fn accelerations<M, T: Scalar, Q: Dim, C: Dim, U: Dim>(
    model: &M,
    config: &DynamicsConfig<T>,
    q: &OVector<T, Q>,
    qd: &OVector<T, Q>,
    t: T,
    tau: &OVector<T, U>,
) -> Result<AccelerationsOf<T, Q, C>, Error>
where
    M: Equations<Q, C, U, T> + ?Sized,
    DefaultAllocator: Sizes<Q, C, U>,
{
    if let Some(generated) = generated_forward_dynamics(model, q, qd, t, tau)? {
        return Ok(generated);
    }
    let eval::Terms { m, h, phi_q, gamma } = eval::dynamics_terms(model, q, qd, t)?;
    let f = eval::actuator_forces(model, tau, t)? - h;
    let c = stabilised_rhs(model, &config.baumgarte, q, qd, t, &phi_q, gamma)?;
    let kkt = Kkt::new(m, &phi_q, config.max_condition, t)?;
    let (qdd, lambda) = kkt.solve(&f, &c);
    eval::check_result(&qdd, Quantity::Acceleration, t)?;
    eval::check_result(&lambda, Quantity::ConstraintForces, t)?;
    Ok(AccelerationsOf {
        qdd,
        lambda,
        condition: kkt.condition,
    })
}

/// The accelerations of an unconstrained model by its generated
/// [`Equations::forward_dynamics`] (one program, `M` factored on the graph),
/// where it has one, every acceleration is finite and every pivot relative
/// to its diagonal entry of `M` is above epsilon (the factorisation's own
/// criterion); `None` sends the caller to the factorisation of `M`, which
/// reports what is wrong (a mass matrix that is not positive definite, a
/// non-finite output).
///
/// Not inlined: in one function with the fallback (the generated
/// `dynamics_terms` and the factorisation, inlined too) the generated
/// program ran about 1.3x slower (the UR5's `accelerations`, 453 ns to
/// 340 ns in a criterion run on the shared cores).
#[inline(never)]
pub(crate) fn generated_forward_dynamics<M, T: Scalar, Q: Dim, C: Dim, U: Dim>(
    model: &M,
    q: &OVector<T, Q>,
    qd: &OVector<T, Q>,
    t: T,
    tau: &OVector<T, U>,
) -> Result<Option<AccelerationsOf<T, Q, C>>, Error>
where
    M: Equations<Q, C, U, T> + ?Sized,
    DefaultAllocator: Sizes<Q, C, U>,
{
    let (nq, nc, _) = model.sizes();
    if nc.value() != 0 {
        return Ok(None);
    }
    let f = eval::actuator_forces(model, tau, t)?;
    let mut qdd = OVector::<T, Q>::zeros_generic(nq, Const::<1>);
    let mut d = qdd.clone();
    let valid = model.forward_dynamics(q, qd, &f, t, &mut qdd, &mut d) && solved(&qdd, &d);
    Ok(valid.then(|| AccelerationsOf {
        qdd,
        lambda: OVector::<T, C>::zeros_generic(nc, Const::<1>),
        condition: T::one(),
    }))
}

/// Whether a generated solve of `M = L^T D L` holds: every pivot `d`
/// (relative to `M`'s diagonal) finite and above the precision's epsilon,
/// and the accelerations `qdd` finite.
pub(crate) fn solved<T: Scalar, Q: Dim>(qdd: &OVector<T, Q>, d: &OVector<T, Q>) -> bool
where
    DefaultAllocator: Allocator<Q>,
{
    d.iter().all(|&p| p.is_finite() && p > T::EPSILON) && all_finite(qdd)
}

/// `gamma - 2 alpha (Phi_q qd + Phi_t) - beta^2 Phi` from the given `Phi_q`
/// and `gamma` (zero-sized when `NC == 0`).
pub(crate) fn stabilised_rhs<M, T: Scalar, Q: Dim, C: Dim, U: Dim>(
    model: &M,
    gains: &Baumgarte,
    q: &OVector<T, Q>,
    qd: &OVector<T, Q>,
    t: T,
    phi_q: &OMatrix<T, C, Q>,
    gamma: OVector<T, C>,
) -> Result<OVector<T, C>, Error>
where
    M: Equations<Q, C, U, T> + ?Sized,
    DefaultAllocator: Sizes<Q, C, U>,
{
    if gamma.nrows() == 0 {
        return Ok(gamma);
    }
    let mut c = gamma;
    if gains.alpha != 0.0 || gains.beta != 0.0 {
        let phi = eval::constraints(model, q, t)?;
        let phi_t = eval::constraint_time_derivative(model, q, t)?;
        let phi_dot = phi_q * qd + phi_t;
        c -= phi_dot * T::of(2.0 * gains.alpha) + phi * T::of(gains.beta * gains.beta);
    }
    Ok(c)
}
