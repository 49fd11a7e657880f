//! Inverse dynamics along a prescribed motion: the real-time torque path.
//!
//! Given the values, velocities and accelerations of `NP` prescribed
//! coordinates (for a parallel robot: the platform pose), one call of
//! [`InverseDynamics::solve`]
//!
//! 1. solves `Phi(q, t) = 0` for the other coordinates by Newton from the
//!    previous solution (bounded iterations, minimum-norm steps),
//! 2. solves `[Phi_q; S] qd = [-Phi_t; v]` and `[Phi_q; S] qdd = [gamma; a]`
//!    (`S` selects the prescribed coordinates),
//! 3. solves `Phi_q^T lambda + B tau = M qdd + h` for the actuator inputs and
//!    constraint forces ([`forces`]), `M qdd + h` from one call of
//!    [`Model::inverse_dynamics`] (generated models compute it without
//!    forming `M`) and `gamma` from [`Model::constraint_rhs`].
//!
//! **Fast path** (the common, well-posed case, e.g. a non-redundant parallel
//! robot): when the Jacobian of the free coordinates `J_f` (the columns of
//! `Phi_q` of the coordinates that are not prescribed) is square, it is
//! inverted once per call on the stack (`invert_in_place`: small diagonal
//! blocks, such as one 3 x 3 block per chain of a parallel robot, in closed
//! form, anything else by Gauss–Jordan elimination with partial pivoting),
//! and everything reuses that inverse:
//!
//! * Newton runs as a chord (simplified Newton) iteration with the inverse
//!   from the previous call, i.e. at the previous solution; it re-factors at
//!   the current iterate whenever the residual does not shrink by a factor 4
//!   per step (the residual test keeps it exact). Its iterates after the
//!   first are evaluated with [`Model::constraints_and_jacobian`], so the
//!   Jacobian at the solution comes with its last residual;
//! * with `X = J_f^-1 J_p` (`J_p`: the prescribed columns),
//!   `qd_f = -J_f^-1 (Phi_t + J_p v)` and `qdd_f = J_f^-1 (gamma - J_p a)`;
//! * the forces: the null space of `Phi_q` is spanned by the columns of
//!   `N = [-X; I]` (free rows; prescribed rows), and `N^T Phi_q^T = 0`, so
//!   `G tau = r_p - X^T r_f` with `G = N^T B = B_p - X^T B_f` (`NP x NU`,
//!   square when `NU = NP`) and `r = M qdd + h`; then
//!   `lambda = J_f^-T (r_f - B_f tau)` exactly.
//!
//! The fast path is taken only where it is known to give what the SVD path
//! gives. Its conditioning checks are upper bounds of the SVD quantities
//! (from explicit inverses, so rigorous up to rounding):
//! `cond_2(J_f) <= |J_f|_F |J_f^-1|_F`; `Phi_q` has full row rank when
//! `|Phi_q|_F |J_f^-1|_F < 1 / rank_tolerance`; and the condition of `B`
//! projected onto the null space is at most
//! `min(|G|_F, |B|_F) |G^-1|_F sqrt(1 + |X|_F^2)`. Whenever an assumption
//! fails (not square, zero pivot, a bound above its limit) the call falls
//! back to the SVD path below, which decides (and reports errors) exactly as
//! before. [`InverseReport::kinematics`] and [`ForceReport::path`] say which
//! path was taken.
//!
//! **SVD path**: one-sided Jacobi SVDs on the stack with capped sweep counts,
//! so redundancy is handled by minimum-norm least squares: redundant
//! constraints give the minimum-norm `lambda`, redundant actuation the
//! minimum-norm `tau`; an under-actuated system gets the least-squares `tau`
//! and a non-zero `force_residual` in the report.

mod forces;
mod solver;

pub use forces::forces;
pub use solver::{InverseDynamics, InverseDynamicsOf};

use crate::scalar::Scalar;
use nalgebra::allocator::Allocator;
use nalgebra::{Const, DefaultAllocator, Dim, OVector, U1};

/// Configuration of the inverse-dynamics solver.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InverseConfig<T: Scalar = f64> {
    /// Target `max |Phi|` of the position solve (model units).
    pub position_tolerance: T,
    /// Cap on Newton iterations of the position solve.
    pub max_iterations: u32,
    /// Singular values below `rank_tolerance * sigma_max` count as zero when
    /// deciding the rank of `Phi_q` (redundant constraints).
    pub rank_tolerance: T,
    /// Largest accepted condition (`sigma_max / sigma_k`) of the Jacobian of
    /// the free coordinates and of the projected actuation matrix.
    pub max_condition: T,
    /// Cap on Jacobi SVD sweeps.
    pub max_sweeps: u32,
    /// Try the fast path (square systems inverted on the stack,
    /// see the module docs) before the SVDs. `false` forces the SVD path
    /// everywhere (reference results, diagnostics).
    pub fast_path: bool,
}

impl<T: Scalar> Default for InverseConfig<T> {
    fn default() -> Self {
        InverseConfig {
            position_tolerance: T::POSITION_TOLERANCE,
            max_iterations: 20,
            rank_tolerance: T::RANK_TOLERANCE,
            max_condition: T::MAX_CONDITION,
            max_sweeps: 40,
            fast_path: true,
        }
    }
}

/// Full solution of one inverse-dynamics call, `Q` coordinates, `C`
/// constraints and `U` inputs of fixed or run-time size
/// ([`InverseSolution`]: fixed).
#[derive(Clone, Debug, PartialEq)]
pub struct InverseSolutionOf<T: Scalar, Q: Dim, C: Dim, U: Dim>
where
    DefaultAllocator: Allocator<Q> + Allocator<C> + Allocator<U>,
{
    /// Time.
    pub t: T,
    /// All coordinates.
    pub q: OVector<T, Q>,
    /// All velocities.
    pub qd: OVector<T, Q>,
    /// All accelerations.
    pub qdd: OVector<T, Q>,
    /// Actuator inputs.
    pub tau: OVector<T, U>,
    /// Constraint forces (multipliers; generalized force `Phi_q^T lambda`).
    pub lambda: OVector<T, C>,
}

impl<T: Scalar, Q: Dim, C: Dim, U: Dim> InverseSolutionOf<T, Q, C, U>
where
    DefaultAllocator: Allocator<Q> + Allocator<C> + Allocator<U>,
{
    /// All zeros, for the sizes `(Q, C, U)` (e.g. [`crate::Equations::sizes`]).
    pub fn zeros((nq, nc, nu): (Q, C, U)) -> Self {
        InverseSolutionOf {
            t: T::zero(),
            q: OVector::zeros_generic(nq, U1),
            qd: OVector::zeros_generic(nq, U1),
            qdd: OVector::zeros_generic(nq, U1),
            tau: OVector::zeros_generic(nu, U1),
            lambda: OVector::zeros_generic(nc, U1),
        }
    }
}

/// [`InverseSolutionOf`] of a model of fixed size.
pub type InverseSolution<const NQ: usize, const NC: usize, const NU: usize, T = f64> =
    InverseSolutionOf<T, Const<NQ>, Const<NC>, Const<NU>>;

impl<T: Scalar, const NQ: usize, const NC: usize, const NU: usize> Copy
    for InverseSolution<NQ, NC, NU, T>
{
}

impl<T: Scalar, const NQ: usize, const NC: usize, const NU: usize> Default
    for InverseSolution<NQ, NC, NU, T>
{
    fn default() -> Self {
        InverseSolutionOf::zeros((Const, Const, Const))
    }
}

/// Which method solved a linear system (see the module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum SolvePath {
    /// Fast path: a square system inverted on the stack (small diagonal
    /// blocks in closed form, otherwise Gauss–Jordan elimination with
    /// partial pivoting); the reported conditions are upper bounds of the
    /// 2-norm conditions the SVD path would report.
    #[default]
    Elimination,
    /// Jacobi SVD, minimum-norm least squares (redundant or not well-posed
    /// systems, or [`InverseConfig::fast_path`] off); conditions are exact
    /// 2-norm ratios of singular values.
    Svd,
}

/// Diagnostics of one inverse-dynamics call.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct InverseReport<T: Scalar = f64> {
    /// Newton iterations of the position solve.
    pub iterations: u32,
    /// Jacobians evaluated and factored in this call (inverses of `J_f` or
    /// SVDs), the one at the solution included: 1 when the chord iteration
    /// with the previous call's inverse converged.
    pub factorizations: u32,
    /// `max |Phi|` at the solution.
    pub position_residual: T,
    /// `max |Phi_q qd + Phi_t|` at the solution.
    pub velocity_residual: T,
    /// `max |Phi_q qdd - gamma|` at the solution.
    pub acceleration_residual: T,
    /// Condition of the Jacobian of the free coordinates at the solution:
    /// `sigma_max / sigma_min` on the SVD path, its upper bound
    /// `|J_f|_F |J_f^-1|_F` (at most `NC` times larger) on the fast path.
    pub jacobian_condition: T,
    /// How the velocity and acceleration systems were solved.
    pub kinematics: SolvePath,
    /// Diagnostics of the force solve.
    pub forces: ForceReport<T>,
}

/// Diagnostics of [`forces`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ForceReport<T: Scalar = f64> {
    /// Numerical rank of `Phi_q`.
    pub constraint_rank: usize,
    /// Condition of `B` projected onto the null space of `Phi_q`, over the
    /// singular values that must be non-zero (`min(NU, NQ - rank Phi_q)`);
    /// an upper bound of it on the fast path.
    pub actuation_condition: T,
    /// `max |Phi_q^T lambda + B tau - (M qdd + h)|`: zero (to rounding) unless
    /// the system is under-actuated for this motion.
    pub residual: T,
    /// How the system was solved.
    pub path: SolvePath,
}
