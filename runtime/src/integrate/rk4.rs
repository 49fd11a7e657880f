//! Classical fourth-order Runge–Kutta.

use super::{
    begin_step, finish_step, name_fastest_mode, qdd_at, IntegratorOf, StepReport, StepSettings,
};
use crate::dynamics::DynamicsConfig;
use crate::error::{Error, ErrorKind, Quantity};
use crate::eval;
use crate::input::InputOf;
use crate::model::{Equations, Sizes};
use crate::scalar::Scalar;
use crate::state::StateOf;
use nalgebra::allocator::Allocator;
use nalgebra::{DefaultAllocator, Dim, OVector};

/// Explicit classical RK4 with a fixed step.
///
/// Besides the `max_step` check, each step estimates `dt * rho(J)` from its
/// stages: with `k_i` the stage derivatives of `y = (q, qd)`,
/// `k3 - k2 = (dt/2)^2 J^2 k1 + O(dt^3)`, so
/// `(dt rho)^2 ~ 4 |k3 - k2| / |k1|` (a two-step power iteration, exact for a
/// linear oscillator or a linear damper). RK4 is stable for `dt |lambda|`
/// below about 2.8; a step whose estimate exceeds
/// [`stability_limit`](Rk4::stability_limit) fails with
/// [`ErrorKind::StepTooLarge`] before the state is touched. The stages see
/// only the modes the state excites (a stiff mode at rest goes unseen until
/// it grows), so on refusal a bounded power iteration on the model
/// linearised at the state (at most 96 accelerations) finds the fastest mode; the
/// error carries it as `rate` (rad/s; the stage estimate `value / dt` when
/// the iteration fails), and its message names it (rad/s and Hz) with the
/// largest step that could be stable, `limit / rate`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rk4<T: Scalar = f64> {
    /// Shared settings.
    pub settings: StepSettings<T>,
    /// Largest accepted estimate of `dt * rho(J)`; `f64::INFINITY` disables the check.
    pub stability_limit: T,
}

impl<T: Scalar> Default for Rk4<T> {
    fn default() -> Self {
        Rk4 {
            settings: StepSettings::default(),
            stability_limit: T::of(2.8),
        }
    }
}

impl<T: Scalar> Rk4<T> {
    /// RK4 with the given settings and the default stability limit.
    pub fn new(settings: StepSettings<T>) -> Self {
        Rk4 {
            settings,
            ..Self::default()
        }
    }
}

/// The second and third stages of an RK4 step of size `h` from `s` (the
/// first being `(s.qd, a0)`), and the estimate of `h * rho(J)` from them:
/// `k3 - k2 = (h/2)^2 J^2 k1 + O(h^3)`, so `(h rho)^2 ~ 4 |k3 - k2| / |k1|`
/// (exact for a linear oscillator or a linear damper).
pub(crate) struct HalfStages<T: Scalar, Q: Dim>
where
    DefaultAllocator: Allocator<Q>,
{
    pub k2q: OVector<T, Q>,
    pub k2v: OVector<T, Q>,
    pub k3q: OVector<T, Q>,
    pub k3v: OVector<T, Q>,
    pub estimate: T,
}

/// Computes [`HalfStages`] (two accelerations).
pub(crate) fn half_stages<M, I, T: Scalar, Q: Dim, C: Dim, U: Dim>(
    model: &M,
    dynamics: &DynamicsConfig<T>,
    s: &StateOf<T, Q>,
    a0: &OVector<T, Q>,
    input: &I,
    h: T,
) -> Result<HalfStages<T, Q>, Error>
where
    M: Equations<Q, C, U, T> + ?Sized,
    I: InputOf<U, T> + ?Sized,
    DefaultAllocator: Sizes<Q, C, U>,
{
    let t = s.t;
    let half = T::of(0.5) * h;
    let (k1q, k1v) = (&s.qd, a0);
    let q2 = &s.q + k1q * half;
    let v2 = &s.qd + k1v * half;
    let k2v = qdd_at(model, dynamics, &q2, &v2, t + half, input)?;
    let k2q = v2;
    let q3 = &s.q + &k2q * half;
    let v3 = &s.qd + &k2v * half;
    let k3v = qdd_at(model, dynamics, &q3, &v3, t + half, input)?;
    let k3q = v3;
    let den = k1q.norm_squared() + k1v.norm_squared();
    let num = (&k3q - &k2q).norm_squared() + (&k3v - &k2v).norm_squared();
    let estimate = if den > T::zero() {
        T::of(2.0) * Scalar::square_root(Scalar::square_root(num / den))
    } else {
        T::zero()
    };
    Ok(HalfStages {
        k2q,
        k2v,
        k3q,
        k3v,
        estimate,
    })
}

/// One RK4 step from `s` without projection; returns the new state and the
/// stability estimate. Checks the stability estimate against `limit`.
pub(crate) fn rk4_raw<M, I, T: Scalar, Q: Dim, C: Dim, U: Dim>(
    model: &M,
    dynamics: &DynamicsConfig<T>,
    s: &StateOf<T, Q>,
    input: &I,
    h: T,
    limit: T,
) -> Result<(StateOf<T, Q>, T), Error>
where
    M: Equations<Q, C, U, T> + ?Sized,
    I: InputOf<U, T> + ?Sized,
    DefaultAllocator: Sizes<Q, C, U>,
{
    let t = s.t;
    let k1v = qdd_at(model, dynamics, &s.q, &s.qd, t, input)?;
    let HalfStages {
        k2q,
        k2v,
        k3q,
        k3v,
        estimate,
    } = half_stages(model, dynamics, s, &k1v, input, h)?;
    if estimate > limit {
        return Err(Error::new(
            ErrorKind::StepTooLarge {
                dt: h.into(),
                value: estimate.into(),
                limit: limit.into(),
                rate: Some((estimate / h).into()),
            },
            t,
        ));
    }
    let k1q = &s.qd;
    let q4 = &s.q + &k3q * h;
    let v4 = &s.qd + &k3v * h;
    let k4v = qdd_at(model, dynamics, &q4, &v4, t + h, input)?;
    let k4q = v4;
    let sixth = h / T::of(6.0);
    let q = &s.q + (k1q + (k2q + k3q) * T::of(2.0) + k4q) * sixth;
    let qd = &s.qd + (k1v + (k2v + k3v) * T::of(2.0) + k4v) * sixth;
    eval::check_result(&q, Quantity::Position, t)?;
    eval::check_result(&qd, Quantity::Velocity, t)?;
    Ok((StateOf { q, qd, t: t + h }, estimate))
}

impl<T: Scalar, Q: Dim, C: Dim, U: Dim> IntegratorOf<Q, C, U, T> for Rk4<T>
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
        let dynamics = &self.settings.dynamics;
        let (mut next, estimate) = rk4_raw(model, dynamics, state, input, dt, self.stability_limit)
            .map_err(|e| name_fastest_mode(e, model, dynamics, state, input))?;
        let (projection, drift) = finish_step(model, &mut next, &self.settings)?;
        let t = next.t;
        *state = next;
        Ok(StepReport {
            t,
            dt,
            iterations: 0,
            stability_estimate: estimate,
            projection,
            drift,
        })
    }
}

#[cfg(test)]
mod tests {
    extern crate std;

    use super::*;
    use crate::integrate::IntegratorOf;
    use crate::model::Model;
    use crate::state::State;
    use nalgebra::{SMatrix, SVector};

    /// `x'' = -w^2 x`: unit mass, stiffness `w^2`, no constraints.
    struct Oscillator {
        w: f64,
    }

    impl Model<1, 0, 1> for Oscillator {
        const NAME: &'static str = "oscillator";
        const COORDINATES: [&'static str; 1] = ["x"];
        const ACTUATORS: [&'static str; 1] = ["f"];
        fn mass_matrix(&self, _: &SVector<f64, 1>, _: f64, m: &mut SMatrix<f64, 1, 1>) {
            m[(0, 0)] = 1.0;
        }
        fn bias(&self, q: &SVector<f64, 1>, _: &SVector<f64, 1>, _: f64, h: &mut SVector<f64, 1>) {
            h[0] = self.w * self.w * q[0];
        }
        fn constraints(&self, _: &SVector<f64, 1>, _: f64, _: &mut SVector<f64, 0>) {}
        fn constraint_jacobian(&self, _: &SVector<f64, 1>, _: f64, _: &mut SMatrix<f64, 0, 1>) {}
        fn constraint_time_derivative(&self, _: &SVector<f64, 1>, _: f64, _: &mut SVector<f64, 0>) {
        }
        fn constraint_rhs(
            &self,
            _: &SVector<f64, 1>,
            _: &SVector<f64, 1>,
            _: f64,
            _: &mut SVector<f64, 0>,
        ) {
        }
        fn actuator_map(&self, b: &mut SMatrix<f64, 1, 1>) {
            b[(0, 0)] = 1.0;
        }
        fn kinetic_energy(&self, _: &SVector<f64, 1>, qd: &SVector<f64, 1>, _: f64) -> f64 {
            0.5 * qd[0] * qd[0]
        }
        fn potential_energy(&self, q: &SVector<f64, 1>, _: f64) -> f64 {
            0.5 * self.w * self.w * q[0] * q[0]
        }
    }

    /// Two uncoupled oscillators, `x_k'' = -w_k^2 x_k`.
    struct TwoOscillators {
        w: [f64; 2],
    }

    impl Model<2, 0, 0> for TwoOscillators {
        const NAME: &'static str = "two_oscillators";
        const COORDINATES: [&'static str; 2] = ["x1", "x2"];
        const ACTUATORS: [&'static str; 0] = [];
        fn mass_matrix(&self, _: &SVector<f64, 2>, _: f64, m: &mut SMatrix<f64, 2, 2>) {
            *m = SMatrix::identity();
        }
        fn bias(&self, q: &SVector<f64, 2>, _: &SVector<f64, 2>, _: f64, h: &mut SVector<f64, 2>) {
            *h = SVector::from([self.w[0].powi(2) * q[0], self.w[1].powi(2) * q[1]]);
        }
        fn constraints(&self, _: &SVector<f64, 2>, _: f64, _: &mut SVector<f64, 0>) {}
        fn constraint_jacobian(&self, _: &SVector<f64, 2>, _: f64, _: &mut SMatrix<f64, 0, 2>) {}
        fn constraint_time_derivative(&self, _: &SVector<f64, 2>, _: f64, _: &mut SVector<f64, 0>) {
        }
        fn constraint_rhs(
            &self,
            _: &SVector<f64, 2>,
            _: &SVector<f64, 2>,
            _: f64,
            _: &mut SVector<f64, 0>,
        ) {
        }
        fn actuator_map(&self, _: &mut SMatrix<f64, 2, 0>) {}
        fn kinetic_energy(&self, _: &SVector<f64, 2>, qd: &SVector<f64, 2>, _: f64) -> f64 {
            0.5 * qd.norm_squared()
        }
        fn potential_energy(&self, q: &SVector<f64, 2>, _: f64) -> f64 {
            0.5 * (self.w[0].powi(2) * q[0].powi(2) + self.w[1].powi(2) * q[1].powi(2))
        }
    }

    #[test]
    fn a_refusal_reports_one_rate_for_the_product_and_the_stable_step() {
        // The state excites only the 3000 rad/s mode (dt w = 3 > 2.8, so the
        // stages refuse the step); the power iteration finds the 6000 rad/s
        // one. The message's dt * rho(J) and its stable step come from the
        // same (larger) rate: 6.0 and 2.8 / 6000 = 4.667e-4 s.
        let model = TwoOscillators {
            w: [3000.0, 6000.0],
        };
        let mut s = State::new(SVector::from([1e-3, 0.0]), SVector::from([0.5, 0.0]), 0.0);
        let e = Rk4::default()
            .step(&model, &mut s, &SVector::<f64, 0>::zeros(), 1e-3)
            .unwrap_err();
        let ErrorKind::StepTooLarge {
            value,
            rate: Some(rate),
            ..
        } = e.kind
        else {
            panic!("expected the stability check, got {e}");
        };
        assert!((rate / 6000.0 - 1.0).abs() < 1e-6, "{rate}");
        assert_eq!(value, 1e-3 * rate);
        let msg = std::format!("{e}");
        for part in ["dt * rho(J) = 6.000e0", "6.000e3 rad/s", "4.667e-4 s"] {
            assert!(msg.contains(part), "`{part}` not in: {msg}");
        }
    }

    #[test]
    fn refused_step_names_the_fastest_mode() {
        // 1 kHz oscillator (w = 2 pi 1000 rad/s) at 1 ms: dt w = 6.28 > 2.8.
        // For a linear oscillator the stage estimate is exact, so the error
        // carries rate = w and the message names 1 kHz and the stable step
        // 2.8 / w = 4.46e-4 s.
        let w = 2.0 * core::f64::consts::PI * 1000.0;
        let model = Oscillator { w };
        let start = State::new(SVector::from([1e-3]), SVector::from([0.5]), 0.0);
        let mut s = start;
        let e = Rk4::default()
            .step(&model, &mut s, &SVector::<f64, 1>::zeros(), 1e-3)
            .unwrap_err();
        assert_eq!(s, start);
        let ErrorKind::StepTooLarge {
            dt,
            value,
            limit,
            rate: Some(rate),
        } = e.kind
        else {
            panic!("expected the stability check, got {e}");
        };
        assert_eq!((dt, limit), (1e-3, 2.8));
        assert!((rate / w - 1.0).abs() < 1e-9, "{rate} vs {w}");
        assert!((value - rate * dt).abs() < 1e-12 * value);
        let msg = std::format!("{e}");
        for part in [
            "step size 1e-3",
            "1.000e3 Hz",
            "6.283e3 rad/s",
            "4.456e-4 s",
        ] {
            assert!(msg.contains(part), "`{part}` not in: {msg}");
        }
        // Below the limit the step is taken and reports the same estimate.
        let r = Rk4::default()
            .step(&model, &mut s, &SVector::<f64, 1>::zeros(), 4e-4)
            .unwrap();
        assert!((r.stability_estimate - 4e-4 * w).abs() < 1e-9);
    }
}
