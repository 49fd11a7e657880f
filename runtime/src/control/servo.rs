//! Servo constraints (Blajer & Kołodziejczyk): `NP` outputs `y(q)` of the
//! model are prescribed, `y(q(t)) = y_d(t)`, and at every state the `NU = NP`
//! actuator inputs `u` are chosen so that the outputs follow; the other
//! coordinates (the elastic ones of a flexible scene, say) move as the
//! dynamics make them.
//!
//! With `Y_q = dy/dq` and the servo constraint stabilised like the closure
//! constraints (gains `alpha_s`, `beta_s`, [`ServoConfig::output_gains`]),
//! the accelerations, multipliers and inputs solve
//!
//! ```text
//! [ M      -Phi_q^T  -B ] [qdd   ]   [ -h ]
//! [ Phi_q   0         0 ] [lambda] = [ c  ]   c = gamma - 2 alpha dPhi/dt - beta^2 Phi
//! [ Y_q     0         0 ] [u     ]   [ s  ]   s = yd'' + 2 alpha_s (yd' - y')
//!                                                  + beta_s^2 (y_d - y) - a_y
//! ```
//!
//! with `y' = Y_q qd + dy/dt` and `a_y = y'' - Y_q qdd` the outputs' rates
//! and convective accelerations (explicit time terms included: a marker on
//! a frame that moves with time), so that the output error `e = y_d - y` obeys `e'' + 2 alpha_s e' +
//! beta_s^2 e = 0`. It is solved by linearity: the constrained forward
//! dynamics (the KKT solve of [`crate::accelerations`], a Schur complement
//! on a Cholesky of `M`) gives `qdd = x_0 + P B u` with `x_0` the
//! accelerations without input and `P = M^-1 - M^-1 Phi_q^T (Phi_q M^-1
//! Phi_q^T)^-1 Phi_q M^-1`, the inverse mass restricted to the motions the
//! constraints admit; the output rows then read
//!
//! ```text
//! (Y_q P B) u = s - Y_q x_0
//! ```
//!
//! The `NP x NU` servo matrix `Y_q P B` is the outputs' acceleration per
//! unit input. Construction requires `NP == NU` (more outputs over-determine
//! the inputs, fewer leave them undetermined). With `a_i = |y_i,q|_{M^-1}`
//! and `b_j = |B[:, j]|_{M^-1}` (norms in the inverse mass metric), the
//! normalised matrix `S~_ij = (Y_q P B)_ij / (a_i b_j)` is independent of
//! the units of outputs and inputs and has entries of magnitude at most 1
//! (`P` is a projector in that metric), exactly 1 for an actuator driving
//! its output coordinate directly in an unconstrained model with a diagonal
//! mass matrix. It is solved by a Jacobi SVD, and `1 / sigma_min(S~)`, the
//! servo condition, above
//! [`ServoConfig::max_condition`] is [`ErrorKind::SingularServo`]: the
//! prescription does not determine the inputs there (the actuators cannot
//! accelerate the outputs along the admissible motions, e.g. a slider-crank
//! at dead centre with the slider prescribed and the crank driven).
//!
//! As a [`Model`], [`Servo`] has the bias forces `h - B u(q, qd, t)`: any
//! integrator of this crate, given zero input, integrates the servo-
//! constrained motion, every unprescribed coordinate included. The closure
//! constraints' stabilisation in `c` must be the integrator's
//! ([`ServoConfig::dynamics`] = the integrator's
//! [`crate::StepSettings::dynamics`]) for the outputs to follow exactly.

use super::feedback::subtract_input;
use super::{TargetOf, Trajectory};
use crate::dynamics::{stabilised_rhs, Baumgarte, DynamicsConfig, Kkt};
use crate::error::{check_indices, invalid_configuration, Error, ErrorKind, Quantity};
use crate::eval::{self, Terms};
use crate::input::LinearOf;
use crate::integrate::IntegratorOf;
use crate::linalg::Svd;
use crate::model::{Equations, Model, PrescribedSizes};
use crate::scalar::Scalar;
use crate::state::{Drift, StateOf};
use core::cell::Cell;
use core::marker::PhantomData;
use core::ops::ControlFlow;
use nalgebra::allocator::Allocator;
#[cfg(feature = "alloc")]
use nalgebra::Dyn;
use nalgebra::{Const, DefaultAllocator, Dim, OMatrix, OVector, SMatrix, SVector, U1};

/// `N` outputs `y(q, t)` of a model with `Q` coordinates (each fixed or
/// known at run time), with their Jacobian; [`Coordinates`] selects
/// coordinates.
pub trait Outputs<Q: Dim, N: Dim, T: Scalar = f64>
where
    DefaultAllocator: Allocator<Q> + Allocator<N> + Allocator<N, Q>,
{
    /// The number of outputs.
    fn count(&self) -> N;

    /// Checks the set-up for a model with `nq` coordinates ([`Servo::new`]
    /// calls it); the default accepts it.
    fn validate(&self, nq: usize) -> Result<(), Error> {
        let _ = nq;
        Ok(())
    }

    /// Writes every entry of `out` at `(q, qd, t)`: the outputs, their rates
    /// (`Y_q qd` plus any explicit time derivative), `Y_q = dy/dq` and the
    /// convective term, so that `y'' = Y_q qdd + convective`.
    fn evaluate(&self, q: &OVector<T, Q>, qd: &OVector<T, Q>, t: T, out: &mut OutputTerms<T, Q, N>);
}

/// What [`Outputs::evaluate`] writes, `N` outputs of a model with `Q`
/// coordinates.
#[derive(Clone, Debug, PartialEq)]
pub struct OutputTerms<T: Scalar, Q: Dim, N: Dim>
where
    DefaultAllocator: Allocator<N> + Allocator<N, Q>,
{
    /// The outputs `y`.
    pub y: OVector<T, N>,
    /// Their rates `y' = Y_q qd + dy/dt`.
    pub rate: OVector<T, N>,
    /// Their Jacobian `Y_q = dy/dq`.
    pub y_q: OMatrix<T, N, Q>,
    /// The accelerations' part without `qdd`: `y'' - Y_q qdd`.
    pub convective: OVector<T, N>,
}

impl<T: Scalar, Q: Dim, N: Dim> OutputTerms<T, Q, N>
where
    DefaultAllocator: Allocator<N> + Allocator<N, Q>,
{
    /// Zeros for `n` outputs of `q` coordinates.
    pub fn zeros(q: Q, n: N) -> Self {
        let y = OVector::<T, N>::zeros_generic(n, U1);
        OutputTerms {
            rate: y.clone(),
            convective: y.clone(),
            y,
            y_q: OMatrix::<T, N, Q>::zeros_generic(n, q),
        }
    }
}

/// Prescribed coordinates: output `k` is `q[self.0[k]]` (`Y_q` selects, no
/// convective term). Any list of indices (an array `[usize; NP]` for
/// `Const<NP>` outputs, a slice for `Dyn`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Coordinates<I>(pub I);

impl<T: Scalar, Q: Dim, N: Dim, I: AsRef<[usize]>> Outputs<Q, N, T> for Coordinates<I>
where
    DefaultAllocator: Allocator<Q> + Allocator<N> + Allocator<N, Q>,
{
    /// The number of indices (`N` is `Dyn`, or fixed to that number:
    /// [`Outputs::validate`] checks it).
    fn count(&self) -> N {
        N::from_usize(self.0.as_ref().len())
    }
    /// [`ErrorKind::InvalidIndex`] if an index is not below `nq` or repeats;
    /// [`ErrorKind::InvalidConfiguration`] if `N` is fixed to another number.
    fn validate(&self, nq: usize) -> Result<(), Error> {
        if N::try_to_usize().is_some_and(|n| n != self.0.as_ref().len()) {
            return Err(invalid_configuration(
                "servo: the number of prescribed coordinates differs from the outputs' size",
            ));
        }
        check_indices("prescribed coordinate", self.0.as_ref(), nq, true)
    }
    fn evaluate(
        &self,
        q: &OVector<T, Q>,
        qd: &OVector<T, Q>,
        _t: T,
        out: &mut OutputTerms<T, Q, N>,
    ) {
        out.y_q.fill(T::zero());
        out.convective.fill(T::zero());
        for (k, &i) in self.0.as_ref().iter().enumerate() {
            // Validated indices; an invalid one gives NaN, never a panic.
            match (q.get(i), qd.get(i)) {
                (Some(&qi), Some(&qdi)) => {
                    out.y[k] = qi;
                    out.rate[k] = qdi;
                    out.y_q[(k, i)] = T::one();
                }
                _ => (out.y[k], out.rate[k]) = (T::NAN, T::NAN),
            }
        }
    }
}

/// Settings of [`Servo`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ServoConfig<T: Scalar = f64> {
    /// Stabilisation of the servo constraints `y - y_d` (1/s).
    pub output_gains: Baumgarte,
    /// Stabilisation and conditioning limit of the closure constraints:
    /// must be the integrator's [`crate::StepSettings::dynamics`].
    pub dynamics: DynamicsConfig<T>,
    /// Largest accepted servo condition `1 / sigma_min` of the normalised
    /// servo matrix (module docs).
    pub max_condition: T,
    /// Cap on Jacobi SVD sweeps of the servo matrix.
    pub max_sweeps: u32,
    /// Whether [`servo_run`]'s trial step keeps the integrator's coordinate
    /// projection. Off, the inputs are those at the state the trial step's
    /// own iteration reached: on stiff elastic coordinates projecting the
    /// trial state moves them off the iteration's accelerations (the flexible
    /// parallel robot's torques then differ by up to 3 N m at 10 rad/s, and
    /// at coarse steps the projection's Newton matrix turns singular). The
    /// step taken keeps its projection either way.
    pub trial_projection: bool,
}

impl<T: Scalar> Default for ServoConfig<T> {
    /// Both stabilisations at the default Baumgarte gains (as the default
    /// [`crate::StepSettings`]), condition limit [`Scalar::MAX_CONDITION`]
    /// (`1e8` in f64, `1e4` in f32), 40 sweeps, trial step with projection.
    fn default() -> Self {
        ServoConfig {
            output_gains: Baumgarte::default(),
            dynamics: DynamicsConfig::default(),
            max_condition: T::MAX_CONDITION,
            max_sweeps: 40,
            trial_projection: true,
        }
    }
}

/// The servo solve at one state, `Q` coordinates, `C` constraints, `U`
/// inputs of fixed or run-time size ([`ServoSolution`]: fixed).
#[derive(Clone, Debug, PartialEq)]
pub struct ServoSolutionOf<T: Scalar, Q: Dim, C: Dim, U: Dim>
where
    DefaultAllocator: Allocator<Q> + Allocator<C> + Allocator<U>,
{
    /// Actuator inputs.
    pub tau: OVector<T, U>,
    /// Accelerations under them.
    pub qdd: OVector<T, Q>,
    /// Constraint forces (multipliers).
    pub lambda: OVector<T, C>,
    /// Servo condition: `1 / sigma_min` of the normalised servo matrix
    /// (module docs).
    pub condition: T,
}

impl<T: Scalar, const NQ: usize, const NC: usize, const NU: usize> Copy
    for ServoSolutionOf<T, Const<NQ>, Const<NC>, Const<NU>>
{
}

/// [`ServoSolutionOf`] of a model of fixed size.
pub type ServoSolution<const NQ: usize, const NC: usize, const NU: usize, T = f64> =
    ServoSolutionOf<T, Const<NQ>, Const<NC>, Const<NU>>;

/// The model `inner` with its inputs chosen so that the `N` outputs `O`
/// follow the path `P` (module docs). As a model ([`Equations`]) its bias
/// forces are `h - B u(q, qd, t)`; integrate it with zero input. A failed
/// solve inside a model evaluation writes NaN bias forces (which the
/// integrator reports) and keeps the error for [`Servo::take_failure`].
/// Computes in the model's scalar `T` (`f64` unless named), the path and the
/// outputs included.
pub struct Servo<'a, M: ?Sized, O, P, N, T: Scalar = f64> {
    inner: &'a M,
    outputs: O,
    path: P,
    /// Settings.
    pub config: ServoConfig<T>,
    failure: Cell<Option<Error>>,
    count: PhantomData<N>,
}

impl<'a, M: ?Sized, O, P, N: Dim, T: Scalar> Servo<'a, M, O, P, N, T> {
    /// Servo constraints making `outputs` of `inner` follow `path`.
    ///
    /// Errors: [`ErrorKind::InvalidConfiguration`] unless there are as many
    /// outputs as inputs; whatever [`Outputs::validate`] reports (for
    /// [`Coordinates`], [`ErrorKind::InvalidIndex`]).
    pub fn new<Q: Dim, C: Dim, U: Dim>(
        inner: &'a M,
        outputs: O,
        path: P,
        config: ServoConfig<T>,
    ) -> Result<Self, Error>
    where
        M: Equations<Q, C, U, T>,
        O: Outputs<Q, N, T>,
        P: Trajectory<N, T>,
        DefaultAllocator: PrescribedSizes<Q, C, U, N>,
    {
        let (nq, _, nu) = inner.sizes();
        outputs.validate(nq.value())?;
        let np = outputs.count().value();
        if np > nu.value() {
            return Err(invalid_configuration(
                "servo: more prescribed outputs than actuator inputs (NP > NU): \
                 the prescription over-determines the inputs",
            ));
        }
        if np < nu.value() {
            return Err(invalid_configuration(
                "servo: fewer prescribed outputs than actuator inputs (NP < NU): \
                 the prescription does not determine the inputs",
            ));
        }
        Ok(Servo {
            inner,
            outputs,
            path,
            config,
            failure: Cell::new(None),
            count: PhantomData,
        })
    }

    /// The wrapped model.
    pub fn inner(&self) -> &'a M {
        self.inner
    }

    /// The prescribed outputs.
    pub fn outputs(&self) -> &O {
        &self.outputs
    }

    /// The prescribed path.
    pub fn path(&self) -> &P {
        &self.path
    }

    /// The error of the last failed solve inside a model evaluation, if any
    /// since the last [`Servo::take_failure`].
    pub fn failure(&self) -> Option<Error> {
        self.failure.get()
    }

    /// [`Servo::failure`], clearing it.
    pub fn take_failure(&self) -> Option<Error> {
        self.failure.take()
    }

    /// The inputs (with the accelerations and multipliers under them) at
    /// `(q, qd, t)`.
    ///
    /// Errors: non-finite model outputs or outputs `y` ([`Quantity::Outputs`]);
    /// [`ErrorKind::NonFiniteInput`] for a non-finite path;
    /// [`ErrorKind::MassMatrixNotPositiveDefinite`],
    /// [`ErrorKind::SingularConstraintJacobian`] as in forward dynamics;
    /// [`ErrorKind::SingularServo`]; [`ErrorKind::DecompositionNotConverged`];
    /// [`ErrorKind::NonFiniteResult`].
    pub fn solve<Q: Dim, C: Dim, U: Dim>(
        &self,
        q: &OVector<T, Q>,
        qd: &OVector<T, Q>,
        t: T,
    ) -> Result<ServoSolutionOf<T, Q, C, U>, Error>
    where
        M: Equations<Q, C, U, T>,
        O: Outputs<Q, N, T>,
        P: Trajectory<N, T>,
        DefaultAllocator: PrescribedSizes<Q, C, U, N>,
    {
        let terms = eval::dynamics_terms(self.inner, q, qd, t)?;
        self.solve_terms(q, qd, t, terms)
    }

    /// [`Servo::solve`] from the model's terms at the state.
    fn solve_terms<Q: Dim, C: Dim, U: Dim>(
        &self,
        q: &OVector<T, Q>,
        qd: &OVector<T, Q>,
        t: T,
        terms: Terms<T, Q, C>,
    ) -> Result<ServoSolutionOf<T, Q, C, U>, Error>
    where
        M: Equations<Q, C, U, T>,
        O: Outputs<Q, N, T>,
        P: Trajectory<N, T>,
        DefaultAllocator: PrescribedSizes<Q, C, U, N>,
    {
        eval::check_terms(&terms, t)?;
        let (nq, nc, nu) = self.inner.sizes();
        let np = self.outputs.count();
        let b = eval::actuator_map(self.inner, t)?;
        let dynamics = &self.config.dynamics;
        let c = stabilised_rhs(
            self.inner,
            &dynamics.baumgarte,
            q,
            qd,
            t,
            &terms.phi_q,
            terms.gamma,
        )?;
        let kkt = Kkt::new(terms.m, &terms.phi_q, dynamics.max_condition, t)?;
        // qdd = x0 + xb u, lambda = mu0 + mub u.
        let (x0, mu0) = kkt.solve(&-terms.h, &c);
        let mut xb = OMatrix::<T, Q, U>::zeros_generic(nq, nu);
        let mut mub = OMatrix::<T, C, U>::zeros_generic(nc, nu);
        let no_constraint = OVector::<T, C>::zeros_generic(nc, U1);
        for j in 0..nu.value() {
            let (x, mu) = kkt.solve(&b.column(j).into_owned(), &no_constraint);
            xb.set_column(j, &x);
            mub.set_column(j, &mu);
        }
        let mut out = OutputTerms::zeros(nq, np);
        self.outputs.evaluate(q, qd, t, &mut out);
        for o in [&out.y, &out.rate, &out.convective] {
            eval::check(o, Quantity::Outputs, t)?;
        }
        eval::check(&out.y_q, Quantity::Outputs, t)?;
        let OutputTerms {
            y,
            rate,
            y_q,
            convective,
        } = out;
        let target: TargetOf<T, N> = self.path.at(t);
        for (x, quantity) in [
            (&target.position, Quantity::PrescribedPosition),
            (&target.velocity, Quantity::PrescribedVelocity),
            (&target.acceleration, Quantity::PrescribedAcceleration),
        ] {
            if x.nrows() != np.value() {
                return Err(invalid_configuration(
                    "servo: the path gives another number of values than there are outputs",
                ));
            }
            if let Some(index) = crate::linalg::first_non_finite(x) {
                return Err(Error::new(ErrorKind::NonFiniteInput { quantity, index }, t));
            }
        }
        let gains = &self.config.output_gains;
        let s = target.acceleration
            + (target.velocity - rate) * T::of(2.0 * gains.alpha)
            + (target.position - y) * T::of(gains.beta * gains.beta)
            - convective;
        // Scales: the M^-1-norms of the output gradients and of the
        // actuator columns.
        let rows = OVector::<T, N>::from_fn_generic(np, U1, |i, _| {
            kkt.inverse_mass_norm(&y_q.row(i).transpose())
        });
        let cols = OVector::<T, U>::from_fn_generic(nu, U1, |j, _| {
            kkt.inverse_mass_norm(&b.column(j).into_owned())
        });
        let (tau, condition) = solve_normalised(
            &(&y_q * &xb),
            &(s - &y_q * &x0),
            (&rows, &cols),
            &self.config,
            t,
        )?;
        let qdd = x0 + xb * &tau;
        let lambda = mu0 + mub * &tau;
        eval::check_result(&qdd, Quantity::Acceleration, t)?;
        eval::check_result(&lambda, Quantity::ConstraintForces, t)?;
        Ok(ServoSolutionOf {
            tau,
            qdd,
            lambda,
            condition,
        })
    }
}

/// Solves the square system `a x = rhs` with `a` normalised to
/// `a~ = diag(1 / rows) a diag(1 / cols)`; returns `x` and `1 / sigma_min(a~)`,
/// or [`ErrorKind::SingularServo`] when that exceeds `limit` (a zero row or
/// column scale: infinite).
fn solve_normalised<T: Scalar, N: Dim, U: Dim>(
    a: &OMatrix<T, N, U>,
    rhs: &OVector<T, N>,
    (rows, cols): (&OVector<T, N>, &OVector<T, U>),
    config: &ServoConfig<T>,
    t: T,
) -> Result<(OVector<T, U>, T), Error>
where
    DefaultAllocator: Allocator<N, U> + Allocator<U, U> + Allocator<U> + Allocator<N>,
{
    let limit = config.max_condition;
    let singular = |condition: T| {
        Error::new(
            ErrorKind::SingularServo {
                condition: condition.into(),
                limit: limit.into(),
            },
            t,
        )
    };
    if !(rows.iter().chain(cols.iter()).all(|s| *s > T::zero())) {
        return Err(singular(T::INFINITY));
    }
    let (np, nu) = a.shape_generic();
    let mut scaled = a.clone();
    for j in 0..nu.value() {
        for i in 0..np.value() {
            scaled[(i, j)] /= rows[i] * cols[j];
        }
    }
    eval::check_result(&scaled, Quantity::Input, t)?;
    let svd = Svd::new(&scaled, config.max_sweeps)
        .map_err(|sweeps| Error::new(ErrorKind::DecompositionNotConverged { sweeps }, t))?;
    let condition = match nu.value() {
        0 => T::one(),
        n => T::one() / svd.sigma_sorted(n - 1),
    };
    if !(condition <= limit) {
        return Err(singular(condition));
    }
    let mut z = OVector::<T, U>::zeros_generic(nu, U1);
    svd.solve(&rhs.component_div(rows), nu.value(), &mut z);
    let x = z.component_div(cols);
    eval::check_result(&x, Quantity::Input, t)?;
    Ok((x, condition))
}

impl<'a, M: ?Sized, O, P, N: Dim, T: Scalar> Servo<'a, M, O, P, N, T> {
    /// The inner model's `M`, `h - B u`, `Phi_q`, `gamma` (NaN `h` and the
    /// error kept on failure).
    #[allow(clippy::too_many_arguments)]
    fn terms_under_input<Q: Dim, C: Dim, U: Dim>(
        &self,
        q: &OVector<T, Q>,
        qd: &OVector<T, Q>,
        t: T,
        m: &mut OMatrix<T, Q, Q>,
        h: &mut OVector<T, Q>,
        phi_q: &mut OMatrix<T, C, Q>,
        gamma: &mut OVector<T, C>,
    ) where
        M: Equations<Q, C, U, T>,
        O: Outputs<Q, N, T>,
        P: Trajectory<N, T>,
        DefaultAllocator: PrescribedSizes<Q, C, U, N>,
    {
        self.inner.dynamics_terms(q, qd, t, m, h, phi_q, gamma);
        let terms = Terms {
            m: m.clone(),
            h: h.clone(),
            phi_q: phi_q.clone(),
            gamma: gamma.clone(),
        };
        match self.solve_terms::<Q, C, U>(q, qd, t, terms) {
            Ok(solution) => subtract_input(self.inner, &solution.tau, h),
            Err(e) => {
                self.failure.set(Some(e));
                h.fill(T::NAN);
            }
        }
    }

    /// `h - B u` alone.
    fn bias_under_input<Q: Dim, C: Dim, U: Dim>(
        &self,
        q: &OVector<T, Q>,
        qd: &OVector<T, Q>,
        t: T,
        h: &mut OVector<T, Q>,
    ) where
        M: Equations<Q, C, U, T>,
        O: Outputs<Q, N, T>,
        P: Trajectory<N, T>,
        DefaultAllocator: PrescribedSizes<Q, C, U, N>,
    {
        let (nq, nc, _) = self.inner.sizes();
        let mut terms = Terms::<T, Q, C>::zeros(nq, nc);
        self.terms_under_input::<Q, C, U>(
            q,
            qd,
            t,
            &mut terms.m,
            h,
            &mut terms.phi_q,
            &mut terms.gamma,
        );
    }
}

/// A servo of a model of fixed size is one ([`Model`]).
impl<M, O, P, T, const NQ: usize, const NC: usize, const NU: usize, const NP: usize>
    Model<NQ, NC, NU, T> for Servo<'_, M, O, P, Const<NP>, T>
where
    M: Model<NQ, NC, NU, T>,
    O: Outputs<Const<NQ>, Const<NP>, T>,
    P: Trajectory<Const<NP>, T>,
    T: Scalar,
{
    crate::forward_model!(inner: M, NQ, NC, NU, T);
    fn bias(&self, q: &SVector<T, NQ>, qd: &SVector<T, NQ>, t: T, h: &mut SVector<T, NQ>) {
        self.bias_under_input::<Const<NQ>, Const<NC>, Const<NU>>(q, qd, t, h)
    }
    fn dynamics_terms(
        &self,
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        t: T,
        m: &mut SMatrix<T, NQ, NQ>,
        h: &mut SVector<T, NQ>,
        phi_q: &mut SMatrix<T, NC, NQ>,
        gamma: &mut SVector<T, NC>,
    ) {
        self.terms_under_input::<Const<NQ>, Const<NC>, Const<NU>>(q, qd, t, m, h, phi_q, gamma)
    }
}

/// A servo of a model of run-time size is one ([`Equations`] over `Dyn`;
/// with the `alloc` feature).
#[cfg(feature = "alloc")]
impl<M, O, P, T, N> Equations<Dyn, Dyn, Dyn, T> for Servo<'_, M, O, P, N, T>
where
    M: Equations<Dyn, Dyn, Dyn, T> + ?Sized,
    O: Outputs<Dyn, N, T>,
    P: Trajectory<N, T>,
    T: Scalar,
    N: Dim,
    DefaultAllocator: PrescribedSizes<Dyn, Dyn, Dyn, N>,
{
    crate::model::forward_equations!(inner, Dyn, Dyn, Dyn, T);
    fn bias(&self, q: &OVector<T, Dyn>, qd: &OVector<T, Dyn>, t: T, h: &mut OVector<T, Dyn>) {
        self.bias_under_input::<Dyn, Dyn, Dyn>(q, qd, t, h)
    }
    /// Not provided (the inputs' derivatives are unknown).
    fn bias_jacobians(
        &self,
        _: &OVector<T, Dyn>,
        _: &OVector<T, Dyn>,
        _: T,
        _: &mut OMatrix<T, Dyn, Dyn>,
        _: &mut OMatrix<T, Dyn, Dyn>,
    ) -> bool {
        false
    }
    fn dynamics_terms(
        &self,
        q: &OVector<T, Dyn>,
        qd: &OVector<T, Dyn>,
        t: T,
        m: &mut OMatrix<T, Dyn, Dyn>,
        h: &mut OVector<T, Dyn>,
        phi_q: &mut OMatrix<T, Dyn, Dyn>,
        gamma: &mut OVector<T, Dyn>,
    ) {
        self.terms_under_input::<Dyn, Dyn, Dyn>(q, qd, t, m, h, phi_q, gamma)
    }
    /// `M qdd + h - B u(q, qd, t)`.
    fn inverse_dynamics(
        &self,
        q: &OVector<T, Dyn>,
        qd: &OVector<T, Dyn>,
        qdd: &OVector<T, Dyn>,
        t: T,
        tau: &mut OVector<T, Dyn>,
    ) {
        let n = Dyn(q.nrows());
        let mut m = OMatrix::<T, Dyn, Dyn>::zeros_generic(n, n);
        self.inner.mass_matrix(q, t, &mut m);
        self.bias(q, qd, t, tau);
        *tau += m * qdd;
    }
}

/// One sample of [`servo_run`], `Q` coordinates and `U` inputs of fixed or
/// run-time size ([`ServoSample`]: fixed).
#[derive(Clone, Debug, PartialEq)]
pub struct ServoSampleOf<T: Scalar, Q: Dim, U: Dim>
where
    DefaultAllocator: Allocator<Q> + Allocator<U>,
{
    /// The state.
    pub state: StateOf<T, Q>,
    /// The actuator inputs at that time.
    pub tau: OVector<T, U>,
}

impl<T: Scalar, const NQ: usize, const NU: usize> Copy for ServoSampleOf<T, Const<NQ>, Const<NU>> {}

/// [`ServoSampleOf`] of a model of fixed size.
pub type ServoSample<const NQ: usize, const NU: usize, T = f64> =
    ServoSampleOf<T, Const<NQ>, Const<NU>>;

/// Summary of [`servo_run`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ServoSummary<T: Scalar = f64> {
    /// Steps taken.
    pub steps: usize,
    /// Largest servo condition seen.
    pub max_condition: T,
    /// Largest constraint drift after any step.
    pub max_drift: Drift<T>,
}

/// Inverse dynamics with the unprescribed coordinates integrated: `steps`
/// steps of `dt` from `state` (which should have its outputs on the path)
/// along the servo's prescription, calling `record` with the start and the
/// state after every step, with the inputs at that time.
///
/// Each step is a predictor-corrector pair: a trial step of the servo model
/// (by a copy of `integrator`) gives the inputs `tau_{n+1}` at the state it
/// reaches; the step taken is that of the plain model under the inputs
/// interpolated linearly from `tau_n` to `tau_{n+1}` ([`Linear`]), from the
/// integrator's own memory. So the recorded motion is exactly the forward
/// simulation, by the same integrator and step, of the recorded inputs; the
/// servo stabilisation acts on that motion. `record` gets `tau_{n+1}` with
/// the state the plain step reached (not the trial's). With
/// [`ServoConfig::trial_projection`] off, the trial step is taken without
/// the integrator's coordinate projection.
///
/// `record` returns whether to go on: [`ControlFlow::Break`] stops the run
/// after that sample (the summary counts the steps taken), e.g. when the
/// caller cannot store the sample.
///
/// Stops at the first error (the state is then the last one recorded): a
/// failure of the servo solve inside the trial step is returned as such
/// (e.g. [`ErrorKind::SingularServo`]), not as the non-finite bias forces
/// the integrator saw.
pub fn servo_run<'a, M, O, P, G, F, T: Scalar, Q: Dim, C: Dim, U: Dim, N: Dim>(
    servo: &Servo<'a, M, O, P, N, T>,
    integrator: &mut G,
    state: &mut StateOf<T, Q>,
    dt: T,
    steps: usize,
    mut record: F,
) -> Result<ServoSummary<T>, Error>
where
    M: Equations<Q, C, U, T> + ?Sized,
    O: Outputs<Q, N, T>,
    P: Trajectory<N, T>,
    G: IntegratorOf<Q, C, U, T> + Clone,
    F: FnMut(&ServoSampleOf<T, Q, U>) -> ControlFlow<()>,
    Servo<'a, M, O, P, N, T>: Equations<Q, C, U, T>,
    DefaultAllocator: PrescribedSizes<Q, C, U, N>,
{
    state.check_finite()?;
    let first = servo.solve::<Q, C, U>(&state.q, &state.qd, state.t)?;
    let mut sample = ServoSampleOf {
        state: state.clone(),
        tau: first.tau,
    };
    let mut summary = ServoSummary {
        max_condition: first.condition,
        ..ServoSummary::default()
    };
    if record(&sample).is_break() {
        return Ok(summary);
    }
    let zero = OVector::<T, U>::zeros_generic(sample.tau.shape_generic().0, U1);
    for _ in 0..steps {
        servo.take_failure();
        let mut trial_integrator = integrator.clone();
        if !servo.config.trial_projection {
            trial_integrator.settings_mut().projection = None;
        }
        let mut trial = state.clone();
        trial_integrator
            .step(servo, &mut trial, &zero, dt)
            .map_err(|e| servo.take_failure().unwrap_or(e))?;
        let next = servo.solve::<Q, C, U>(&trial.q, &trial.qd, trial.t)?;
        let input = LinearOf {
            t0: state.t,
            tau0: sample.tau,
            t1: trial.t,
            tau1: next.tau,
        };
        let report = integrator.step(servo.inner, state, &input, dt)?;
        summary.steps += 1;
        summary.max_condition = summary.max_condition.max(next.condition);
        summary.max_drift.position = summary.max_drift.position.max(report.drift.position);
        summary.max_drift.velocity = summary.max_drift.velocity.max(report.drift.velocity);
        sample = ServoSampleOf {
            state: state.clone(),
            tau: input.tau1,
        };
        if record(&sample).is_break() {
            break;
        }
    }
    Ok(summary)
}
