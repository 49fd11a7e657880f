//! Issue 4: the rigid robot's real-time torque path, and how it splits
//! between the generated terms and the linear solves.
//! Run with `cargo bench -p flexdyn-parallel-robot --bench robot`.

use std::path::Path;

use criterion::{black_box, criterion_group, criterion_main, Criterion};
use flexdyn::codegen::interpret::{Function, Interpreted, Scratch};
use flexdyn::runtime::nalgebra::{SMatrix, SVector};
use flexdyn::runtime::{
    accelerations, DynamicsConfig, IntegratorOf, InverseConfig, InverseDynamics, InverseReport,
    InverseSolution, Model, Rk4, State,
};
use flexdyn_parallel_robot::robot::{inverse_kinematics, Circle, Geometry};
use flexdyn_parallel_robot::scenes::parallel_robot_rigid::ParallelRobotRigid;

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
    let mut report = InverseReport::default();
    group.bench_function("inverse_dynamics_call", |b| {
        b.iter(|| {
            // Advance along the circle so every call warm-starts from the last one.
            t += 0.001;
            let [p, v, a] = circle.at(t);
            report = solver
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
    {
        // Newton iterations and Jacobian factorisations per call along the
        // benchmarked motion (1 ms ticks).
        let mut s = solver;
        let mut out = sol;
        let (mut iterations, mut factorizations) = ([0u32; 8], [0u32; 8]);
        for k in 1..=2000 {
            let tk = t + 1e-3 * k as f64;
            let [p, v, a] = circle.at(tk);
            let r = s
                .solve(
                    &model,
                    tk,
                    &SVector::from(p),
                    &SVector::from(v),
                    &SVector::from(a),
                    &mut out,
                )
                .unwrap();
            iterations[(r.iterations as usize).min(7)] += 1;
            factorizations[(r.factorizations as usize).min(7)] += 1;
        }
        println!("2000 calls: Newton iterations histogram {iterations:?}, factorisations {factorizations:?}");
    }
    // The model evaluations one call makes, timed alone: Newton evaluates
    // Phi at its starting point and Phi with Phi_q (one fused program) at
    // each of its `iterations` iterates; then Phi_t, the fused
    // `dynamics_terms` (M, h, Phi_q, gamma) and B once. The rest of
    // `inverse_dynamics_call` is the linear algebra and the checks.
    println!(
        "inverse_dynamics_call: {} Newton iterations in the last call, {:?}",
        report.iterations, report
    );
    group.bench_function("generated_terms_of_one_call", |b| {
        let mut phi = SVector::<f64, 9>::zeros();
        let mut j = SMatrix::<f64, 9, 12>::zeros();
        let mut pt = SVector::<f64, 9>::zeros();
        let mut g = SVector::<f64, 9>::zeros();
        let mut m = SMatrix::<f64, 12, 12>::zeros();
        let mut h = SVector::<f64, 12>::zeros();
        let mut bm = SMatrix::<f64, 12, 3>::zeros();
        b.iter(|| {
            model.constraints(black_box(&q), 0.0, &mut phi);
            for _ in 0..report.iterations {
                model.constraints_and_jacobian(black_box(&q), 0.0, &mut phi, &mut j);
            }
            model.constraint_time_derivative(black_box(&q), 0.0, &mut pt);
            model.dynamics_terms(
                black_box(&q),
                black_box(&qd),
                0.0,
                &mut m,
                &mut h,
                &mut j,
                &mut g,
            );
            model.actuator_map(&mut bm);
            black_box((&phi, &j, &pt, &g, &m, &h, &bm));
        })
    });
    let tau = sol.tau;
    group.bench_function("forward_accelerations", |b| {
        let cfg = DynamicsConfig::default();
        b.iter(|| {
            accelerations(&model, &cfg, black_box(&q), black_box(&qd), 0.0, &tau)
                .unwrap()
                .qdd
        })
    });
    group.bench_function("rk4_step_1ms", |b| {
        let mut rk4 = Rk4::default();
        let start = State::new(q, qd, 0.0);
        b.iter(|| {
            let mut s = start;
            rk4.step(&model, black_box(&mut s), &tau, 1e-3).unwrap();
            s.q
        })
    });
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
    group.bench_function("constraints_and_jacobian", |b| {
        let mut phi = SVector::<f64, 9>::zeros();
        let mut j = SMatrix::<f64, 9, 12>::zeros();
        b.iter(|| model.constraints_and_jacobian(black_box(&q), 0.0, &mut phi, &mut j))
    });
    group.bench_function("dynamics_terms", |b| {
        let mut m = SMatrix::<f64, 12, 12>::zeros();
        let mut h = SVector::<f64, 12>::zeros();
        let mut j = SMatrix::<f64, 9, 12>::zeros();
        let mut g = SVector::<f64, 9>::zeros();
        b.iter(|| {
            model.dynamics_terms(
                black_box(&q),
                black_box(&qd),
                0.0,
                &mut m,
                &mut h,
                &mut j,
                &mut g,
            )
        })
    });
    // The same function from the scene file by the interpreter (what
    // `flexdyn` runs for a scene it has not compiled in), bitwise equal.
    group.bench_function("dynamics_terms_interpreted", |b| {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/parallel_robot_rigid.toml");
        let it = Interpreted::load(&path).unwrap_or_else(|e| panic!("{e}"));
        let tape = it
            .tape(Function::DynamicsTerms)
            .expect("every scene has it");
        let params: Vec<f64> = it.parameters().iter().map(|(_, v)| *v).collect();
        let (q, qd) = (q.as_slice().to_vec(), qd.as_slice().to_vec());
        let mut scratch = Scratch::default();
        let mut out = vec![0.0; tape.output_len()];
        b.iter(|| {
            tape.eval(
                black_box(&q),
                black_box(&qd),
                0.0,
                &params,
                &mut scratch,
                &mut out,
            );
            black_box(&out);
        })
    });
    group.finish();
}

/// The flexible robot (39 coordinates, kHz modes) with the generalized-alpha
/// integrator at the paper's 5 ms step, its Newton matrix from the generated
/// bias Jacobians against finite differences, from rest at the circle's
/// start under zero torque (the robot sags and swings under gravity).
fn flexible_robot(c: &mut Criterion) {
    use flexdyn::runtime::integrate::{GeneralizedAlpha, StepSettings};
    use flexdyn::runtime::FiniteDifferenceJacobians;
    use flexdyn_parallel_robot::robot::{initial_state, Layout};
    use flexdyn_parallel_robot::scenes::parallel_robot_flexible::ParallelRobotFlexible;
    let model = ParallelRobotFlexible::default();
    let layout = Layout::of(&model).unwrap();
    let p0 = Circle::paper(2.0).at(0.0)[0];
    let start = initial_state(&model, &layout, &Geometry::SPEC, 0.0, p0, [0.0; 3]).unwrap();
    let tau = SVector::<f64, 3>::zeros();
    let mut group = c.benchmark_group("parallel_robot_flexible");
    fn run<M: Model<39, 12, 3>>(
        group: &mut criterion::BenchmarkGroup<'_, criterion::measurement::WallTime>,
        name: &str,
        model: &M,
        start: State<39>,
        tau: &SVector<f64, 3>,
    ) {
        let mut integrator =
            GeneralizedAlpha::<39, 12>::new(StepSettings::default(), Default::default());
        let mut state = start;
        group.bench_function(name, |b| {
            b.iter(|| {
                if state.t > 1.0 {
                    state = start;
                }
                if let Err(e) = integrator.step(model, &mut state, tau, 0.005) {
                    panic!("{name}: {e:?}");
                }
                black_box(&state);
            })
        });
    }
    run(
        &mut group,
        "generalized_alpha_step_5ms",
        &model,
        start,
        &tau,
    );
    run(
        &mut group,
        "generalized_alpha_step_5ms_fd_jacobians",
        &FiniteDifferenceJacobians(model),
        start,
        &tau,
    );
    group.finish();
}

criterion_group!(benches, robot, flexible_robot);
criterion_main!(benches);
