//! Calls every generated function of the rigid robot and of the flexible
//! spin-up beam on opaque inputs and exits. Nothing else is linked, so the
//! linked program contains panic machinery only if a generated function can
//! reach it: the test of the thumbv7em build checks that it contains none.

#![no_std]
#![no_main]

use core::hint::black_box;

use flexdyn_cortex_m_firmware::exit;
use flexdyn_runtime::nalgebra::{SMatrix, SVector};
use flexdyn_runtime::Model;

#[path = "../models.rs"]
mod models;

/// Every method of the model, on inputs the compiler cannot see, with
/// outputs it must keep.
#[inline(never)]
fn all_terms<M: Model<NQ, NC, NU>, const NQ: usize, const NC: usize, const NU: usize>(model: &M) {
    let model = black_box(model);
    let q = black_box(SVector::<f64, NQ>::zeros());
    let qd = black_box(SVector::<f64, NQ>::zeros());
    let t = black_box(0.0);
    let mut m = SMatrix::<f64, NQ, NQ>::zeros();
    let mut h = SVector::<f64, NQ>::zeros();
    let mut phi = SVector::<f64, NC>::zeros();
    let mut phi_q = SMatrix::<f64, NC, NQ>::zeros();
    let mut phi_t = SVector::<f64, NC>::zeros();
    let mut gamma = SVector::<f64, NC>::zeros();
    let mut b = SMatrix::<f64, NQ, NU>::zeros();
    model.mass_matrix(&q, t, &mut m);
    model.bias(&q, &qd, t, &mut h);
    model.constraints(&q, t, &mut phi);
    model.constraint_jacobian(&q, t, &mut phi_q);
    model.constraint_time_derivative(&q, t, &mut phi_t);
    model.constraint_rhs(&q, &qd, t, &mut gamma);
    model.actuator_map(&mut b);
    black_box((&m, &h, &phi, &phi_q, &phi_t, &gamma, &b));
    model.constraints_and_jacobian(&q, t, &mut phi, &mut phi_q);
    model.dynamics_terms(&q, &qd, t, &mut m, &mut h, &mut phi_q, &mut gamma);
    black_box((&m, &h, &phi, &phi_q, &gamma));
    black_box(model.kinetic_energy(&q, &qd, t));
    black_box(model.potential_energy(&q, t));
}

#[no_mangle]
fn main() -> ! {
    all_terms(&models::parallel_robot_rigid::ParallelRobotRigid);
    all_terms(&models::spin_up_beam::SpinUpBeam::default());
    exit(true)
}
