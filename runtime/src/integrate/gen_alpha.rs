//! Implicit generalized-α integrator with bounded Newton iterations.

use super::{begin_step, finish_step, Integrator, StepReport, StepSettings};
use crate::dynamics::{accelerations, stabilised_rhs};
use crate::error::{Error, ErrorKind, Quantity};
use crate::eval;
use crate::input::Input;
use crate::linalg::{all_finite, Lu};
use crate::model::Model;
use crate::state::State;
use nalgebra::{SMatrix, SVector};

/// Parameters of [`GeneralizedAlpha`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GeneralizedAlphaConfig {
    /// Spectral radius at infinite frequency, in `[0, 1]`: 1 = no numerical
    /// dissipation (trapezoidal / average-acceleration Newmark, energy
    /// conserving on linear systems); smaller values damp the unresolved
    /// high-frequency modes more strongly (0 = asymptotic annihilation).
    pub rho_inf: f64,
    /// Cap on Newton iterations per step.
    pub max_iterations: u32,
    /// Relative tolerance on the Newton corrections of `q` and `qd`.
    pub rtol: f64,
    /// Absolute tolerance on the Newton corrections of `q` and `qd`.
    pub atol: f64,
    /// Relative finite-difference step for the bias Jacobians
    /// (`delta_j = fd_step * max(|x_j|, 1)`).
    pub fd_step: f64,
    /// Largest accepted condition estimate of the iteration matrix.
    pub max_condition: f64,
    /// The iteration matrix is re-evaluated when a Newton correction is not
    /// smaller than this fraction of the previous one.
    pub refresh_ratio: f64,
}

impl Default for GeneralizedAlphaConfig {
    fn default() -> Self {
        GeneralizedAlphaConfig {
            rho_inf: 0.8,
            max_iterations: 12,
            rtol: 1e-10,
            atol: 1e-12,
            fd_step: 1.5e-8,
            max_condition: 1e14,
            refresh_ratio: 0.25,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
struct Memory<const NQ: usize, const NC: usize> {
    state: State<NQ>,
    a: SVector<f64, NQ>,
    a_aux: SVector<f64, NQ>,
    lambda: SVector<f64, NC>,
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
/// Newton's iteration matrix `[[M + c_v h_qd + c_q K, -Phi_q^T], [s Phi_q, 0]]`
/// (with `K = d(M a + h - Phi_q^T lambda)/dq`) is solved by a Schur
/// complement with two partially pivoted LU factorisations. `h_q`, `h_qd` come
/// from [`Model::bias_jacobians`] when the model provides them (then `K = h_q`,
/// neglecting the smaller geometric terms), otherwise from forward finite
/// differences. The matrix is reused while the corrections contract fast and
/// refreshed otherwise. Second order; unconditionally stable for linear
/// problems; for `rho_inf < 1` unresolved modes (e.g. kHz flexible modes at a
/// 5 ms step) are damped instead of resonating.
///
/// The integrator remembers `a`, `a~` and `lambda` of the state it produced;
/// if it is handed a different state (bitwise), it re-initialises them from
/// a forward-dynamics solve (`a~ = a`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GeneralizedAlpha<const NQ: usize, const NC: usize> {
    /// Shared settings.
    pub settings: StepSettings,
    /// Scheme parameters.
    pub config: GeneralizedAlphaConfig,
    memory: Option<Memory<NQ, NC>>,
}

impl<const NQ: usize, const NC: usize> GeneralizedAlpha<NQ, NC> {
    /// Generalized-α with the given settings and parameters.
    pub fn new(settings: StepSettings, config: GeneralizedAlphaConfig) -> Self {
        GeneralizedAlpha { settings, config, memory: None }
    }

    /// Forgets the acceleration history (the next step re-initialises it).
    pub fn reset(&mut self) {
        self.memory = None;
    }

    /// `(alpha_m, alpha_f, beta, gamma)` for `rho_inf` (clamped to `[0, 1]`).
    pub fn coefficients(rho_inf: f64) -> (f64, f64, f64, f64) {
        let rho = if rho_inf.is_finite() { rho_inf.clamp(0.0, 1.0) } else { 1.0 };
        let am = (2.0 * rho - 1.0) / (rho + 1.0);
        let af = rho / (rho + 1.0);
        let gamma = 0.5 + af - am;
        let beta = 0.25 * (gamma + 0.5) * (gamma + 0.5);
        (am, af, beta, gamma)
    }
}

/// Iteration matrix, factored.
struct Jacobian<const NQ: usize, const NC: usize> {
    lu_a: Lu<NQ>,
    lu_w: Lu<NC>,
    /// `A^-1 Phi_q^T`.
    x: SMatrix<f64, NQ, NC>,
    phi_q: SMatrix<f64, NC, NQ>,
    w_scale: SVector<f64, NC>,
}

impl<const NQ: usize, const NC: usize, const NU: usize> Integrator<NQ, NC, NU> for GeneralizedAlpha<NQ, NC> {
    fn step<M, I>(&mut self, model: &M, state: &mut State<NQ>, input: &I, dt: f64) -> Result<StepReport, Error>
    where
        M: Model<NQ, NC, NU>,
        I: Input<NU> + ?Sized,
    {
        begin_step(state, dt, self.settings.max_step)?;
        let cfg = self.config;
        let dyn_cfg = self.settings.dynamics;
        let t0 = state.t;
        let h = dt;
        let t1 = t0 + h;
        let mem = match self.memory {
            Some(m) if m.state.same_bits(state) => m,
            _ => {
                let tau0 = input.at(t0);
                eval::check_input(&tau0, t0)?;
                let acc = accelerations(model, &dyn_cfg, &state.q, &state.qd, t0, &tau0)?;
                Memory { state: *state, a: acc.qdd, a_aux: acc.qdd, lambda: acc.lambda }
            }
        };
        let tau1 = input.at(t1);
        eval::check_input(&tau1, t1)?;
        let b = eval::actuator_map(model, t1)?;
        let f_ext = b * tau1;

        let (am, af, beta, gamma) = Self::coefficients(cfg.rho_inf);
        let k = 1.0 / (1.0 - am);
        let aux_base = (mem.a * af - mem.a_aux * am) * k;
        let q_base = state.q + state.qd * h + mem.a_aux * (h * h * (0.5 - beta)) + aux_base * (h * h * beta);
        let v_base = state.qd + mem.a_aux * (h * (1.0 - gamma)) + aux_base * (h * gamma);
        let cq = h * h * beta * (1.0 - af) * k;
        let cv = h * gamma * (1.0 - af) * k;
        let gains = dyn_cfg.baumgarte;
        let s = 1.0 + 2.0 * gains.alpha * cv + gains.beta * gains.beta * cq;

        let mut a = mem.a;
        let mut lambda = mem.lambda;
        let mut jac: Option<Jacobian<NQ, NC>> = None;
        let mut prev_err = f64::INFINITY;
        let mut err = f64::INFINITY;
        let mut iterations = 0u32;
        let mut converged = false;
        while iterations < cfg.max_iterations {
            iterations += 1;
            let q1 = q_base + a * cq;
            let v1 = v_base + a * cv;
            let m = eval::mass(model, &q1, t1)?;
            let hb = eval::bias(model, &q1, &v1, t1)?;
            let phi_q = eval::constraint_jacobian(model, &q1, t1)?;
            let g0 = m * a + hb - phi_q.transpose() * lambda;
            let r1 = g0 - f_ext;
            let c = stabilised_rhs(model, &gains, &q1, &v1, t1, &phi_q)?;
            let r2 = phi_q * a - c;
            let jm = match jac.take() {
                Some(j) => j,
                None => build_jacobian(model, &cfg, &dyn_cfg.max_condition, &q1, &v1, t1, &a, &lambda, &m, &hb, &g0, &phi_q, cq, cv)?,
            };
            // Delta a = d0 + X Delta lambda, W Delta lambda = -r2 / s - Phi_q d0.
            let mut d0 = -r1;
            jm.lu_a.solve(&mut d0);
            let rhs = -r2 / s - jm.phi_q * d0;
            let mut y = rhs.component_mul(&jm.w_scale);
            jm.lu_w.solve(&mut y);
            let dl = y.component_mul(&jm.w_scale);
            let da = d0 + jm.x * dl;
            a += da;
            lambda += dl;
            if !all_finite(&a) || !all_finite(&lambda) {
                return Err(Error::new(ErrorKind::NewtonNotConverged { iterations, residual: f64::INFINITY }, t0));
            }
            err = 0.0;
            for i in 0..NQ {
                let eq = (cq * da[i]).abs() / (cfg.atol + cfg.rtol * q1[i].abs());
                let ev = (cv * da[i]).abs() / (cfg.atol + cfg.rtol * v1[i].abs());
                err = err.max(eq).max(ev);
            }
            if err <= 1.0 {
                converged = true;
                break;
            }
            if err <= cfg.refresh_ratio * prev_err {
                jac = Some(jm);
            }
            prev_err = err;
        }
        if !converged {
            return Err(Error::new(ErrorKind::NewtonNotConverged { iterations, residual: err }, t0));
        }
        let q1 = q_base + a * cq;
        let v1 = v_base + a * cv;
        let a_aux = aux_base + a * ((1.0 - af) * k);
        eval::check_result(&q1, Quantity::Position, t0)?;
        eval::check_result(&v1, Quantity::Velocity, t0)?;
        let mut next = State { q: q1, qd: v1, t: t1 };
        let (projection, drift) = finish_step(model, &mut next, &self.settings)?;
        self.memory = Some(Memory { state: next, a, a_aux, lambda });
        *state = next;
        Ok(StepReport { t: t1, dt, iterations, stability_estimate: 0.0, projection, drift })
    }
}

/// Builds and factors the Newton iteration matrix at `(q, v, a, lambda)`.
#[allow(clippy::too_many_arguments)]
fn build_jacobian<M, const NQ: usize, const NC: usize, const NU: usize>(
    model: &M,
    cfg: &GeneralizedAlphaConfig,
    max_constraint_condition: &f64,
    q: &SVector<f64, NQ>,
    v: &SVector<f64, NQ>,
    t: f64,
    a: &SVector<f64, NQ>,
    lambda: &SVector<f64, NC>,
    m: &SMatrix<f64, NQ, NQ>,
    hb: &SVector<f64, NQ>,
    g0: &SVector<f64, NQ>,
    phi_q: &SMatrix<f64, NC, NQ>,
    cq: f64,
    cv: f64,
) -> Result<Jacobian<NQ, NC>, Error>
where
    M: Model<NQ, NC, NU>,
{
    let mut hq = SMatrix::<f64, NQ, NQ>::zeros();
    let mut hv = SMatrix::<f64, NQ, NQ>::zeros();
    if model.bias_jacobians(q, v, t, &mut hq, &mut hv) {
        if !all_finite(&hq) || !all_finite(&hv) {
            return Err(Error::new(ErrorKind::NonFiniteModelOutput { quantity: Quantity::BiasJacobian }, t));
        }
    } else {
        for j in 0..NQ {
            let delta = cfg.fd_step * q[j].abs().max(1.0);
            let mut qp = *q;
            qp[j] += delta;
            let delta = qp[j] - q[j];
            let mp = eval::mass(model, &qp, t)?;
            let hp = eval::bias(model, &qp, v, t)?;
            let jp = eval::constraint_jacobian(model, &qp, t)?;
            let gp = mp * a + hp - jp.transpose() * lambda;
            hq.set_column(j, &((gp - g0) / delta));
        }
        for j in 0..NQ {
            let delta = cfg.fd_step * v[j].abs().max(1.0);
            let mut vp = *v;
            vp[j] += delta;
            let delta = vp[j] - v[j];
            let hp = eval::bias(model, q, &vp, t)?;
            hv.set_column(j, &((hp - hb) / delta));
        }
    }
    let a_mat = m + hv * cv + hq * cq;
    let lu_a = match Lu::factor(&a_mat, cfg.max_condition) {
        Ok((lu, _)) => lu,
        Err(condition) => return Err(Error::new(ErrorKind::SingularIterationMatrix { condition }, t)),
    };
    let mut x = phi_q.transpose();
    for j in 0..NC {
        let mut col: SVector<f64, NQ> = x.column(j).into_owned();
        lu_a.solve(&mut col);
        x.set_column(j, &col);
    }
    let w = phi_q * x;
    let mut w_scale = SVector::<f64, NC>::zeros();
    for i in 0..NC {
        let d = w[(i, i)].abs();
        if !(d > 0.0) || !d.is_finite() {
            return Err(Error::new(
                ErrorKind::SingularConstraintJacobian { condition: f64::INFINITY, limit: *max_constraint_condition },
                t,
            ));
        }
        w_scale[i] = 1.0 / crate::math::sqrt(d);
    }
    let mut ws = w;
    for j in 0..NC {
        for i in 0..NC {
            ws[(i, j)] *= w_scale[i] * w_scale[j];
        }
    }
    let lu_w = match Lu::factor(&ws, *max_constraint_condition) {
        Ok((lu, _)) => lu,
        Err(condition) => {
            return Err(Error::new(
                ErrorKind::SingularConstraintJacobian { condition, limit: *max_constraint_condition },
                t,
            ))
        }
    };
    Ok(Jacobian { lu_a, lu_w, x, phi_q: *phi_q, w_scale })
}
