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

use crate::error::{Error, ErrorKind, Quantity};
use crate::eval;
use crate::linalg::{
    all_finite, first_non_finite, invert_in_place, mul_vec_acc, norm_squared, tr_mul_vec_acc, Svd,
};
use crate::model::Model;
use crate::scalar::Scalar;
use crate::state::inf_norm;
use nalgebra::{SMatrix, SVector};

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

/// Full solution of one inverse-dynamics call.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InverseSolution<const NQ: usize, const NC: usize, const NU: usize, T: Scalar = f64> {
    /// Time.
    pub t: T,
    /// All coordinates.
    pub q: SVector<T, NQ>,
    /// All velocities.
    pub qd: SVector<T, NQ>,
    /// All accelerations.
    pub qdd: SVector<T, NQ>,
    /// Actuator inputs.
    pub tau: SVector<T, NU>,
    /// Constraint forces (multipliers; generalized force `Phi_q^T lambda`).
    pub lambda: SVector<T, NC>,
}

impl<T: Scalar, const NQ: usize, const NC: usize, const NU: usize> Default
    for InverseSolution<NQ, NC, NU, T>
{
    fn default() -> Self {
        InverseSolution {
            t: T::zero(),
            q: SVector::zeros(),
            qd: SVector::zeros(),
            qdd: SVector::zeros(),
            tau: SVector::zeros(),
            lambda: SVector::zeros(),
        }
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

/// Solves `Phi_q^T lambda + B tau = M qdd + h` at a known `(q, qd, qdd, t)`
/// (minimum-norm least squares, see the module docs). Returns
/// `(tau, lambda, report)`.
///
/// When [`InverseConfig::fast_path`] is set and `[Phi_q^T B]` is square
/// (`NC + NU = NQ`), it is inverted on the stack (as `J_f` is) and the
/// result is used if `Phi_q` has full rank and the actuation is well
/// conditioned by the bounds of the module docs (here: `|Phi_q|_F |S|_F <
/// 1 / rank_tolerance` and `|B|_F |T|_F <= max_condition`, with `S` and `T`
/// the `lambda` and `tau` rows of the inverse, `|T|_2` being exactly the
/// norm of the inverse of the projected actuation matrix); otherwise the SVDs
/// decide.
///
/// Errors: non-finite model outputs, [`ErrorKind::DecompositionNotConverged`],
/// [`ErrorKind::SingularActuation`], [`ErrorKind::NonFiniteResult`].
#[allow(clippy::type_complexity)]
pub fn forces<M, T: Scalar, const NQ: usize, const NC: usize, const NU: usize>(
    model: &M,
    config: &InverseConfig<T>,
    q: &SVector<T, NQ>,
    qd: &SVector<T, NQ>,
    qdd: &SVector<T, NQ>,
    t: T,
) -> Result<(SVector<T, NU>, SVector<T, NC>, ForceReport<T>), Error>
where
    M: Model<NQ, NC, NU, T>,
{
    let mut r = SVector::<T, NQ>::zeros();
    eval::inverse_dynamics_into(model, q, qd, qdd, t, &mut r)?;
    let b = eval::actuator_map(model, t)?;
    let phi_q = eval::constraint_jacobian(model, q, t)?;
    forces_from(config, &phi_q, &b, &r, t)
}

type ForceSolution<T, const NC: usize, const NU: usize> =
    (SVector<T, NU>, SVector<T, NC>, ForceReport<T>);

/// [`forces`] from evaluated `Phi_q`, `B` and `r = M qdd + h`.
fn forces_from<T: Scalar, const NQ: usize, const NC: usize, const NU: usize>(
    config: &InverseConfig<T>,
    phi_q: &SMatrix<T, NC, NQ>,
    b: &SMatrix<T, NQ, NU>,
    r: &SVector<T, NQ>,
    t: T,
) -> Result<ForceSolution<T, NC, NU>, Error> {
    if config.fast_path && NC + NU == NQ {
        if let Some(solution) = forces_square(config, phi_q, b, r, t)? {
            return Ok(solution);
        }
    }
    forces_svd(config, phi_q, b, r, t)
}

/// Fast path of [`forces`] for `NC + NU = NQ`; `Ok(None)` when its
/// assumptions do not hold.
fn forces_square<T: Scalar, const NQ: usize, const NC: usize, const NU: usize>(
    config: &InverseConfig<T>,
    phi_q: &SMatrix<T, NC, NQ>,
    b: &SMatrix<T, NQ, NU>,
    r: &SVector<T, NQ>,
    t: T,
) -> Result<Option<ForceSolution<T, NC, NU>>, Error> {
    // [Phi_q^T B], inverted in place.
    let mut inv = SMatrix::<T, NQ, NQ>::zeros();
    for j in 0..NC {
        for i in 0..NQ {
            inv[(i, j)] = phi_q[(j, i)];
        }
    }
    for j in 0..NU {
        for i in 0..NQ {
            inv[(i, NC + j)] = b[(i, j)];
        }
    }
    if !invert_in_place(&mut inv) {
        return Ok(None);
    }
    let (mut s2, mut t2) = (T::zero(), T::zero());
    for j in 0..NQ {
        for i in 0..NQ {
            let x = inv[(i, j)] * inv[(i, j)];
            if i < NC {
                s2 += x;
            } else {
                t2 += x;
            }
        }
    }
    let full_rank =
        Scalar::square_root(norm_squared(phi_q) * s2) * config.rank_tolerance < T::one();
    let actuation_condition = if NU == 0 {
        T::one()
    } else {
        Scalar::square_root(norm_squared(b) * t2)
    };
    if !full_rank || !(actuation_condition <= config.max_condition) {
        return Ok(None);
    }
    let x = inv * r;
    let mut lambda = SVector::<T, NC>::zeros();
    let mut tau = SVector::<T, NU>::zeros();
    for i in 0..NC {
        lambda[i] = x[i];
    }
    for j in 0..NU {
        tau[j] = x[NC + j];
    }
    finish_forces(
        phi_q,
        b,
        r,
        tau,
        lambda,
        NC,
        actuation_condition,
        SolvePath::Elimination,
        t,
    )
    .map(Some)
}

/// Checks the results and computes the residual of a force solve.
#[allow(clippy::too_many_arguments)]
fn finish_forces<T: Scalar, const NQ: usize, const NC: usize, const NU: usize>(
    phi_q: &SMatrix<T, NC, NQ>,
    b: &SMatrix<T, NQ, NU>,
    r: &SVector<T, NQ>,
    tau: SVector<T, NU>,
    lambda: SVector<T, NC>,
    constraint_rank: usize,
    actuation_condition: T,
    path: SolvePath,
    t: T,
) -> Result<ForceSolution<T, NC, NU>, Error> {
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
fn forces_svd<T: Scalar, const NQ: usize, const NC: usize, const NU: usize>(
    config: &InverseConfig<T>,
    phi_q: &SMatrix<T, NC, NQ>,
    b: &SMatrix<T, NQ, NU>,
    r: &SVector<T, NQ>,
    t: T,
) -> Result<ForceSolution<T, NC, NU>, Error> {
    let p_svd = svd(&phi_q.transpose(), config.max_sweeps, t)?;
    let rank_c = p_svd.rank(config.rank_tolerance);
    // Components of r and B outside the range of Phi_q^T, i.e. along the
    // free motion directions.
    let mut r_free = *r;
    p_svd.remove_range(&mut r_free, rank_c);
    let mut b_free = *b;
    for j in 0..NU {
        let mut col: SVector<T, NQ> = b.column(j).into_owned();
        p_svd.remove_range(&mut col, rank_c);
        b_free.set_column(j, &col);
    }
    let b_svd = svd(&b_free, config.max_sweeps, t)?;
    let needed = NU.min(NQ.saturating_sub(rank_c));
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
    let mut tau = SVector::<T, NU>::zeros();
    b_svd.solve(&r_free, needed, &mut tau);
    let mut lambda = SVector::<T, NC>::zeros();
    p_svd.solve(&(r - b * tau), rank_c, &mut lambda);
    finish_forces(
        phi_q,
        b,
        r,
        tau,
        lambda,
        rank_c,
        actuation_condition,
        SolvePath::Svd,
        t,
    )
}

fn svd<T: Scalar, const R: usize, const C: usize>(
    a: &SMatrix<T, R, C>,
    max_sweeps: u32,
    t: T,
) -> Result<Svd<R, C, T>, Error> {
    Svd::new(a, max_sweeps)
        .map_err(|sweeps| Error::new(ErrorKind::DecompositionNotConverged { sweeps }, t))
}

/// What [`InverseDynamics::free_inverse`] found besides the inverse.
#[derive(Clone, Copy)]
struct FreeInverse<T: Scalar> {
    /// `|J_f|_F |J_f^-1|_F`.
    condition: T,
    /// `|J_f|_F^2`.
    jf_norm2: T,
    /// `|J_f^-1|_F^2`.
    inv_norm2: T,
}

/// Which inverse of `J_f` the chord steps use.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Chord {
    /// None: the next step is a full Newton step.
    None,
    /// The previous call's, at the guess.
    Cached,
    /// One computed at an earlier iterate of this call.
    Local,
}

/// A chord (simplified Newton) step with an old inverse of the free Jacobian
/// must reduce `max |Phi|` at least by this factor; otherwise the Jacobian is
/// re-evaluated and inverted at the current iterate.
const CHORD_CONTRACTION: f64 = 0.25;

/// Inverse dynamics with `NP` prescribed coordinates; keeps the previous
/// position solution as the Newton starting point of the next call, and on
/// the fast path the inverse of the free-coordinate Jacobian there.
/// Two solvers are equal when their settings and that kept state are (the
/// scratch storage of a call does not count).
#[derive(Clone, Copy, Debug)]
pub struct InverseDynamics<
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NP: usize,
    T: Scalar = f64,
> {
    /// Solver settings.
    pub config: InverseConfig<T>,
    prescribed: [usize; NP],
    /// The free coordinates in increasing order (the first `NQ - NP` entries).
    free: [usize; NQ],
    guess: SVector<T, NQ>,
    /// `J_f^-1` at `guess` (fast path), if known.
    jacobian_inverse: Option<SMatrix<T, NC, NC>>,
    /// Time, velocities and accelerations of the solution `guess`, for the
    /// second-order predictor of the next starting point.
    motion: Option<(T, SVector<T, NQ>, SVector<T, NQ>)>,
    /// Scratch for the Jacobians of two Newton iterates (overwritten before
    /// every read; kept here so that a call does not clear them).
    jacobians: [SMatrix<T, NC, NQ>; 2],
}

impl<T: Scalar, const NQ: usize, const NC: usize, const NU: usize, const NP: usize> PartialEq
    for InverseDynamics<NQ, NC, NU, NP, T>
{
    fn eq(&self, other: &Self) -> bool {
        self.config == other.config
            && self.prescribed == other.prescribed
            && self.free == other.free
            && self.guess == other.guess
            && self.jacobian_inverse == other.jacobian_inverse
            && self.motion == other.motion
    }
}

impl<T: Scalar, const NQ: usize, const NC: usize, const NU: usize, const NP: usize>
    InverseDynamics<NQ, NC, NU, NP, T>
{
    /// Creates the solver for the coordinates `prescribed` (indices into `q`),
    /// starting the first position solve from `initial_guess`.
    ///
    /// Fails with [`ErrorKind::InvalidIndex`] if an index is out of range or
    /// repeated, with [`ErrorKind::InvalidConfiguration`] if there are fewer
    /// constraints than free coordinates (`NC < NQ - NP`, the motion would be
    /// under-determined);
    /// with [`ErrorKind::NonFiniteState`] if the guess is not finite.
    pub fn new(
        prescribed: [usize; NP],
        initial_guess: SVector<T, NQ>,
        config: InverseConfig<T>,
    ) -> Result<Self, Error> {
        crate::error::check_indices("prescribed coordinate", &prescribed, NQ, true)?;
        if NP > NQ || NC < NQ - NP {
            return Err(Error::new(
                ErrorKind::InvalidConfiguration {
                    reason: "fewer constraints than free coordinates: the motion is not determined",
                },
                T::zero(),
            ));
        }
        if let Some(index) = first_non_finite(&initial_guess) {
            return Err(Error::new(
                ErrorKind::NonFiniteState {
                    quantity: Quantity::Position,
                    index,
                },
                T::zero(),
            ));
        }
        let mut free = [0usize; NQ];
        let mut n = 0;
        for i in 0..NQ {
            if !prescribed.contains(&i) {
                free[n] = i;
                n += 1;
            }
        }
        Ok(InverseDynamics {
            config,
            prescribed,
            free,
            guess: initial_guess,
            jacobian_inverse: None,
            motion: None,
            jacobians: [SMatrix::zeros(); 2],
        })
    }

    /// The prescribed coordinate indices.
    pub fn prescribed(&self) -> &[usize; NP] {
        &self.prescribed
    }

    /// The current Newton starting point (the last solution).
    pub fn guess(&self) -> &SVector<T, NQ> {
        &self.guess
    }

    /// Replaces the Newton starting point (e.g. to select an assembly mode).
    pub fn set_guess(&mut self, q: SVector<T, NQ>) {
        self.guess = q;
        self.jacobian_inverse = None;
        self.motion = None;
    }

    /// Whether the fast path applies to the shape: `J_f` square.
    fn square(&self) -> bool {
        self.config.fast_path && NP <= NQ && NC == NQ - NP
    }

    /// `Phi_q` with the prescribed columns zeroed.
    fn free_jacobian(&self, phi_q: &SMatrix<T, NC, NQ>) -> SMatrix<T, NC, NQ> {
        let mut j = *phi_q;
        for &i in self.prescribed.iter() {
            j.column_mut(i).fill(T::zero());
        }
        j
    }

    /// Writes `J_f^-1` to `inv` and returns the bound `|J_f|_F |J_f^-1|_F` of
    /// its condition with the squared norms, if `J_f` is invertible and the
    /// bound is within `limit` (call only when [`Self::square`]).
    fn free_inverse(
        &self,
        phi_q: &SMatrix<T, NC, NQ>,
        limit: T,
        inv: &mut SMatrix<T, NC, NC>,
    ) -> Option<FreeInverse<T>> {
        // Column copies through the slices (nalgebra's column views copy
        // element by element).
        let (from, to) = (phi_q.as_slice(), inv.as_mut_slice());
        for (k, col) in to.chunks_exact_mut(NC.max(1)).enumerate() {
            let i = self.free[k];
            col.copy_from_slice(&from[i * NC..(i + 1) * NC]);
        }
        let jf_norm2 = norm_squared(inv);
        if !invert_in_place(inv) {
            return None;
        }
        let inv_norm2 = norm_squared(inv);
        let condition = if NC == 0 {
            T::one()
        } else {
            Scalar::square_root(jf_norm2 * inv_norm2)
        };
        (condition <= limit).then_some(FreeInverse {
            condition,
            jf_norm2,
            inv_norm2,
        })
    }

    /// Newton starting point for prescribed positions `p` at `t`: the last
    /// solution, with its free coordinates moved along its own motion,
    /// `q + qd dt + qdd dt^2 / 2` (`dt` the time since it), when that
    /// extrapolation predicts the prescribed coordinates at least four times
    /// better than the last solution does (a smooth trajectory with
    /// consistent `v` and `a`); otherwise (jumps, quasi-static use with zero
    /// `v` and `a`, first call) the last solution itself. The prescribed
    /// coordinates are set to `p`.
    fn start(&self, t: T, p: &SVector<T, NP>) -> SVector<T, NQ> {
        let mut q = self.guess;
        if let Some((t0, qd, qdd)) = &self.motion {
            let dt = t - *t0;
            let (mut err_predicted, mut err_held) = (T::zero(), T::zero());
            for (k, &i) in self.prescribed.iter().enumerate() {
                let predicted = q[i] + dt * (qd[i] + T::of(0.5) * dt * qdd[i]);
                err_predicted = err_predicted.max((p[k] - predicted).abs());
                err_held = err_held.max((p[k] - q[i]).abs());
            }
            if T::of(4.0) * err_predicted <= err_held {
                let moved = q + (qd + qdd * (T::of(0.5) * dt)) * dt;
                if all_finite(&moved) {
                    q = moved;
                }
            }
        }
        for (k, &i) in self.prescribed.iter().enumerate() {
            q[i] = p[k];
        }
        q
    }

    /// Vector with the prescribed entries set to `x` and zeros elsewhere.
    fn scatter(&self, x: &SVector<T, NP>) -> SVector<T, NQ> {
        let mut v = SVector::<T, NQ>::zeros();
        for (k, &i) in self.prescribed.iter().enumerate() {
            v[i] = x[k];
        }
        v
    }

    /// `y` with its free entries set to `x_f` (call only when [`Self::square`]).
    fn scatter_free(&self, x_f: &SVector<T, NC>, y: &mut SVector<T, NQ>) {
        for k in 0..NC {
            y[self.free[k]] = x_f[k];
        }
    }

    /// One inverse-dynamics evaluation at time `t` for prescribed positions
    /// `p`, velocities `v` and accelerations `a` (in the order of
    /// `prescribed`). Writes the full solution to `out`. On error `out` and
    /// the solver are unchanged.
    ///
    /// Errors: [`ErrorKind::NonFiniteInput`], non-finite model outputs,
    /// [`ErrorKind::SingularConstraintJacobian`] (free coordinates not
    /// determined: singular configuration), [`ErrorKind::NewtonNotConverged`]
    /// (residual = `max |Phi|`), [`ErrorKind::DecompositionNotConverged`],
    /// [`ErrorKind::SingularActuation`], [`ErrorKind::NonFiniteResult`].
    pub fn solve<M>(
        &mut self,
        model: &M,
        t: T,
        p: &SVector<T, NP>,
        v: &SVector<T, NP>,
        a: &SVector<T, NP>,
        out: &mut InverseSolution<NQ, NC, NU, T>,
    ) -> Result<InverseReport<T>, Error>
    where
        M: Model<NQ, NC, NU, T>,
    {
        if !t.is_finite() {
            return Err(Error::new(
                ErrorKind::NonFiniteInput {
                    quantity: Quantity::Time,
                    index: 0,
                },
                t,
            ));
        }
        for (x, quantity) in [
            (p, Quantity::PrescribedPosition),
            (v, Quantity::PrescribedVelocity),
            (a, Quantity::PrescribedAcceleration),
        ] {
            if let Some(index) = first_non_finite(x) {
                return Err(Error::new(ErrorKind::NonFiniteInput { quantity, index }, t));
            }
        }
        let cfg = self.config;
        let nf = NQ.saturating_sub(NP);
        let square = self.square();
        // 1. Positions: Newton with minimum-norm steps (SVD path) or chord
        //    steps with an inverse of J_f that is refreshed when it does not
        //    contract well enough (fast path).
        let mut q = self.start(t, p);
        let mut iterations = 0u32;
        let mut factorizations = 1u32;
        let mut phi = eval::constraints(model, &q, t)?;
        let mut res = inf_norm(&phi);
        // Iterates after the first are evaluated with their Jacobian (one
        // program for both): the last one's is the Jacobian at the solution.
        // `jacobians[current]` is at `q` when `have_jacobian`.
        let mut current = 0;
        let mut have_jacobian = false;
        // The inverse for chord steps: the previous call's (at the guess), or
        // one computed at an iterate into `local`.
        let mut local = SMatrix::<T, NC, NC>::zeros();
        let mut chord = match (square, &self.jacobian_inverse) {
            (true, Some(_)) => Chord::Cached,
            _ => Chord::None,
        };
        loop {
            if res <= cfg.position_tolerance {
                break;
            }
            if iterations >= cfg.max_iterations {
                return Err(Error::new(
                    ErrorKind::NewtonNotConverged {
                        iterations,
                        residual: res.into(),
                        tolerance: cfg.position_tolerance.into(),
                    },
                    t,
                ));
            }
            let mut dq = SVector::<T, NQ>::zeros();
            // A full Newton step (Jacobian at this iterate), always accepted.
            let fresh = chord == Chord::None;
            if fresh {
                factorizations += 1;
                if !have_jacobian {
                    eval::constraint_jacobian_into(model, &q, t, &mut self.jacobians[current])?;
                    have_jacobian = true;
                }
                let phi_q = &self.jacobians[current];
                if square
                    && self
                        .free_inverse(phi_q, cfg.max_condition, &mut local)
                        .is_some()
                {
                    chord = Chord::Local;
                } else {
                    let jsvd = svd(&self.free_jacobian(phi_q).transpose(), cfg.max_sweeps, t)?;
                    check_condition(&jsvd, nf, cfg.max_condition, t)?;
                    jsvd.solve_transpose(&(-phi), nf, &mut dq);
                }
            }
            let inv = match chord {
                Chord::Cached => self.jacobian_inverse.as_ref(),
                Chord::Local => Some(&local),
                Chord::None => None,
            };
            if let Some(inv) = inv {
                let mut step = SVector::<T, NC>::zeros();
                mul_vec_acc(inv, (-phi).as_slice(), step.as_mut_slice());
                self.scatter_free(&step, &mut dq);
            }
            let q_new = q + dq;
            eval::check_result(&q_new, Quantity::Position, t)?;
            iterations += 1;
            let mut phi_new = SVector::<T, NC>::zeros();
            eval::constraints_and_jacobian(
                model,
                &q_new,
                t,
                &mut phi_new,
                &mut self.jacobians[1 - current],
            )?;
            let res_new = inf_norm(&phi_new);
            if !fresh && !(res_new <= T::of(CHORD_CONTRACTION) * res) {
                // The old inverse no longer contracts well: refresh it, and
                // keep this step only if it reduced the residual.
                chord = Chord::None;
                if !(res_new < res) {
                    continue;
                }
            }
            q = q_new;
            phi = phi_new;
            res = res_new;
            current = 1 - current;
            have_jacobian = true;
        }
        // 2. Velocities and accelerations.
        if !have_jacobian {
            eval::constraint_jacobian_into(model, &q, t, &mut self.jacobians[current])?;
        }
        let phi_q = &self.jacobians[current];
        let phi_t = eval::constraint_time_derivative(model, &q, t)?;
        // The inverse at the solution overwrites the iterates' (no copy).
        let inv = &mut local;
        let fast = if square {
            self.free_inverse(phi_q, cfg.max_condition, inv)
        } else {
            None
        };
        let mut qd = self.scatter(v);
        let mut qdd = self.scatter(a);
        let gamma;
        let jacobian_condition;
        // X = J_f^-1 J_p on the fast path.
        let mut x = SMatrix::<T, NC, NP>::zeros();
        let mut jp_norm2 = T::zero();
        if let Some(f) = fast {
            jacobian_condition = f.condition;
            // X = J_f^-1 J_p column by column, and w = Phi_t + J_p v, so that
            // qd_f = -J_f^-1 w and qdd_f = J_f^-1 (gamma - J_p a).
            let mut w = phi_t;
            let mut u = SVector::<T, NC>::zeros();
            for (k, &i) in self.prescribed.iter().enumerate() {
                let jp = &phi_q.as_slice()[i * NC..(i + 1) * NC];
                jp_norm2 += jp.iter().map(|e| *e * *e).sum::<T>();
                mul_vec_acc(inv, jp, &mut x.as_mut_slice()[k * NC..(k + 1) * NC]);
                for ((w, u), e) in w.iter_mut().zip(u.iter_mut()).zip(jp) {
                    *w += *e * v[k];
                    *u -= *e * a[k];
                }
            }
            let mut qd_f = SVector::<T, NC>::zeros();
            mul_vec_acc(inv, w.as_slice(), qd_f.as_mut_slice());
            self.scatter_free(&-qd_f, &mut qd);
            gamma = eval::constraint_rhs(model, &q, &qd, t)?;
            let mut qdd_f = SVector::<T, NC>::zeros();
            mul_vec_acc(inv, (u + gamma).as_slice(), qdd_f.as_mut_slice());
            self.scatter_free(&qdd_f, &mut qdd);
        } else {
            let jsvd = svd(&self.free_jacobian(phi_q).transpose(), cfg.max_sweeps, t)?;
            jacobian_condition = check_condition(&jsvd, nf, cfg.max_condition, t)?;
            let mut qd_f = SVector::<T, NQ>::zeros();
            jsvd.solve_transpose(&(-phi_t - phi_q * qd), nf, &mut qd_f);
            qd += qd_f;
            gamma = eval::constraint_rhs(model, &q, &qd, t)?;
            let mut qdd_f = SVector::<T, NQ>::zeros();
            jsvd.solve_transpose(&(gamma - phi_q * qdd), nf, &mut qdd_f);
            qdd += qdd_f;
            for (k, &i) in self.prescribed.iter().enumerate() {
                qd[i] = v[k];
                qdd[i] = a[k];
            }
        }
        eval::check_result(&qd, Quantity::Velocity, t)?;
        eval::check_result(&qdd, Quantity::Acceleration, t)?;
        // 3. Forces.
        let b = eval::actuator_map(model, t)?;
        let mut r = SVector::<T, NQ>::zeros();
        eval::inverse_dynamics_into(model, &q, &qd, &qdd, t, &mut r)?;
        let fast_forces = match fast {
            Some(f) => self.forces_eliminated(
                &cfg,
                inv,
                &x,
                (f.jf_norm2 + jp_norm2) * f.inv_norm2,
                phi_q,
                &b,
                &r,
                t,
            )?,
            None => None,
        };
        let (tau, lambda, force_report) = match fast_forces {
            Some(solution) => solution,
            None => forces_from(&cfg, phi_q, &b, &r, t)?,
        };
        let (velocity_residual, acceleration_residual) =
            residual_norms(phi_q, (&qd, &phi_t), (&qdd, &-gamma));
        let report = InverseReport {
            iterations,
            factorizations,
            position_residual: res,
            velocity_residual,
            acceleration_residual,
            jacobian_condition,
            kinematics: if fast.is_some() {
                SolvePath::Elimination
            } else {
                SolvePath::Svd
            },
            forces: force_report,
        };
        self.guess = q;
        self.jacobian_inverse = fast.map(|_| *inv);
        self.motion = Some((t, qd, qdd));
        *out = InverseSolution {
            t,
            q,
            qd,
            qdd,
            tau,
            lambda,
        };
        Ok(report)
    }

    /// Fast-path force solve by elimination of `lambda` through `J_f^-1`
    /// (module docs); `Ok(None)` when `NU != NP` or a bound fails.
    #[allow(clippy::too_many_arguments)]
    fn forces_eliminated(
        &self,
        cfg: &InverseConfig<T>,
        inv: &SMatrix<T, NC, NC>,
        x: &SMatrix<T, NC, NP>,
        phi_q_inv_norm2: T,
        phi_q: &SMatrix<T, NC, NQ>,
        b: &SMatrix<T, NQ, NU>,
        r: &SVector<T, NQ>,
        t: T,
    ) -> Result<Option<ForceSolution<T, NC, NU>>, Error> {
        if NU != NP {
            return Ok(None);
        }
        let mut b_f = SMatrix::<T, NC, NU>::zeros();
        let mut r_f = SVector::<T, NC>::zeros();
        for k in 0..NC {
            let i = self.free[k];
            r_f[k] = r[i];
            for j in 0..NU {
                b_f[(k, j)] = b[(i, j)];
            }
        }
        let mut xt_b = SMatrix::<T, NP, NU>::zeros();
        for (b_col, out) in b_f
            .as_slice()
            .chunks_exact(NC.max(1))
            .zip(xt_b.as_mut_slice().chunks_exact_mut(NP.max(1)))
        {
            tr_mul_vec_acc(x, b_col, out);
        }
        let mut xt_r = SVector::<T, NP>::zeros();
        tr_mul_vec_acc(x, r_f.as_slice(), xt_r.as_mut_slice());
        // G = B_p - X^T B_f and g = r_p - X^T r_f (NP x NP since NU == NP).
        let mut g = SMatrix::<T, NP, NP>::zeros();
        let mut rhs = SVector::<T, NP>::zeros();
        for (k, &i) in self.prescribed.iter().enumerate() {
            rhs[k] = r[i] - xt_r[k];
            for j in 0..NP {
                g[(k, j)] = b[(i, j)] - xt_b[(k, j)];
            }
        }
        let mut g_inv = g;
        if !invert_in_place(&mut g_inv) {
            return Ok(None);
        }
        let full_rank = Scalar::square_root(phi_q_inv_norm2) * cfg.rank_tolerance < T::one();
        let actuation_condition = if NP == 0 {
            T::one()
        } else {
            Scalar::square_root(
                norm_squared(&g).min(norm_squared(b))
                    * norm_squared(&g_inv)
                    * (T::one() + norm_squared(x)),
            )
        };
        if !full_rank || !(actuation_condition <= cfg.max_condition) {
            return Ok(None);
        }
        let tau_p = g_inv * rhs;
        let mut tau = SVector::<T, NU>::zeros();
        for j in 0..NU {
            tau[j] = tau_p[j];
        }
        let mut f = r_f;
        mul_vec_acc(&b_f, (-tau).as_slice(), f.as_mut_slice());
        let mut lambda = SVector::<T, NC>::zeros();
        tr_mul_vec_acc(inv, f.as_slice(), lambda.as_mut_slice());
        finish_forces(
            phi_q,
            b,
            r,
            tau,
            lambda,
            NC,
            actuation_condition,
            SolvePath::Elimination,
            t,
        )
        .map(Some)
    }
}

/// `(max |a x + c|, max |a y + d|)`, in one pass over `a`.
fn residual_norms<T: Scalar, const R: usize, const C: usize>(
    a: &SMatrix<T, R, C>,
    (x, c): (&SVector<T, C>, &SVector<T, R>),
    (y, d): (&SVector<T, C>, &SVector<T, R>),
) -> (T, T) {
    let (mut u, mut v) = (*c, *d);
    for ((col, xk), yk) in a
        .as_slice()
        .chunks_exact(R.max(1))
        .zip(x.iter())
        .zip(y.iter())
    {
        for ((ui, vi), e) in u.iter_mut().zip(v.iter_mut()).zip(col) {
            *ui += *e * *xk;
            *vi += *e * *yk;
        }
    }
    (inf_norm(&u), inf_norm(&v))
}

/// Checks that the leading `needed` singular values are well conditioned.
fn check_condition<T: Scalar, const R: usize, const C: usize>(
    svd: &Svd<R, C, T>,
    needed: usize,
    limit: T,
    t: T,
) -> Result<T, Error> {
    let condition = svd.condition_of_leading(needed);
    if condition <= limit {
        Ok(condition)
    } else {
        Err(Error::new(
            ErrorKind::SingularConstraintJacobian {
                condition: condition.into(),
                limit: limit.into(),
            },
            t,
        ))
    }
}
