//! Coordinate projection of `q` and `qd` back onto the constraint manifold.
//!
//! Positions: Newton iterations `q <- q + dq` with the mass-weighted
//! minimum-norm correction `min |dq|_M  s.t.  Phi_q dq = -Phi` (metric `M`
//! evaluated once at the starting point). Velocities: the `M`-orthogonal
//! projection onto `Phi_q qd + Phi_t = 0` at the corrected positions, which
//! removes the least kinetic energy.

use crate::dynamics::Kkt;
use crate::error::{Error, ErrorKind, Quantity, Stage};
use crate::eval;
use crate::model::{Equations, Sizes};
use crate::scalar::Scalar;
use crate::state::{inf_norm, Drift, StateOf};
use nalgebra::allocator::Allocator;
use nalgebra::{DefaultAllocator, Dim, OVector, U1};

/// Configuration of [`project`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProjectionConfig<T: Scalar = f64> {
    /// Target `max |Phi|` after projection (model units).
    pub position_tolerance: T,
    /// Velocity residual `max |Phi_q qd + Phi_t|` above which velocities are projected.
    pub velocity_tolerance: T,
    /// Cap on Newton iterations for the position projection.
    pub max_iterations: u32,
    /// Largest accepted condition estimate of `Phi_q M^-1 Phi_q^T`.
    pub max_condition: T,
}

impl<T: Scalar> Default for ProjectionConfig<T> {
    fn default() -> Self {
        ProjectionConfig {
            position_tolerance: T::POSITION_TOLERANCE,
            velocity_tolerance: T::POSITION_TOLERANCE,
            max_iterations: 8,
            max_condition: T::KKT_MAX_CONDITION,
        }
    }
}

/// What a projection did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ProjectionReport<T: Scalar = f64> {
    /// Newton iterations of the position projection (0 if already within tolerance).
    pub iterations: u32,
    /// True if the velocities were projected.
    pub velocity_projected: bool,
    /// Drift before projection.
    pub before: Drift<T>,
    /// Drift after projection.
    pub after: Drift<T>,
}

/// Projects `state.q` and `state.qd` onto the constraint manifold at
/// `state.t`. On error `state` is unchanged.
///
/// Errors: non-finite model outputs, [`ErrorKind::MassMatrixNotPositiveDefinite`],
/// [`ErrorKind::SingularConstraintJacobian`], [`ErrorKind::NewtonNotConverged`]
/// (residual = `max |Phi|` after the last iteration, tolerance =
/// `position_tolerance`). Every error names the projection and its tolerance
/// in [`Error::stage`] ([`Stage::PositionProjection`] or
/// [`Stage::VelocityProjection`]).
pub fn project<M, T: Scalar, Q: Dim, C: Dim, U: Dim>(
    model: &M,
    state: &mut StateOf<T, Q>,
    config: &ProjectionConfig<T>,
) -> Result<ProjectionReport<T>, Error>
where
    M: Equations<Q, C, U, T> + ?Sized,
    DefaultAllocator: Sizes<Q, C, U>,
{
    project_with(model, state, config, T::zero(), false)
}

/// [`project`], optionally (`velocity_from_position_dt > 0`) adding the
/// position correction divided by that step to the velocities before the
/// velocity projection (SHAKE-style consistency for schemes with
/// `q_{n+1} = q_n + dt qd_{n+1}`); `after_step` marks the errors' stage as
/// run by an integrator after its step.
pub(crate) fn project_with<M, T: Scalar, Q: Dim, C: Dim, U: Dim>(
    model: &M,
    state: &mut StateOf<T, Q>,
    config: &ProjectionConfig<T>,
    velocity_from_position_dt: T,
    after_step: bool,
) -> Result<ProjectionReport<T>, Error>
where
    M: Equations<Q, C, U, T> + ?Sized,
    DefaultAllocator: Sizes<Q, C, U>,
{
    if model.sizes().1.value() == 0 {
        return Ok(ProjectionReport::default());
    }
    state.check_finite()?;
    project_finite(model, state, config, velocity_from_position_dt, after_step)
}

/// [`project_with`] on a finite state: the solves, with their matrices on
/// the stack (hundreds of KiB for the padded models of the root crate).
///
/// Kept out of line so that no cheap early return precedes the large frame.
/// With such a return (the finiteness check above) LLVM's x86-64 backend
/// may shrink-wrap the prologue, moving it after that check; the prologue's
/// inline stack probe loop uses `r11` as its scratch register without
/// checking that it is free there, and when the register allocator had
/// kept a value in `r11` across the check (here the address of
/// `state.qd`), the probe overwrote it: the velocity projection then read
/// `qd` from probed stack memory. Seen with rustc 1.95 on the padded
/// (64, 24, 8) model: a velocity drift of 0.68 before projection instead
/// of 1e-6, torques off by 1.7e-5 N m, vanishing with `-C codegen-units=1`
/// or any change of the inlining (the same class of bug as LLVM's RISC-V
/// issue 198699). Here the frame is set up on entry, before any branch.
#[inline(never)]
fn project_finite<M, T: Scalar, Q: Dim, C: Dim, U: Dim>(
    model: &M,
    state: &mut StateOf<T, Q>,
    config: &ProjectionConfig<T>,
    velocity_from_position_dt: T,
    after_step: bool,
) -> Result<ProjectionReport<T>, Error>
where
    M: Equations<Q, C, U, T> + ?Sized,
    DefaultAllocator: Sizes<Q, C, U>,
{
    let positions = project_positions(model, state, config).map_err(|e| {
        e.in_stage(Stage::PositionProjection {
            tolerance: config.position_tolerance.into(),
            after_step,
        })
    })?;
    project_velocities(model, state, config, velocity_from_position_dt, positions).map_err(|e| {
        e.in_stage(Stage::VelocityProjection {
            tolerance: config.velocity_tolerance.into(),
            after_step,
        })
    })
}

/// Result of the position part of [`project_with`].
struct Positions<T: Scalar, Q: Dim, C: Dim>
where
    DefaultAllocator: Allocator<Q> + Allocator<C>,
{
    /// Projected positions.
    q: OVector<T, Q>,
    /// Constraint residuals there.
    phi: OVector<T, C>,
    /// Newton iterations.
    iterations: u32,
    /// Drift before (the velocity part still 0).
    before: Drift<T>,
}

/// The position part of [`project_with`].
fn project_positions<M, T: Scalar, Q: Dim, C: Dim, U: Dim>(
    model: &M,
    state: &StateOf<T, Q>,
    config: &ProjectionConfig<T>,
) -> Result<Positions<T, Q, C>, Error>
where
    M: Equations<Q, C, U, T> + ?Sized,
    DefaultAllocator: Sizes<Q, C, U>,
{
    let t = state.t;
    let mut q = state.q.clone();
    let m0 = eval::mass(model, &q, t)?;
    let zero_f = OVector::<T, Q>::zeros_generic(q.shape_generic().0, U1);
    let mut iterations = 0u32;
    let mut phi = eval::constraints(model, &q, t)?;
    let before = Drift {
        position: inf_norm(&phi),
        velocity: T::zero(),
    };
    loop {
        let res = inf_norm(&phi);
        if res <= config.position_tolerance {
            break;
        }
        if iterations >= config.max_iterations {
            return Err(Error::new(
                ErrorKind::NewtonNotConverged {
                    iterations,
                    residual: res.into(),
                    tolerance: config.position_tolerance.into(),
                },
                t,
            ));
        }
        let phi_q = eval::constraint_jacobian(model, &q, t)?;
        let kkt = Kkt::new(m0.clone(), &phi_q, config.max_condition, t)?;
        let (dq, _) = kkt.solve(&zero_f, &(-phi));
        q += dq;
        eval::check_result(&q, Quantity::Position, t)?;
        iterations += 1;
        phi = eval::constraints(model, &q, t)?;
    }
    Ok(Positions {
        q,
        phi,
        iterations,
        before,
    })
}

/// The velocity part of [`project_with`], at the projected positions `q`;
/// writes `state` only on success.
fn project_velocities<M, T: Scalar, Q: Dim, C: Dim, U: Dim>(
    model: &M,
    state: &mut StateOf<T, Q>,
    config: &ProjectionConfig<T>,
    velocity_from_position_dt: T,
    positions: Positions<T, Q, C>,
) -> Result<ProjectionReport<T>, Error>
where
    M: Equations<Q, C, U, T> + ?Sized,
    DefaultAllocator: Sizes<Q, C, U>,
{
    let Positions {
        q,
        phi,
        iterations,
        mut before,
    } = positions;
    let t = state.t;
    let zero_f = OVector::<T, Q>::zeros_generic(q.shape_generic().0, U1);
    let phi_q = eval::constraint_jacobian(model, &q, t)?;
    let phi_t = eval::constraint_time_derivative(model, &q, t)?;
    let mut qd = state.qd.clone();
    {
        let phi_q0 = eval::constraint_jacobian(model, &state.q, t)?;
        let phi_t0 = eval::constraint_time_derivative(model, &state.q, t)?;
        before.velocity = inf_norm(&(phi_q0 * &state.qd + phi_t0));
    }
    if velocity_from_position_dt > T::zero() {
        qd += (&q - &state.q) / velocity_from_position_dt;
    }
    let vres = &phi_q * &qd + &phi_t;
    let mut velocity_projected = false;
    if inf_norm(&vres) > config.velocity_tolerance {
        let m = eval::mass(model, &q, t)?;
        let kkt = Kkt::new(m, &phi_q, config.max_condition, t)?;
        let (dv, _) = kkt.solve(&zero_f, &(-vres));
        qd += dv;
        eval::check_result(&qd, Quantity::Velocity, t)?;
        velocity_projected = true;
    }
    let after = Drift {
        position: inf_norm(&phi),
        velocity: inf_norm(&(phi_q * &qd + phi_t)),
    };
    state.q = q;
    state.qd = qd;
    Ok(ProjectionReport {
        iterations,
        velocity_projected,
        before,
        after,
    })
}
