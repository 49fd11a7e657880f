// The measured inverse-dynamics run, shared by the firmware and the host
// crate that checks its torques: the rigid robot warm-started at its pose at
// `t = 0` on the paper's circle, then called at 1 kHz.

use flexdyn_runtime::nalgebra::SVector;
use flexdyn_runtime::{math, InverseConfig, InverseDynamics, InverseSolution, Model};

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

/// Solver of the rigid robot's inverse dynamics.
pub type Solver = InverseDynamics<12, 9, 3, 3>;
/// One call's solution.
pub type Solution = InverseSolution<12, 9, 3>;

/// Platform position, velocity and acceleration on the circle at `t`.
fn circle(t: f64) -> [SVector<f64, 3>; 3] {
    let (s, c) = math::sin_cos(OMEGA * t);
    let (r, w) = (RADIUS, OMEGA);
    [
        SVector::from([CENTER[0] + r * c, CENTER[1] + r * s, CENTER[2]]),
        SVector::from([-r * w * s, r * w * c, 0.0]),
        SVector::from([-r * w * w * c, -r * w * w * s, 0.0]),
    ]
}

/// The solver after its call at `t = 0` (from [`Q0`]); `None` if it fails.
pub fn warm_solver<M: Model<12, 9, 3>>(model: &M) -> Option<Solver> {
    let mut solver = Solver::new(PLATFORM, SVector::from(Q0), InverseConfig::default()).ok()?;
    let [p, v, a] = circle(0.0);
    solver
        .solve(model, 0.0, &p, &v, &a, &mut Solution::default())
        .ok()?;
    Some(solver)
}

/// Call `k` (`1..=CALLS`) of the run, at `t = k DT`; `false` if it fails.
pub fn call<M: Model<12, 9, 3>>(
    model: &M,
    solver: &mut Solver,
    k: u32,
    out: &mut Solution,
) -> bool {
    let t = f64::from(k) * DT;
    let [p, v, a] = circle(t);
    solver.solve(model, t, &p, &v, &a, out).is_ok()
}
