//! Constrained forward dynamics: the KKT system
//!
//! ```text
//! M qdd - Phi_q^T lambda = B tau - h
//! Phi_q qdd              = gamma - 2 alpha (Phi_q qd + Phi_t) - beta^2 Phi
//! ```
//!
//! solved by a Schur complement on the stack: Cholesky `M = L L^T`,
//! `Y = L^-1 Phi_q^T`, `S = Y^T Y = Phi_q M^-1 Phi_q^T` factored by an
//! equilibrated, diagonally pivoted Cholesky whose pivot ratio is the
//! condition estimate reported (and checked) for the constraint Jacobian.

use crate::error::{Error, ErrorKind, Quantity};
use crate::eval;
use crate::linalg::{cholesky, solve_lower, solve_lower_transpose, SpdSolver};
use crate::model::Model;
use crate::scalar::Scalar;
use nalgebra::{SMatrix, SVector};

/// Baumgarte stabilisation gains: the acceleration constraint becomes
/// `Phi_q qdd = gamma - 2 alpha dPhi/dt - beta^2 Phi`, which makes the
/// constraint violation obey `Phi'' + 2 alpha Phi' + beta^2 Phi = 0`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Baumgarte {
    /// Damping gain `alpha` (1/s).
    pub alpha: f64,
    /// Stiffness gain `beta` (1/s).
    pub beta: f64,
}

impl Baumgarte {
    /// No stabilisation (`alpha = beta = 0`): pure index-1 formulation.
    pub const NONE: Baumgarte = Baumgarte {
        alpha: 0.0,
        beta: 0.0,
    };
}

impl Default for Baumgarte {
    /// `alpha = beta = 10 / s` (critically damped violation, time constant 0.1 s).
    fn default() -> Self {
        Baumgarte {
            alpha: 10.0,
            beta: 10.0,
        }
    }
}

/// Configuration of the constrained acceleration solve.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DynamicsConfig<T: Scalar = f64> {
    /// Baumgarte gains.
    pub baumgarte: Baumgarte,
    /// Largest accepted condition estimate of the (equilibrated)
    /// `Phi_q M^-1 Phi_q^T`; above it the solve fails with
    /// [`ErrorKind::SingularConstraintJacobian`].
    pub max_condition: T,
}

impl<T: Scalar> Default for DynamicsConfig<T> {
    fn default() -> Self {
        DynamicsConfig {
            baumgarte: Baumgarte::default(),
            max_condition: T::KKT_MAX_CONDITION,
        }
    }
}

/// Result of a forward-dynamics solve.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Accelerations<const NQ: usize, const NC: usize, T: Scalar = f64> {
    /// Generalized accelerations `qdd`.
    pub qdd: SVector<T, NQ>,
    /// Constraint forces (Lagrange multipliers) `lambda`; the generalized
    /// constraint force is `Phi_q^T lambda`.
    pub lambda: SVector<T, NC>,
    /// Condition estimate of `Phi_q M^-1 Phi_q^T` (1 when unconstrained).
    pub condition: T,
}

/// Factored saddle-point matrix `[[M, Phi_q^T], [Phi_q, 0]]`.
pub(crate) struct Kkt<const NQ: usize, const NC: usize, T: Scalar = f64> {
    l: SMatrix<T, NQ, NQ>,
    y: SMatrix<T, NQ, NC>,
    s: SpdSolver<NC, T>,
    pub(crate) condition: T,
}

impl<T: Scalar, const NQ: usize, const NC: usize> Kkt<NQ, NC, T> {
    /// Factors the KKT matrix; errors are reported at time `t`.
    pub(crate) fn new(
        mut m: SMatrix<T, NQ, NQ>,
        phi_q: &SMatrix<T, NC, NQ>,
        max_condition: T,
        t: T,
    ) -> Result<Self, Error> {
        if let Err((pivot, value)) = cholesky(&mut m) {
            return Err(Error::new(
                ErrorKind::MassMatrixNotPositiveDefinite {
                    pivot,
                    value: value.into(),
                },
                t,
            ));
        }
        let mut y = phi_q.transpose();
        solve_lower(&m, &mut y);
        let s_mat = y.transpose() * y;
        match SpdSolver::factor(&s_mat, max_condition) {
            Ok((s, condition)) => Ok(Kkt {
                l: m,
                y,
                s,
                condition,
            }),
            Err(condition) => Err(Error::new(
                ErrorKind::SingularConstraintJacobian {
                    condition: condition.into(),
                    limit: max_condition.into(),
                },
                t,
            )),
        }
    }

    /// `sqrt(v^T M^-1 v)`.
    pub(crate) fn inverse_mass_norm(&self, v: &SVector<T, NQ>) -> T {
        let mut z = *v;
        solve_lower(&self.l, &mut z);
        z.norm()
    }

    /// Solves `M x - Phi_q^T mu = f`, `Phi_q x = c`.
    pub(crate) fn solve(
        &self,
        f: &SVector<T, NQ>,
        c: &SVector<T, NC>,
    ) -> (SVector<T, NQ>, SVector<T, NC>) {
        let mut z = *f;
        solve_lower(&self.l, &mut z);
        let mut mu = c - self.y.transpose() * z;
        self.s.solve(&mut mu);
        let mut x = z + self.y * mu;
        solve_lower_transpose(&self.l, &mut x);
        (x, mu)
    }
}

/// Solves the constrained equations of motion for the accelerations and
/// constraint forces at `(q, qd, t)` with actuator input `tau`.
///
/// The inputs are assumed finite (the integrators check them); model outputs
/// are checked. Errors: [`ErrorKind::NonFiniteModelOutput`],
/// [`ErrorKind::MassMatrixNotPositiveDefinite`],
/// [`ErrorKind::SingularConstraintJacobian`], [`ErrorKind::NonFiniteResult`].
pub fn accelerations<M, T: Scalar, const NQ: usize, const NC: usize, const NU: usize>(
    model: &M,
    config: &DynamicsConfig<T>,
    q: &SVector<T, NQ>,
    qd: &SVector<T, NQ>,
    t: T,
    tau: &SVector<T, NU>,
) -> Result<Accelerations<NQ, NC, T>, Error>
where
    M: Model<NQ, NC, NU, T>,
{
    let eval::Terms { m, h, phi_q, gamma } = eval::dynamics_terms(model, q, qd, t)?;
    let b = eval::actuator_map(model, t)?;
    let f = b * tau - h;
    let c = stabilised_rhs(model, &config.baumgarte, q, qd, t, &phi_q, gamma)?;
    let kkt = Kkt::new(m, &phi_q, config.max_condition, t)?;
    let (qdd, lambda) = kkt.solve(&f, &c);
    eval::check_result(&qdd, Quantity::Acceleration, t)?;
    eval::check_result(&lambda, Quantity::ConstraintForces, t)?;
    Ok(Accelerations {
        qdd,
        lambda,
        condition: kkt.condition,
    })
}

/// `gamma - 2 alpha (Phi_q qd + Phi_t) - beta^2 Phi` from the given `Phi_q`
/// and `gamma` (zero-sized when `NC == 0`).
pub(crate) fn stabilised_rhs<M, T: Scalar, const NQ: usize, const NC: usize, const NU: usize>(
    model: &M,
    gains: &Baumgarte,
    q: &SVector<T, NQ>,
    qd: &SVector<T, NQ>,
    t: T,
    phi_q: &SMatrix<T, NC, NQ>,
    gamma: SVector<T, NC>,
) -> Result<SVector<T, NC>, Error>
where
    M: Model<NQ, NC, NU, T>,
{
    if NC == 0 {
        return Ok(SVector::zeros());
    }
    let mut c = gamma;
    if gains.alpha != 0.0 || gains.beta != 0.0 {
        let phi = eval::constraints(model, q, t)?;
        let phi_t = eval::constraint_time_derivative(model, q, t)?;
        let phi_dot = phi_q * qd + phi_t;
        c -= phi_dot * T::of(2.0 * gains.alpha) + phi * T::of(gains.beta * gains.beta);
    }
    Ok(c)
}
