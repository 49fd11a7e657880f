//! Control of any scene by wrapping its model: the wrapper changes only the
//! bias forces, `h - B u(q, qd, t)`, so every integrator of this crate runs
//! the closed loop unchanged.
//!
//! * [`Feedback`]: a state-feedback law `u = law(q, qd, t)` ([`FeedbackLaw`],
//!   any closure of the state) added to whatever input the integrator
//!   applies.
//! * [`JointPd`]: the feedback law `u_j = kp_j (r_j(t) - q_{i_j}) + kd_j
//!   (rd_j(t) - qd_{i_j})`, actuator `j` acting on coordinate `i_j`, with the
//!   references from a [`Trajectory`].
//! * [`Servo`]: servo constraints (Blajer & Kołodziejczyk): at every state
//!   the `NU` inputs are those for which `NP = NU` prescribed outputs
//!   `y(q)` ([`Outputs`]; [`Coordinates`] selects coordinates) follow a
//!   [`Trajectory`] `y_d(t)`; every other coordinate (elastic ones, say) is
//!   integrated. [`servo_run`] drives it along the prescription and hands
//!   each sample to a callback: inverse dynamics of flexible scenes.
//!
//! [`Servo`] and [`servo_run`] compute in the model's scalar (`f64` or
//! `f32`, see [`crate::Scalar`]); [`Feedback`] and [`JointPd`] in `f64`.
//!
//! None of the wrappers provides analytic bias Jacobians (the law's
//! derivatives are unknown), so the implicit integrator differentiates the
//! closed loop numerically. The wrappers evaluate the model in place: no
//! allocation, and failures are [`crate::Error`] values.

mod feedback;
mod pd;
mod servo;

pub use feedback::{Feedback, FeedbackLaw};
pub use pd::{JointPd, JointPdOf};
pub use servo::{
    servo_run, Coordinates, OutputTerms, Outputs, Servo, ServoConfig, ServoSample, ServoSampleOf,
    ServoSolution, ServoSolutionOf, ServoSummary,
};

use crate::scalar::Scalar;
use nalgebra::allocator::Allocator;
use nalgebra::{Const, DefaultAllocator, Dim, OVector};

/// Desired values, rates and accelerations of `N` quantities at one time,
/// in `T`, `N` fixed or known at run time ([`Target`]: fixed).
#[derive(Clone, Debug, PartialEq)]
pub struct TargetOf<T: Scalar, N: Dim>
where
    DefaultAllocator: Allocator<N>,
{
    /// Desired values.
    pub position: OVector<T, N>,
    /// Their time derivatives.
    pub velocity: OVector<T, N>,
    /// Their second time derivatives.
    pub acceleration: OVector<T, N>,
}

impl<T: Scalar, const N: usize> Copy for TargetOf<T, Const<N>> {}

/// [`TargetOf`] of `N` quantities (fixed), in `T` (`f64` unless named).
pub type Target<const N: usize, T = f64> = TargetOf<T, Const<N>>;

/// A desired motion of `N` quantities: the references of [`JointPd`] (which
/// uses the values and rates, in `f64`) and the prescription of [`Servo`]
/// (in the servo's scalar). Any `Fn(T) -> TargetOf<T, N>` is one.
pub trait Trajectory<N: Dim, T: Scalar = f64>
where
    DefaultAllocator: Allocator<N>,
{
    /// The desired motion at time `t`.
    fn at(&self, t: T) -> TargetOf<T, N>;
}

impl<F, T: Scalar, N: Dim> Trajectory<N, T> for F
where
    F: Fn(T) -> TargetOf<T, N>,
    DefaultAllocator: Allocator<N>,
{
    #[inline]
    fn at(&self, t: T) -> TargetOf<T, N> {
        self(t)
    }
}
