//! Classical fourth-order Runge–Kutta.

use super::{begin_step, finish_step, qdd_at, Integrator, StepReport, StepSettings};
use crate::dynamics::DynamicsConfig;
use crate::error::{Error, ErrorKind, Quantity};
use crate::eval;
use crate::input::Input;
use crate::math::sqrt;
use crate::model::Model;
use crate::state::State;

/// Explicit classical RK4 with a fixed step.
///
/// Besides the `max_step` check, each step estimates `dt * rho(J)` from its
/// stages: with `k_i` the stage derivatives of `y = (q, qd)`,
/// `k3 - k2 = (dt/2)^2 J^2 k1 + O(dt^3)`, so
/// `(dt rho)^2 ~ 4 |k3 - k2| / |k1|` (a two-step power iteration, exact for a
/// linear oscillator or a linear damper). RK4 is stable for `dt |lambda|`
/// below about 2.8; a step whose estimate exceeds
/// [`stability_limit`](Rk4::stability_limit) fails with
/// [`ErrorKind::StepTooLarge`] before the state is touched.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rk4 {
    /// Shared settings.
    pub settings: StepSettings,
    /// Largest accepted estimate of `dt * rho(J)`; `f64::INFINITY` disables the check.
    pub stability_limit: f64,
}

impl Default for Rk4 {
    fn default() -> Self {
        Rk4 {
            settings: StepSettings::default(),
            stability_limit: 2.8,
        }
    }
}

impl Rk4 {
    /// RK4 with the given settings and the default stability limit.
    pub fn new(settings: StepSettings) -> Self {
        Rk4 {
            settings,
            ..Self::default()
        }
    }
}

/// One RK4 step from `s` without projection; returns the new state and the
/// stability estimate. Checks the stability estimate against `limit`.
pub(crate) fn rk4_raw<M, I, const NQ: usize, const NC: usize, const NU: usize>(
    model: &M,
    dynamics: &DynamicsConfig,
    s: &State<NQ>,
    input: &I,
    h: f64,
    limit: f64,
) -> Result<(State<NQ>, f64), Error>
where
    M: Model<NQ, NC, NU>,
    I: Input<NU> + ?Sized,
{
    let t = s.t;
    let half = 0.5 * h;
    let k1q = s.qd;
    let k1v = qdd_at(model, dynamics, &s.q, &s.qd, t, input)?;
    let q2 = s.q + k1q * half;
    let v2 = s.qd + k1v * half;
    let k2q = v2;
    let k2v = qdd_at(model, dynamics, &q2, &v2, t + half, input)?;
    let q3 = s.q + k2q * half;
    let v3 = s.qd + k2v * half;
    let k3q = v3;
    let k3v = qdd_at(model, dynamics, &q3, &v3, t + half, input)?;
    let den = k1q.norm_squared() + k1v.norm_squared();
    let num = (k3q - k2q).norm_squared() + (k3v - k2v).norm_squared();
    let estimate = if den > 0.0 {
        2.0 * sqrt(sqrt(num / den))
    } else {
        0.0
    };
    if estimate > limit {
        return Err(Error::new(
            ErrorKind::StepTooLarge {
                dt: h,
                value: estimate,
                limit,
            },
            t,
        ));
    }
    let q4 = s.q + k3q * h;
    let v4 = s.qd + k3v * h;
    let k4q = v4;
    let k4v = qdd_at(model, dynamics, &q4, &v4, t + h, input)?;
    let sixth = h / 6.0;
    let q = s.q + (k1q + (k2q + k3q) * 2.0 + k4q) * sixth;
    let qd = s.qd + (k1v + (k2v + k3v) * 2.0 + k4v) * sixth;
    eval::check_result(&q, Quantity::Position, t)?;
    eval::check_result(&qd, Quantity::Velocity, t)?;
    Ok((State { q, qd, t: t + h }, estimate))
}

impl<const NQ: usize, const NC: usize, const NU: usize> Integrator<NQ, NC, NU> for Rk4 {
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
        let (mut next, estimate) = rk4_raw(
            model,
            &self.settings.dynamics,
            state,
            input,
            dt,
            self.stability_limit,
        )?;
        let (projection, drift) = finish_step(model, &mut next, &self.settings)?;
        *state = next;
        Ok(StepReport {
            t: next.t,
            dt,
            iterations: 0,
            stability_estimate: estimate,
            projection,
            drift,
        })
    }
}
