//! Inverse dynamics along a prescribed motion: the real-time torque path.
//!
//! Given the values, velocities and accelerations of `NP` prescribed
//! coordinates (for a parallel robot: the platform pose), one call of
//! [`InverseDynamics::solve`]
//!
//! 1. solves `Phi(q, t) = 0` for the other coordinates by Newton from the
//!    previous solution (bounded iterations, minimum-norm steps),
//! 2. solves `[Phi_q; S] qd = [-Phi_t; v]` and `[Phi_q; S] qdd = [gamma; a]`
//!    (`S` selects the prescribed coordinates),
//! 3. solves `Phi_q^T lambda + B tau = M qdd + h` for the actuator inputs and
//!    constraint forces ([`forces`]).
//!
//! All decompositions are one-sided Jacobi SVDs on the stack with capped
//! sweep counts, so redundancy is handled by minimum-norm least squares:
//! redundant constraints give the minimum-norm `lambda`, redundant actuation
//! the minimum-norm `tau`; an under-actuated system gets the least-squares
//! `tau` and a non-zero `force_residual` in the report.

use crate::error::{Error, ErrorKind, Quantity};
use crate::eval;
use crate::linalg::{first_non_finite, Svd};
use crate::model::Model;
use crate::state::inf_norm;
use nalgebra::{SMatrix, SVector};

/// Configuration of the inverse-dynamics solver.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InverseConfig {
    /// Target `max |Phi|` of the position solve (model units).
    pub position_tolerance: f64,
    /// Cap on Newton iterations of the position solve.
    pub max_iterations: u32,
    /// Singular values below `rank_tolerance * sigma_max` count as zero when
    /// deciding the rank of `Phi_q` (redundant constraints).
    pub rank_tolerance: f64,
    /// Largest accepted condition (`sigma_max / sigma_k`) of the Jacobian of
    /// the free coordinates and of the projected actuation matrix.
    pub max_condition: f64,
    /// Cap on Jacobi SVD sweeps.
    pub max_sweeps: u32,
}

impl Default for InverseConfig {
    fn default() -> Self {
        InverseConfig {
            position_tolerance: 1e-12,
            max_iterations: 20,
            rank_tolerance: 1e-10,
            max_condition: 1e8,
            max_sweeps: 40,
        }
    }
}

/// Full solution of one inverse-dynamics call.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InverseSolution<const NQ: usize, const NC: usize, const NU: usize> {
    /// Time.
    pub t: f64,
    /// All coordinates.
    pub q: SVector<f64, NQ>,
    /// All velocities.
    pub qd: SVector<f64, NQ>,
    /// All accelerations.
    pub qdd: SVector<f64, NQ>,
    /// Actuator inputs.
    pub tau: SVector<f64, NU>,
    /// Constraint forces (multipliers; generalized force `Phi_q^T lambda`).
    pub lambda: SVector<f64, NC>,
}

impl<const NQ: usize, const NC: usize, const NU: usize> Default for InverseSolution<NQ, NC, NU> {
    fn default() -> Self {
        InverseSolution {
            t: 0.0,
            q: SVector::zeros(),
            qd: SVector::zeros(),
            qdd: SVector::zeros(),
            tau: SVector::zeros(),
            lambda: SVector::zeros(),
        }
    }
}

/// Diagnostics of one inverse-dynamics call.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct InverseReport {
    /// Newton iterations of the position solve.
    pub iterations: u32,
    /// `max |Phi|` at the solution.
    pub position_residual: f64,
    /// `max |Phi_q qd + Phi_t|` at the solution.
    pub velocity_residual: f64,
    /// `max |Phi_q qdd - gamma|` at the solution.
    pub acceleration_residual: f64,
    /// Condition (`sigma_max / sigma_min`) of the Jacobian of the free coordinates.
    pub jacobian_condition: f64,
    /// Diagnostics of the force solve.
    pub forces: ForceReport,
}

/// Diagnostics of [`forces`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ForceReport {
    /// Numerical rank of `Phi_q`.
    pub constraint_rank: usize,
    /// Condition of `B` projected onto the null space of `Phi_q`, over the
    /// singular values that must be non-zero (`min(NU, NQ - rank Phi_q)`).
    pub actuation_condition: f64,
    /// `max |Phi_q^T lambda + B tau - (M qdd + h)|`: zero (to rounding) unless
    /// the system is under-actuated for this motion.
    pub residual: f64,
}

/// Solves `Phi_q^T lambda + B tau = M qdd + h` at a known `(q, qd, qdd, t)`
/// (minimum-norm least squares, see the module docs). Returns
/// `(tau, lambda, report)`.
///
/// Errors: non-finite model outputs, [`ErrorKind::DecompositionNotConverged`],
/// [`ErrorKind::SingularActuation`], [`ErrorKind::NonFiniteResult`].
#[allow(clippy::type_complexity)]
pub fn forces<M, const NQ: usize, const NC: usize, const NU: usize>(
    model: &M,
    config: &InverseConfig,
    q: &SVector<f64, NQ>,
    qd: &SVector<f64, NQ>,
    qdd: &SVector<f64, NQ>,
    t: f64,
) -> Result<(SVector<f64, NU>, SVector<f64, NC>, ForceReport), Error>
where
    M: Model<NQ, NC, NU>,
{
    let m = eval::mass(model, q, t)?;
    let h = eval::bias(model, q, qd, t)?;
    let b = eval::actuator_map(model, t)?;
    let phi_q = eval::constraint_jacobian(model, q, t)?;
    let r = m * qdd + h;
    let p_svd = svd(&phi_q.transpose(), config.max_sweeps, t)?;
    let rank_c = p_svd.rank(config.rank_tolerance);
    // Components of r and B outside the range of Phi_q^T, i.e. along the
    // free motion directions.
    let mut r_free = r;
    p_svd.remove_range(&mut r_free, rank_c);
    let mut b_free = b;
    for j in 0..NU {
        let mut col: SVector<f64, NQ> = b.column(j).into_owned();
        p_svd.remove_range(&mut col, rank_c);
        b_free.set_column(j, &col);
    }
    let b_svd = svd(&b_free, config.max_sweeps, t)?;
    let needed = NU.min(NQ.saturating_sub(rank_c));
    let actuation_condition = b_svd.condition_of_leading(needed);
    if !(actuation_condition <= config.max_condition) {
        return Err(Error::new(
            ErrorKind::SingularActuation {
                condition: actuation_condition,
                limit: config.max_condition,
            },
            t,
        ));
    }
    let mut tau = SVector::<f64, NU>::zeros();
    b_svd.solve(&r_free, needed, &mut tau);
    let mut lambda = SVector::<f64, NC>::zeros();
    p_svd.solve(&(r - b * tau), rank_c, &mut lambda);
    eval::check_result(&tau, Quantity::Input, t)?;
    eval::check_result(&lambda, Quantity::ConstraintForces, t)?;
    let residual = inf_norm(&(phi_q.transpose() * lambda + b * tau - r));
    Ok((
        tau,
        lambda,
        ForceReport {
            constraint_rank: rank_c,
            actuation_condition,
            residual,
        },
    ))
}

fn svd<const R: usize, const C: usize>(
    a: &SMatrix<f64, R, C>,
    max_sweeps: u32,
    t: f64,
) -> Result<Svd<R, C>, Error> {
    Svd::new(a, max_sweeps)
        .map_err(|sweeps| Error::new(ErrorKind::DecompositionNotConverged { sweeps }, t))
}

/// Inverse dynamics with `NP` prescribed coordinates; keeps the previous
/// position solution as the Newton starting point of the next call.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InverseDynamics<const NQ: usize, const NC: usize, const NU: usize, const NP: usize> {
    /// Solver settings.
    pub config: InverseConfig,
    prescribed: [usize; NP],
    guess: SVector<f64, NQ>,
}

impl<const NQ: usize, const NC: usize, const NU: usize, const NP: usize>
    InverseDynamics<NQ, NC, NU, NP>
{
    /// Creates the solver for the coordinates `prescribed` (indices into `q`),
    /// starting the first position solve from `initial_guess`.
    ///
    /// Fails with [`ErrorKind::InvalidConfiguration`] if an index is out of
    /// range or repeated, or if there are fewer constraints than free
    /// coordinates (`NC < NQ - NP`, the motion would be under-determined);
    /// with [`ErrorKind::NonFiniteState`] if the guess is not finite.
    pub fn new(
        prescribed: [usize; NP],
        initial_guess: SVector<f64, NQ>,
        config: InverseConfig,
    ) -> Result<Self, Error> {
        for (k, &i) in prescribed.iter().enumerate() {
            if i >= NQ {
                return Err(Error::new(
                    ErrorKind::InvalidConfiguration {
                        reason: "prescribed coordinate index out of range",
                    },
                    0.0,
                ));
            }
            if prescribed[..k].contains(&i) {
                return Err(Error::new(
                    ErrorKind::InvalidConfiguration {
                        reason: "prescribed coordinate index repeated",
                    },
                    0.0,
                ));
            }
        }
        if NP > NQ || NC < NQ - NP {
            return Err(Error::new(
                ErrorKind::InvalidConfiguration {
                    reason: "fewer constraints than free coordinates: the motion is not determined",
                },
                0.0,
            ));
        }
        if let Some(index) = first_non_finite(&initial_guess) {
            return Err(Error::new(
                ErrorKind::NonFiniteState {
                    quantity: Quantity::Position,
                    index,
                },
                0.0,
            ));
        }
        Ok(InverseDynamics {
            config,
            prescribed,
            guess: initial_guess,
        })
    }

    /// The prescribed coordinate indices.
    pub fn prescribed(&self) -> &[usize; NP] {
        &self.prescribed
    }

    /// The current Newton starting point (the last solution).
    pub fn guess(&self) -> &SVector<f64, NQ> {
        &self.guess
    }

    /// Replaces the Newton starting point (e.g. to select an assembly mode).
    pub fn set_guess(&mut self, q: SVector<f64, NQ>) {
        self.guess = q;
    }

    /// `Phi_q` with the prescribed columns zeroed.
    fn free_jacobian(&self, phi_q: &SMatrix<f64, NC, NQ>) -> SMatrix<f64, NC, NQ> {
        let mut j = *phi_q;
        for &i in self.prescribed.iter() {
            j.column_mut(i).fill(0.0);
        }
        j
    }

    /// Vector with the prescribed entries set to `x` and zeros elsewhere.
    fn scatter(&self, x: &SVector<f64, NP>) -> SVector<f64, NQ> {
        let mut v = SVector::<f64, NQ>::zeros();
        for (k, &i) in self.prescribed.iter().enumerate() {
            v[i] = x[k];
        }
        v
    }

    /// One inverse-dynamics evaluation at time `t` for prescribed positions
    /// `p`, velocities `v` and accelerations `a` (in the order of
    /// `prescribed`). Writes the full solution to `out`. On error `out` and
    /// the solver are unchanged.
    ///
    /// Errors: [`ErrorKind::NonFiniteInput`], non-finite model outputs,
    /// [`ErrorKind::SingularConstraintJacobian`] (free coordinates not
    /// determined: singular configuration), [`ErrorKind::NewtonNotConverged`]
    /// (residual = `max |Phi|`), [`ErrorKind::DecompositionNotConverged`],
    /// [`ErrorKind::SingularActuation`], [`ErrorKind::NonFiniteResult`].
    pub fn solve<M>(
        &mut self,
        model: &M,
        t: f64,
        p: &SVector<f64, NP>,
        v: &SVector<f64, NP>,
        a: &SVector<f64, NP>,
        out: &mut InverseSolution<NQ, NC, NU>,
    ) -> Result<InverseReport, Error>
    where
        M: Model<NQ, NC, NU>,
    {
        if !t.is_finite() {
            return Err(Error::new(
                ErrorKind::NonFiniteInput {
                    quantity: Quantity::Time,
                    index: 0,
                },
                t,
            ));
        }
        for (x, quantity) in [
            (p, Quantity::PrescribedPosition),
            (v, Quantity::PrescribedVelocity),
            (a, Quantity::PrescribedAcceleration),
        ] {
            if let Some(index) = first_non_finite(x) {
                return Err(Error::new(ErrorKind::NonFiniteInput { quantity, index }, t));
            }
        }
        let cfg = self.config;
        let nf = NQ.saturating_sub(NP);
        // 1. Positions.
        let mut q = self.guess;
        for (k, &i) in self.prescribed.iter().enumerate() {
            q[i] = p[k];
        }
        let mut iterations = 0u32;
        let mut phi = eval::constraints(model, &q, t)?;
        loop {
            let res = inf_norm(&phi);
            if res <= cfg.position_tolerance {
                break;
            }
            if iterations >= cfg.max_iterations {
                return Err(Error::new(
                    ErrorKind::NewtonNotConverged {
                        iterations,
                        residual: res,
                    },
                    t,
                ));
            }
            let phi_q = eval::constraint_jacobian(model, &q, t)?;
            let jsvd = svd(&self.free_jacobian(&phi_q).transpose(), cfg.max_sweeps, t)?;
            check_condition(&jsvd, nf, cfg.max_condition, t)?;
            let mut dq = SVector::<f64, NQ>::zeros();
            jsvd.solve_transpose(&(-phi), nf, &mut dq);
            q += dq;
            eval::check_result(&q, Quantity::Position, t)?;
            iterations += 1;
            phi = eval::constraints(model, &q, t)?;
        }
        // 2. Velocities and accelerations.
        let phi_q = eval::constraint_jacobian(model, &q, t)?;
        let phi_t = eval::constraint_time_derivative(model, &q, t)?;
        let jsvd = svd(&self.free_jacobian(&phi_q).transpose(), cfg.max_sweeps, t)?;
        let jacobian_condition = check_condition(&jsvd, nf, cfg.max_condition, t)?;
        let v_full = self.scatter(v);
        let mut qd = SVector::<f64, NQ>::zeros();
        jsvd.solve_transpose(&(-phi_t - phi_q * v_full), nf, &mut qd);
        qd += v_full;
        let gamma = eval::constraint_rhs(model, &q, &qd, t)?;
        let a_full = self.scatter(a);
        let mut qdd = SVector::<f64, NQ>::zeros();
        jsvd.solve_transpose(&(gamma - phi_q * a_full), nf, &mut qdd);
        qdd += a_full;
        for (k, &i) in self.prescribed.iter().enumerate() {
            qd[i] = v[k];
            qdd[i] = a[k];
        }
        eval::check_result(&qd, Quantity::Velocity, t)?;
        eval::check_result(&qdd, Quantity::Acceleration, t)?;
        // 3. Forces.
        let (tau, lambda, force_report) = forces(model, &cfg, &q, &qd, &qdd, t)?;
        let report = InverseReport {
            iterations,
            position_residual: inf_norm(&phi),
            velocity_residual: inf_norm(&(phi_q * qd + phi_t)),
            acceleration_residual: inf_norm(&(phi_q * qdd - gamma)),
            jacobian_condition,
            forces: force_report,
        };
        self.guess = q;
        *out = InverseSolution {
            t,
            q,
            qd,
            qdd,
            tau,
            lambda,
        };
        Ok(report)
    }
}

/// Checks that the leading `needed` singular values are well conditioned.
fn check_condition<const R: usize, const C: usize>(
    svd: &Svd<R, C>,
    needed: usize,
    limit: f64,
    t: f64,
) -> Result<f64, Error> {
    let condition = svd.condition_of_leading(needed);
    if condition <= limit {
        Ok(condition)
    } else {
        Err(Error::new(
            ErrorKind::SingularConstraintJacobian { condition, limit },
            t,
        ))
    }
}
