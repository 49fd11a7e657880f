//! Error values returned by every solver in this crate.
//!
//! Errors are small `Copy` values: an [`ErrorKind`] saying what went wrong,
//! with the numbers that show it, and the simulation time at which it
//! happened. No solver panics on bad numbers; every failure is one of these.

use core::fmt;

/// Which quantity an error refers to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Quantity {
    /// Generalized coordinates `q`.
    Position,
    /// Generalized velocities `qd`.
    Velocity,
    /// Generalized accelerations `qdd`.
    Acceleration,
    /// Time `t`.
    Time,
    /// Actuator inputs `tau`.
    Input,
    /// Prescribed coordinate values (inverse dynamics).
    PrescribedPosition,
    /// Prescribed coordinate velocities (inverse dynamics).
    PrescribedVelocity,
    /// Prescribed coordinate accelerations (inverse dynamics).
    PrescribedAcceleration,
    /// Mass matrix `M` returned by the model.
    MassMatrix,
    /// Bias forces `h` returned by the model.
    Bias,
    /// Inverse dynamics `M qdd + h` returned by the model.
    InverseDynamics,
    /// Analytic bias Jacobians returned by the model.
    BiasJacobian,
    /// Inverse-dynamics derivatives returned by the model.
    InverseDynamicsDerivatives,
    /// Constraint residuals `Phi` returned by the model.
    Constraints,
    /// Constraint Jacobian `Phi_q` returned by the model.
    ConstraintJacobian,
    /// Explicit time derivative `Phi_t` returned by the model.
    ConstraintTimeDerivative,
    /// Acceleration right-hand side `gamma` returned by the model.
    ConstraintRhs,
    /// Actuator map `B` returned by the model.
    ActuatorMap,
    /// Constraint forces (Lagrange multipliers) `lambda`.
    ConstraintForces,
    /// Prescribed outputs of a servo: `y`, its rates, `Y_q` or the convective term.
    Outputs,
}

impl Quantity {
    /// Short human-readable name.
    pub const fn name(self) -> &'static str {
        match self {
            Quantity::Position => "position q",
            Quantity::Velocity => "velocity qd",
            Quantity::Acceleration => "acceleration qdd",
            Quantity::Time => "time t",
            Quantity::Input => "actuator input tau",
            Quantity::PrescribedPosition => "prescribed position",
            Quantity::PrescribedVelocity => "prescribed velocity",
            Quantity::PrescribedAcceleration => "prescribed acceleration",
            Quantity::MassMatrix => "mass matrix M",
            Quantity::Bias => "bias forces h",
            Quantity::InverseDynamics => "inverse dynamics M qdd + h",
            Quantity::BiasJacobian => "bias Jacobians",
            Quantity::InverseDynamicsDerivatives => "inverse-dynamics derivatives",
            Quantity::Constraints => "constraints Phi",
            Quantity::ConstraintJacobian => "constraint Jacobian Phi_q",
            Quantity::ConstraintTimeDerivative => "constraint time derivative Phi_t",
            Quantity::ConstraintRhs => "constraint acceleration rhs gamma",
            Quantity::ActuatorMap => "actuator map B",
            Quantity::ConstraintForces => "constraint forces lambda",
            Quantity::Outputs => "servo outputs y, their rates, Y_q or the convective term",
        }
    }
}

/// What went wrong.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ErrorKind {
    /// A component of the state passed in (`q`, `qd` or `t`) is NaN or infinite.
    NonFiniteState {
        /// [`Quantity::Position`], [`Quantity::Velocity`] or [`Quantity::Time`].
        quantity: Quantity,
        /// Index of the first offending component.
        index: usize,
    },
    /// A caller-supplied input (actuator input, prescribed motion) is NaN or infinite.
    NonFiniteInput {
        /// Which input.
        quantity: Quantity,
        /// Index of the first offending component.
        index: usize,
    },
    /// The model returned a NaN or infinite value.
    NonFiniteModelOutput {
        /// Which model function.
        quantity: Quantity,
    },
    /// The solve completed on finite data but produced NaN or infinity
    /// (overflow), typically because the step was far too large.
    NonFiniteResult {
        /// Which result.
        quantity: Quantity,
    },
    /// The mass matrix is not (numerically) positive definite: the Cholesky
    /// pivot at `pivot` is `value <= 0`.
    MassMatrixNotPositiveDefinite {
        /// Index of the failing pivot.
        pivot: usize,
        /// The pivot value (diagonal of the partially factored matrix).
        value: f64,
    },
    /// The constraint Jacobian is singular or too ill-conditioned for the
    /// operation (rank deficient `Phi_q M^-1 Phi_q^T`, or the Jacobian of the
    /// unprescribed coordinates in inverse dynamics).
    SingularConstraintJacobian {
        /// Condition estimate (`f64::INFINITY` when exactly singular).
        condition: f64,
        /// The limit it exceeded.
        limit: f64,
    },
    /// The Newton iteration matrix of the implicit integrator is singular.
    SingularIterationMatrix {
        /// Condition estimate (`f64::INFINITY` when exactly singular).
        condition: f64,
    },
    /// The actuators cannot balance the required forces: `[Phi_q^T B]` does not
    /// span the space it must (actuation singularity of a parallel mechanism,
    /// or a zero actuator map).
    SingularActuation {
        /// Condition estimate of the actuation matrix projected onto the
        /// free motion directions.
        condition: f64,
        /// The limit it exceeded.
        limit: f64,
    },
    /// The prescribed outputs of a servo do not determine the actuator
    /// inputs at this state: the servo matrix `Y_q P B` (the outputs'
    /// acceleration per unit input along the motions the constraints admit,
    /// see [`crate::control`]) is singular or too ill-conditioned.
    SingularServo {
        /// Servo condition `1 / sigma_min` of the servo matrix normalised by
        /// the inverse-mass norms of the output gradients and actuator
        /// columns (`f64::INFINITY` when exactly singular).
        condition: f64,
        /// The limit it exceeded.
        limit: f64,
    },
    /// A Newton iteration (of an implicit step, a position projection or
    /// inverse kinematics) did not reach its tolerance within its iteration
    /// cap. From a projection the error's [`Error::stage`] names it.
    NewtonNotConverged {
        /// Iterations performed.
        iterations: u32,
        /// Last residual / correction norm, relative to the tolerance where the
        /// solver uses a scaled norm (see the solver's docs).
        residual: f64,
        /// The tolerance `residual` had to reach (1 for a scaled norm).
        tolerance: f64,
    },
    /// The fixed-point stage iteration of [`crate::GaussLegendre4`] failed:
    /// its increments grew (or a stage value became non-finite) or it used
    /// its sweep cap. The iteration contracts only for steps well below the
    /// period of the fastest mode (`dt * omega` below about
    /// [`GAUSS_LEGENDRE_CONTRACTION_LIMIT`] on an undamped mode).
    StageIterationFailed {
        /// The step size.
        dt: f64,
        /// Sweeps performed.
        sweeps: u32,
        /// Last scaled stage increment (1 = at tolerance; infinite when a
        /// stage value became non-finite).
        increment: f64,
        /// True when the increments grew (divergence), false when the sweep
        /// cap ran out on a slowly contracting iteration.
        diverged: bool,
        /// The spectral radius `rho(J)` (rad/s) of the model linearised at
        /// the state, from the power iteration of [`crate::Rk4`]'s refusal,
        /// so that the message names the fastest mode and a step that lets
        /// the iteration contract, or, where no mode comes near the
        /// contraction limit, abrupt forces; `None` when it could not be
        /// measured.
        rate: Option<f64>,
    },
    /// An iterative dense decomposition (Jacobi SVD) did not converge within
    /// its sweep cap.
    DecompositionNotConverged {
        /// Sweeps performed.
        sweeps: u32,
    },
    /// The step size is not a finite positive number.
    InvalidStepSize {
        /// The offending step size.
        dt: f64,
    },
    /// The step size exceeds what the integrator accepts: either the configured
    /// `max_step`, or (explicit schemes) the estimated stability limit
    /// `dt * spectral_radius`.
    StepTooLarge {
        /// The offending step size.
        dt: f64,
        /// The measured quantity that exceeded its limit: `dt` itself for the
        /// `max_step` check, the estimate of `dt * rho(J)` for the stability check.
        value: f64,
        /// The limit.
        limit: f64,
        /// Stability check only: the estimated spectral radius `rho(J)` in
        /// 1/s, i.e. the angular frequency (rad/s) of the fastest
        /// oscillation (or the fastest decay rate), so that the message can
        /// name the offending mode and the largest step that could be stable
        /// (`limit / rate`). Within a step (adaptive RK4) it is `value / dt`
        /// from the stages, which see only the modes the state excites;
        /// [`crate::Rk4`] and [`crate::SemiImplicitEuler`] take the larger
        /// of it and a bounded power iteration's on the model linearised at
        /// the state, which finds the fastest mode even when it is not
        /// excited, and report `value = dt * rate` from that one number.
        /// `None` for the `max_step` check.
        rate: Option<f64>,
    },
    /// An explicit scheme's stability estimate refused the step, but the
    /// model linearised at the state has no mode near the rate its stages
    /// saw (below 1/[`crate::ABRUPT_RATIO`] of it): the forces change
    /// abruptly within the step, not at a fast mode. A switch (`sign`,
    /// `step`, `abs`, `min`, `max` of a coordinate or rate, such as Coulomb
    /// friction near rest) or a sharply stiffening force.
    AbruptForces {
        /// The offending step size.
        dt: f64,
        /// The stages' estimate of `dt * rho(J)`.
        value: f64,
        /// The stability limit.
        limit: f64,
        /// The fastest mode of the model linearised at the state, rad/s.
        linear_rate: f64,
    },
    /// The adaptive integrator would need a step below its minimum step size.
    StepSizeUnderflow {
        /// The step size it would need.
        dt: f64,
        /// The configured minimum.
        min_step: f64,
    },
    /// The adaptive integrator rejected too many trial steps in one call.
    TooManyRejections {
        /// Trial steps rejected.
        rejections: u32,
        /// Scaled error norm of the last trial (1 = at tolerance).
        error_norm: f64,
    },
    /// An adaptive integrator asked to advance by a fixed interval used up
    /// its substep budget before reaching the end of it.
    SubstepLimit {
        /// Accepted substeps taken.
        substeps: u32,
        /// Part of the interval covered before giving up.
        reached: f64,
    },
    /// An index in a solver's set-up (a prescribed coordinate, the
    /// coordinate an actuator's feedback acts on) is out of range or repeated.
    InvalidIndex {
        /// What the indices select.
        what: &'static str,
        /// Position of the offending entry in the caller's list.
        entry: usize,
        /// The offending index.
        index: usize,
        /// Number of valid indices (`0..len`); an index below it is a repeat
        /// of an earlier entry.
        len: usize,
    },
    /// A set-up parameter (e.g. a feedback gain) is outside its valid range.
    InvalidParameter {
        /// Which parameter, with its valid range.
        what: &'static str,
        /// Index of the offending entry.
        index: usize,
        /// The offending value.
        value: f64,
    },
    /// Invalid solver set-up (e.g. too few constraints to determine the free
    /// coordinates, or a servo with more or fewer prescribed outputs than
    /// actuator inputs).
    InvalidConfiguration {
        /// What is wrong.
        reason: &'static str,
    },
}

/// Where inside a solver an error happened, when that is not the solver's
/// main iteration: it names the stage and its tolerance in the message.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Stage {
    /// Position projection onto `Phi = 0` ([`crate::project`], or after an
    /// integration step when [`crate::StepSettings::projection`] is set).
    PositionProjection {
        /// Target `max |Phi|`.
        tolerance: f64,
        /// True when run by an integrator after its step.
        after_step: bool,
    },
    /// Velocity projection onto `Phi_q qd + Phi_t = 0`.
    VelocityProjection {
        /// Velocity residual above which velocities are projected.
        tolerance: f64,
        /// True when run by an integrator after its step.
        after_step: bool,
    },
    /// A model evaluation or acceleration solve inside the stage iteration
    /// of [`crate::GaussLegendre4`].
    StageIteration {
        /// The step size.
        dt: f64,
        /// The sweep (from 1; 0 for the start-of-step evaluation).
        sweep: u32,
    },
}

impl fmt::Display for Stage {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let when = |after: bool| if after { " after the step" } else { "" };
        match *self {
            Stage::PositionProjection {
                tolerance,
                after_step,
            } => write!(
                f,
                "position projection{} (tolerance max |Phi| <= {:e})",
                when(after_step),
                tolerance
            ),
            Stage::VelocityProjection {
                tolerance,
                after_step,
            } => write!(
                f,
                "velocity projection{} (tolerance max |Phi_q qd + Phi_t| <= {:e})",
                when(after_step),
                tolerance
            ),
            Stage::StageIteration { dt, sweep } => write!(
                f,
                "Gauss-Legendre stage iteration at step size {:e}, sweep {}",
                dt, sweep
            ),
        }
    }
}

/// `dt * omega` below which the fixed-point stage iteration of
/// [`crate::GaussLegendre4`] contracts on an undamped linear oscillator of
/// circular frequency `omega`: the iteration matrix is `-(omega dt)^2 A^2`
/// with `A` the Butcher matrix, whose eigenvalues have `|lambda|^2 = 1/12`,
/// so the bound is `sqrt(12)`.
pub const GAUSS_LEGENDRE_CONTRACTION_LIMIT: f64 = 3.464_101_615_137_754_6;

/// A solver error: what went wrong and at which simulation time.
///
/// `t` is the time at which the failure was detected: the start of the step
/// for checks of the state, the step size and the nonlinear iterations; the
/// stage time inside the step for failures of a model evaluation or of an
/// acceleration solve; the call's time for inverse dynamics. After a failed
/// step the state still holds the start-of-step values.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Error {
    /// What went wrong.
    pub kind: ErrorKind,
    /// Simulation time at which it happened.
    pub t: f64,
    /// The stage it happened in, where that is not the solver's main
    /// iteration (a projection, a Gauss–Legendre stage sweep).
    pub stage: Option<Stage>,
}

impl Error {
    /// Creates an error at time `t` (`f64` or `f32`).
    pub fn new(kind: ErrorKind, t: impl Into<f64>) -> Self {
        Error {
            kind,
            t: t.into(),
            stage: None,
        }
    }

    /// The same error, marked as having happened in `stage` (unless it
    /// already names a stage).
    pub const fn in_stage(mut self, stage: Stage) -> Self {
        if self.stage.is_none() {
            self.stage = Some(stage);
        }
        self
    }
}

/// [`ErrorKind::InvalidConfiguration`] at time 0 (a set-up error).
pub(crate) fn invalid_configuration(reason: &'static str) -> Error {
    Error::new(ErrorKind::InvalidConfiguration { reason }, 0.0)
}

/// Checks that every entry of `indices` is below `len` and, if `distinct`,
/// that none repeats an earlier one ([`ErrorKind::InvalidIndex`] naming the
/// first offender).
pub(crate) fn check_indices(
    what: &'static str,
    indices: &[usize],
    len: usize,
    distinct: bool,
) -> Result<(), Error> {
    for (entry, &index) in indices.iter().enumerate() {
        if index >= len || (distinct && indices[..entry].contains(&index)) {
            return Err(Error::new(
                ErrorKind::InvalidIndex {
                    what,
                    entry,
                    index,
                    len,
                },
                0.0,
            ));
        }
    }
    Ok(())
}

/// What a refusal no mode explains means, and what to do.
const ABRUPT: &str = "the forces change abruptly within the step (a switch such as sign, step, \
                      abs, min or max of a coordinate or rate, for example Coulomb friction near \
                      rest, or a sharply stiffening force), which smaller steps do not remove; \
                      smooth the switch (docs/scene-format.md, Switches)";

impl fmt::Display for ErrorKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            ErrorKind::NonFiniteState { quantity, index } => {
                write!(f, "non-finite state: {}[{}]", quantity.name(), index)
            }
            ErrorKind::NonFiniteInput { quantity, index } => {
                write!(f, "non-finite input: {}[{}]", quantity.name(), index)
            }
            ErrorKind::NonFiniteModelOutput { quantity } => {
                write!(f, "model returned a non-finite {}", quantity.name())
            }
            ErrorKind::NonFiniteResult { quantity } => {
                write!(f, "solve produced a non-finite {} (overflow; step too large?)", quantity.name())
            }
            ErrorKind::MassMatrixNotPositiveDefinite { pivot, value } => write!(
                f,
                "mass matrix not positive definite: Cholesky pivot {} = {:e}",
                pivot, value
            ),
            ErrorKind::SingularConstraintJacobian { condition, limit } => write!(
                f,
                "singular or ill-conditioned constraint Jacobian: condition estimate {:e} > limit {:e}",
                condition, limit
            ),
            ErrorKind::SingularIterationMatrix { condition } => write!(
                f,
                "singular Newton iteration matrix: condition estimate {:e}",
                condition
            ),
            ErrorKind::SingularActuation { condition, limit } => write!(
                f,
                "actuation singular: condition estimate {:e} > limit {:e}",
                condition, limit
            ),
            ErrorKind::SingularServo { condition, limit } => write!(
                f,
                "the prescribed outputs do not determine the actuator inputs here: servo matrix \
                 Y_q P B singular or ill-conditioned (condition estimate {:e} > limit {:e})",
                condition, limit
            ),
            ErrorKind::NewtonNotConverged {
                iterations,
                residual,
                tolerance,
            } => write!(
                f,
                "Newton iteration did not converge in {} iterations (residual {:e} > tolerance {:e})",
                iterations, residual, tolerance
            ),
            ErrorKind::StageIterationFailed {
                dt,
                sweeps,
                increment,
                diverged: true,
                rate,
            } => {
                write!(
                    f,
                    "Gauss-Legendre stage iteration diverged at step size {:e} (scaled stage \
                     increment {:.3e} after {} sweeps, growing): the fixed-point iteration \
                     contracts only for dt * omega below about {:.2}",
                    dt, increment, sweeps, GAUSS_LEGENDRE_CONTRACTION_LIMIT
                )?;
                match rate {
                    // No mode of the linearised model comes near the limit
                    // at this step: not a stiffness the step can resolve.
                    Some(rate)
                        if dt * rate * crate::ABRUPT_RATIO < GAUSS_LEGENDRE_CONTRACTION_LIMIT =>
                    {
                        write!(
                            f,
                            ", but the model linearised at the state has no mode near that (the \
                             fastest at {rate:.3e} rad/s, dt * omega = {:.3e}): {ABRUPT}",
                            dt * rate
                        )
                    }
                    Some(rate) => write!(
                        f,
                        "; the fastest mode is at about {:.3e} rad/s ({:.3e} Hz), so steps must \
                         be below {:.3e} s for it to contract and below about {:.3e} s for it to \
                         converge quickly",
                        rate,
                        rate / (2.0 * core::f64::consts::PI),
                        GAUSS_LEGENDRE_CONTRACTION_LIMIT / rate,
                        0.5 * GAUSS_LEGENDRE_CONTRACTION_LIMIT / rate
                    ),
                    None => write!(f, "; use a smaller step"),
                }
            }
            ErrorKind::StageIterationFailed {
                dt,
                sweeps,
                increment,
                diverged: false,
                rate,
            } => {
                write!(
                    f,
                    "Gauss-Legendre stage iteration did not converge in {} sweeps at step size \
                     {:e} (scaled stage increment {:.3e} > tolerance 1)",
                    sweeps, dt, increment
                )?;
                match rate {
                    Some(rate)
                        if dt * rate * crate::ABRUPT_RATIO < GAUSS_LEGENDRE_CONTRACTION_LIMIT =>
                    {
                        write!(
                            f,
                            ", although the model linearised at the state has no mode that \
                             keeps it from contracting (the fastest at {rate:.3e} rad/s, dt * \
                             omega = {:.3e}): {ABRUPT}",
                            dt * rate
                        )
                    }
                    _ => write!(f, ": use a smaller step or allow more sweeps"),
                }
            }
            ErrorKind::DecompositionNotConverged { sweeps } => {
                write!(f, "Jacobi SVD did not converge in {} sweeps", sweeps)
            }
            ErrorKind::InvalidStepSize { dt } => write!(f, "invalid step size {:e}", dt),
            ErrorKind::StepTooLarge {
                dt,
                value,
                limit,
                rate: Some(rate),
            } => write!(
                f,
                "step size {:e} too large for the explicit scheme: estimated dt * rho(J) = {:.3e} \
                 exceeds its stability limit {:e}; the fastest mode is at about {:.3e} rad/s \
                 ({:.3e} Hz), so stable steps are below {:.3e} s",
                dt,
                value,
                limit,
                rate,
                rate / (2.0 * core::f64::consts::PI),
                limit / rate
            ),
            ErrorKind::StepTooLarge {
                dt,
                value,
                limit,
                rate: None,
            } => write!(
                f,
                "step size {:e} too large: {:e} exceeds limit {:e}",
                dt, value, limit
            ),
            ErrorKind::AbruptForces {
                dt,
                value,
                limit,
                linear_rate,
            } => write!(
                f,
                "step size {:e} refused by the explicit scheme: its stages see dt * rho(J) = \
                 {:.3e}, beyond its stability limit {:e}, but the model linearised at the state \
                 has no mode faster than {:.3e} rad/s: {ABRUPT}",
                dt, value, limit, linear_rate
            ),
            ErrorKind::StepSizeUnderflow { dt, min_step } => write!(
                f,
                "adaptive step size {:e} fell below the minimum {:e}",
                dt, min_step
            ),
            ErrorKind::TooManyRejections { rejections, error_norm } => write!(
                f,
                "adaptive step rejected {} times (last scaled error {:e})",
                rejections, error_norm
            ),
            ErrorKind::SubstepLimit { substeps, reached } => write!(
                f,
                "adaptive integration used its {} substeps after covering {:e} of the interval",
                substeps, reached
            ),
            ErrorKind::InvalidIndex {
                what,
                entry,
                index,
                len,
            } => {
                if index >= len {
                    write!(
                        f,
                        "invalid {} index: entry {} is {}, outside 0..{}",
                        what, entry, index, len
                    )
                } else {
                    write!(
                        f,
                        "invalid {} index: entry {} repeats index {}",
                        what, entry, index
                    )
                }
            }
            ErrorKind::InvalidParameter { what, index, value } => {
                write!(f, "invalid {} [{}] = {}", what, index, value)
            }
            ErrorKind::InvalidConfiguration { reason } => write!(f, "invalid configuration: {}", reason),
        }
    }
}

/// A time (or any number) as messages print it: in plain decimal between
/// `1e-4` and `1e9` (and zero), in exponent form elsewhere, so that a time
/// of `1e300` is 6 characters, not 301 digits.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Time(pub f64);

impl fmt::Display for Time {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let size = self.0.abs();
        if size == 0.0 || (1e-4..1e9).contains(&size) || !size.is_finite() {
            write!(f, "{}", self.0)
        } else {
            write!(f, "{:e}", self.0)
        }
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let t = Time(self.t);
        match self.stage {
            Some(stage) => write!(f, "at t = {} s: {}: {}", t, stage, self.kind),
            None => write!(f, "at t = {} s: {}", t, self.kind),
        }
    }
}

impl core::error::Error for Error {}
