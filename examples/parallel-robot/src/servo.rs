//! Closed-loop and servo-constrained dynamics of the robot scenes (rigid and
//! flexible), built on the runtime's integrators by wrapping a generated
//! model:
//!
//! * [`Feedback`]: the model with a state-feedback actuator input
//!   `tau_fb(q, qd, t)` added to the applied torques (the joint-space PD loop
//!   [`JointPd`] of `parallel-robot simulate --pd`).
//! * [`Servo`]: the model with the actuator torques chosen at every state so
//!   that the platform centre follows a prescribed path (servo constraints,
//!   Blajer & Kołodziejczyk): the flexible robot's inverse dynamics with its
//!   elastic coordinates integrated ([`flexible_inverse`], `parallel-robot inverse`
//!   on a flexible scene).
//!
//! Both only change the bias forces `h` of the wrapped model (`h - B tau`),
//! so every runtime integrator applies unchanged; neither provides analytic
//! bias Jacobians, so the implicit integrator differentiates them
//! numerically, feedback included.

use std::cell::RefCell;

use flexdyn_runtime::nalgebra::{DMatrix, DVector, SMatrix, SVector};
use flexdyn_runtime::{Baumgarte, Model, State};

use crate::robot::{Circle, Geometry, Layout, TorqueTable};

/// `model` with the actuator input `law(q, qd, t)` added to whatever input
/// the integrator applies.
pub struct Feedback<'a, M, F> {
    /// The wrapped model.
    pub inner: &'a M,
    /// The feedback law.
    pub law: F,
}

impl<M, F, const NQ: usize, const NC: usize> Model<NQ, NC, 3> for Feedback<'_, M, F>
where
    M: Model<NQ, NC, 3>,
    F: Fn(&SVector<f64, NQ>, &SVector<f64, NQ>, f64) -> [f64; 3],
{
    flexdyn_runtime::forward_model!(inner: M, NQ, NC, 3);
    fn bias(&self, q: &SVector<f64, NQ>, qd: &SVector<f64, NQ>, t: f64, h: &mut SVector<f64, NQ>) {
        self.inner.bias(q, qd, t, h);
        subtract_input(self.inner, &(self.law)(q, qd, t), h);
    }
    fn dynamics_terms(
        &self,
        q: &SVector<f64, NQ>,
        qd: &SVector<f64, NQ>,
        t: f64,
        m: &mut SMatrix<f64, NQ, NQ>,
        h: &mut SVector<f64, NQ>,
        phi_q: &mut SMatrix<f64, NC, NQ>,
        gamma: &mut SVector<f64, NC>,
    ) {
        self.inner.dynamics_terms(q, qd, t, m, h, phi_q, gamma);
        subtract_input(self.inner, &(self.law)(q, qd, t), h);
    }
}

fn subtract_input<M, const NQ: usize, const NC: usize>(
    model: &M,
    tau: &[f64; 3],
    h: &mut SVector<f64, NQ>,
) where
    M: Model<NQ, NC, 3>,
{
    let mut b = SMatrix::<f64, NQ, 3>::zeros();
    model.actuator_map(&mut b);
    *h -= b * SVector::<f64, 3>::from(*tau);
}

/// Joint-space PD loop on the actuated joints:
/// `tau_fb = kp (th_ref(t) - th) + kd (thd_ref(t) - thd)`, with the reference
/// angles `th11, th21, th31` sampled in time (e.g. the rigid inverse
/// dynamics' table) and their rates from [`TorqueTable::rate_at`].
#[derive(Debug, Clone)]
pub struct JointPd {
    /// Proportional gain, N m/rad.
    pub kp: f64,
    /// Derivative gain, N m s/rad.
    pub kd: f64,
    /// Reference angles of the actuated joints.
    pub reference: TorqueTable,
    /// Indices of the actuated joints among the coordinates.
    pub actuated: [usize; 3],
}

impl JointPd {
    /// Checks the gains: finite and non-negative.
    pub fn new(
        kp: f64,
        kd: f64,
        reference: TorqueTable,
        actuated: [usize; 3],
    ) -> Result<JointPd, String> {
        if !(kp.is_finite() && kp >= 0.0 && kd.is_finite() && kd >= 0.0) {
            return Err(format!(
                "PD gains must be finite and non-negative, got kp = {kp}, kd = {kd}"
            ));
        }
        Ok(JointPd {
            kp,
            kd,
            reference,
            actuated,
        })
    }

    /// The feedback torques at a state.
    pub fn torques<const NQ: usize>(
        &self,
        q: &SVector<f64, NQ>,
        qd: &SVector<f64, NQ>,
        t: f64,
    ) -> [f64; 3] {
        let (r, rd) = (self.reference.at(t), self.reference.rate_at(t));
        std::array::from_fn(|j| {
            let i = self.actuated[j];
            self.kp * (r[j] - q[i]) + self.kd * (rd[j] - qd[i])
        })
    }
}

/// Servo constraints on the platform centre: at every state the actuator
/// torques `tau` are those for which the constrained accelerations satisfy
///
/// ```text
/// S qdd = a_ref(t) + 2 alpha (v_ref(t) - S qd) + beta^2 (p_ref(t) - S q)
/// ```
///
/// (`S` selects `px, py, pz`), i.e. the linear system
///
/// ```text
/// [ M      -Phi_q^T  -B ] [qdd   ]   [ -h ]
/// [ Phi_q   0         0 ] [lambda] = [ c  ]      c = gamma - 2 a_B dPhi/dt - b_B^2 Phi
/// [ S       0         0 ] [tau   ]   [ s  ]
/// ```
///
/// solved by a Schur complement on `M` (Cholesky) and an LU of the
/// `(NC + 3)`-square matrix `[Phi_q; S] M^-1 [Phi_q^T, B]`. As a model its
/// bias forces are `h - B tau(q, qd, t)`: integrating it integrates the
/// elastic coordinates under the torques that keep the platform on the path.
/// The Baumgarte gains must be those of the integrator's dynamics solve.
pub struct Servo<'a, M> {
    /// The wrapped model.
    pub inner: &'a M,
    /// Indices of `px, py, pz`.
    pub platform: [usize; 3],
    /// The prescribed path of the platform centre.
    pub path: Circle,
    /// Stabilisation of the servo constraints (1/s).
    pub gains: Baumgarte,
    /// Stabilisation of the closure constraints (the integrator's).
    pub baumgarte: Baumgarte,
    failure: RefCell<Option<String>>,
}

impl<'a, M> Servo<'a, M> {
    /// Servo constraints keeping `platform` on `path`; both stabilisations at
    /// the runtime's default Baumgarte gains.
    pub fn new(inner: &'a M, platform: [usize; 3], path: Circle) -> Self {
        Servo {
            inner,
            platform,
            path,
            gains: Baumgarte::default(),
            baumgarte: Baumgarte::default(),
            failure: RefCell::new(None),
        }
    }

    /// Why the last torque solve failed, if it did (the integrator then sees
    /// non-finite bias forces and reports that).
    pub fn failure(&self) -> Option<String> {
        self.failure.borrow().clone()
    }

    /// The servo torques at a state.
    pub fn torques<const NQ: usize, const NC: usize>(
        &self,
        q: &SVector<f64, NQ>,
        qd: &SVector<f64, NQ>,
        t: f64,
    ) -> Result<[f64; 3], String>
    where
        M: Model<NQ, NC, 3>,
    {
        let mut m = SMatrix::<f64, NQ, NQ>::zeros();
        let mut h = SVector::<f64, NQ>::zeros();
        let mut phi_q = SMatrix::<f64, NC, NQ>::zeros();
        let mut gamma = SVector::<f64, NC>::zeros();
        self.inner
            .dynamics_terms(q, qd, t, &mut m, &mut h, &mut phi_q, &mut gamma);
        self.torques_from_terms(q, qd, t, &m, &h, &phi_q, &gamma)
    }

    #[allow(clippy::too_many_arguments)]
    fn torques_from_terms<const NQ: usize, const NC: usize>(
        &self,
        q: &SVector<f64, NQ>,
        qd: &SVector<f64, NQ>,
        t: f64,
        m: &SMatrix<f64, NQ, NQ>,
        h: &SVector<f64, NQ>,
        phi_q: &SMatrix<f64, NC, NQ>,
        gamma: &SVector<f64, NC>,
    ) -> Result<[f64; 3], String>
    where
        M: Model<NQ, NC, 3>,
    {
        let mut phi = SVector::<f64, NC>::zeros();
        let mut phi_t = SVector::<f64, NC>::zeros();
        let mut b = SMatrix::<f64, NQ, 3>::zeros();
        self.inner.constraints(q, t, &mut phi);
        self.inner.constraint_time_derivative(q, t, &mut phi_t);
        self.inner.actuator_map(&mut b);
        let chol = m
            .cholesky()
            .ok_or_else(|| format!("at t = {t} s: the mass matrix is not positive definite"))?;
        let yc = chol.solve(&phi_q.transpose());
        let yb = chol.solve(&b);
        let z = chol.solve(h);
        let n = NC + 3;
        let row = |r: usize| -> (usize, bool) {
            if r < NC {
                (r, true)
            } else {
                (self.platform[r - NC], false)
            }
        };
        // G Y with G = [Phi_q; S], Y = M^-1 [Phi_q^T, B].
        let gy = |r: usize, y: &dyn Fn(usize) -> f64| -> f64 {
            match row(r) {
                (r, true) => (0..NQ).map(|i| phi_q[(r, i)] * y(i)).sum(),
                (i, false) => y(i),
            }
        };
        let a = DMatrix::from_fn(n, n, |r, c| {
            if c < NC {
                gy(r, &|i| yc[(i, c)])
            } else {
                gy(r, &|i| yb[(i, c - NC)])
            }
        });
        let [p, v, acc] = self.path.at(t);
        let (al, be) = (self.baumgarte.alpha, self.baumgarte.beta);
        let c = gamma - (phi_q * qd + phi_t) * (2.0 * al) - phi * (be * be);
        let (sa, sb) = (self.gains.alpha, self.gains.beta);
        let rhs = DVector::from_fn(n, |r, _| {
            let known = if r < NC {
                c[r]
            } else {
                let (k, i) = (r - NC, self.platform[r - NC]);
                acc[k] + 2.0 * sa * (v[k] - qd[i]) + sb * sb * (p[k] - q[i])
            };
            known + gy(r, &|i| z[i])
        });
        let lu = a.clone().full_piv_lu();
        let sol = lu.solve(&rhs).filter(|x| x.iter().all(|v| v.is_finite()));
        let sol = sol.ok_or_else(|| {
            format!(
                "at t = {t} s: the servo constraints cannot be met (the actuators do not \
                 control the platform here: actuation singularity)"
            )
        })?;
        Ok([sol[NC], sol[NC + 1], sol[NC + 2]])
    }
}

impl<M, const NQ: usize, const NC: usize> Model<NQ, NC, 3> for Servo<'_, M>
where
    M: Model<NQ, NC, 3>,
{
    flexdyn_runtime::forward_model!(inner: M, NQ, NC, 3);
    fn bias(&self, q: &SVector<f64, NQ>, qd: &SVector<f64, NQ>, t: f64, h: &mut SVector<f64, NQ>) {
        let mut m = SMatrix::<f64, NQ, NQ>::zeros();
        let mut phi_q = SMatrix::<f64, NC, NQ>::zeros();
        let mut gamma = SVector::<f64, NC>::zeros();
        self.dynamics_terms(q, qd, t, &mut m, h, &mut phi_q, &mut gamma);
    }
    fn dynamics_terms(
        &self,
        q: &SVector<f64, NQ>,
        qd: &SVector<f64, NQ>,
        t: f64,
        m: &mut SMatrix<f64, NQ, NQ>,
        h: &mut SVector<f64, NQ>,
        phi_q: &mut SMatrix<f64, NC, NQ>,
        gamma: &mut SVector<f64, NC>,
    ) {
        self.inner.dynamics_terms(q, qd, t, m, h, phi_q, gamma);
        match self.torques_from_terms(q, qd, t, m, h, phi_q, gamma) {
            Ok(tau) => subtract_input(self.inner, &tau, h),
            Err(e) => {
                *self.failure.borrow_mut() = Some(e);
                h.fill(f64::NAN);
            }
        }
    }
}

/// Spectral radius at infinite frequency of the generalized-α scheme of
/// [`flexible_inverse`]: 0 (asymptotic annihilation), so that the elastic
/// and joint modes the step cannot resolve (all of them at 0.005 s: the
/// first link mode is 157 Hz) are damped out within a step or two instead of
/// ringing in the torques; the resolved, slow response stays second-order
/// accurate.
pub const SERVO_RHO_INF: f64 = 0.0;

/// One sample of [`flexible_inverse`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServoSample<const NQ: usize> {
    /// The state (platform on the path, elastic coordinates integrated).
    pub state: State<NQ>,
    /// The actuator torques at that state, N m.
    pub tau: [f64; 3],
}

/// Inverse dynamics of a robot scene with its elastic coordinates integrated:
/// the servo-constrained model ([`Servo`]) integrated by generalized-α
/// (`rho_inf` = [`SERVO_RHO_INF`], coordinate projection after every step)
/// with one step per interval of `times` (which must increase; the paper's
/// 0.005 s step for the CLI), from the robot in static equilibrium on the path at
/// `times[0]` ([`crate::robot::initial_state`]). Returns the state and the
/// torques at every time.
///
/// Each step is a predictor-corrector pair: a trial step of the servo model
/// gives the torques `tau_{n+1}` at the end of the step; the step actually
/// taken is that of the plain model under the torques interpolated linearly
/// from `tau_n` to `tau_{n+1}`, from the same integrator memory. So the
/// recorded trajectory is exactly the one that `parallel-robot simulate` reproduces
/// (same scheme and step) from the torque table, and the servo constraints'
/// stabilisation acts on that trajectory. For a scene with no elastic
/// coordinates this reproduces the rigid inverse dynamics.
pub fn flexible_inverse<M, const NQ: usize, const NC: usize>(
    model: &M,
    layout: &Layout,
    g: &Geometry,
    circle: &Circle,
    times: &[f64],
    tick: &mut dyn FnMut(),
) -> Result<Vec<ServoSample<NQ>>, String>
where
    M: Model<NQ, NC, 3>,
{
    use flexdyn_runtime::integrate::{GeneralizedAlpha, StepSettings};
    use flexdyn_runtime::{Integrator, Linear};
    let Some(&t0) = times.first() else {
        return Ok(Vec::new());
    };
    let [p0, v0, _] = circle.at(t0);
    let mut state = crate::robot::initial_state(model, layout, g, t0, p0, v0)?;
    let servo = Servo::new(model, layout.platform, *circle);
    let settings = StepSettings::with_projection();
    let config = flexdyn_runtime::GeneralizedAlphaConfig {
        rho_inf: SERVO_RHO_INF,
        filter_start: false,
        ..Default::default()
    };
    let mut integ = GeneralizedAlpha::<NQ, NC>::new(settings, config);
    let zero = SVector::<f64, 3>::zeros();
    let mut tau = servo.torques(&state.q, &state.qd, t0)?;
    let mut out = Vec::with_capacity(times.len());
    out.push(ServoSample { state, tau });
    tick();
    let fail = |e: flexdyn_runtime::Error| match servo.failure() {
        Some(why) => why,
        None => e.to_string(),
    };
    for w in times.windows(2) {
        let dt = w[1] - w[0];
        // The closed form tells precisely why a point cannot be reached.
        crate::robot::inverse_kinematics(g, circle.at(w[1])[0])
            .map_err(|e| format!("at t = {} s: {e}", w[1]))?;
        // The trial step without the projection, so that the torques are those
        // at the state its Newton iteration converged to.
        let mut trial_integ = integ;
        trial_integ.settings.projection = None;
        let mut trial = state;
        trial_integ
            .step(&servo, &mut trial, &zero, dt)
            .map_err(fail)?;
        let next = servo.torques(&trial.q, &trial.qd, trial.t)?;
        let input = Linear {
            t0: state.t,
            tau0: SVector::from(tau),
            t1: trial.t,
            tau1: SVector::from(next),
        };
        Integrator::<NQ, NC, 3>::step(&mut integ, model, &mut state, &input, dt).map_err(fail)?;
        tau = next;
        out.push(ServoSample { state, tau });
        tick();
    }
    Ok(out)
}
