//! Issue 4: the rigid robot's real-time torque path, and how it splits
//! between the generated terms and the linear solves.
//! Run with `cargo bench --bench robot`.

use criterion::{black_box, criterion_group, criterion_main, Criterion};
use flexdyn::robot::{inverse_kinematics, Circle, Geometry};
use flexdyn::runtime::nalgebra::{SMatrix, SVector};
use flexdyn::runtime::{InverseConfig, InverseDynamics, InverseSolution, Model};
use flexdyn::scenes::parallel_robot_rigid::ParallelRobotRigid;

fn robot(c: &mut Criterion) {
    let model = ParallelRobotRigid;
    let circle = Circle::paper(2.0);
    let q0 = inverse_kinematics(&Geometry::SPEC, circle.at(0.0)[0]).unwrap();
    let mut solver = InverseDynamics::<12, 9, 3, 3>::new(
        [9, 10, 11],
        SVector::from(q0),
        InverseConfig::default(),
    )
    .unwrap();
    let mut sol = InverseSolution::<12, 9, 3>::default();
    let mut group = c.benchmark_group("parallel_robot_rigid");
    let mut t = 0.0;
    group.bench_function("inverse_dynamics_call", |b| {
        b.iter(|| {
            // Advance along the circle so every call warm-starts from the last one.
            t += 0.001;
            let [p, v, a] = circle.at(t);
            solver
                .solve(
                    &model,
                    t,
                    &SVector::from(p),
                    &SVector::from(v),
                    &SVector::from(a),
                    &mut sol,
                )
                .unwrap();
            black_box(&sol.tau);
        })
    });
    let (q, qd) = (sol.q, sol.qd);
    group.bench_function("mass_matrix", |b| {
        let mut m = SMatrix::<f64, 12, 12>::zeros();
        b.iter(|| model.mass_matrix(black_box(&q), 0.0, &mut m))
    });
    group.bench_function("bias", |b| {
        let mut h = SVector::<f64, 12>::zeros();
        b.iter(|| model.bias(black_box(&q), black_box(&qd), 0.0, &mut h))
    });
    group.bench_function("constraints", |b| {
        let mut phi = SVector::<f64, 9>::zeros();
        b.iter(|| model.constraints(black_box(&q), 0.0, &mut phi))
    });
    group.bench_function("constraint_jacobian", |b| {
        let mut j = SMatrix::<f64, 9, 12>::zeros();
        b.iter(|| model.constraint_jacobian(black_box(&q), 0.0, &mut j))
    });
    group.bench_function("constraint_rhs", |b| {
        let mut g = SVector::<f64, 9>::zeros();
        b.iter(|| model.constraint_rhs(black_box(&q), black_box(&qd), 0.0, &mut g))
    });
    group.finish();
}

criterion_group!(benches, robot);
criterion_main!(benches);
