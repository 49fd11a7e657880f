//! Semi-implicit (symplectic) Euler.

use super::{begin_step, finish_step_with, qdd_at, Integrator, StepReport, StepSettings};
use crate::error::{Error, Quantity};
use crate::eval;
use crate::input::Input;
use crate::model::Model;
use crate::state::State;

/// Semi-implicit Euler: `qd' = qd + dt qdd(q, qd, t)`, then `q' = q + dt qd'`.
///
/// First order, one acceleration solve per step. For a separable Hamiltonian
/// (constant mass matrix, position-dependent forces, e.g. spring–mass
/// chains) it is symplectic: the energy error stays bounded (`O(dt)`) with no
/// secular drift. With a configuration-dependent mass matrix it is only
/// semi-implicit. Stable for `dt * omega_max < 2` on undamped oscillations.
///
/// With projection enabled, the position correction `dq` is also applied to
/// the velocities as `dq / dt` before they are projected (SHAKE/RATTLE-style),
/// so that `q_{n+1} - q_n = dt qd_{n+1}` holds up to the velocity
/// projection and the correction acts as a constraint impulse.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SemiImplicitEuler {
    /// Shared settings.
    pub settings: StepSettings,
}

impl SemiImplicitEuler {
    /// Semi-implicit Euler with the given settings.
    pub fn new(settings: StepSettings) -> Self {
        SemiImplicitEuler { settings }
    }
}

impl<const NQ: usize, const NC: usize, const NU: usize> Integrator<NQ, NC, NU>
    for SemiImplicitEuler
{
    fn step<M, I>(
        &mut self,
        model: &M,
        state: &mut State<NQ>,
        input: &I,
        dt: f64,
    ) -> Result<StepReport, Error>
    where
        M: Model<NQ, NC, NU>,
        I: Input<NU> + ?Sized,
    {
        begin_step(state, dt, self.settings.max_step)?;
        let t = state.t;
        let qdd = qdd_at(
            model,
            &self.settings.dynamics,
            &state.q,
            &state.qd,
            t,
            input,
        )?;
        let qd = state.qd + qdd * dt;
        let q = state.q + qd * dt;
        eval::check_result(&q, Quantity::Position, t)?;
        eval::check_result(&qd, Quantity::Velocity, t)?;
        let mut next = State { q, qd, t: t + dt };
        let (projection, drift) = finish_step_with(model, &mut next, &self.settings, dt)?;
        *state = next;
        Ok(StepReport {
            t: next.t,
            dt,
            iterations: 0,
            stability_estimate: 0.0,
            projection,
            drift,
        })
    }
}
