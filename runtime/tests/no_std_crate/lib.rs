//! A `#![no_std]` library that uses `flexdyn-runtime` and defines its own
//! `#[panic_handler]`: if the runtime or any of its dependencies linked
//! `std`, compiling it fails with "duplicate lang item `panic_impl`".
//!
//! Not a test target itself: `tests/no_std.rs` copies it into a standalone
//! crate (own workspace, no dev-dependencies, so no feature unification with
//! test-only crates) and runs `cargo build` on it. It instantiates every
//! solver with a small model so that all generic code is compiled for the
//! no_std graph too.
#![no_std]

use flexdyn_runtime::control::{
    servo_run, Coordinates, Feedback, JointPd, Servo, ServoConfig, Target,
};
use flexdyn_runtime::nalgebra::{SMatrix, SVector};
use flexdyn_runtime::{
    AdaptiveRk4, Error, GaussLegendre4, GeneralizedAlpha, Integrator, IntegratorOf, InverseConfig, InverseDynamics,
    InverseSolution, Model, Rk4, SemiImplicitEuler, State, StepSettings,
};

#[panic_handler]
fn panic(_info: &core::panic::PanicInfo) -> ! {
    loop {}
}

/// A point mass on a circle of radius 1 in Cartesian coordinates, with
/// gravity, a horizontal force and one holonomic constraint.
pub struct CirclePendulum;

impl Model<2, 1, 1> for CirclePendulum {
    const NAME: &'static str = "circle_pendulum";
    const COORDINATES: [&'static str; 2] = ["x", "y"];
    const ACTUATORS: [&'static str; 1] = ["fx"];
    fn mass_matrix(&self, _q: &SVector<f64, 2>, _t: f64, m: &mut SMatrix<f64, 2, 2>) {
        *m = SMatrix::identity();
    }
    fn bias(&self, _q: &SVector<f64, 2>, _qd: &SVector<f64, 2>, _t: f64, h: &mut SVector<f64, 2>) {
        *h = SVector::<f64, 2>::new(0.0, 9.81);
    }
    fn constraints(&self, q: &SVector<f64, 2>, _t: f64, phi: &mut SVector<f64, 1>) {
        phi[0] = q.norm_squared() - 1.0;
    }
    fn constraint_jacobian(&self, q: &SVector<f64, 2>, _t: f64, j: &mut SMatrix<f64, 1, 2>) {
        *j = q.transpose() * 2.0;
    }
    fn constraint_time_derivative(&self, _q: &SVector<f64, 2>, _t: f64, p: &mut SVector<f64, 1>) {
        p[0] = 0.0;
    }
    fn constraint_rhs(&self, _q: &SVector<f64, 2>, qd: &SVector<f64, 2>, _t: f64, g: &mut SVector<f64, 1>) {
        g[0] = -2.0 * qd.norm_squared();
    }
    fn actuator_map(&self, b: &mut SMatrix<f64, 2, 1>) {
        *b = SMatrix::<f64, 2, 1>::new(1.0, 0.0);
    }
    fn kinetic_energy(&self, _q: &SVector<f64, 2>, qd: &SVector<f64, 2>, _t: f64) -> f64 {
        0.5 * qd.norm_squared()
    }
    fn potential_energy(&self, q: &SVector<f64, 2>, _t: f64) -> f64 {
        9.81 * q[1]
    }
}

/// Simulates `steps` steps with every integrator; returns the final states.
pub fn simulate(steps: usize) -> Result<[State<2>; 5], Error> {
    let model = CirclePendulum;
    let s0 = State::new(SVector::<f64, 2>::new(0.6, -0.8), SVector::zeros(), 0.0);
    let tau = SVector::<f64, 1>::new(0.1);
    let settings = StepSettings::with_projection();
    let mut out = [s0; 5];
    for _ in 0..steps {
        Rk4::new(settings).step(&model, &mut out[0], &tau, 1e-3)?;
        SemiImplicitEuler::new(settings).step(&model, &mut out[1], &tau, 1e-3)?;
        GaussLegendre4::new(settings).step(&model, &mut out[2], &tau, 1e-3)?;
        AdaptiveRk4::default().step(&model, &mut out[4], &tau, 1e-3)?;
    }
    let mut ga = GeneralizedAlpha::<2, 1>::default();
    for _ in 0..steps {
        ga.step(&model, &mut out[3], &tau, 1e-3)?;
    }
    Ok(out)
}

/// One inverse-dynamics call with `x` prescribed.
pub fn torque(x: f64, v: f64, a: f64) -> Result<f64, Error> {
    let guess = SVector::<f64, 2>::new(x, -1.0);
    let mut id = InverseDynamics::<2, 1, 1, 1>::new([0], guess, InverseConfig::default())?;
    let mut sol = InverseSolution::default();
    id.solve(
        &CirclePendulum,
        0.0,
        &SVector::<f64, 1>::new(x),
        &SVector::<f64, 1>::new(v),
        &SVector::<f64, 1>::new(a),
        &mut sol,
    )?;
    Ok(sol.tau[0])
}

/// `x` held at `x0`.
fn hold(x0: f64) -> impl Fn(f64) -> Target<1> {
    move |_t| Target {
        position: SVector::<f64, 1>::new(x0),
        velocity: SVector::zeros(),
        acceleration: SVector::zeros(),
    }
}

/// `steps` steps of a PD loop on `x` and of servo constraints on `x`; the
/// final states and the last servo input.
pub fn control(steps: usize) -> Result<([State<2>; 2], f64), Error> {
    let model = CirclePendulum;
    let s0 = State::new(SVector::<f64, 2>::new(0.6, -0.8), SVector::zeros(), 0.0);
    let settings = StepSettings::with_projection();
    let pd = JointPd::<_, 2, 1>::new([0], [10.0], [2.0], hold(0.5))?;
    let closed = Feedback::new(&model, pd);
    let mut out = [s0; 2];
    let mut ga = GeneralizedAlpha::<2, 1>::new(settings, Default::default());
    for _ in 0..steps {
        ga.step(&closed, &mut out[0], &SVector::<f64, 1>::zeros(), 1e-3)?;
    }
    let servo = Servo::new(&model, Coordinates([0]), hold(0.6), ServoConfig::default())?;
    let mut last = 0.0;
    servo_run(&servo, &mut Rk4::new(settings), &mut out[1], 1e-3, steps, |s| {
        last = s.tau[0];
        core::ops::ControlFlow::Continue(())
    })?;
    Ok((out, last))
}
