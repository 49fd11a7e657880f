//! Two-stage Gauss–Legendre collocation (implicit, symplectic, order 4).

use super::{
    begin_step, finish_step, name_fastest_mode, qdd_at, IntegratorOf, StepReport, StepSettings,
};
use crate::error::{Error, ErrorKind, Quantity, Stage};
use crate::eval;
use crate::input::InputOf;
use crate::linalg::all_finite;
use crate::model::{Equations, Sizes};
use crate::scalar::Scalar;
use crate::state::StateOf;
use nalgebra::{DefaultAllocator, Dim, OVector, U1};

const SQRT3_6: f64 = 0.288_675_134_594_812_9; // sqrt(3) / 6
const NODES: [f64; 2] = [0.5 - SQRT3_6, 0.5 + SQRT3_6];
const A: [[f64; 2]; 2] = [[0.25, 0.25 - SQRT3_6], [0.25 + SQRT3_6, 0.25]];

/// Two-stage Gauss–Legendre Runge–Kutta method (order 4) with a bounded
/// fixed-point iteration on the stage accelerations.
///
/// Symplectic for separable Hamiltonian systems (constant mass matrix) and
/// symmetric (time-reversible) in general, so on conservative models the
/// energy error stays bounded at `O(dt^4)` without secular drift: the
/// scheme for long, accurate runs of non-stiff conservative scenes. The
/// fixed-point iteration contracts only for `dt` well below the period of the
/// fastest mode; for stiff models use [`super::GeneralizedAlpha`].
///
/// Stage iteration: `V_i = qd + dt sum_j a_ij A_j`, `Q_i = q + dt sum_j a_ij V_j`,
/// `A_i <- qdd(Q_i, V_i, t + c_i dt)` until the implied position and velocity
/// changes `dt^2 |dA|`, `dt |dA|` are within `atol + rtol |x|`; at most
/// `max_iterations` sweeps, else [`ErrorKind::StageIterationFailed`]. On an
/// undamped mode of circular frequency `omega` the sweep multiplies the
/// stage error by `(omega dt)^2 / 12` (the eigenvalues of the Butcher matrix
/// have `|lambda|^2 = 1/12`), so the iteration contracts only for
/// `dt * omega < sqrt(12)` ([`crate::GAUSS_LEGENDRE_CONTRACTION_LIMIT`]).
/// When the scaled increment grows in two sweeps in a row, a stage value
/// becomes non-finite (checked before any model call sees it), or the model
/// cannot be evaluated at the stage values after a sweep whose increment
/// grew (a mass matrix no longer positive definite), the step
/// fails at once with [`ErrorKind::StageIterationFailed`] marked
/// `diverged`, naming the step, the fastest mode of the model linearised at
/// the state (power iteration, as [`super::Rk4`] does on refusal) and a step
/// that would let the iteration contract. Errors of the model evaluations
/// inside the iteration name the sweep ([`crate::Stage::StageIteration`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GaussLegendre4<T: Scalar = f64> {
    /// Shared settings.
    pub settings: StepSettings<T>,
    /// Cap on fixed-point sweeps per step.
    pub max_iterations: u32,
    /// Relative tolerance of the stage iteration (default `1e-13`, at
    /// least `100 eps`: `1.2e-5` in f32).
    pub rtol: T,
    /// Absolute tolerance of the stage iteration (default `1e-15`, at
    /// least `eps`: `1.2e-7` in f32).
    pub atol: T,
}

impl<T: Scalar> Default for GaussLegendre4<T> {
    fn default() -> Self {
        GaussLegendre4 {
            settings: StepSettings::default(),
            max_iterations: 50,
            rtol: T::of(1e-13).max(T::EPSILON * T::of(100.0)),
            atol: T::of(1e-15).max(T::EPSILON),
        }
    }
}

impl<T: Scalar> GaussLegendre4<T> {
    /// Gauss–Legendre with the given settings and default iteration control.
    pub fn new(settings: StepSettings<T>) -> Self {
        GaussLegendre4 {
            settings,
            ..Self::default()
        }
    }
}

impl<T: Scalar, Q: Dim, C: Dim, U: Dim> IntegratorOf<Q, C, U, T> for GaussLegendre4<T>
where
    DefaultAllocator: Sizes<Q, C, U>,
{
    fn settings_mut(&mut self) -> &mut StepSettings<T> {
        &mut self.settings
    }

    fn step<M, I>(
        &mut self,
        model: &M,
        state: &mut StateOf<T, Q>,
        input: &I,
        dt: T,
    ) -> Result<StepReport<T>, Error>
    where
        M: Equations<Q, C, U, T> + ?Sized,
        I: InputOf<U, T> + ?Sized,
    {
        begin_step(state, dt, self.settings.max_step)?;
        let (t, h) = (state.t, dt);
        let dyn_cfg = &self.settings.dynamics;
        let in_sweep = |sweep: u32| {
            move |e: Error| {
                e.in_stage(Stage::StageIteration {
                    dt: h.into(),
                    sweep,
                })
            }
        };
        let failed = |sweeps: u32, increment: T, diverged: bool| {
            let e = Error::new(
                ErrorKind::StageIterationFailed {
                    dt: h.into(),
                    sweeps,
                    increment: increment.into(),
                    diverged,
                    rate: None,
                },
                t,
            );
            name_fastest_mode(e, model, dyn_cfg, state, input)
        };
        let a0 = qdd_at(model, dyn_cfg, &state.q, &state.qd, t, input).map_err(in_sweep(0))?;
        let nq = state.q.shape_generic().0;
        let mut acc = [a0.clone(), a0];
        let mut vel = [state.qd.clone(), state.qd.clone()];
        let mut iterations = 0u32;
        let mut err = T::INFINITY;
        // Sweeps in a row whose increment grew: two mean divergence.
        let mut growing = 0u32;
        while iterations < self.max_iterations {
            iterations += 1;
            for i in 0..2 {
                vel[i] = &state.qd + (&acc[0] * T::of(A[i][0]) + &acc[1] * T::of(A[i][1])) * h;
            }
            let mut new = [
                OVector::<T, Q>::zeros_generic(nq, U1),
                OVector::<T, Q>::zeros_generic(nq, U1),
            ];
            for i in 0..2 {
                let qi = &state.q + (&vel[0] * T::of(A[i][0]) + &vel[1] * T::of(A[i][1])) * h;
                // A diverging iteration reaches non-finite stage values
                // first; no model call sees them.
                if !all_finite(&qi) || !all_finite(&vel[i]) {
                    return Err(failed(iterations, T::INFINITY, true));
                }
                new[i] = match qdd_at(model, dyn_cfg, &qi, &vel[i], t + T::of(NODES[i]) * h, input)
                {
                    Ok(a) => a,
                    // A growing iteration that reaches stage values the
                    // model cannot evaluate (a mass matrix no longer
                    // positive definite) has diverged: say so, with the
                    // fastest mode and a step that converges.
                    Err(_) if growing >= 1 => return Err(failed(iterations, err, true)),
                    Err(e) => return Err(in_sweep(iterations)(e)),
                };
            }
            let previous = err;
            err = T::zero();
            for i in 0..2 {
                let d = &new[i] - &acc[i];
                for k in 0..nq.value() {
                    let eq = (h * h * d[k]).abs() / (self.atol + self.rtol * state.q[k].abs());
                    let ev = (h * d[k]).abs() / (self.atol + self.rtol * state.qd[k].abs());
                    err = err.max(eq).max(ev);
                }
            }
            acc = new;
            if err <= T::one() {
                break;
            }
            growing = if err > previous { growing + 1 } else { 0 };
            if growing >= 2 || !err.is_finite() {
                return Err(failed(iterations, err, true));
            }
        }
        if !(err <= T::one()) {
            return Err(failed(iterations, err, false));
        }
        for i in 0..2 {
            vel[i] = &state.qd + (&acc[0] * T::of(A[i][0]) + &acc[1] * T::of(A[i][1])) * h;
        }
        let q = &state.q + (&vel[0] + &vel[1]) * (T::of(0.5) * h);
        let qd = &state.qd + (&acc[0] + &acc[1]) * (T::of(0.5) * h);
        eval::check_result(&q, Quantity::Position, t)?;
        eval::check_result(&qd, Quantity::Velocity, t)?;
        let mut next = StateOf { q, qd, t: t + h };
        let (projection, drift) = finish_step(model, &mut next, &self.settings)?;
        *state = next;
        Ok(StepReport {
            t: t + h,
            dt,
            iterations,
            stability_estimate: T::zero(),
            projection,
            drift,
        })
    }
}
