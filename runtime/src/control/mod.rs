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
//! None of the wrappers provides analytic bias Jacobians (the law's
//! derivatives are unknown), so the implicit integrator differentiates the
//! closed loop numerically. The wrappers evaluate the model in place: no
//! allocation, and failures are [`crate::Error`] values.

mod feedback;
mod pd;
mod servo;

pub use feedback::{Feedback, FeedbackLaw};
pub use pd::JointPd;
pub use servo::{
    servo_run, Coordinates, Outputs, Servo, ServoConfig, ServoSample, ServoSolution, ServoSummary,
};

use nalgebra::SVector;

/// Desired values, rates and accelerations of `N` quantities at one time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Target<const N: usize> {
    /// Desired values.
    pub position: SVector<f64, N>,
    /// Their time derivatives.
    pub velocity: SVector<f64, N>,
    /// Their second time derivatives.
    pub acceleration: SVector<f64, N>,
}

/// A desired motion of `N` quantities: the references of [`JointPd`] (which
/// uses the values and rates) and the prescription of [`Servo`]. Any
/// `Fn(f64) -> Target<N>` is one.
pub trait Trajectory<const N: usize> {
    /// The desired motion at time `t`.
    fn at(&self, t: f64) -> Target<N>;
}

impl<F, const N: usize> Trajectory<N> for F
where
    F: Fn(f64) -> Target<N>,
{
    #[inline]
    fn at(&self, t: f64) -> Target<N> {
        self(t)
    }
}
