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
//!   one force evaluation per step;
//! * [`GaussLegendre4`]: two-stage Gauss–Legendre collocation, implicit,
//!   symplectic / symmetric, order 4, for accurate long runs of non-stiff
//!   conservative scenes;
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
pub use gen_alpha::{GeneralizedAlpha, GeneralizedAlphaConfig};
pub use rk4::Rk4;
pub use semi_implicit::SemiImplicitEuler;

use crate::dynamics::{accelerations, DynamicsConfig};
use crate::error::{Error, ErrorKind};
use crate::eval;
use crate::input::Input;
use crate::model::Model;
use crate::projection::{project_with, ProjectionConfig, ProjectionReport};
use crate::state::{constraint_drift, Drift, State};
use nalgebra::SVector;

/// Settings shared by all integrators.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepSettings {
    /// Constrained acceleration solve (Baumgarte gains, conditioning limit).
    pub dynamics: DynamicsConfig,
    /// Coordinate projection after every step, if set.
    pub projection: Option<ProjectionConfig>,
    /// Largest accepted step size; larger steps fail with
    /// [`ErrorKind::StepTooLarge`]. Default: no limit.
    pub max_step: f64,
}

impl Default for StepSettings {
    fn default() -> Self {
        StepSettings {
            dynamics: DynamicsConfig::default(),
            projection: None,
            max_step: f64::INFINITY,
        }
    }
}

impl StepSettings {
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
pub struct StepReport {
    /// Time after the step.
    pub t: f64,
    /// Step size taken.
    pub dt: f64,
    /// Iteration count: Newton iterations ([`GeneralizedAlpha`]), stage
    /// fixed-point sweeps ([`GaussLegendre4`]), accepted substeps
    /// ([`AdaptiveRk4`] used as an [`Integrator`]); 0 for the fixed-step
    /// explicit schemes.
    pub iterations: u32,
    /// Explicit schemes: estimate of `dt * rho(J)` (spectral radius of the
    /// linearised dynamics) from the RK stages; 0 where not measured.
    pub stability_estimate: f64,
    /// The projection performed after the step, if any.
    pub projection: Option<ProjectionReport>,
    /// Constraint drift of the state after the step (after projection).
    pub drift: Drift,
}

/// A time integrator: advances `state` by `dt` under the input `input`.
pub trait Integrator<const NQ: usize, const NC: usize, const NU: usize> {
    /// Advances `state` by `dt`. On error the state (and any integrator
    /// memory) is left as it was before the call.
    fn step<M, I>(
        &mut self,
        model: &M,
        state: &mut State<NQ>,
        input: &I,
        dt: f64,
    ) -> Result<StepReport, Error>
    where
        M: Model<NQ, NC, NU>,
        I: Input<NU> + ?Sized;
}

/// Summary of [`run`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RunSummary {
    /// Steps taken.
    pub steps: usize,
    /// Largest position and velocity drift seen after any step.
    pub max_drift: Drift,
    /// Largest Newton iteration count of any step.
    pub max_iterations: u32,
}

/// Takes `steps` steps of size `dt`, calling `observe` after each. Stops at the
/// first error (the state is then the one before the failed step).
pub fn run<G, M, I, F, const NQ: usize, const NC: usize, const NU: usize>(
    integrator: &mut G,
    model: &M,
    state: &mut State<NQ>,
    input: &I,
    dt: f64,
    steps: usize,
    mut observe: F,
) -> Result<RunSummary, Error>
where
    G: Integrator<NQ, NC, NU>,
    M: Model<NQ, NC, NU>,
    I: Input<NU> + ?Sized,
    F: FnMut(&State<NQ>, &StepReport),
{
    let mut summary = RunSummary::default();
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
pub(crate) fn begin_step<const NQ: usize>(
    state: &State<NQ>,
    dt: f64,
    max_step: f64,
) -> Result<(), Error> {
    state.check_finite()?;
    if !(dt > 0.0) || !dt.is_finite() || !(state.t + dt).is_finite() {
        return Err(Error::new(ErrorKind::InvalidStepSize { dt }, state.t));
    }
    if dt > max_step {
        return Err(Error::new(
            ErrorKind::StepTooLarge {
                dt,
                value: dt,
                limit: max_step,
                rate: None,
            },
            state.t,
        ));
    }
    Ok(())
}

/// Accelerations at `(q, qd, t)` with the input sampled at `t`.
pub(crate) fn qdd_at<M, I, const NQ: usize, const NC: usize, const NU: usize>(
    model: &M,
    config: &DynamicsConfig,
    q: &SVector<f64, NQ>,
    qd: &SVector<f64, NQ>,
    t: f64,
    input: &I,
) -> Result<SVector<f64, NQ>, Error>
where
    M: Model<NQ, NC, NU>,
    I: Input<NU> + ?Sized,
{
    let tau = input.at(t);
    eval::check_input(&tau, t)?;
    Ok(accelerations(model, config, q, qd, t, &tau)?.qdd)
}

/// Post-step work: optional projection, then the drift measurement.
pub(crate) fn finish_step<M, const NQ: usize, const NC: usize, const NU: usize>(
    model: &M,
    next: &mut State<NQ>,
    settings: &StepSettings,
) -> Result<(Option<ProjectionReport>, Drift), Error>
where
    M: Model<NQ, NC, NU>,
{
    finish_step_with(model, next, settings, 0.0)
}

/// [`finish_step`] with the SHAKE-style velocity update of
/// [`crate::projection::project_with`].
pub(crate) fn finish_step_with<M, const NQ: usize, const NC: usize, const NU: usize>(
    model: &M,
    next: &mut State<NQ>,
    settings: &StepSettings,
    velocity_from_position_dt: f64,
) -> Result<(Option<ProjectionReport>, Drift), Error>
where
    M: Model<NQ, NC, NU>,
{
    let projection = match &settings.projection {
        Some(cfg) if NC > 0 => Some(project_with(model, next, cfg, velocity_from_position_dt)?),
        _ => None,
    };
    let drift = match projection {
        Some(p) => p.after,
        None => constraint_drift(model, next),
    };
    Ok((projection, drift))
}
