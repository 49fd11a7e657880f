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
//! [ Y_q     0         0 ] [u     ]   [ s  ]   s = yd'' + 2 alpha_s (yd' - Y_q qd)
//!                                                  + beta_s^2 (y_d - y) - (dY_q/dt) qd
//! ```
//!
//! so that the output error `e = y_d - y` obeys `e'' + 2 alpha_s e' +
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
use super::Trajectory;
use crate::dynamics::{stabilised_rhs, Baumgarte, DynamicsConfig, Kkt};
use crate::error::{check_indices, Error, ErrorKind, Quantity};
use crate::eval::{self, Terms};
use crate::input::Linear;
use crate::integrate::IntegratorOf;
use crate::linalg::Svd;
use crate::model::Model;
use crate::scalar::Scalar;
use crate::state::{Drift, State};
use core::cell::Cell;
use nalgebra::{Const, SMatrix, SVector};

/// `NP` outputs `y(q)` of a model with `NQ` coordinates, with their
/// Jacobian; [`Coordinates`] selects coordinates.
pub trait Outputs<const NQ: usize, const NP: usize, T: Scalar = f64> {
    /// Checks the set-up ([`Servo::new`] calls it); the default accepts it.
    fn validate(&self) -> Result<(), Error> {
        Ok(())
    }

    /// Writes `y(q)`, `Y_q = dy/dq` and the convective term `(dY_q/dt) qd`
    /// (so that `y'' = Y_q qdd + (dY_q/dt) qd`). Every output is written.
    fn evaluate(
        &self,
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        y: &mut SVector<T, NP>,
        y_q: &mut SMatrix<T, NP, NQ>,
        convective: &mut SVector<T, NP>,
    );
}

/// Prescribed coordinates: output `k` is `q[self.0[k]]` (`Y_q` selects, no
/// convective term).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Coordinates<const NP: usize>(pub [usize; NP]);

impl<T: Scalar, const NQ: usize, const NP: usize> Outputs<NQ, NP, T> for Coordinates<NP> {
    /// [`ErrorKind::InvalidIndex`] if an index is not below `NQ` or repeats.
    fn validate(&self) -> Result<(), Error> {
        check_indices("prescribed coordinate", &self.0, NQ, true)
    }

    fn evaluate(
        &self,
        q: &SVector<T, NQ>,
        _qd: &SVector<T, NQ>,
        y: &mut SVector<T, NP>,
        y_q: &mut SMatrix<T, NP, NQ>,
        convective: &mut SVector<T, NP>,
    ) {
        y_q.fill(T::zero());
        convective.fill(T::zero());
        for (k, &i) in self.0.iter().enumerate() {
            // Validated indices; an invalid one gives NaN, never a panic.
            match q.get(i) {
                Some(&qi) => {
                    y[k] = qi;
                    y_q[(k, i)] = T::one();
                }
                None => y[k] = T::NAN,
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

/// The servo solve at one state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ServoSolution<const NQ: usize, const NC: usize, const NU: usize, T: Scalar = f64> {
    /// Actuator inputs.
    pub tau: SVector<T, NU>,
    /// Accelerations under them.
    pub qdd: SVector<T, NQ>,
    /// Constraint forces (multipliers).
    pub lambda: SVector<T, NC>,
    /// Servo condition: `1 / sigma_min` of the normalised servo matrix
    /// (module docs).
    pub condition: T,
}

/// The model `inner` with its inputs chosen so that the outputs `O` follow
/// the path `P` (module docs). As a [`Model`] its bias forces are
/// `h - B u(q, qd, t)`; integrate it with zero input. A failed solve inside
/// a model evaluation writes NaN bias forces (which the integrator reports)
/// and keeps the error for [`Servo::take_failure`]. Computes in the model's
/// scalar `T` (`f64` unless named), the path and the outputs included.
pub struct Servo<'a, M, O, P, const NP: usize, T: Scalar = f64> {
    inner: &'a M,
    outputs: O,
    path: P,
    /// Settings.
    pub config: ServoConfig<T>,
    failure: Cell<Option<Error>>,
}

impl<'a, M, O, P, T: Scalar, const NP: usize> Servo<'a, M, O, P, NP, T> {
    /// Servo constraints making `outputs` of `inner` follow `path`.
    ///
    /// Errors: [`ErrorKind::InvalidConfiguration`] unless `NP == NU`;
    /// whatever [`Outputs::validate`] reports (for [`Coordinates`],
    /// [`ErrorKind::InvalidIndex`]).
    pub fn new<const NQ: usize, const NC: usize, const NU: usize>(
        inner: &'a M,
        outputs: O,
        path: P,
        config: ServoConfig<T>,
    ) -> Result<Self, Error>
    where
        M: Model<NQ, NC, NU, T>,
        O: Outputs<NQ, NP, T>,
        P: Trajectory<Const<NP>, T>,
    {
        if NP > NU {
            return Err(Error::new(
                ErrorKind::InvalidConfiguration {
                    reason: "servo: more prescribed outputs than actuator inputs (NP > NU): \
                             the prescription over-determines the inputs",
                },
                0.0,
            ));
        }
        if NP < NU {
            return Err(Error::new(
                ErrorKind::InvalidConfiguration {
                    reason: "servo: fewer prescribed outputs than actuator inputs (NP < NU): \
                             the prescription does not determine the inputs",
                },
                0.0,
            ));
        }
        outputs.validate()?;
        Ok(Servo {
            inner,
            outputs,
            path,
            config,
            failure: Cell::new(None),
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
    pub fn solve<const NQ: usize, const NC: usize, const NU: usize>(
        &self,
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        t: T,
    ) -> Result<ServoSolution<NQ, NC, NU, T>, Error>
    where
        M: Model<NQ, NC, NU, T>,
        O: Outputs<NQ, NP, T>,
        P: Trajectory<Const<NP>, T>,
    {
        let terms = eval::dynamics_terms(self.inner, q, qd, t)?;
        self.solve_terms(q, qd, t, terms)
    }

    /// [`Servo::solve`] from the model's terms at the state.
    fn solve_terms<const NQ: usize, const NC: usize, const NU: usize>(
        &self,
        q: &SVector<T, NQ>,
        qd: &SVector<T, NQ>,
        t: T,
        terms: Terms<T, Const<NQ>, Const<NC>>,
    ) -> Result<ServoSolution<NQ, NC, NU, T>, Error>
    where
        M: Model<NQ, NC, NU, T>,
        O: Outputs<NQ, NP, T>,
        P: Trajectory<Const<NP>, T>,
    {
        eval::check_terms(&terms, t)?;
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
        let mut xb = SMatrix::<T, NQ, NU>::zeros();
        let mut mub = SMatrix::<T, NC, NU>::zeros();
        for j in 0..NU {
            let (x, mu) = kkt.solve(&b.column(j).into_owned(), &SVector::zeros());
            xb.set_column(j, &x);
            mub.set_column(j, &mu);
        }
        let mut y = SVector::<T, NP>::zeros();
        let mut y_q = SMatrix::<T, NP, NQ>::zeros();
        let mut convective = SVector::<T, NP>::zeros();
        self.outputs
            .evaluate(q, qd, &mut y, &mut y_q, &mut convective);
        for o in [&y, &convective] {
            eval::check(o, Quantity::Outputs, t)?;
        }
        eval::check(&y_q, Quantity::Outputs, t)?;
        let target = self.path.at(t);
        for (x, quantity) in [
            (&target.position, Quantity::PrescribedPosition),
            (&target.velocity, Quantity::PrescribedVelocity),
            (&target.acceleration, Quantity::PrescribedAcceleration),
        ] {
            if let Some(index) = crate::linalg::first_non_finite(x) {
                return Err(Error::new(ErrorKind::NonFiniteInput { quantity, index }, t));
            }
        }
        let gains = &self.config.output_gains;
        let s = target.acceleration
            + (target.velocity - y_q * qd) * T::of(2.0 * gains.alpha)
            + (target.position - y) * T::of(gains.beta * gains.beta)
            - convective;
        // Scales: the M^-1-norms of the output gradients and of the
        // actuator columns.
        let rows = SVector::<T, NP>::from_fn(|i, _| kkt.inverse_mass_norm(&y_q.row(i).transpose()));
        let cols =
            SVector::<T, NU>::from_fn(|j, _| kkt.inverse_mass_norm(&b.column(j).into_owned()));
        let (tau, condition) = solve_normalised(
            &(y_q * xb),
            &(s - y_q * x0),
            (&rows, &cols),
            &self.config,
            t,
        )?;
        let qdd = x0 + xb * tau;
        let lambda = mu0 + mub * tau;
        eval::check_result(&qdd, Quantity::Acceleration, t)?;
        eval::check_result(&lambda, Quantity::ConstraintForces, t)?;
        Ok(ServoSolution {
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
fn solve_normalised<T: Scalar, const NP: usize, const NU: usize>(
    a: &SMatrix<T, NP, NU>,
    rhs: &SVector<T, NP>,
    (rows, cols): (&SVector<T, NP>, &SVector<T, NU>),
    config: &ServoConfig<T>,
    t: T,
) -> Result<(SVector<T, NU>, T), Error> {
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
    let mut scaled = *a;
    for j in 0..NU {
        for i in 0..NP {
            scaled[(i, j)] /= rows[i] * cols[j];
        }
    }
    eval::check_result(&scaled, Quantity::Input, t)?;
    let svd = Svd::new(&scaled, config.max_sweeps)
        .map_err(|sweeps| Error::new(ErrorKind::DecompositionNotConverged { sweeps }, t))?;
    let condition = if NU == 0 {
        T::one()
    } else {
        T::one() / svd.sigma_sorted(NU - 1)
    };
    if !(condition <= limit) {
        return Err(singular(condition));
    }
    let mut z = SVector::<T, NU>::zeros();
    svd.solve(&rhs.component_div(rows), NU, &mut z);
    let x = z.component_div(cols);
    eval::check_result(&x, Quantity::Input, t)?;
    Ok((x, condition))
}

impl<M, O, P, T, const NQ: usize, const NC: usize, const NU: usize, const NP: usize>
    Model<NQ, NC, NU, T> for Servo<'_, M, O, P, NP, T>
where
    M: Model<NQ, NC, NU, T>,
    O: Outputs<NQ, NP, T>,
    P: Trajectory<Const<NP>, T>,
    T: Scalar,
{
    crate::forward_model!(inner: M, NQ, NC, NU, T);
    fn bias(&self, q: &SVector<T, NQ>, qd: &SVector<T, NQ>, t: T, h: &mut SVector<T, NQ>) {
        let mut terms = Terms::<T, Const<NQ>, Const<NC>>::zeros(Const, Const);
        self.dynamics_terms(
            q,
            qd,
            t,
            &mut terms.m,
            h,
            &mut terms.phi_q,
            &mut terms.gamma,
        );
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
        self.inner.dynamics_terms(q, qd, t, m, h, phi_q, gamma);
        let terms = Terms {
            m: *m,
            h: *h,
            phi_q: *phi_q,
            gamma: *gamma,
        };
        match self.solve_terms(q, qd, t, terms) {
            Ok(solution) => subtract_input(self.inner, &solution.tau, h),
            Err(e) => {
                self.failure.set(Some(e));
                h.fill(T::NAN);
            }
        }
    }
}

/// One sample of [`servo_run`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ServoSample<const NQ: usize, const NU: usize, T: Scalar = f64> {
    /// The state.
    pub state: State<NQ, T>,
    /// The actuator inputs at that time.
    pub tau: SVector<T, NU>,
}

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
/// Stops at the first error (the state is then the last one recorded): a
/// failure of the servo solve inside the trial step is returned as such
/// (e.g. [`ErrorKind::SingularServo`]), not as the non-finite bias forces
/// the integrator saw.
pub fn servo_run<
    M,
    O,
    P,
    G,
    F,
    T: Scalar,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NP: usize,
>(
    servo: &Servo<'_, M, O, P, NP, T>,
    integrator: &mut G,
    state: &mut State<NQ, T>,
    dt: T,
    steps: usize,
    mut record: F,
) -> Result<ServoSummary<T>, Error>
where
    M: Model<NQ, NC, NU, T>,
    O: Outputs<NQ, NP, T>,
    P: Trajectory<Const<NP>, T>,
    G: IntegratorOf<Const<NQ>, Const<NC>, Const<NU>, T> + Clone,
    F: FnMut(&ServoSample<NQ, NU, T>),
{
    state.check_finite()?;
    let first = servo.solve(&state.q, &state.qd, state.t)?;
    let mut tau = first.tau;
    let mut summary = ServoSummary {
        max_condition: first.condition,
        ..ServoSummary::default()
    };
    record(&ServoSample { state: *state, tau });
    let zero = SVector::<T, NU>::zeros();
    for _ in 0..steps {
        servo.take_failure();
        let mut trial_integrator = integrator.clone();
        if !servo.config.trial_projection {
            trial_integrator.settings_mut().projection = None;
        }
        let mut trial = *state;
        trial_integrator
            .step(servo, &mut trial, &zero, dt)
            .map_err(|e| servo.take_failure().unwrap_or(e))?;
        let next = servo.solve(&trial.q, &trial.qd, trial.t)?;
        let input = Linear {
            t0: state.t,
            tau0: tau,
            t1: trial.t,
            tau1: next.tau,
        };
        let report = integrator.step(servo.inner, state, &input, dt)?;
        tau = next.tau;
        summary.steps += 1;
        summary.max_condition = summary.max_condition.max(next.condition);
        summary.max_drift.position = summary.max_drift.position.max(report.drift.position);
        summary.max_drift.velocity = summary.max_drift.velocity.max(report.drift.velocity);
        record(&ServoSample { state: *state, tau });
    }
    Ok(summary)
}
