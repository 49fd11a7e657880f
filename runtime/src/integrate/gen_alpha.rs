//! Implicit generalized-α integrator with bounded Newton iterations.

use super::{begin_step, finish_step, IntegratorOf, StepReport, StepSettings};
use crate::dynamics::{accelerations, stabilised_rhs};
use crate::error::{Error, ErrorKind, Quantity};
use crate::eval;
use crate::input::InputOf;
use crate::linalg::{all_finite, Lu};
use crate::model::{Equations, Sizes};
use crate::scalar::Scalar;
use crate::state::StateOf;
use nalgebra::allocator::Allocator;
use nalgebra::{Const, DefaultAllocator, Dim, OMatrix, OVector, U1};

/// Parameters of [`GeneralizedAlpha`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GeneralizedAlphaConfig<T: Scalar = f64> {
    /// Spectral radius at infinite frequency, in `[0, 1]`: 1 = no numerical
    /// dissipation (trapezoidal / average-acceleration Newmark, energy
    /// conserving on linear systems); smaller values damp the unresolved
    /// high-frequency modes more strongly (0 = asymptotic annihilation).
    pub rho_inf: T,
    /// Cap on Newton iterations per step.
    pub max_iterations: u32,
    /// Relative tolerance on the Newton corrections of `q` and `qd`.
    pub rtol: T,
    /// Absolute tolerance on the Newton corrections of `q` and `qd`.
    pub atol: T,
    /// Relative finite-difference step for the bias Jacobians
    /// (`delta_j = fd_step * max(|x_j|, 1)`).
    pub fd_step: T,
    /// Largest accepted condition estimate of the iteration matrix.
    pub max_condition: T,
    /// The iteration matrix is re-evaluated when a Newton correction is not
    /// smaller than this fraction of the previous one.
    pub refresh_ratio: T,
    /// When starting (or restarting) from a state, initialise the auxiliary
    /// acceleration with the low-pass filtered `a~_0 = J^-1 M a_0` (`J` the
    /// Newton iteration matrix) instead of `a~_0 = a_0`. The two agree to
    /// `O((omega dt)^2)` on resolved modes; on unresolved stiff modes the
    /// filtered value removes the start-up overshoot of generalized-α
    /// (energy of a mode at `omega dt = 100` grows about 500-fold in the
    /// first step with `rho_inf = 0` otherwise). Ignored for `rho_inf = 1`,
    /// where `a~` must equal `a`.
    pub filter_start: bool,
}

impl<T: Scalar> Default for GeneralizedAlphaConfig<T> {
    /// `rho_inf = 0.8`, 12 iterations, `rtol = 1e-10` (at least `100 eps`:
    /// 1.2e-5 in f32), `atol = 1e-12` (at least `eps`), `fd_step = 1.5e-8`
    /// (at least `sqrt(eps)`: 3.5e-4 in f32), condition limit
    /// [`Scalar::ITERATION_MAX_CONDITION`], refresh ratio 0.25, filtered
    /// start.
    fn default() -> Self {
        GeneralizedAlphaConfig {
            rho_inf: T::of(0.8),
            max_iterations: 12,
            rtol: T::of(1e-10).max(T::EPSILON * T::of(100.0)),
            atol: T::of(1e-12).max(T::EPSILON),
            fd_step: T::of(1.5e-8).max(T::EPSILON.square_root()),
            max_condition: T::ITERATION_MAX_CONDITION,
            refresh_ratio: T::of(0.25),
            filter_start: true,
        }
    }
}

#[derive(Clone, Debug, PartialEq)]
struct Memory<T: Scalar, Q: Dim, C: Dim>
where
    DefaultAllocator: Allocator<Q> + Allocator<C>,
{
    state: StateOf<T, Q>,
    a: OVector<T, Q>,
    a_aux: OVector<T, Q>,
    lambda: OVector<T, C>,
}

/// Generalized-α (Chung–Hulbert 1993, in the form of Arnold & Brüls 2007)
/// on the Baumgarte-stabilised equations of motion.
///
/// Per step the unknowns are the accelerations `a = qdd_{n+1}` and the
/// multipliers `lambda_{n+1}`; positions and velocities follow from the
/// Newmark relations with the auxiliary acceleration `a~`:
///
/// ```text
/// (1 - am) a~_{n+1} + am a~_n = (1 - af) a_{n+1} + af a_n
/// q_{n+1}  = q_n + h qd_n + h^2 (1/2 - beta) a~_n + h^2 beta a~_{n+1}
/// qd_{n+1} = qd_n + h (1 - gamma) a~_n + h gamma a~_{n+1}
/// M a + h(q, qd) - Phi_q^T lambda - B tau(t_{n+1}) = 0
/// Phi_q a - gamma(q, qd) + 2 alpha (Phi_q qd + Phi_t) + beta_B^2 Phi = 0
/// ```
///
/// with `q_{n+1} = q_base + c_q a`, `qd_{n+1} = v_base + c_v a`. Newton's
/// iteration matrix `[[J11, -Phi_q^T], [J21, 0]]`, `J11 = dR1/da`,
/// `J21 = dR2/da`, is solved by a Schur complement with two partially
/// pivoted LU factorisations (`J11` is `NQ x NQ`, the Schur complement
/// `J21 J11^-1 Phi_q^T` is `NC x NC`). Without analytic Jacobians `J11` and
/// `J21` are forward differences of the residual along each `a_j` (`NQ`
/// residual evaluations): the exact Newton matrix up to truncation,
/// including the mass-matrix, constraint-force and `gamma` derivatives. When
/// the model implements [`Model::bias_jacobians`], `J11 = M + c_v h_qd +
/// c_q h_q` and `J21 = (1 + 2 alpha c_v + beta_B^2 c_q) Phi_q` (the smaller
/// geometric terms are neglected; Newton still converges, linearly; if it
/// has not converged after half of `max_iterations`, the remaining
/// iterations use the finite-difference matrix). The matrix is reused
/// while the corrections contract fast and refreshed otherwise; at most
/// `max_iterations` iterations, converged when the implied corrections of
/// `q` and `qd` are within `atol + rtol |x|`.
///
/// Second order; unconditionally stable for linear problems; for
/// `rho_inf < 1` unresolved modes (e.g. kHz flexible modes at a 5 ms step)
/// are damped instead of resonating, without start-up overshoot (see
/// [`GeneralizedAlphaConfig::filter_start`]).
///
/// Computes in `T` (`f64` unless named; the defaults of
/// [`GeneralizedAlphaConfig`] follow it).
///
/// The integrator remembers `a`, `a~` and `lambda` of the state it produced;
/// if it is handed a different state (compared bitwise), it re-initialises
/// them from a forward-dynamics solve, so external changes to the state
/// (resets, projections, events) are safe.
///
/// `Q` coordinates and `C` constraints of fixed or run-time size
/// ([`GeneralizedAlpha`]: fixed).
#[derive(Clone, Debug, PartialEq)]
pub struct GeneralizedAlphaOf<T: Scalar, Q: Dim, C: Dim>
where
    DefaultAllocator: Allocator<Q> + Allocator<C>,
{
    /// Shared settings.
    pub settings: StepSettings<T>,
    /// Scheme parameters.
    pub config: GeneralizedAlphaConfig<T>,
    memory: Option<Memory<T, Q, C>>,
}

/// [`GeneralizedAlphaOf`] for a model of fixed size.
pub type GeneralizedAlpha<const NQ: usize, const NC: usize, T = f64> =
    GeneralizedAlphaOf<T, Const<NQ>, Const<NC>>;

impl<T: Scalar, const NQ: usize, const NC: usize> Copy for Memory<T, Const<NQ>, Const<NC>> {}
impl<T: Scalar, const NQ: usize, const NC: usize> Copy
    for GeneralizedAlphaOf<T, Const<NQ>, Const<NC>>
{
}

impl<T: Scalar, Q: Dim, C: Dim> Default for GeneralizedAlphaOf<T, Q, C>
where
    DefaultAllocator: Allocator<Q> + Allocator<C>,
{
    fn default() -> Self {
        Self::new(StepSettings::default(), GeneralizedAlphaConfig::default())
    }
}

impl<T: Scalar, Q: Dim, C: Dim> GeneralizedAlphaOf<T, Q, C>
where
    DefaultAllocator: Allocator<Q> + Allocator<C>,
{
    /// Generalized-α with the given settings and parameters.
    pub fn new(settings: StepSettings<T>, config: GeneralizedAlphaConfig<T>) -> Self {
        GeneralizedAlphaOf {
            settings,
            config,
            memory: None,
        }
    }

    /// Forgets the acceleration history (the next step re-initialises it).
    pub fn reset(&mut self) {
        self.memory = None;
    }

    /// `(alpha_m, alpha_f, beta, gamma)` for `rho_inf` (clamped to `[0, 1]`).
    pub fn coefficients(rho_inf: T) -> (T, T, T, T) {
        let (zero, one, half) = (T::zero(), T::one(), T::of(0.5));
        let rho = if rho_inf.is_finite() {
            rho_inf.clamp(zero, one)
        } else {
            one
        };
        let am = (T::of(2.0) * rho - one) / (rho + one);
        let af = rho / (rho + one);
        let gamma = half + af - am;
        let beta = T::of(0.25) * (gamma + half) * (gamma + half);
        (am, af, beta, gamma)
    }
}

/// Iteration matrix, factored.
struct Jacobian<T: Scalar, Q: Dim, C: Dim>
where
    DefaultAllocator: Sizes<Q, C, C>,
{
    lu_a: Lu<T, Q>,
    lu_w: Lu<T, C>,
    /// `J11^-1 Phi_q^T`.
    x: OMatrix<T, Q, C>,
    /// `dR2/da`.
    j21: OMatrix<T, C, Q>,
    w_scale: OVector<T, C>,
}

/// Everything a step's residual depends on besides `(a, lambda)`.
struct Ctx<T: Scalar, Q: Dim>
where
    DefaultAllocator: Allocator<Q>,
{
    q_base: OVector<T, Q>,
    v_base: OVector<T, Q>,
    cq: T,
    cv: T,
    t: T,
    f_ext: OVector<T, Q>,
    gains: crate::dynamics::Baumgarte,
}

/// Residuals at one iterate.
struct Residual<T: Scalar, Q: Dim, C: Dim>
where
    DefaultAllocator: Sizes<Q, C, C>,
{
    r1: OVector<T, Q>,
    r2: OVector<T, C>,
    phi_q: OMatrix<T, C, Q>,
    m: OMatrix<T, Q, Q>,
}

impl<T: Scalar, Q: Dim> Ctx<T, Q>
where
    DefaultAllocator: Allocator<Q>,
{
    fn q(&self, a: &OVector<T, Q>) -> OVector<T, Q> {
        &self.q_base + a * self.cq
    }
    fn v(&self, a: &OVector<T, Q>) -> OVector<T, Q> {
        &self.v_base + a * self.cv
    }
    /// `R1 = M a + h - Phi_q^T lambda - B tau`, `R2 = Phi_q a - c`.
    fn residual<M, C: Dim, U: Dim>(
        &self,
        model: &M,
        a: &OVector<T, Q>,
        lambda: &OVector<T, C>,
    ) -> Result<Residual<T, Q, C>, Error>
    where
        M: Equations<Q, C, U, T> + ?Sized,
        DefaultAllocator: Sizes<Q, C, U> + Sizes<Q, C, C>,
    {
        let q = self.q(a);
        let v = self.v(a);
        let eval::Terms { m, h, phi_q, gamma } = eval::dynamics_terms(model, &q, &v, self.t)?;
        let r1 = &m * a + h - phi_q.transpose() * lambda - &self.f_ext;
        let c = stabilised_rhs(model, &self.gains, &q, &v, self.t, &phi_q, gamma)?;
        let r2 = &phi_q * a - c;
        Ok(Residual { r1, r2, phi_q, m })
    }
}

impl<T: Scalar, Q: Dim, C: Dim, U: Dim> IntegratorOf<Q, C, U, T> for GeneralizedAlphaOf<T, Q, C>
where
    DefaultAllocator: Sizes<Q, C, U> + Sizes<Q, C, C>,
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
        let cfg = self.config;
        let dyn_cfg = self.settings.dynamics;
        let t0 = state.t;
        let h = dt;
        let t1 = t0 + h;
        let tau1 = input.at(t1);
        eval::check_input(&tau1, t1)?;
        let f_ext = eval::actuator_forces(model, &tau1, t1)?;
        let (am, af, beta, gamma) = Self::coefficients(cfg.rho_inf);
        let one = T::one();
        let k = one / (one - am);
        let cq = h * h * beta * (one - af) * k;
        let cv = h * gamma * (one - af) * k;
        let gains = dyn_cfg.baumgarte;
        let make_ctx = |mem: &Memory<T, Q, C>| {
            let aux_base = (&mem.a * af - &mem.a_aux * am) * k;
            let q_base = &state.q
                + &state.qd * h
                + &mem.a_aux * (h * h * (T::of(0.5) - beta))
                + &aux_base * (h * h * beta);
            let v_base = &state.qd + &mem.a_aux * (h * (one - gamma)) + &aux_base * (h * gamma);
            (
                Ctx {
                    q_base,
                    v_base,
                    cq,
                    cv,
                    t: t1,
                    f_ext: f_ext.clone(),
                    gains,
                },
                aux_base,
            )
        };
        let mem = match &self.memory {
            Some(m) if m.state.same_bits(state) => m.clone(),
            _ => {
                let tau0 = input.at(t0);
                eval::check_input(&tau0, t0)?;
                let acc = accelerations(model, &dyn_cfg, &state.q, &state.qd, t0, &tau0)?;
                let mut mem = Memory {
                    state: state.clone(),
                    a: acc.qdd.clone(),
                    a_aux: acc.qdd,
                    lambda: acc.lambda,
                };
                if cfg.filter_start && cfg.rho_inf < one {
                    let (ctx, _) = make_ctx(&mem);
                    let res = ctx.residual(model, &mem.a, &mem.lambda)?;
                    let jm = build_jacobian(
                        model,
                        &cfg,
                        dyn_cfg.max_condition,
                        &ctx,
                        &mem.a,
                        &mem.lambda,
                        &res,
                        false,
                    )?;
                    let mut filtered = eval::mass(model, &state.q, t0)? * &mem.a;
                    jm.lu_a.solve(&mut filtered);
                    if all_finite(&filtered) {
                        mem.a_aux = filtered;
                    }
                }
                mem
            }
        };
        let (ctx, aux_base) = make_ctx(&mem);
        let mut a = mem.a;
        let mut lambda = mem.lambda;
        let mut jac: Option<Jacobian<T, Q, C>> = None;
        let mut prev_err = T::INFINITY;
        let mut err = T::INFINITY;
        let mut iterations = 0u32;
        let mut converged = false;
        while iterations < cfg.max_iterations {
            iterations += 1;
            // The analytic Newton matrix leaves out the derivatives of
            // `M a` and `Phi_q^T lambda` in `q`; where that stalls Newton
            // (large constraint forces on stiff parts), the second half of
            // the iterations uses the exact finite-difference matrix.
            let exact = iterations > cfg.max_iterations / 2;
            if exact && iterations == cfg.max_iterations / 2 + 1 {
                jac = None;
            }
            let res = ctx.residual(model, &a, &lambda)?;
            let jm = match jac.take() {
                Some(j) => j,
                None => build_jacobian(
                    model,
                    &cfg,
                    dyn_cfg.max_condition,
                    &ctx,
                    &a,
                    &lambda,
                    &res,
                    exact,
                )?,
            };
            // Delta a = d0 + X Delta lambda, (J21 X) Delta lambda = -r2 - J21 d0.
            let mut d0 = -res.r1;
            jm.lu_a.solve(&mut d0);
            let rhs = -res.r2 - &jm.j21 * &d0;
            let mut y = rhs.component_mul(&jm.w_scale);
            jm.lu_w.solve(&mut y);
            let dl = y.component_mul(&jm.w_scale);
            let da = d0 + &jm.x * &dl;
            a += &da;
            lambda += dl;
            if !all_finite(&a) || !all_finite(&lambda) {
                return Err(Error::new(
                    ErrorKind::NewtonNotConverged {
                        iterations,
                        residual: f64::INFINITY,
                        tolerance: 1.0,
                    },
                    t0,
                ));
            }
            let q1 = ctx.q(&a);
            let v1 = ctx.v(&a);
            err = T::zero();
            for i in 0..da.nrows() {
                let eq = (cq * da[i]).abs() / (cfg.atol + cfg.rtol * q1[i].abs());
                let ev = (cv * da[i]).abs() / (cfg.atol + cfg.rtol * v1[i].abs());
                err = err.max(eq).max(ev);
            }
            if err <= one {
                converged = true;
                break;
            }
            if err <= cfg.refresh_ratio * prev_err {
                jac = Some(jm);
            }
            prev_err = err;
        }
        if !converged {
            return Err(Error::new(
                ErrorKind::NewtonNotConverged {
                    iterations,
                    residual: err.into(),
                    tolerance: 1.0,
                },
                t0,
            ));
        }
        let q1 = ctx.q(&a);
        let v1 = ctx.v(&a);
        let a_aux = aux_base + &a * ((one - af) * k);
        eval::check_result(&q1, Quantity::Position, t0)?;
        eval::check_result(&v1, Quantity::Velocity, t0)?;
        let mut next = StateOf {
            q: q1,
            qd: v1,
            t: t1,
        };
        let (projection, drift) = finish_step(model, &mut next, &self.settings)?;
        *state = next.clone();
        self.memory = Some(Memory {
            state: next,
            a,
            a_aux,
            lambda,
        });
        Ok(StepReport {
            t: t1,
            dt,
            iterations,
            stability_estimate: T::zero(),
            projection,
            drift,
        })
    }
}

/// Builds and factors the Newton iteration matrix at `(a, lambda)`.
///
/// Without analytic bias Jacobians (or with `finite_differences`) the blocks `dR1/da`, `dR2/da` are forward
/// differences of the residual itself in the direction of each `a_j` (exact
/// Newton matrix up to truncation). The step `delta_j` is chosen so that
/// neither the implied position change `c_q delta_j` nor the velocity change
/// `c_v delta_j` exceeds `fd_step * max(|x_j|, 1)`.
#[allow(clippy::too_many_arguments)]
fn build_jacobian<M, T: Scalar, Q: Dim, C: Dim, U: Dim>(
    model: &M,
    cfg: &GeneralizedAlphaConfig<T>,
    max_constraint_condition: T,
    ctx: &Ctx<T, Q>,
    a: &OVector<T, Q>,
    lambda: &OVector<T, C>,
    res: &Residual<T, Q, C>,
    finite_differences: bool,
) -> Result<Jacobian<T, Q, C>, Error>
where
    M: Equations<Q, C, U, T> + ?Sized,
    DefaultAllocator: Sizes<Q, C, U> + Sizes<Q, C, C>,
{
    let t = ctx.t;
    let (nq, nc, _) = model.sizes();
    let mut j11 = OMatrix::<T, Q, Q>::zeros_generic(nq, nq);
    let mut j21 = OMatrix::<T, C, Q>::zeros_generic(nc, nq);
    let mut hq = OMatrix::<T, Q, Q>::zeros_generic(nq, nq);
    let mut hv = OMatrix::<T, Q, Q>::zeros_generic(nq, nq);
    let q = ctx.q(a);
    let v = ctx.v(a);
    if !finite_differences && model.bias_jacobians(&q, &v, t, &mut hq, &mut hv) {
        if !all_finite(&hq) || !all_finite(&hv) {
            return Err(Error::new(
                ErrorKind::NonFiniteModelOutput {
                    quantity: Quantity::BiasJacobian,
                },
                t,
            ));
        }
        j11 = &res.m + hv * ctx.cv + hq * ctx.cq;
        let g = ctx.gains;
        j21 = &res.phi_q
            * (T::one() + T::of(2.0 * g.alpha) * ctx.cv + T::of(g.beta * g.beta) * ctx.cq);
    } else {
        for j in 0..nq.value() {
            let dq = cfg.fd_step * q[j].abs().max(T::one()) / ctx.cq;
            let dv = cfg.fd_step * v[j].abs().max(T::one()) / ctx.cv;
            let mut ap = a.clone();
            ap[j] += dq.min(dv);
            let delta = ap[j] - a[j];
            if !(delta > T::zero()) || !delta.is_finite() {
                return Err(Error::new(
                    ErrorKind::SingularIterationMatrix {
                        condition: f64::INFINITY,
                    },
                    t,
                ));
            }
            let rp = ctx.residual(model, &ap, lambda)?;
            j11.set_column(j, &((rp.r1 - &res.r1) / delta));
            j21.set_column(j, &((rp.r2 - &res.r2) / delta));
        }
    }
    let lu_a = match Lu::factor(&j11, cfg.max_condition) {
        Ok((lu, _)) => lu,
        Err(condition) => {
            return Err(Error::new(
                ErrorKind::SingularIterationMatrix {
                    condition: condition.into(),
                },
                t,
            ))
        }
    };
    let mut x = res.phi_q.transpose();
    for j in 0..nc.value() {
        let mut col: OVector<T, Q> = x.column(j).into_owned();
        lu_a.solve(&mut col);
        x.set_column(j, &col);
    }
    let w = &j21 * &x;
    let mut w_scale = OVector::<T, C>::zeros_generic(nc, U1);
    for i in 0..nc.value() {
        let d = w[(i, i)].abs();
        if !(d > T::zero()) || !d.is_finite() {
            return Err(Error::new(
                ErrorKind::SingularConstraintJacobian {
                    condition: f64::INFINITY,
                    limit: max_constraint_condition.into(),
                },
                t,
            ));
        }
        w_scale[i] = T::one() / d.square_root();
    }
    let mut ws = w;
    for j in 0..nc.value() {
        for i in 0..nc.value() {
            ws[(i, j)] *= w_scale[i] * w_scale[j];
        }
    }
    let lu_w = match Lu::factor(&ws, max_constraint_condition) {
        Ok((lu, _)) => lu,
        Err(condition) => {
            return Err(Error::new(
                ErrorKind::SingularConstraintJacobian {
                    condition: condition.into(),
                    limit: max_constraint_condition.into(),
                },
                t,
            ))
        }
    };
    Ok(Jacobian {
        lu_a,
        lu_w,
        x,
        j21,
        w_scale,
    })
}
