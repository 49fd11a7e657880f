//! [`InverseDynamicsOf`]: one inverse-dynamics call per sample, in three
//! steps (module docs of the parent): the position solve (Newton or chord
//! iterations), the velocity and acceleration solves, the force solve.

use super::forces::{finish_forces, forces_from, svd, ForceSolution};
use super::{InverseConfig, InverseReport, InverseSolutionOf, SolvePath};
use crate::error::{check_indices, invalid_configuration, Error, ErrorKind, Quantity};
use crate::eval;
use crate::linalg::{
    all_finite, first_non_finite, invert_in_place, mul_vec_acc, norm_squared, tr_mul_vec_acc, Svd,
};
use crate::model::{Equations, PrescribedSizes};
use crate::scalar::Scalar;
use crate::state::inf_norm;
use core::marker::PhantomData;
use nalgebra::allocator::Allocator;
use nalgebra::{Const, DefaultAllocator, Dim, OMatrix, OVector, SVector, U1};

/// What [`InverseDynamicsOf::free_inverse`] found besides the inverse.
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

/// The outcome of the position solve.
struct Positions<T: Scalar, Q: Dim>
where
    DefaultAllocator: Allocator<Q>,
{
    q: OVector<T, Q>,
    iterations: u32,
    factorizations: u32,
    residual: T,
}

/// The velocities and accelerations with what the force solve reuses.
struct Rates<T: Scalar, Q: Dim, C: Dim, P: Dim>
where
    DefaultAllocator: Allocator<Q> + Allocator<C> + Allocator<C, P>,
{
    qd: OVector<T, Q>,
    qdd: OVector<T, Q>,
    phi_t: OVector<T, C>,
    gamma: OVector<T, C>,
    jacobian_condition: T,
    /// On the fast path: `J_f^-1` (in the caller's `local`) found.
    fast: Option<Fast<T, C, P>>,
}

/// What the fast path's force solve reuses from the rates.
struct Fast<T: Scalar, C: Dim, P: Dim>
where
    DefaultAllocator: Allocator<C, P>,
{
    inverse: FreeInverse<T>,
    /// `X = J_f^-1 J_p`.
    x: OMatrix<T, C, P>,
    /// `|J_p|_F^2`.
    jp_norm2: T,
}

/// Time, velocities and accelerations of a solution.
type Motion<T, Q> = (T, OVector<T, Q>, OVector<T, Q>);

/// Inverse dynamics with `P` prescribed coordinates of a model with `Q`
/// coordinates, `C` constraints and `U` inputs, of fixed or run-time size
/// ([`InverseDynamics`]: fixed); keeps the previous position solution as
/// the Newton starting point of the next call, and on the fast path the
/// inverse of the free-coordinate Jacobian there. Two solvers are equal
/// when their settings and that kept state are (the scratch storage of a
/// call does not count).
#[derive(Clone, Debug)]
pub struct InverseDynamicsOf<T: Scalar, Q: Dim, C: Dim, U: Dim, P: Dim>
where
    DefaultAllocator: PrescribedSizes<Q, C, U, P>,
{
    /// Solver settings.
    pub config: InverseConfig<T>,
    prescribed: OVector<usize, P>,
    /// The free coordinates in increasing order (the first `NQ - NP` entries).
    free: OVector<usize, Q>,
    guess: OVector<T, Q>,
    /// `J_f^-1` at `guess` (fast path), if known.
    jacobian_inverse: Option<OMatrix<T, C, C>>,
    /// Time, velocities and accelerations of the solution `guess`, for the
    /// second-order predictor of the next starting point.
    motion: Option<Motion<T, Q>>,
    /// Scratch for the Jacobians of two Newton iterates (overwritten before
    /// every read; kept here so that a call does not clear them).
    jacobians: [OMatrix<T, C, Q>; 2],
    inputs: PhantomData<U>,
}

/// [`InverseDynamicsOf`] of a model of fixed size: no heap, everything on
/// the stack.
pub type InverseDynamics<
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NP: usize,
    T = f64,
> = InverseDynamicsOf<T, Const<NQ>, Const<NC>, Const<NU>, Const<NP>>;

impl<T: Scalar, const NQ: usize, const NC: usize, const NU: usize, const NP: usize> Copy
    for InverseDynamics<NQ, NC, NU, NP, T>
{
}

impl<T: Scalar, Q: Dim, C: Dim, U: Dim, P: Dim> PartialEq for InverseDynamicsOf<T, Q, C, U, P>
where
    DefaultAllocator: PrescribedSizes<Q, C, U, P>,
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
        Self::with_sizes(Const, &prescribed, initial_guess, config)
    }
}

impl<T: Scalar, Q: Dim, C: Dim, U: Dim, P: Dim> InverseDynamicsOf<T, Q, C, U, P>
where
    DefaultAllocator: PrescribedSizes<Q, C, U, P>,
{
    /// [`InverseDynamics::new`] for `model`, of any size: the coordinates
    /// `prescribed` (indices into `q`), the first position solve from
    /// `initial_guess`. Fails as `new` does, and with
    /// [`ErrorKind::InvalidConfiguration`] when the guess does not have one
    /// value per coordinate of the model or `P` is fixed to another number
    /// of prescribed coordinates.
    pub fn for_model<M>(
        model: &M,
        prescribed: &[usize],
        initial_guess: OVector<T, Q>,
        config: InverseConfig<T>,
    ) -> Result<Self, Error>
    where
        M: Equations<Q, C, U, T> + ?Sized,
    {
        let (nq, nc, _) = model.sizes();
        if initial_guess.nrows() != nq.value() {
            return Err(invalid_configuration(
                "inverse dynamics: the initial guess needs one value per coordinate",
            ));
        }
        Self::with_sizes(nc, prescribed, initial_guess, config)
    }

    fn with_sizes(
        nc: C,
        prescribed: &[usize],
        initial_guess: OVector<T, Q>,
        config: InverseConfig<T>,
    ) -> Result<Self, Error> {
        let nq = initial_guess.shape_generic().0;
        let (n, np) = (nq.value(), prescribed.len());
        check_indices("prescribed coordinate", prescribed, n, true)?;
        if P::try_to_usize().is_some_and(|fixed| fixed != np) {
            return Err(invalid_configuration(
                "inverse dynamics: the number of prescribed coordinates differs from the \
                 solver's",
            ));
        }
        if np > n || nc.value() < n - np {
            return Err(invalid_configuration(
                "fewer constraints than free coordinates: the motion is not determined",
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
        let mut free = OVector::<usize, Q>::from_element_generic(nq, U1, 0);
        for (k, i) in (0..n).filter(|i| !prescribed.contains(i)).enumerate() {
            free[k] = i;
        }
        let jacobian = OMatrix::<T, C, Q>::zeros_generic(nc, nq);
        Ok(InverseDynamicsOf {
            config,
            prescribed: OVector::from_fn_generic(P::from_usize(np), U1, |k, _| prescribed[k]),
            free,
            guess: initial_guess,
            jacobian_inverse: None,
            motion: None,
            jacobians: [jacobian.clone(), jacobian],
            inputs: PhantomData,
        })
    }

    /// The prescribed coordinate indices.
    pub fn prescribed(&self) -> &[usize] {
        self.prescribed.as_slice()
    }

    /// The current Newton starting point (the last solution).
    pub fn guess(&self) -> &OVector<T, Q> {
        &self.guess
    }

    /// Replaces the Newton starting point (e.g. to select an assembly mode).
    pub fn set_guess(&mut self, q: OVector<T, Q>) {
        self.guess = q;
        self.jacobian_inverse = None;
        self.motion = None;
    }

    fn nc(&self) -> C {
        self.jacobians[0].shape_generic().0
    }

    /// Whether the fast path applies to the shape: `J_f` square.
    fn square(&self) -> bool {
        let (nq, np) = (self.guess.nrows(), self.prescribed.nrows());
        self.config.fast_path && np <= nq && self.nc().value() == nq - np
    }

    /// `Phi_q` with the prescribed columns zeroed.
    fn free_jacobian(&self, phi_q: &OMatrix<T, C, Q>) -> OMatrix<T, C, Q> {
        let mut j = phi_q.clone();
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
        phi_q: &OMatrix<T, C, Q>,
        limit: T,
        inv: &mut OMatrix<T, C, C>,
    ) -> Option<FreeInverse<T>> {
        // Column copies through the slices (nalgebra's column views copy
        // element by element).
        let nc = phi_q.nrows();
        let (from, to) = (phi_q.as_slice(), inv.as_mut_slice());
        for (k, col) in to.chunks_exact_mut(nc.max(1)).enumerate() {
            let i = self.free[k];
            col.copy_from_slice(&from[i * nc..(i + 1) * nc]);
        }
        let jf_norm2 = norm_squared(inv);
        if !invert_in_place(inv) {
            return None;
        }
        let inv_norm2 = norm_squared(inv);
        let condition = if nc == 0 {
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
    fn start(&self, t: T, p: &OVector<T, P>) -> OVector<T, Q> {
        let mut q = self.guess.clone();
        if let Some((t0, qd, qdd)) = &self.motion {
            let dt = t - *t0;
            let (mut err_predicted, mut err_held) = (T::zero(), T::zero());
            for (k, &i) in self.prescribed.iter().enumerate() {
                let predicted = q[i] + dt * (qd[i] + T::of(0.5) * dt * qdd[i]);
                err_predicted = err_predicted.max((p[k] - predicted).abs());
                err_held = err_held.max((p[k] - q[i]).abs());
            }
            if T::of(4.0) * err_predicted <= err_held {
                let moved = &q + (qd + qdd * (T::of(0.5) * dt)) * dt;
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
    fn scatter(&self, x: &OVector<T, P>) -> OVector<T, Q> {
        let mut v = OVector::<T, Q>::zeros_generic(self.guess.shape_generic().0, U1);
        for (k, &i) in self.prescribed.iter().enumerate() {
            v[i] = x[k];
        }
        v
    }

    /// `y` with its free entries set to `x_f` (call only when [`Self::square`]).
    fn scatter_free(&self, x_f: &OVector<T, C>, y: &mut OVector<T, Q>) {
        for (k, x) in x_f.iter().enumerate() {
            y[self.free[k]] = *x;
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
        p: &OVector<T, P>,
        v: &OVector<T, P>,
        a: &OVector<T, P>,
        out: &mut InverseSolutionOf<T, Q, C, U>,
    ) -> Result<InverseReport<T>, Error>
    where
        M: Equations<Q, C, U, T> + ?Sized,
    {
        check_prescription(t, p, v, a)?;
        let cfg = self.config;
        let nc = self.nc();
        // The inverse of J_f for chord steps computed in this call, then the
        // one at the solution.
        let mut inv = OMatrix::<T, C, C>::zeros_generic(nc, nc);
        // 1. Positions; `jacobians[current]` is the Jacobian at the solution.
        let (positions, current) = self.positions(model, t, p, &mut inv)?;
        let q = &positions.q;
        // 2. Velocities and accelerations.
        let rates = self.rates(model, t, q, current, v, a, &mut inv)?;
        let phi_q = &self.jacobians[current];
        // 3. Forces.
        let b = eval::actuator_map(model, t)?;
        let mut r = OVector::<T, Q>::zeros_generic(q.shape_generic().0, U1);
        eval::inverse_dynamics_into(model, q, &rates.qd, &rates.qdd, t, &mut r)?;
        let fast_forces = match &rates.fast {
            Some(f) => {
                let phi_q_inv_norm2 = (f.inverse.jf_norm2 + f.jp_norm2) * f.inverse.inv_norm2;
                self.forces_eliminated(&cfg, &inv, &f.x, phi_q_inv_norm2, phi_q, &b, &r, t)?
            }
            None => None,
        };
        let (tau, lambda, force_report) = match fast_forces {
            Some(solution) => solution,
            None => forces_from(&cfg, phi_q, &b, &r, t)?,
        };
        let (velocity_residual, acceleration_residual) = residual_norms(
            phi_q,
            (&rates.qd, &rates.phi_t),
            (&rates.qdd, &-&rates.gamma),
        );
        let report = InverseReport {
            iterations: positions.iterations,
            factorizations: positions.factorizations,
            position_residual: positions.residual,
            velocity_residual,
            acceleration_residual,
            jacobian_condition: rates.jacobian_condition,
            kinematics: if rates.fast.is_some() {
                SolvePath::Elimination
            } else {
                SolvePath::Svd
            },
            forces: force_report,
        };
        self.guess.copy_from(q);
        self.jacobian_inverse = rates.fast.map(|_| inv);
        self.motion = Some((t, rates.qd.clone(), rates.qdd.clone()));
        out.t = t;
        out.q = positions.q;
        out.qd = rates.qd;
        out.qdd = rates.qdd;
        out.tau = tau;
        out.lambda = lambda;
        Ok(report)
    }

    /// The position solve: Newton with minimum-norm steps (SVD path) or
    /// chord steps with an inverse of `J_f` that is refreshed when it does
    /// not contract well enough (fast path), into `local` when computed
    /// here. Returns the solution and which of `jacobians` is at it.
    fn positions<M>(
        &mut self,
        model: &M,
        t: T,
        p: &OVector<T, P>,
        local: &mut OMatrix<T, C, C>,
    ) -> Result<(Positions<T, Q>, usize), Error>
    where
        M: Equations<Q, C, U, T> + ?Sized,
    {
        let cfg = self.config;
        let nf = self.guess.nrows().saturating_sub(self.prescribed.nrows());
        let square = self.square();
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
        let mut chord = match (square, &self.jacobian_inverse) {
            (true, Some(_)) => Chord::Cached,
            _ => Chord::None,
        };
        let mut dq = OVector::<T, Q>::zeros_generic(q.shape_generic().0, U1);
        let mut step = OVector::<T, C>::zeros_generic(self.nc(), U1);
        let mut phi_new = step.clone();
        while res > cfg.position_tolerance {
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
            dq.fill(T::zero());
            // A full Newton step (Jacobian at this iterate), always accepted.
            let fresh = chord == Chord::None;
            if fresh {
                factorizations += 1;
                if !have_jacobian {
                    eval::constraint_jacobian_into(model, &q, t, &mut self.jacobians[current])?;
                    have_jacobian = true;
                }
                let phi_q = &self.jacobians[current];
                if square && self.free_inverse(phi_q, cfg.max_condition, local).is_some() {
                    chord = Chord::Local;
                } else {
                    let jsvd = svd(&self.free_jacobian(phi_q).transpose(), cfg.max_sweeps, t)?;
                    check_condition(&jsvd, nf, cfg.max_condition, t)?;
                    jsvd.solve_transpose(&(-&phi), nf, &mut dq);
                }
            }
            let inv = match chord {
                Chord::Cached => self.jacobian_inverse.as_ref(),
                Chord::Local => Some(&*local),
                Chord::None => None,
            };
            if let Some(inv) = inv {
                step.fill(T::zero());
                mul_vec_acc(inv, (-&phi).as_slice(), step.as_mut_slice());
                self.scatter_free(&step, &mut dq);
            }
            let q_new = &q + &dq;
            eval::check_result(&q_new, Quantity::Position, t)?;
            iterations += 1;
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
            core::mem::swap(&mut phi, &mut phi_new);
            res = res_new;
            current = 1 - current;
            have_jacobian = true;
        }
        if !have_jacobian {
            eval::constraint_jacobian_into(model, &q, t, &mut self.jacobians[current])?;
        }
        Ok((
            Positions {
                q,
                iterations,
                factorizations,
                residual: res,
            },
            current,
        ))
    }

    /// The velocities and accelerations at the solution `q` (whose Jacobian
    /// is `jacobians[current]`): through `J_f^-1`, written to `inv`, on the
    /// fast path, otherwise by minimum-norm least squares.
    #[allow(clippy::too_many_arguments)]
    fn rates<M>(
        &self,
        model: &M,
        t: T,
        q: &OVector<T, Q>,
        current: usize,
        v: &OVector<T, P>,
        a: &OVector<T, P>,
        inv: &mut OMatrix<T, C, C>,
    ) -> Result<Rates<T, Q, C, P>, Error>
    where
        M: Equations<Q, C, U, T> + ?Sized,
    {
        let cfg = self.config;
        let phi_q = &self.jacobians[current];
        let (nc, np) = (self.nc(), self.prescribed.shape_generic().0);
        let nf = q.nrows().saturating_sub(np.value());
        let phi_t = eval::constraint_time_derivative(model, q, t)?;
        let found = if self.square() {
            self.free_inverse(phi_q, cfg.max_condition, inv)
        } else {
            None
        };
        let mut qd = self.scatter(v);
        let mut qdd = self.scatter(a);
        let (gamma, jacobian_condition, fast) = if let Some(f) = found {
            // X = J_f^-1 J_p column by column, and w = Phi_t + J_p v, so that
            // qd_f = -J_f^-1 w and qdd_f = J_f^-1 (gamma - J_p a).
            let c = nc.value();
            let mut x = OMatrix::<T, C, P>::zeros_generic(nc, np);
            let mut jp_norm2 = T::zero();
            let mut w = phi_t.clone();
            let mut u = OVector::<T, C>::zeros_generic(nc, U1);
            for (k, &i) in self.prescribed.iter().enumerate() {
                let jp = &phi_q.as_slice()[i * c..(i + 1) * c];
                jp_norm2 += jp.iter().map(|e| *e * *e).sum::<T>();
                mul_vec_acc(inv, jp, &mut x.as_mut_slice()[k * c..(k + 1) * c]);
                for ((w, u), e) in w.iter_mut().zip(u.iter_mut()).zip(jp) {
                    *w += *e * v[k];
                    *u -= *e * a[k];
                }
            }
            let mut qd_f = OVector::<T, C>::zeros_generic(nc, U1);
            mul_vec_acc(inv, w.as_slice(), qd_f.as_mut_slice());
            self.scatter_free(&-qd_f, &mut qd);
            let gamma = eval::constraint_rhs(model, q, &qd, t)?;
            let mut qdd_f = OVector::<T, C>::zeros_generic(nc, U1);
            mul_vec_acc(inv, (u + &gamma).as_slice(), qdd_f.as_mut_slice());
            self.scatter_free(&qdd_f, &mut qdd);
            let fast = Fast {
                inverse: f,
                x,
                jp_norm2,
            };
            (gamma, f.condition, Some(fast))
        } else {
            let jsvd = svd(&self.free_jacobian(phi_q).transpose(), cfg.max_sweeps, t)?;
            let condition = check_condition(&jsvd, nf, cfg.max_condition, t)?;
            let mut qd_f = OVector::<T, Q>::zeros_generic(q.shape_generic().0, U1);
            jsvd.solve_transpose(&(-&phi_t - phi_q * &qd), nf, &mut qd_f);
            qd += &qd_f;
            let gamma = eval::constraint_rhs(model, q, &qd, t)?;
            jsvd.solve_transpose(&(&gamma - phi_q * &qdd), nf, &mut qd_f);
            qdd += qd_f;
            for (k, &i) in self.prescribed.iter().enumerate() {
                qd[i] = v[k];
                qdd[i] = a[k];
            }
            (gamma, condition, None)
        };
        eval::check_result(&qd, Quantity::Velocity, t)?;
        eval::check_result(&qdd, Quantity::Acceleration, t)?;
        Ok(Rates {
            qd,
            qdd,
            phi_t,
            gamma,
            jacobian_condition,
            fast,
        })
    }

    /// Fast-path force solve by elimination of `lambda` through `J_f^-1`
    /// (module docs); `Ok(None)` when `NU != NP` or a bound fails.
    #[allow(clippy::too_many_arguments)]
    fn forces_eliminated(
        &self,
        cfg: &InverseConfig<T>,
        inv: &OMatrix<T, C, C>,
        x: &OMatrix<T, C, P>,
        phi_q_inv_norm2: T,
        phi_q: &OMatrix<T, C, Q>,
        b: &OMatrix<T, Q, U>,
        r: &OVector<T, Q>,
        t: T,
    ) -> Result<Option<ForceSolution<T, C, U>>, Error> {
        let nu = b.shape_generic().1;
        let (nc, np) = x.shape_generic();
        let (c, u, p) = (nc.value(), nu.value(), np.value());
        if u != p {
            return Ok(None);
        }
        let mut b_f = OMatrix::<T, C, U>::zeros_generic(nc, nu);
        let mut r_f = OVector::<T, C>::zeros_generic(nc, U1);
        for k in 0..c {
            let i = self.free[k];
            r_f[k] = r[i];
            for j in 0..u {
                b_f[(k, j)] = b[(i, j)];
            }
        }
        let mut xt_b = OMatrix::<T, P, U>::zeros_generic(np, nu);
        for (b_col, out) in b_f
            .as_slice()
            .chunks_exact(c.max(1))
            .zip(xt_b.as_mut_slice().chunks_exact_mut(p.max(1)))
        {
            tr_mul_vec_acc(x, b_col, out);
        }
        let mut xt_r = OVector::<T, P>::zeros_generic(np, U1);
        tr_mul_vec_acc(x, r_f.as_slice(), xt_r.as_mut_slice());
        // G = B_p - X^T B_f and g = r_p - X^T r_f (NP x NP since NU == NP).
        let mut g = OMatrix::<T, P, P>::zeros_generic(np, np);
        let mut rhs = OVector::<T, P>::zeros_generic(np, U1);
        for (k, &i) in self.prescribed.iter().enumerate() {
            rhs[k] = r[i] - xt_r[k];
            for j in 0..p {
                g[(k, j)] = b[(i, j)] - xt_b[(k, j)];
            }
        }
        let mut g_inv = g.clone();
        if !invert_in_place(&mut g_inv) {
            return Ok(None);
        }
        let full_rank = Scalar::square_root(phi_q_inv_norm2) * cfg.rank_tolerance < T::one();
        let actuation_condition = if p == 0 {
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
        let tau_p = &g_inv * &rhs;
        let tau = OVector::<T, U>::from_fn_generic(nu, U1, |j, _| tau_p[j]);
        let mut f = r_f;
        mul_vec_acc(&b_f, (-&tau).as_slice(), f.as_mut_slice());
        let mut lambda = OVector::<T, C>::zeros_generic(nc, U1);
        tr_mul_vec_acc(inv, f.as_slice(), lambda.as_mut_slice());
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
}

/// Checks that `t` and the prescription are finite.
fn check_prescription<T: Scalar, P: Dim>(
    t: T,
    p: &OVector<T, P>,
    v: &OVector<T, P>,
    a: &OVector<T, P>,
) -> Result<(), Error>
where
    DefaultAllocator: Allocator<P>,
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
    Ok(())
}

/// `(max |a x + c|, max |a y + d|)`, in one pass over `a`.
fn residual_norms<T: Scalar, R: Dim, C: Dim>(
    a: &OMatrix<T, R, C>,
    (x, c): (&OVector<T, C>, &OVector<T, R>),
    (y, d): (&OVector<T, C>, &OVector<T, R>),
) -> (T, T)
where
    DefaultAllocator: Allocator<R, C> + Allocator<R> + Allocator<C>,
{
    let (mut u, mut v) = (c.clone(), d.clone());
    for ((col, xk), yk) in a
        .as_slice()
        .chunks_exact(a.nrows().max(1))
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
fn check_condition<T: Scalar, R: Dim, C: Dim>(
    svd: &Svd<T, R, C>,
    needed: usize,
    limit: T,
    t: T,
) -> Result<T, Error>
where
    DefaultAllocator: Allocator<R, C> + Allocator<C, C> + Allocator<C> + Allocator<R>,
{
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
