//! Instructions and stack of the rigid robot's generated terms, of one
//! flexible scene's fused terms and its tip marker's kinematics (the
//! deflection included), and of the runtime's inverse-dynamics call
//! at 1 kHz along the paper's circle, in f64 and in f32, on an emulated
//! Cortex-M4F. Prints `count NAME INSTRUCTIONS STACK_BYTES` lines, the
//! torques of the last call as `tau I BITS` (hex of the f64) and
//! `tau_f32 I BITS` (hex of the f32), and `done`.

#![no_std]
#![no_main]

use core::hint::black_box;

use flexdyn_cortex_m_firmware::{exit, line, measure, overhead, start_timer, thousand_nops, Cost};
use flexdyn_runtime::nalgebra::{SMatrix, SVector, Scalar};
use flexdyn_runtime::Model;

#[path = "../models.rs"]
mod models;
#[path = "../motion.rs"]
mod motion;
use models::{parallel_robot_rigid as rigid, spin_up_beam as beam};

/// The state at which the terms are measured: the robot's pose at `t = 0`
/// on the circle (the first `NQ` values of `Q0` for another model) and
/// some velocities, rounded to the model's scalar type by `real`.
fn state<T: Scalar, const NQ: usize>(real: fn(f64) -> T) -> (SVector<T, NQ>, SVector<T, NQ>) {
    let q = SVector::from_fn(|i, _| real(motion::Q0[i % 12]));
    let qd = SVector::from_fn(|i, _| real(0.1 * i as f64 - 0.5));
    (black_box(q), black_box(qd))
}

/// Measures model `$model` (module `$m` of `models`) in scalar type
/// `$real`: its separate terms when `$separate`, then its fused terms,
/// reported as `$name.<function>`.
macro_rules! measure_terms {
    ($name:literal, $model:expr, $m:ident, $real:ty, $zero:expr, $separate:expr) => {{
        use models::$m::{NC, NQ};
        let model = black_box($model);
        let (q, qd) = state::<$real, NQ>(|x| x as $real);
        let t: $real = black_box(0.0);
        let mut m = SMatrix::<$real, NQ, NQ>::zeros();
        let mut h = SVector::<$real, NQ>::zeros();
        let mut phi = SVector::<$real, NC>::zeros();
        let mut phi_q = SMatrix::<$real, NC, NQ>::zeros();
        let mut gamma = SVector::<$real, NC>::zeros();
        if $separate {
            report(
                concat!($name, ".mass_matrix"),
                measure($zero, &mut || model.mass_matrix(&q, t, &mut m)),
            );
            report(
                concat!($name, ".bias"),
                measure($zero, &mut || model.bias(&q, &qd, t, &mut h)),
            );
            report(
                concat!($name, ".constraints_and_jacobian"),
                measure($zero, &mut || {
                    model.constraints_and_jacobian(&q, t, &mut phi, &mut phi_q)
                }),
            );
            report(
                concat!($name, ".constraint_rhs"),
                measure($zero, &mut || model.constraint_rhs(&q, &qd, t, &mut gamma)),
            );
        }
        report(
            concat!($name, ".dynamics_terms"),
            measure($zero, &mut || {
                model.dynamics_terms(&q, &qd, t, &mut m, &mut h, &mut phi_q, &mut gamma)
            }),
        );
        black_box((&m, &h, &phi, &phi_q, &gamma));
    }};
}

/// Measures the kinematics of marker 0 of model `$model` (module `$m`) in
/// `$real`: pose and Jacobian in one call, then velocity and acceleration
/// bias, reported as `$name.marker_jacobian` and `$name.marker_motion`.
macro_rules! measure_marker {
    ($name:literal, $model:expr, $m:ident, $real:ty, $zero:expr) => {{
        use models::$m::NQ;
        let model = black_box($model);
        let (q, qd) = state::<$real, NQ>(|x| x as $real);
        let t: $real = black_box(0.0);
        let mut p = SVector::<$real, 3>::zeros();
        let mut r = SMatrix::<$real, 3, 3>::zeros();
        let mut j = SMatrix::<$real, 6, NQ>::zeros();
        let (mut v, mut a) = (SVector::<$real, 6>::zeros(), SVector::<$real, 6>::zeros());
        let mut found = true;
        report(
            concat!($name, ".marker_jacobian"),
            measure($zero, &mut || {
                found &= model.marker_jacobian(0, &q, t, &mut p, &mut r, &mut j)
            }),
        );
        report(
            concat!($name, ".marker_motion"),
            measure($zero, &mut || {
                found &= model.marker_motion(0, &q, &qd, t, &mut v, &mut a)
            }),
        );
        if !found {
            line(format_args!(concat!($name, ": no marker 0")));
            exit(false)
        }
        black_box((&p, &r, &j, &v, &a));
    }};
}

/// Measures the rigid robot's inverse-dynamics run (`motion`) in `T`,
/// reported as `$name.mean` and `$name.max`; the solution of its last call.
fn measure_inverse<T: motion::Real, M: Model<12, 9, 3, T>>(
    name: &str,
    model: &M,
    zero: Cost,
) -> motion::Solution<T> {
    let Some(mut solver) = motion::warm_solver(model) else {
        exit(false)
    };
    let mut sol = motion::Solution::default();
    let (mut total, mut worst) = (Cost::default(), Cost::default());
    for k in 1..=motion::CALLS {
        let mut ok = false;
        let c = measure(zero, &mut || {
            ok = motion::call(model, &mut solver, k, &mut sol)
        });
        if !ok {
            line(format_args!("{name} failed at call {k}"));
            exit(false)
        }
        total.instructions += c.instructions;
        worst.instructions = worst.instructions.max(c.instructions);
        worst.stack = worst.stack.max(c.stack);
    }
    let mean = Cost {
        instructions: total.instructions / motion::CALLS,
        stack: worst.stack,
    };
    report_part(name, ".mean", mean);
    report_part(name, ".max", worst);
    sol
}

fn report(name: &str, c: Cost) {
    report_part(name, "", c);
}

/// Reports measurement `{name}{part}`.
fn report_part(name: &str, part: &str, c: Cost) {
    line(format_args!(
        "count {name}{part} {} {}",
        c.instructions, c.stack
    ));
}

#[no_mangle]
fn main() -> ! {
    start_timer();
    let zero = overhead();
    report("nop1000", measure(zero, &mut || thousand_nops()));

    let model = rigid::ParallelRobotRigid;
    measure_terms!("rigid", model, parallel_robot_rigid, f64, zero, true);
    measure_terms!(
        "rigid_f32",
        models::f32::parallel_robot_rigid::ParallelRobotRigid,
        parallel_robot_rigid,
        f32,
        zero,
        true
    );
    measure_terms!(
        "spin_up_beam",
        beam::SpinUpBeam::default(),
        spin_up_beam,
        f64,
        zero,
        false
    );
    measure_terms!(
        "spin_up_beam_f32",
        models::f32::spin_up_beam::SpinUpBeam::default(),
        spin_up_beam,
        f32,
        zero,
        false
    );

    measure_marker!(
        "spin_up_beam",
        beam::SpinUpBeam::default(),
        spin_up_beam,
        f64,
        zero
    );
    measure_marker!(
        "spin_up_beam_f32",
        models::f32::spin_up_beam::SpinUpBeam::default(),
        spin_up_beam,
        f32,
        zero
    );

    let t = measure_inverse("inverse_dynamics", &model, zero);
    let t32 = measure_inverse(
        "inverse_dynamics_f32",
        &models::f32::parallel_robot_rigid::ParallelRobotRigid,
        zero,
    );
    line(format_args!("t {:016x}", t.t.to_bits()));
    for (i, tau) in t.tau.iter().enumerate() {
        line(format_args!("tau {i} {:016x}", tau.to_bits()));
    }
    for (i, tau) in t32.tau.iter().enumerate() {
        line(format_args!("tau_f32 {i} {:08x}", tau.to_bits()));
    }
    line(format_args!("done"));
    exit(true)
}
