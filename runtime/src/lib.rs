//! flexdyn runtime: solvers for the equations of motion that `flexdyn-codegen`
//! generates. `#![no_std]`, allocation-free, panic-free on bad numbers.
//!
//! * [`Model`]: the interface generated code implements, in `f64` or `f32`
//!   (every solver is generic over the [`Scalar`] type, `f64` by default).
//! * [`Equations`]: the same equations over nalgebra dimensions, fixed
//!   (`Const<N>`: every [`Model`]) or known only at run time (`Dyn`, with
//!   nalgebra's `alloc` feature): the forward-dynamics solvers, projection,
//!   integrators and [`control::Feedback`] take it, written once for both.
//! * [`accelerations`]: constrained forward dynamics (KKT system by a Schur
//!   complement on the stack, Baumgarte stabilisation).
//! * [`project`]: coordinate projection onto the constraint manifold.
//! * [`integrate`]: RK4 (fixed and adaptive), semi-implicit Euler,
//!   Gauss–Legendre (order 4), generalized-α; all in place, state unchanged on error.
//! * [`InverseDynamics`]: prescribed motion to actuator inputs and
//!   constraint forces, one bounded call per control tick.
//! * [`control`]: state feedback, joint PD and servo constraints (prescribed
//!   outputs, inputs chosen to follow them, the other coordinates
//!   integrated) for any scene, as wrapper models.
//!
//! Every fallible call returns [`Error`], a small `Copy` value saying what went
//! wrong ([`ErrorKind`]) and at which time. Loops are bounded by iteration
//! caps in the configuration structs; at fixed sizes all storage is
//! fixed-size on the stack.
#![no_std]
// Unsafe code only in `math::pair` (SSE2 intrinsics, in every x86-64
// target), allowed there and nowhere else.
#![deny(unsafe_code)]
#![deny(missing_docs)]
// `!(x <= limit)` is used deliberately so that NaN fails the check.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
#![cfg_attr(
    not(test),
    deny(clippy::unwrap_used, clippy::expect_used, clippy::panic)
)]

pub mod control;
mod derivatives;
mod dynamics;
mod error;
mod eval;
mod input;
pub mod integrate;
mod inverse_dynamics;
mod linalg;
pub mod math;
mod model;
mod projection;
mod scalar;
mod state;

pub use derivatives::{forward_dynamics_derivatives, ForwardDerivativesOf};
pub use dynamics::{accelerations, Accelerations, AccelerationsOf, Baumgarte, DynamicsConfig};
pub use error::{Error, ErrorKind, Quantity, Stage, Time, GAUSS_LEGENDRE_CONTRACTION_LIMIT};
pub use input::{FromFn, Input, InputOf, Linear, LinearOf};
pub use integrate::{
    run, AdaptiveReport, AdaptiveRk4, AdvanceReport, GaussLegendre4, GeneralizedAlpha,
    GeneralizedAlphaConfig, GeneralizedAlphaOf, Integrator, IntegratorOf, Rk4, RunSummary,
    SemiImplicitEuler, StepReport, StepSettings, ABRUPT_RATIO,
};
pub use inverse_dynamics::{
    forces, ForceReport, InverseConfig, InverseDynamics, InverseDynamicsOf, InverseReport,
    InverseSolution, InverseSolutionOf, SolvePath,
};
pub use model::{Equations, FiniteDifferenceJacobians, Model, PrescribedSizes, Sizes};
pub use nalgebra;
pub use projection::{project, ProjectionConfig, ProjectionReport};
pub use scalar::Scalar;
pub use state::{constraint_drift, total_energy, Drift, State, StateOf};
