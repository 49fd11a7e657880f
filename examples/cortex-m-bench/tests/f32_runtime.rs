//! The runtime in f32 against the same runtime in f64 (the f32 and f64
//! modules of the same scenes, the solvers generic over the scalar):
//!
//! * the rigid robot's inverse dynamics along the paper's circle (one turn at
//!   2 rad/s, 1 kHz, warm-started call to call as on the controller): the
//!   f32 torques and path (all twelve coordinates) against the f64 ones;
//! * the rigid robot driven quasi-statically towards the edge of its
//!   workspace (positions that f32 represents exactly, up to the last f32
//!   value below the edge): the f32 torque error grows with the condition of
//!   the Jacobian of the free coordinates and stays within `10 cond eps`;
//! * f32 refuses where that condition exceeds its limit (1e4) and f64 does
//!   not (1e8): `SingularConstraintJacobian` with f32's own estimate of the
//!   condition (against f64's exact one) and the limit, while both solve at
//!   a well-conditioned pose;
//! * RK4 and Gauss–Legendre on the flexible spin-up beam (rheonomic hub
//!   drive, four elastic modes): the f32 trajectory against the f64 one.
//!
//! The numbers are printed; the bounds are f32's accuracy (`cond * eps`
//! with `eps = 1.2e-7`) with a margin.

use flexdyn_runtime::nalgebra::SVector;
use flexdyn_runtime::{
    ErrorKind, GaussLegendre4, Integrator, InverseConfig, InverseDynamics, InverseReport,
    InverseSolution, Model, Rk4, Scalar, State,
};

#[path = "../firmware/src/models.rs"]
mod models;
// Shared with the firmware; this test does not use the call count.
#[allow(dead_code)]
#[path = "../firmware/src/motion.rs"]
mod motion;

use models::f32::parallel_robot_rigid::ParallelRobotRigid as Rigid32;
use models::parallel_robot_rigid::ParallelRobotRigid as Rigid64;

/// Largest `|a - b|` over the entries.
fn max_diff<const N: usize>(a: &SVector<f32, N>, b: &SVector<f64, N>) -> f64 {
    a.iter()
        .zip(b.iter())
        .fold(0.0, |m, (x, y)| m.max((f64::from(*x) - y).abs()))
}

#[test]
fn rigid_robot_inverse_dynamics_in_f32_follows_f64_along_the_circle() {
    let mut s64 = motion::warm_solver(&Rigid64).expect("f64 first pose");
    let mut s32 = motion::warm_solver(&Rigid32).expect("f32 first pose");
    let (mut o64, mut o32) = (
        motion::Solution::<f64>::default(),
        motion::Solution::default(),
    );
    // One turn at 2 rad/s: pi seconds.
    let calls = 3142;
    let (mut tau_err, mut tau_peak, mut q_err) = (0.0f64, 0.0f64, 0.0f64);
    for k in 1..=calls {
        assert!(
            motion::call(&Rigid64, &mut s64, k, &mut o64),
            "f64 call {k}"
        );
        assert!(
            motion::call(&Rigid32, &mut s32, k, &mut o32),
            "f32 call {k}"
        );
        tau_err = tau_err.max(max_diff(&o32.tau, &o64.tau));
        tau_peak = o64.tau.iter().fold(tau_peak, |m, x| m.max(x.abs()));
        q_err = q_err.max(max_diff(&o32.q, &o64.q));
    }
    println!(
        "rigid robot, circle at 2 rad/s, {calls} calls: f32 torques within {tau_err:.2e} N m \
         ({:.2e} of the peak {tau_peak:.2} N m), coordinates within {q_err:.2e}",
        tau_err / tau_peak
    );
    assert!(tau_err <= 1e-5 * tau_peak, "{tau_err:e} of {tau_peak}");
    assert!(q_err <= 1e-5, "{q_err:e}");
}

/// Quasi-static inverse dynamics of the rigid robot at platform position
/// `(x, 0, z)`, warm-started by `solver`.
fn quasi_static<T: Scalar, M: Model<12, 9, 3, T>>(
    model: &M,
    solver: &mut InverseDynamics<12, 9, 3, 3, T>,
    x: f64,
    z: f64,
) -> Result<(InverseSolution<12, 9, 3, T>, InverseReport<T>), flexdyn_runtime::Error> {
    let p = SVector::from([x, 0.0, z].map(T::of));
    let zero = SVector::zeros();
    let mut out = InverseSolution::default();
    let report = solver.solve(model, T::zero(), &p, &zero, &zero, &mut out)?;
    Ok((out, report))
}

/// The height of the drive to the workspace edge, `(x, 0, HEIGHT)`: the
/// circle's, as f32 represents it (f32 and f64 solve the same problem).
const HEIGHT: f64 = 0.7f32 as f64;

/// The edge of the rigid robot's workspace along `(x, 0, z)`, `x > 0.1`:
/// the largest `x` (to 1e-15 m) where the f64 solve succeeds, marching out
/// by 2 mm from the circle's first pose and then bisecting, warm-started
/// from the last solved position. Returns the edge and the pose there.
fn workspace_edge(z: f64) -> (f64, SVector<f64, 12>) {
    let mut solver = InverseDynamics::new(
        [9, 10, 11],
        SVector::from(motion::Q0),
        InverseConfig::default(),
    )
    .unwrap();
    let mut last = SVector::from(motion::Q0);
    let mut solves = |x: f64| {
        solver.set_guess(last);
        let ok = quasi_static(&Rigid64, &mut solver, x, z).map(|(o, _)| last = o.q);
        ok.is_ok()
    };
    let mut x_ok = 0.1;
    while solves(x_ok + 0.002) {
        x_ok += 0.002;
        assert!(x_ok < 1.0, "no workspace edge along +x");
    }
    let mut x_bad = x_ok + 0.002;
    while x_bad - x_ok > 1e-15 {
        let mid = 0.5 * (x_ok + x_bad);
        if solves(mid) {
            x_ok = mid;
        } else {
            x_bad = mid;
        }
    }
    (x_ok, last)
}

#[test]
fn rigid_robot_near_the_workspace_edge_f32_loses_digits_within_its_bound() {
    // Positions that f32 represents exactly (both solve the same problem):
    // every 2 mm from the circle's first pose outwards, then the 100 f32
    // values below the edge.
    let (edge, _) = workspace_edge(HEIGHT);
    let top = f32_at_most(edge);
    let mut xs: Vec<f64> = (1..)
        .map(|k| f64::from((0.1 + 0.002 * f64::from(k)) as f32))
        .take_while(|x| *x < f64::from(top) - 1e-4)
        .collect();
    xs.extend(
        (0..100)
            .rev()
            .map(|j| f64::from(f32::from_bits(top.to_bits() - j))),
    );

    let q0 = SVector::from(motion::Q0);
    let mut s64 = InverseDynamics::new([9, 10, 11], q0, InverseConfig::default()).unwrap();
    let mut s32 =
        InverseDynamics::new([9, 10, 11], q0.cast::<f32>(), InverseConfig::default()).unwrap();
    // (x, f64 Jacobian condition, f32 torque error relative to the peak)
    let mut samples = Vec::new();
    for &x in &xs {
        let (o64, r64) = quasi_static(&Rigid64, &mut s64, x, HEIGHT)
            .unwrap_or_else(|e| panic!("f64 fails at x = {x} inside the edge {edge}: {e}"));
        let (o32, _) = quasi_static(&Rigid32, &mut s32, x, HEIGHT)
            .unwrap_or_else(|e| panic!("f32 inverse dynamics fails at x = {x}: {e}"));
        let peak = o64.tau.amax().max(1.0);
        samples.push((
            x,
            r64.jacobian_condition,
            max_diff(&o32.tau, &o64.tau) / peak,
        ));
    }
    for (x, cond, err) in samples.iter().step_by(40).chain(samples.last()) {
        println!("x = {x:.9} m: condition {cond:.3e}, f32 torque error {err:.2e} (relative)");
    }
    // Inverse dynamics: where f32 solves, its error stays within its
    // accuracy bound `cond * eps` (with a margin of 10).
    for &(x, cond, err) in &samples {
        assert!(
            err <= 10.0 * cond * f64::from(f32::EPSILON),
            "x = {x}: error {err:e}, condition {cond:e}"
        );
    }
}

/// The largest `f32` value at most `x`.
fn f32_at_most(x: f64) -> f32 {
    let y = x as f32;
    if f64::from(y) > x {
        f32::from_bits(y.to_bits() - 1)
    } else {
        y
    }
}

/// The rigid robot's quasi-static f64 solution at `(x, 0, z)` on the SVD
/// path (its condition is the exact 2-norm one), from `guess`.
fn quasi_static_f64_svd(
    x: f64,
    z: f64,
    guess: SVector<f64, 12>,
) -> Result<(InverseSolution<12, 9, 3>, InverseReport), flexdyn_runtime::Error> {
    let config = InverseConfig {
        fast_path: false,
        ..InverseConfig::default()
    };
    let mut solver = InverseDynamics::new([9, 10, 11], guess, config).unwrap();
    quasi_static(&Rigid64, &mut solver, x, z)
}

#[test]
fn rigid_robot_f32_refuses_where_the_jacobian_condition_exceeds_its_limit() {
    let (limit32, limit64) = (f64::from(f32::MAX_CONDITION), f64::MAX_CONDITION);
    // (x, z, guess, whether J_f's condition there exceeds f32's limit), at
    // positions that f32 represents exactly: the circle's first pose, and
    // the last f32 value below the workspace edge along (x, 0, 0.69) (the
    // condition there depends on how close the edge lies to an f32 value;
    // along (x, 0, 0.7) it is 8,000, 0.69 is the first height below 0.7,
    // every 5 mm, where it exceeds 1e4). f32 starts from the f64 solution
    // there, so that it evaluates J_f at that pose rather than accepting an
    // earlier one (see above).
    let z_edge = 0.69f32 as f64;
    let (edge, q_edge) = workspace_edge(z_edge);
    let x_edge = f64::from(f32_at_most(edge));
    let q0 = SVector::from(motion::Q0);
    for (x, z, guess, beyond_f32) in [(0.1, HEIGHT, q0, false), (x_edge, z_edge, q_edge, true)] {
        let (o64, r64) = quasi_static_f64_svd(x, z, guess)
            .unwrap_or_else(|e| panic!("f64 fails at x = {x}, z = {z}: {e}"));
        let cond64 = r64.jacobian_condition;
        let mut s32 =
            InverseDynamics::new([9, 10, 11], o64.q.cast::<f32>(), InverseConfig::default())
                .unwrap();
        let result32 = quasi_static(&Rigid32, &mut s32, x, z);
        println!(
            "(x, z) = ({x:.9}, {z}) m: f64 condition of J_f {cond64:.4e} (limit {limit64:e}), f32: {}",
            match &result32 {
                Ok((_, r32)) => format!("solved, condition {:.4e}", r32.jacobian_condition),
                Err(e) => format!("{e}"),
            }
        );
        assert!(cond64 <= limit64);
        assert_eq!(
            cond64 > limit32,
            beyond_f32,
            "x = {x}: f64 condition {cond64:e}"
        );
        match result32 {
            Ok((_, r32)) => {
                assert!(!beyond_f32, "f32 solved at x = {x}, condition {cond64:e}");
                let cond32 = f64::from(r32.jacobian_condition);
                assert!(cond32 <= limit32);
                assert!(
                    (0.5..=2.0 * 9.0).contains(&(cond32 / cond64)),
                    "x = {x}: f32 condition (bound) {cond32:e}, f64 {cond64:e}"
                );
            }
            Err(e) => {
                let ErrorKind::SingularConstraintJacobian { condition, limit } = e.kind else {
                    panic!("x = {x}: f32 fails with {e}, not a singular Jacobian");
                };
                assert!(beyond_f32, "f32 refused at x = {x}: {e}");
                assert_eq!(limit, limit32);
                assert!(condition > limit, "{e}");
                // f32's own estimate of the condition (SVD) agrees with
                // f64's to within f32's accuracy at that condition.
                assert!(
                    (condition / cond64 - 1.0).abs() <= 0.1,
                    "f32 condition {condition:e}, f64 {cond64:e}"
                );
                let message = e.to_string();
                for number in [condition, limit] {
                    assert!(message.contains(&format!("{number:e}")), "{message}");
                }
            }
        }
    }
}

/// The spin-up beam from rest over 15 s with `integrator` in f64 and
/// `integrator32` in f32 at step `dt`: the largest difference of the elastic
/// coordinates, their peak (f64), and the final differences of the hub angle
/// and of the time (f32 accumulates `t + dt` with its own rounding).
fn spin_up<G64, G32>(mut integrator: G64, mut integrator32: G32, dt: f64) -> (f64, f64, f64, f64)
where
    G64: Integrator<5, 1, 1, f64>,
    G32: Integrator<5, 1, 1, f32>,
{
    let (m64, m32) = (
        models::spin_up_beam::SpinUpBeam::default(),
        models::f32::spin_up_beam::SpinUpBeam::default(),
    );
    let mut x64 = State::new(SVector::<f64, 5>::zeros(), SVector::zeros(), 0.0);
    let mut x32 = State::new(SVector::<f32, 5>::zeros(), SVector::zeros(), 0.0);
    let (tau64, tau32) = (SVector::<f64, 1>::zeros(), SVector::<f32, 1>::zeros());
    let (mut q_err, mut q_peak) = (0.0f64, 0.0f64);
    let steps = (15.0 / dt).round() as usize;
    for k in 0..steps {
        integrator
            .step(&m64, &mut x64, &tau64, dt)
            .unwrap_or_else(|e| panic!("f64 step {k}: {e}"));
        integrator32
            .step(&m32, &mut x32, &tau32, dt as f32)
            .unwrap_or_else(|e| panic!("f32 step {k}: {e}"));
        // The elastic coordinates (all but the hub angle).
        for i in 1..5 {
            q_err = q_err.max((f64::from(x32.q[i]) - x64.q[i]).abs());
            q_peak = q_peak.max(x64.q[i].abs());
        }
    }
    (
        q_err,
        q_peak,
        (f64::from(x32.q[0]) - x64.q[0]).abs(),
        (f64::from(x32.t) - x64.t).abs(),
    )
}

#[test]
fn spin_up_beam_in_f32_follows_f64_with_rk4_and_gauss_legendre() {
    // Gauss-Legendre's stage iteration contracts only well below the
    // fastest mode's period: a smaller step than RK4's.
    let (rk4, gl) = (5e-3, 1e-3);
    for (name, dt, (q_err, q_peak, hub, drift)) in [
        (
            "RK4",
            rk4,
            spin_up(Rk4::<f64>::default(), Rk4::<f32>::default(), rk4),
        ),
        (
            "Gauss-Legendre",
            gl,
            spin_up(
                GaussLegendre4::<f64>::default(),
                GaussLegendre4::<f32>::default(),
                gl,
            ),
        ),
    ] {
        println!(
            "spin-up beam, {name} at dt = {dt} s for 15 s: f32 elastic coordinates within \
             {q_err:.2e} (peak {q_peak:.3e}), hub angle within {hub:.2e} rad, f32 time \
             {drift:.2e} s off"
        );
        assert!(q_err <= 1e-2 * q_peak, "{name}: {q_err:e} of {q_peak:e}");
        // The prescribed hub angle ends at 6 rad/s: its f32 error is the
        // time's, plus f32's resolution of 45 rad.
        assert!(hub <= 6.5 * drift + 1e-3, "{name}: {hub:e}, time {drift:e}");
    }
}
