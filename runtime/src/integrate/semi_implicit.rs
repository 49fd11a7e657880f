//! Semi-implicit (symplectic) Euler.

use super::rk4::half_stages;
use super::{
    begin_step, finish_step_with, name_fastest_mode, qdd_at, IntegratorOf, StepReport, StepSettings,
};
use crate::error::{Error, ErrorKind, Quantity};
use crate::eval;
use crate::input::InputOf;
use crate::model::{Equations, Sizes};
use crate::state::StateOf;
use nalgebra::DefaultAllocator;
use nalgebra::Dim;

/// Semi-implicit Euler: `qd' = qd + dt qdd(q, qd, t)`, then `q' = q + dt qd'`.
///
/// First order, one acceleration solve per step (three with the stability
/// check). For a separable Hamiltonian (constant mass matrix,
/// position-dependent forces, e.g. spring–mass chains) it is symplectic:
/// the energy error stays bounded (`O(dt)`) with no secular drift. With a
/// configuration-dependent mass matrix it is only semi-implicit.
///
/// Stability: on an undamped oscillation of circular frequency `omega` the
/// step is stable for `dt * omega < 2` (on a linear damper of rate `c`, for
/// `dt * c < 2`); beyond it the mode grows by a factor of more than 1 per
/// step and the run diverges without any other sign. So each step first
/// estimates `dt * rho(J)` as [`super::Rk4`] does, from the two half-step RK
/// stages (two more accelerations; exact for a linear oscillator or damper),
/// and a step whose estimate exceeds
/// [`stability_limit`](SemiImplicitEuler::stability_limit) fails with
/// [`ErrorKind::StepTooLarge`] before the state is touched, naming the
/// fastest mode of the model linearised at the state (power iteration) and
/// the largest step that could be stable. Like RK4's, the estimate sees only
/// the modes the state excites: an unstable mode is caught once it has grown
/// to dominate the step, not before. `stability_limit = f64::INFINITY`
/// turns the check off (one acceleration per step).
///
/// With projection enabled, the position correction `dq` is also applied to
/// the velocities as `dq / dt` before they are projected (SHAKE/RATTLE-style),
/// so that `q_{n+1} - q_n = dt qd_{n+1}` holds up to the velocity
/// projection and the correction acts as a constraint impulse.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SemiImplicitEuler {
    /// Shared settings.
    pub settings: StepSettings,
    /// Largest accepted estimate of `dt * rho(J)` (default 2, the stability
    /// bound); `f64::INFINITY` disables the check.
    pub stability_limit: f64,
}

impl Default for SemiImplicitEuler {
    fn default() -> Self {
        SemiImplicitEuler {
            settings: StepSettings::default(),
            stability_limit: 2.0,
        }
    }
}

impl SemiImplicitEuler {
    /// Semi-implicit Euler with the given settings and the default stability limit.
    pub fn new(settings: StepSettings) -> Self {
        SemiImplicitEuler {
            settings,
            ..Self::default()
        }
    }
}

impl<Q: Dim, C: Dim, U: Dim> IntegratorOf<Q, C, U> for SemiImplicitEuler
where
    DefaultAllocator: Sizes<Q, C, U>,
{
    fn settings_mut(&mut self) -> &mut StepSettings {
        &mut self.settings
    }

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
        begin_step(state, dt, self.settings.max_step)?;
        let t = state.t;
        let dynamics = &self.settings.dynamics;
        let qdd = qdd_at(model, dynamics, &state.q, &state.qd, t, input)?;
        let mut estimate = 0.0;
        if self.stability_limit.is_finite() {
            estimate = half_stages(model, dynamics, state, &qdd, input, dt)?.estimate;
            if estimate > self.stability_limit {
                let e = Error::new(
                    ErrorKind::StepTooLarge {
                        dt,
                        value: estimate,
                        limit: self.stability_limit,
                        rate: Some(estimate / dt),
                    },
                    t,
                );
                return Err(name_fastest_mode(e, model, dynamics, state, input));
            }
        }
        let qd = &state.qd + qdd * dt;
        let q = &state.q + &qd * dt;
        eval::check_result(&q, Quantity::Position, t)?;
        eval::check_result(&qd, Quantity::Velocity, t)?;
        let mut next = StateOf { q, qd, t: t + dt };
        let (projection, drift) = finish_step_with(model, &mut next, &self.settings, dt)?;
        *state = next;
        Ok(StepReport {
            t: t + dt,
            dt,
            iterations: 0,
            stability_estimate: estimate,
            projection,
            drift,
        })
    }
}
