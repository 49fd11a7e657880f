//! Time integrators for the constrained equations of motion.
//!
//! Every integrator advances a [`State`] in place and leaves it unchanged when
//! it returns an error:
//!
//! * [`Rk4`]: classical explicit Runge–Kutta, fixed step, with a cheap
//!   stability estimate that rejects steps too large for the stiffest motion
//!   it sees;
//! * [`AdaptiveRk4`]: RK4 with step-doubling error control;
//! * [`SemiImplicitEuler`]: symplectic (semi-implicit) Euler, first order,
//!   one force evaluation per step, with RK4's stability estimate (two more
//!   evaluations) against its bound `dt * rho(J) < 2`;
//! * [`GaussLegendre4`]: two-stage Gauss–Legendre collocation, implicit,
//!   symplectic / symmetric, order 4, for accurate long runs of non-stiff
//!   conservative scenes; its fixed-point stage iteration contracts only
//!   for `dt * rho(J) < sqrt(12)`, and says so when it diverges;
//! * [`GeneralizedAlpha`]: implicit generalized-α (Chung–Hulbert, in the
//!   Arnold–Brüls form) with bounded Newton iterations, for stiff flexible
//!   models.
//!
//! Constraints are handled at the acceleration level with Baumgarte
//! stabilisation ([`crate::DynamicsConfig`]); optionally each step ends with a
//! coordinate projection ([`crate::ProjectionConfig`]). Every step reports the
//! constraint drift after it.

mod adaptive;
mod gauss_legendre;
mod gen_alpha;
mod rk4;
mod semi_implicit;

pub use adaptive::{AdaptiveReport, AdaptiveRk4, AdvanceReport};
pub use gauss_legendre::GaussLegendre4;
pub use gen_alpha::{GeneralizedAlpha, GeneralizedAlphaConfig, GeneralizedAlphaOf};
pub use rk4::Rk4;
pub use semi_implicit::SemiImplicitEuler;

use crate::dynamics::{accelerations, DynamicsConfig};
use crate::error::{Error, ErrorKind};
use crate::eval;
use crate::input::InputOf;
use crate::model::{Equations, Sizes};
use crate::projection::{project_with, ProjectionConfig, ProjectionReport};
use crate::scalar::Scalar;
use crate::state::{constraint_drift, Drift, StateOf};
use nalgebra::allocator::Allocator;
use nalgebra::{Const, DefaultAllocator, Dim, OVector};

/// Settings shared by all integrators.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepSettings<T: Scalar = f64> {
    /// Constrained acceleration solve (Baumgarte gains, conditioning limit).
    pub dynamics: DynamicsConfig<T>,
    /// Coordinate projection after every step, if set.
    pub projection: Option<ProjectionConfig<T>>,
    /// Largest accepted step size; larger steps fail with
    /// [`ErrorKind::StepTooLarge`]. Default: no limit.
    pub max_step: T,
}

impl<T: Scalar> Default for StepSettings<T> {
    fn default() -> Self {
        StepSettings {
            dynamics: DynamicsConfig::default(),
            projection: None,
            max_step: T::INFINITY,
        }
    }
}

impl<T: Scalar> StepSettings<T> {
    /// Default settings with coordinate projection after every step.
    pub fn with_projection() -> Self {
        StepSettings {
            projection: Some(ProjectionConfig::default()),
            ..Self::default()
        }
    }
}

/// What one step did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StepReport<T: Scalar = f64> {
    /// Time after the step.
    pub t: T,
    /// Step size taken.
    pub dt: T,
    /// Iteration count: Newton iterations ([`GeneralizedAlpha`]), stage
    /// fixed-point sweeps ([`GaussLegendre4`]), accepted substeps
    /// ([`AdaptiveRk4`] used as an [`Integrator`]); 0 for the fixed-step
    /// explicit schemes.
    pub iterations: u32,
    /// Explicit schemes ([`Rk4`], [`AdaptiveRk4`], [`SemiImplicitEuler`]
    /// with its check on): estimate of `dt * rho(J)` (spectral radius of
    /// the linearised dynamics) from the RK stages; 0 where not measured.
    pub stability_estimate: T,
    /// The projection performed after the step, if any.
    pub projection: Option<ProjectionReport<T>>,
    /// Constraint drift of the state after the step (after projection).
    pub drift: Drift<T>,
}

/// A time integrator: advances `state` by `dt` under the input `input`, for
/// models of `Q` coordinates, `C` constraints and `U` inputs (`Const<N>`
/// for generated models, `Dyn` for models of run-time size).
pub trait IntegratorOf<Q: Dim, C: Dim, U: Dim, T: Scalar = f64>
where
    DefaultAllocator: Sizes<Q, C, U>,
{
    /// Advances `state` by `dt`. On error the state (and any integrator
    /// memory) is left as it was before the call.
    fn step<M, I>(
        &mut self,
        model: &M,
        state: &mut StateOf<T, Q>,
        input: &I,
        dt: T,
    ) -> Result<StepReport<T>, Error>
    where
        M: Equations<Q, C, U, T> + ?Sized,
        I: InputOf<U, T> + ?Sized;

    /// The integrator's step settings (e.g. for [`crate::control::servo_run`]
    /// to take its trial step without the coordinate projection).
    fn settings_mut(&mut self) -> &mut StepSettings<T>;
}

/// [`IntegratorOf`] for models of fixed size, `NQ` coordinates, `NC`
/// constraints, `NU` inputs: what firmware code names. Implemented for
/// every [`IntegratorOf`] of those sizes.
pub trait Integrator<const NQ: usize, const NC: usize, const NU: usize, T: Scalar = f64>:
    IntegratorOf<Const<NQ>, Const<NC>, Const<NU>, T>
{
}

impl<G, T: Scalar, const NQ: usize, const NC: usize, const NU: usize> Integrator<NQ, NC, NU, T>
    for G
where
    G: IntegratorOf<Const<NQ>, Const<NC>, Const<NU>, T>,
{
}

/// Summary of [`run`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RunSummary<T: Scalar = f64> {
    /// Steps taken.
    pub steps: usize,
    /// Largest position and velocity drift seen after any step.
    pub max_drift: Drift<T>,
    /// Largest Newton iteration count of any step.
    pub max_iterations: u32,
}

/// Takes `steps` steps of size `dt`, calling `observe` after each. Stops at the
/// first error (the state is then the one before the failed step).
pub fn run<G, M, I, F, T: Scalar, Q: Dim, C: Dim, U: Dim>(
    integrator: &mut G,
    model: &M,
    state: &mut StateOf<T, Q>,
    input: &I,
    dt: T,
    steps: usize,
    mut observe: F,
) -> Result<RunSummary<T>, Error>
where
    G: IntegratorOf<Q, C, U, T>,
    M: Equations<Q, C, U, T> + ?Sized,
    I: InputOf<U, T> + ?Sized,
    F: FnMut(&StateOf<T, Q>, &StepReport<T>),
    DefaultAllocator: Sizes<Q, C, U>,
{
    let mut summary = RunSummary::<T>::default();
    for _ in 0..steps {
        let report = integrator.step(model, state, input, dt)?;
        summary.steps += 1;
        summary.max_drift.position = summary.max_drift.position.max(report.drift.position);
        summary.max_drift.velocity = summary.max_drift.velocity.max(report.drift.velocity);
        summary.max_iterations = summary.max_iterations.max(report.iterations);
        observe(state, &report);
    }
    Ok(summary)
}

/// Validates the state and the step size at the start of a step.
pub(crate) fn begin_step<T: Scalar, Q: Dim>(
    state: &StateOf<T, Q>,
    dt: T,
    max_step: T,
) -> Result<(), Error>
where
    DefaultAllocator: Allocator<Q>,
{
    state.check_finite()?;
    if !(dt > T::zero()) || !dt.is_finite() || !(state.t + dt).is_finite() {
        return Err(Error::new(
            ErrorKind::InvalidStepSize { dt: dt.into() },
            state.t,
        ));
    }
    if dt > max_step {
        return Err(Error::new(
            ErrorKind::StepTooLarge {
                dt: dt.into(),
                value: dt.into(),
                limit: max_step.into(),
                rate: None,
            },
            state.t,
        ));
    }
    Ok(())
}

/// Accelerations at `(q, qd, t)` with the input sampled at `t`.
pub(crate) fn qdd_at<M, I, T: Scalar, Q: Dim, C: Dim, U: Dim>(
    model: &M,
    config: &DynamicsConfig<T>,
    q: &OVector<T, Q>,
    qd: &OVector<T, Q>,
    t: T,
    input: &I,
) -> Result<OVector<T, Q>, Error>
where
    M: Equations<Q, C, U, T> + ?Sized,
    I: InputOf<U, T> + ?Sized,
    DefaultAllocator: Sizes<Q, C, U>,
{
    let tau = input.at(t);
    eval::check_input(&tau, t)?;
    Ok(accelerations(model, config, q, qd, t, &tau)?.qdd)
}

/// Post-step work: optional projection, then the drift measurement.
pub(crate) fn finish_step<M, T: Scalar, Q: Dim, C: Dim, U: Dim>(
    model: &M,
    next: &mut StateOf<T, Q>,
    settings: &StepSettings<T>,
) -> Result<(Option<ProjectionReport<T>>, Drift<T>), Error>
where
    M: Equations<Q, C, U, T> + ?Sized,
    DefaultAllocator: Sizes<Q, C, U>,
{
    finish_step_with(model, next, settings, T::zero())
}

/// [`finish_step`] with the SHAKE-style velocity update of
/// [`crate::projection::project_with`].
pub(crate) fn finish_step_with<M, T: Scalar, Q: Dim, C: Dim, U: Dim>(
    model: &M,
    next: &mut StateOf<T, Q>,
    settings: &StepSettings<T>,
    velocity_from_position_dt: T,
) -> Result<(Option<ProjectionReport<T>>, Drift<T>), Error>
where
    M: Equations<Q, C, U, T> + ?Sized,
    DefaultAllocator: Sizes<Q, C, U>,
{
    let projection = match &settings.projection {
        Some(cfg) if model.sizes().1.value() > 0 => Some(project_with(
            model,
            next,
            cfg,
            velocity_from_position_dt,
            true,
        )?),
        _ => None,
    };
    let drift = match projection {
        Some(p) => p.after,
        None => constraint_drift(model, next),
    };
    Ok((projection, drift))
}

/// Power iterations of [`spectral_radius`]: each costs at most four
/// accelerations.
const RATE_ITERATIONS: usize = 24;

/// Spectral radius of the Jacobian `J` of `(q, qd) -> (qd, qdd)` at `s`, by
/// a power iteration on `J^2` (an undamped mode's pair `+-i w` becomes the
/// real `-w^2`, a decay rate `-s` becomes `s^2`) with finite-difference
/// products `J v`: [`RATE_ITERATIONS`] iterations from a fixed start vector,
/// so bounded work. Used only on the refusal paths of [`Rk4`], [`SemiImplicitEuler`] and
/// [`GaussLegendre4`]; `None` when an
/// evaluation fails.
pub(crate) fn spectral_radius<M, I, T: Scalar, Q: Dim, C: Dim, U: Dim>(
    model: &M,
    dynamics: &DynamicsConfig<T>,
    s: &StateOf<T, Q>,
    input: &I,
) -> Option<T>
where
    M: Equations<Q, C, U, T> + ?Sized,
    I: InputOf<U, T> + ?Sized,
    DefaultAllocator: Sizes<Q, C, U>,
{
    let a0 = qdd_at(model, dynamics, &s.q, &s.qd, s.t, input).ok()?;
    let eps = T::of(1e-7) * (T::one() + s.q.amax() + s.qd.amax());
    let norm = |x: &OVector<T, Q>, y: &OVector<T, Q>| {
        Scalar::square_root(x.norm_squared() + y.norm_squared())
    };
    // J (dq, dv) = (dv, A dq + B dv) with A = dqdd/dq, B = dqdd/dqd, each
    // product by a one-sided difference whose step moves q or qd by eps
    // whatever the size of dq or dv (the model is linearised, not probed far
    // away, and a small part is not lost to rounding next to a large one).
    let nq = s.q.shape_generic().0;
    let apply = |dq: &OVector<T, Q>, dv: &OVector<T, Q>| {
        let mut jv = OVector::<T, Q>::zeros_generic(nq, nalgebra::U1);
        for (x, along_q) in [(dq, true), (dv, false)] {
            let n = Scalar::square_root(x.norm_squared());
            if n > T::zero() {
                let h = eps / n;
                let (q, qd) = if along_q {
                    (&s.q + x * h, s.qd.clone())
                } else {
                    (s.q.clone(), &s.qd + x * h)
                };
                jv += (qdd_at(model, dynamics, &q, &qd, s.t, input).ok()? - &a0) / h;
            }
        }
        Some((dv.clone(), jv))
    };
    // A start with a component along every coordinate and velocity.
    let mut dq = OVector::<T, Q>::from_fn_generic(nq, nalgebra::U1, |i, _| {
        T::one() + T::of(0.37) * T::of(i as f64)
    });
    let mut dv = OVector::<T, Q>::from_fn_generic(nq, nalgebra::U1, |i, _| {
        T::one() - T::of(0.23) * T::of(i as f64)
    });
    let mut rho2 = T::zero();
    for _ in 0..RATE_ITERATIONS {
        let n = norm(&dq, &dv);
        if n == T::zero() {
            // The iterate vanished: `J^2` maps the start (which has a part
            // along every direction) to zero, no mode at all (a free motion,
            // or forces constant near the state).
            return Some(T::zero());
        }
        if !n.is_finite() {
            return None;
        }
        (dq, dv) = (dq / n, dv / n);
        let (xq, xv) = apply(&dq, &dv)?;
        (dq, dv) = apply(&xq, &xv)?;
        rho2 = norm(&dq, &dv);
    }
    let rho = Scalar::square_root(rho2);
    rho.is_finite().then_some(rho)
}

/// How many times faster than the fastest mode of the model linearised at
/// the state the stages of a refused explicit step must see the motion
/// before the refusal blames abrupt forces ([`ErrorKind::AbruptForces`])
/// rather than a mode: on a linear mode the stage estimate is within a
/// factor 1.5 of it.
pub const ABRUPT_RATIO: f64 = 10.0;

/// A stability refusal ([`ErrorKind::StepTooLarge`] with a rate) or a
/// diverged Gauss–Legendre stage iteration, naming the fastest mode of the
/// model linearised at `s` ([`spectral_radius`]): the stages see only the
/// modes the state excites (and, far beyond the limit, their estimate is no
/// longer accurate). A refusal keeps the larger of the two rates, and its
/// `value` becomes `dt` times that rate, so that the reported `dt * rho(J)`
/// and the suggested step `limit / rate` come from one number (and that
/// step satisfies both estimates) — unless the linearised model is more
/// than [`ABRUPT_RATIO`] times slower than the stages' rate, when the
/// refusal becomes [`ErrorKind::AbruptForces`]. Other errors pass
/// unchanged.
pub(crate) fn name_fastest_mode<M, I, T: Scalar, Q: Dim, C: Dim, U: Dim>(
    mut e: Error,
    model: &M,
    dynamics: &DynamicsConfig<T>,
    s: &StateOf<T, Q>,
    input: &I,
) -> Error
where
    M: Equations<Q, C, U, T> + ?Sized,
    I: InputOf<U, T> + ?Sized,
    DefaultAllocator: Sizes<Q, C, U>,
{
    match &mut e.kind {
        ErrorKind::StepTooLarge {
            dt,
            value,
            limit,
            rate: Some(rate),
        } => {
            if let Some(rho) = spectral_radius(model, dynamics, s, input) {
                let linear_rate: f64 = rho.into();
                if linear_rate * ABRUPT_RATIO < *rate {
                    e.kind = ErrorKind::AbruptForces {
                        dt: *dt,
                        value: *value,
                        limit: *limit,
                        linear_rate,
                    };
                } else {
                    *rate = rate.max(linear_rate);
                    *value = *dt * *rate;
                }
            }
        }
        ErrorKind::StageIterationFailed { rate, .. } => {
            *rate = spectral_radius(model, dynamics, s, input).map(Into::into)
        }
        _ => {}
    }
    e
}
