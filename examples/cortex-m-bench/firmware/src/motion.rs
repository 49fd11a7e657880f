// The measured inverse-dynamics run, shared by the firmware and the host
// crate that checks its torques: the rigid robot warm-started at its pose at
// `t = 0` on the paper's circle, then called at 1 kHz.

use flexdyn_runtime::nalgebra::SVector;
use flexdyn_runtime::{math, InverseConfig, InverseDynamics, InverseSolution, Model, Scalar};

/// A scalar type the run computes in, with the runtime's sine and cosine
/// of that type (`math::sin_cos`, `math::f32::sin_cos`).
pub trait Real: Scalar {
    /// `(sin x, cos x)`.
    fn sine_cosine(x: Self) -> (Self, Self);
}

impl Real for f64 {
    fn sine_cosine(x: f64) -> (f64, f64) {
        math::sin_cos(x)
    }
}

impl Real for f32 {
    fn sine_cosine(x: f32) -> (f32, f32) {
        math::f32::sin_cos(x)
    }
}

/// The rigid robot's consistent pose at `t = 0` on the paper's circle
/// (`parallel-robot inverse --scene .../parallel_robot_rigid.toml --states`,
/// its first state).
pub const Q0: [f64; 12] = [
    0.07077240198480617,
    2.299032285161347,
    0.0,
    0.4172169655179958,
    2.497066771033036,
    -0.10846573026975444,
    0.4172169655179958,
    2.497066771033036,
    0.1084657302697544,
    0.1,
    0.0,
    0.7,
];
/// The paper's circle (Eq. 23): centre, radius (m), angular rate (rad/s).
const CENTER: [f64; 3] = [0.0, 0.0, 0.7];
const RADIUS: f64 = 0.1;
const OMEGA: f64 = 2.0;
/// Control period (s) and number of measured calls.
pub const DT: f64 = 1e-3;
pub const CALLS: u32 = 10;
/// The platform coordinates `px, py, pz`.
const PLATFORM: [usize; 3] = [9, 10, 11];

/// Solver of the rigid robot's inverse dynamics in `T`.
pub type Solver<T> = InverseDynamics<12, 9, 3, 3, T>;
/// One call's solution in `T`.
pub type Solution<T> = InverseSolution<12, 9, 3, T>;

/// Platform position, velocity and acceleration on the circle at `t`.
fn circle<T: Real>(t: T) -> [SVector<T, 3>; 3] {
    let (s, c) = T::sine_cosine(T::of(OMEGA) * t);
    let (r, w) = (T::of(RADIUS), T::of(OMEGA));
    let [x, y, z] = CENTER.map(T::of);
    let zero = T::zero();
    [
        SVector::from([x + r * c, y + r * s, z]),
        SVector::from([-r * w * s, r * w * c, zero]),
        SVector::from([-r * w * w * c, -r * w * w * s, zero]),
    ]
}

/// The solver (default configuration of `T`) after its call at `t = 0`
/// (from [`Q0`]); `None` if it fails.
pub fn warm_solver<T: Real, M: Model<12, 9, 3, T>>(model: &M) -> Option<Solver<T>> {
    let mut solver = Solver::new(
        PLATFORM,
        SVector::from(Q0.map(T::of)),
        InverseConfig::default(),
    )
    .ok()?;
    let [p, v, a] = circle(T::zero());
    solver
        .solve(model, T::zero(), &p, &v, &a, &mut Solution::default())
        .ok()?;
    Some(solver)
}

/// Call `k` (`1..=CALLS`) of the run, at `t = k DT`; `false` if it fails.
pub fn call<T: Real, M: Model<12, 9, 3, T>>(
    model: &M,
    solver: &mut Solver<T>,
    k: u32,
    out: &mut Solution<T>,
) -> bool {
    let t = T::of(f64::from(k)) * T::of(DT);
    let [p, v, a] = circle(t);
    solver.solve(model, t, &p, &v, &a, out).is_ok()
}
