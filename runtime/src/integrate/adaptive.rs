//! RK4 with step-doubling error control.

use super::rk4::rk4_raw;
use super::{begin_step, finish_step, name_fastest_mode, IntegratorOf, StepReport, StepSettings};
use crate::error::{Error, ErrorKind};
use crate::input::InputOf;
use crate::math::{exp, ln, sqrt};
use crate::model::{Equations, Sizes};
use crate::state::{Drift, StateOf};
use nalgebra::allocator::Allocator;
use nalgebra::{DefaultAllocator, Dim};

/// Error-controlled RK4.
///
/// Each trial takes one step of size `h` and two of size `h/2`; their
/// difference divided by 15 estimates the local error of the two half steps
/// (Richardson). The scaled RMS norm
/// `sqrt(mean((err_i / (atol + rtol max(|y_i|, |y'_i|)))^2))` over all `q`
/// and `qd` components must be at most 1; the accepted result is the locally
/// extrapolated (fifth-order) value. The next step is
/// `h * clamp(safety * err^(-1/5), min_factor, max_factor)`.
///
/// A trial that fails the RK4 stability estimate or overflows is rejected
/// and retried with `h * min_factor`; if that keeps failing until the step
/// falls below `min_step` or the rejections run out, that failure
/// ([`ErrorKind::StepTooLarge`] / [`ErrorKind::NonFiniteResult`]) is
/// returned. Work per call is bounded by `max_rejections + 1` trials (11
/// acceleration solves each).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AdaptiveRk4 {
    /// Shared settings (`max_step` caps the step size here rather than failing).
    pub settings: StepSettings,
    /// Relative tolerance.
    pub rtol: f64,
    /// Absolute tolerance.
    pub atol: f64,
    /// Safety factor on the step-size prediction.
    pub safety: f64,
    /// Smallest step-size reduction factor per trial.
    pub min_factor: f64,
    /// Largest step-size growth factor per step.
    pub max_factor: f64,
    /// Smallest step size tried before failing with [`ErrorKind::StepSizeUnderflow`].
    pub min_step: f64,
    /// Trials that may be rejected in one step before failing with
    /// [`ErrorKind::TooManyRejections`].
    pub max_rejections: u32,
    /// Cap on accepted substeps per [`Integrator::step`] call (which advances
    /// by exactly the requested `dt`).
    pub max_substeps: u32,
    /// RK4 stability-estimate limit (see [`super::Rk4`]).
    pub stability_limit: f64,
    /// Step size proposed for the next step (`None` until the first step).
    pub dt_next: Option<f64>,
}

impl Default for AdaptiveRk4 {
    fn default() -> Self {
        AdaptiveRk4 {
            settings: StepSettings::default(),
            rtol: 1e-8,
            atol: 1e-10,
            safety: 0.9,
            min_factor: 0.2,
            max_factor: 5.0,
            min_step: 1e-12,
            max_rejections: 30,
            max_substeps: 10_000,
            stability_limit: 2.8,
            dt_next: None,
        }
    }
}

/// Result of one accepted adaptive step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AdaptiveReport {
    /// The accepted step (its `dt` is the step actually taken).
    pub step: StepReport,
    /// Proposed size of the next step.
    pub dt_next: f64,
    /// Trials rejected before acceptance.
    pub rejections: u32,
    /// Scaled error norm of the accepted trial (at most 1).
    pub error_norm: f64,
}

/// Result of [`AdaptiveRk4::advance_to`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct AdvanceReport {
    /// Accepted steps.
    pub steps: u32,
    /// Rejected trials in total.
    pub rejections: u32,
    /// Largest drift after any accepted step.
    pub max_drift: Drift,
    /// True if the target time was reached (false: `max_steps` ran out first).
    pub reached: bool,
}

impl AdaptiveRk4 {
    /// Adaptive RK4 with the given tolerances and default controller settings.
    pub fn new(rtol: f64, atol: f64) -> Self {
        AdaptiveRk4 {
            rtol,
            atol,
            ..Self::default()
        }
    }

    fn error_norm<Q: Dim>(
        &self,
        y0: &StateOf<f64, Q>,
        coarse: &StateOf<f64, Q>,
        fine: &StateOf<f64, Q>,
    ) -> f64
    where
        DefaultAllocator: Allocator<Q>,
    {
        let nq = y0.q.nrows();
        let mut sum = 0.0;
        for i in 0..nq {
            for (a, c, f) in [
                (y0.q[i], coarse.q[i], fine.q[i]),
                (y0.qd[i], coarse.qd[i], fine.qd[i]),
            ] {
                let sc = self.atol + self.rtol * a.abs().max(f.abs());
                let e = (f - c) / 15.0 / sc;
                sum += e * e;
            }
        }
        if nq == 0 {
            0.0
        } else {
            sqrt(sum / (2 * nq) as f64)
        }
    }

    /// One trial: a full step and two half steps; returns the extrapolated
    /// state, the scaled error norm and the stability estimate of the half steps.
    fn trial<M, I, Q: Dim, C: Dim, U: Dim>(
        &self,
        model: &M,
        state: &StateOf<f64, Q>,
        input: &I,
        h: f64,
    ) -> Result<(StateOf<f64, Q>, f64, f64), Error>
    where
        M: Equations<Q, C, U> + ?Sized,
        I: InputOf<U> + ?Sized,
        DefaultAllocator: Sizes<Q, C, U>,
    {
        let dyn_cfg = &self.settings.dynamics;
        let (coarse, _) = rk4_raw(model, dyn_cfg, state, input, h, self.stability_limit)?;
        let (mid, est) = rk4_raw(model, dyn_cfg, state, input, 0.5 * h, self.stability_limit)?;
        let (fine, _) = rk4_raw(model, dyn_cfg, &mid, input, 0.5 * h, self.stability_limit)?;
        let err = self.error_norm(state, &coarse, &fine);
        let q = &fine.q + (&fine.q - coarse.q) / 15.0;
        let qd = &fine.qd + (&fine.qd - coarse.qd) / 15.0;
        Ok((
            StateOf {
                q,
                qd,
                t: state.t + h,
            },
            err,
            est,
        ))
    }

    /// Takes one accepted step, trying `dt_try` first (capped by
    /// `settings.max_step`). The state is unchanged on error.
    pub fn step_adaptive<M, I, Q: Dim, C: Dim, U: Dim>(
        &mut self,
        model: &M,
        state: &mut StateOf<f64, Q>,
        input: &I,
        dt_try: f64,
    ) -> Result<AdaptiveReport, Error>
    where
        M: Equations<Q, C, U> + ?Sized,
        I: InputOf<U> + ?Sized,
        DefaultAllocator: Sizes<Q, C, U>,
    {
        begin_step(state, dt_try, f64::INFINITY)?;
        let mut h = dt_try.min(self.settings.max_step);
        let mut rejections = 0u32;
        // The last trial that failed outright (overflow or stability
        // estimate): reported instead of a generic give-up if no smaller
        // step helps.
        let mut last_failure: Option<Error> = None;
        loop {
            // A refusal that no smaller step cured names the fastest mode,
            // or abrupt forces.
            let named = |e| name_fastest_mode(e, model, &self.settings.dynamics, state, input);
            if h < self.min_step {
                return Err(last_failure.map_or(
                    Error::new(
                        ErrorKind::StepSizeUnderflow {
                            dt: h,
                            min_step: self.min_step,
                        },
                        state.t,
                    ),
                    named,
                ));
            }
            let trial = self.trial(model, state, input, h);
            let (next, err, est) = match trial {
                Ok(v) => v,
                Err(e) => match e.kind {
                    ErrorKind::StepTooLarge { .. } | ErrorKind::NonFiniteResult { .. } => {
                        rejections += 1;
                        if rejections > self.max_rejections {
                            return Err(named(e));
                        }
                        last_failure = Some(e);
                        h *= self.min_factor;
                        continue;
                    }
                    _ => return Err(e),
                },
            };
            last_failure = None;
            let factor = if err > 0.0 && err.is_finite() {
                (self.safety * exp(-0.2 * ln(err))).clamp(self.min_factor, self.max_factor)
            } else if err == 0.0 {
                self.max_factor
            } else {
                self.min_factor
            };
            if err <= 1.0 && next.q.iter().chain(next.qd.iter()).all(|x| x.is_finite()) {
                let mut next = next;
                let (projection, drift) = finish_step(model, &mut next, &self.settings)?;
                let t = next.t;
                *state = next;
                let dt_next = (h * factor).min(self.settings.max_step);
                self.dt_next = Some(dt_next);
                return Ok(AdaptiveReport {
                    step: StepReport {
                        t,
                        dt: h,
                        iterations: 0,
                        stability_estimate: 2.0 * est,
                        projection,
                        drift,
                    },
                    dt_next,
                    rejections,
                    error_norm: err,
                });
            }
            rejections += 1;
            if rejections > self.max_rejections {
                return Err(Error::new(
                    ErrorKind::TooManyRejections {
                        rejections,
                        error_norm: err,
                    },
                    state.t,
                ));
            }
            h *= factor.min(0.9);
        }
    }

    /// Advances to `t_end` with at most `max_steps` accepted steps, starting
    /// from `dt_next` (or `dt_init` on the first call). On error the state is
    /// left after the last accepted step.
    pub fn advance_to<M, I, Q: Dim, C: Dim, U: Dim>(
        &mut self,
        model: &M,
        state: &mut StateOf<f64, Q>,
        input: &I,
        t_end: f64,
        dt_init: f64,
        max_steps: u32,
    ) -> Result<AdvanceReport, Error>
    where
        M: Equations<Q, C, U> + ?Sized,
        I: InputOf<U> + ?Sized,
        DefaultAllocator: Sizes<Q, C, U>,
    {
        let mut report = AdvanceReport::default();
        while report.steps < max_steps {
            let remaining = t_end - state.t;
            if !(remaining > 1e-14 * t_end.abs().max(1.0)) {
                report.reached = true;
                return Ok(report);
            }
            let h = self.dt_next.unwrap_or(dt_init).min(remaining);
            let proposed = self.dt_next;
            let r = self.step_adaptive(model, state, input, h)?;
            if r.step.dt >= remaining {
                state.t = t_end;
                // Keep the proposal from before a clipped final step.
                self.dt_next = Some(proposed.map_or(r.dt_next, |p| p.max(r.dt_next)));
            }
            report.steps += 1;
            report.rejections += r.rejections;
            report.max_drift.position = report.max_drift.position.max(r.step.drift.position);
            report.max_drift.velocity = report.max_drift.velocity.max(r.step.drift.velocity);
        }
        report.reached = !(t_end - state.t > 1e-14 * t_end.abs().max(1.0));
        Ok(report)
    }
}

impl<Q: Dim, C: Dim, U: Dim> IntegratorOf<Q, C, U> for AdaptiveRk4
where
    DefaultAllocator: Sizes<Q, C, U>,
{
    fn settings_mut(&mut self) -> &mut StepSettings {
        &mut self.settings
    }

    /// Advances by exactly `dt` with as many error-controlled substeps as
    /// needed (at most `max_substeps`, otherwise [`ErrorKind::SubstepLimit`]).
    /// The report's `iterations` is the number of substeps. State and
    /// step-size memory are restored on error.
    fn step<M, I>(
        &mut self,
        model: &M,
        state: &mut StateOf<f64, Q>,
        input: &I,
        dt: f64,
    ) -> Result<StepReport, Error>
    where
        M: Equations<Q, C, U> + ?Sized,
        I: InputOf<U> + ?Sized,
        DefaultAllocator: Sizes<Q, C, U>,
    {
        begin_step(state, dt, f64::INFINITY)?;
        let saved = state.clone();
        let saved_dt = self.dt_next;
        let t_end = state.t + dt;
        let result = self.advance_to(model, state, input, t_end, dt, self.max_substeps);
        match result {
            Ok(r) if r.reached => {
                state.t = t_end;
                Ok(StepReport {
                    t: t_end,
                    dt,
                    iterations: r.steps,
                    stability_estimate: 0.0,
                    projection: None,
                    drift: crate::state::constraint_drift(model, state),
                })
            }
            Ok(r) => {
                let (reached, t) = (state.t - saved.t, saved.t);
                *state = saved;
                self.dt_next = saved_dt;
                Err(Error::new(
                    ErrorKind::SubstepLimit {
                        substeps: r.steps,
                        reached,
                    },
                    t,
                ))
            }
            Err(e) => {
                *state = saved;
                self.dt_next = saved_dt;
                Err(e)
            }
        }
    }
}
