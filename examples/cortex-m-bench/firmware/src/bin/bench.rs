//! Instructions and stack of the rigid robot's generated terms, of one
//! flexible scene's fused terms and of the runtime's inverse-dynamics call
//! at 1 kHz along the paper's circle, on an emulated Cortex-M4F. Prints
//! `count NAME INSTRUCTIONS STACK_BYTES` lines, the torques of the last call
//! as `tau I BITS` (hex of the f64) and `done`.

#![no_std]
#![no_main]

use core::hint::black_box;

use flexdyn_cortex_m_firmware::{exit, line, measure, overhead, start_timer, thousand_nops, Cost};
use flexdyn_runtime::nalgebra::{SMatrix, SVector};
use flexdyn_runtime::Model;

#[path = "../models.rs"]
mod models;
#[path = "../motion.rs"]
mod motion;
use models::{parallel_robot_rigid as rigid, spin_up_beam as beam};

type V12 = SVector<f64, 12>;

fn report(name: &str, c: Cost) {
    line(format_args!("count {name} {} {}", c.instructions, c.stack));
}

#[no_mangle]
fn main() -> ! {
    start_timer();
    let zero = overhead();
    report("nop1000", measure(zero, &mut || thousand_nops()));

    let model = rigid::ParallelRobotRigid;
    let q = black_box(V12::from(motion::Q0));
    let qd = black_box(V12::from_fn(|i, _| 0.1 * i as f64 - 0.5));
    let t = black_box(0.0);
    let mut m = SMatrix::<f64, 12, 12>::zeros();
    let mut h = V12::zeros();
    let mut phi = SVector::<f64, 9>::zeros();
    let mut phi_q = SMatrix::<f64, 9, 12>::zeros();
    let mut gamma = SVector::<f64, 9>::zeros();
    report(
        "rigid.mass_matrix",
        measure(zero, &mut || model.mass_matrix(&q, t, &mut m)),
    );
    report(
        "rigid.bias",
        measure(zero, &mut || model.bias(&q, &qd, t, &mut h)),
    );
    report(
        "rigid.constraints_and_jacobian",
        measure(zero, &mut || {
            model.constraints_and_jacobian(&q, t, &mut phi, &mut phi_q)
        }),
    );
    report(
        "rigid.constraint_rhs",
        measure(zero, &mut || model.constraint_rhs(&q, &qd, t, &mut gamma)),
    );
    report(
        "rigid.dynamics_terms",
        measure(zero, &mut || {
            model.dynamics_terms(&q, &qd, t, &mut m, &mut h, &mut phi_q, &mut gamma)
        }),
    );
    black_box((&m, &h, &phi, &phi_q, &gamma));

    let beam = black_box(beam::SpinUpBeam::default());
    let bq = black_box(SVector::<f64, 5>::from_fn(|i, _| 0.1 * i as f64));
    let mut bm = SMatrix::<f64, 5, 5>::zeros();
    let mut bh = SVector::<f64, 5>::zeros();
    let mut bphi_q = SMatrix::<f64, 1, 5>::zeros();
    let mut bgamma = SVector::<f64, 1>::zeros();
    report(
        "spin_up_beam.dynamics_terms",
        measure(zero, &mut || {
            beam.dynamics_terms(&bq, &bq, t, &mut bm, &mut bh, &mut bphi_q, &mut bgamma)
        }),
    );
    black_box((&bm, &bh, &bphi_q, &bgamma));

    let Some(mut solver) = motion::warm_solver(&model) else {
        exit(false)
    };
    let mut sol = motion::Solution::default();
    let (mut total, mut worst) = (Cost::default(), Cost::default());
    for k in 1..=motion::CALLS {
        let mut ok = false;
        let c = measure(zero, &mut || {
            ok = motion::call(&model, &mut solver, k, &mut sol)
        });
        if !ok {
            line(format_args!("inverse dynamics failed at call {k}"));
            exit(false)
        }
        total.instructions += c.instructions;
        worst.instructions = worst.instructions.max(c.instructions);
        worst.stack = worst.stack.max(c.stack);
    }
    report(
        "inverse_dynamics.mean",
        Cost {
            instructions: total.instructions / motion::CALLS,
            stack: worst.stack,
        },
    );
    report("inverse_dynamics.max", worst);
    line(format_args!("t {:016x}", sol.t.to_bits()));
    for (i, tau) in sol.tau.iter().enumerate() {
        line(format_args!("tau {i} {:016x}", tau.to_bits()));
    }
    line(format_args!("done"));
    exit(true)
}
