//! Calls every generated function of the rigid robot and of the flexible
//! spin-up beam (its tip marker's included), in f64 and in f32, on opaque inputs and exits. Nothing else
//! is linked, so the linked program contains panic machinery only if a
//! generated function can reach it: the test of the thumbv7em build checks
//! that it contains none.

#![no_std]
#![no_main]

use core::hint::black_box;

use flexdyn_cortex_m_firmware::exit;
use flexdyn_runtime::nalgebra::{SMatrix, SVector};
use flexdyn_runtime::Model;

#[path = "../models.rs"]
mod models;

/// Every function of `model` (NQ, NC, NU: the module's constants), in
/// scalar type `real`, on inputs the compiler cannot see, with outputs it
/// must keep.
macro_rules! all_terms {
    ($model:expr, $m:ident, $real:ty) => {{
        use models::$m::{NC, NQ, NU};
        let model = black_box($model);
        let q = black_box(SVector::<$real, NQ>::zeros());
        let qd = black_box(SVector::<$real, NQ>::zeros());
        let t: $real = black_box(0.0);
        let mut m = SMatrix::<$real, NQ, NQ>::zeros();
        let mut h = SVector::<$real, NQ>::zeros();
        let mut phi = SVector::<$real, NC>::zeros();
        let mut phi_q = SMatrix::<$real, NC, NQ>::zeros();
        let mut phi_t = SVector::<$real, NC>::zeros();
        let mut gamma = SVector::<$real, NC>::zeros();
        let mut b = SMatrix::<$real, NQ, NU>::zeros();
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
        // Markers, at an index the compiler cannot see (one past the last
        // answers `false`).
        let marker = black_box(0usize);
        let mut p = SVector::<$real, 3>::zeros();
        let mut r = SMatrix::<$real, 3, 3>::zeros();
        let mut j = SMatrix::<$real, 6, NQ>::zeros();
        let (mut v, mut a) = (SVector::<$real, 6>::zeros(), SVector::<$real, 6>::zeros());
        black_box(model.marker_pose(marker, &q, t, &mut p, &mut r));
        black_box(model.marker_jacobian(marker, &q, t, &mut p, &mut r, &mut j));
        black_box(model.marker_motion(marker, &q, &qd, t, &mut v, &mut a));
        black_box((&p, &r, &j, &v, &a));
    }};
}

#[inline(never)]
fn rigid_f64() {
    all_terms!(
        models::parallel_robot_rigid::ParallelRobotRigid,
        parallel_robot_rigid,
        f64
    );
}

#[inline(never)]
fn beam_f64() {
    all_terms!(
        models::spin_up_beam::SpinUpBeam::default(),
        spin_up_beam,
        f64
    );
}

#[inline(never)]
fn rigid_f32() {
    all_terms!(
        models::f32::parallel_robot_rigid::ParallelRobotRigid,
        parallel_robot_rigid,
        f32
    );
}

#[inline(never)]
fn beam_f32() {
    all_terms!(
        models::f32::spin_up_beam::SpinUpBeam::default(),
        spin_up_beam,
        f32
    );
}

#[no_mangle]
fn main() -> ! {
    rigid_f64();
    beam_f64();
    rigid_f32();
    beam_f32();
    exit(true)
}
