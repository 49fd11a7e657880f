//! Issues 3 and 7: nanoseconds per generated term (`M`, `h`, `Phi_q`,
//! `gamma`, and the fused `dynamics_terms`), per inverse-dynamics call and
//! per integrator step for the generated five-bar and slider-crank scenes.
//! Run with `cargo bench --bench scenes`.

use criterion::{black_box, criterion_group, criterion_main, Criterion};
use flexdyn::runtime::integrate::{
    GaussLegendre4, GeneralizedAlpha, Rk4, SemiImplicitEuler, StepSettings,
};
use flexdyn::runtime::nalgebra::{SMatrix, SVector};
use flexdyn::runtime::{
    FiniteDifferenceJacobians, Integrator, InverseConfig, InverseDynamics, InverseSolution, Model,
    State,
};
use flexdyn::scenes::{five_bar::FiveBar, slider_crank::SliderCrank};

/// Consistent start of the slider-crank: crank angle theta, rod angle and
/// slider position from the closure equations.
fn slider_crank_state(theta: f64, omega: f64) -> State<3> {
    let (r, l) = (0.1, 0.3);
    let phi = (r * theta.sin() / l).asin();
    let x = r * theta.cos() + l * phi.cos();
    let phid = r * theta.cos() * omega / (l * phi.cos());
    let xd = -r * theta.sin() * omega - l * phi.sin() * phid;
    State::new(
        SVector::from([theta, phi, x]),
        SVector::from([omega, phid, xd]),
        0.0,
    )
}

fn steps<M, G, const NQ: usize, const NC: usize, const NU: usize>(
    c: &mut Criterion,
    name: &str,
    model: &M,
    start: State<NQ>,
    mut integrator: G,
) where
    M: Model<NQ, NC, NU>,
    G: Integrator<NQ, NC, NU>,
{
    let tau = SVector::<f64, NU>::zeros();
    let mut state = start;
    c.bench_function(name, |b| {
        b.iter(|| {
            if integrator.step(model, &mut state, &tau, 1e-3).is_err() {
                state = start;
            }
            black_box(&state);
        })
    });
}

/// Each generated term at one consistent state.
fn terms<M, const NQ: usize, const NC: usize, const NU: usize>(
    c: &mut Criterion,
    scene: &str,
    model: &M,
    s: &State<NQ>,
) where
    M: Model<NQ, NC, NU>,
{
    let (q, qd) = (black_box(s.q), black_box(s.qd));
    let mut m = SMatrix::<f64, NQ, NQ>::zeros();
    let mut h = SVector::<f64, NQ>::zeros();
    let mut j = SMatrix::<f64, NC, NQ>::zeros();
    let mut g = SVector::<f64, NC>::zeros();
    c.bench_function(&format!("{scene}/mass_matrix"), |b| {
        b.iter(|| model.mass_matrix(&q, 0.0, black_box(&mut m)))
    });
    c.bench_function(&format!("{scene}/bias"), |b| {
        b.iter(|| model.bias(&q, &qd, 0.0, black_box(&mut h)))
    });
    c.bench_function(&format!("{scene}/constraint_jacobian"), |b| {
        b.iter(|| model.constraint_jacobian(&q, 0.0, black_box(&mut j)))
    });
    c.bench_function(&format!("{scene}/constraint_rhs"), |b| {
        b.iter(|| model.constraint_rhs(&q, &qd, 0.0, black_box(&mut g)))
    });
    c.bench_function(&format!("{scene}/dynamics_terms"), |b| {
        b.iter(|| model.dynamics_terms(&q, &qd, 0.0, &mut m, &mut h, &mut j, black_box(&mut g)))
    });
}

fn slider_crank(c: &mut Criterion) {
    let model = SliderCrank;
    let start = slider_crank_state(0.3, 5.0);
    terms(c, "slider_crank", &model, &start);
    steps(
        c,
        "slider_crank/rk4_step",
        &model,
        start,
        Rk4::new(StepSettings::default()),
    );
    steps(
        c,
        "slider_crank/semi_implicit_step",
        &model,
        start,
        SemiImplicitEuler::new(StepSettings::default()),
    );
    steps(
        c,
        "slider_crank/gauss_legendre4_step",
        &model,
        start,
        GaussLegendre4::new(StepSettings::default()),
    );
    steps(
        c,
        "slider_crank/generalized_alpha_step",
        &model,
        start,
        GeneralizedAlpha::<3, 2>::new(StepSettings::default(), Default::default()),
    );
    steps(
        c,
        "slider_crank/generalized_alpha_step_fd_jacobians",
        &FiniteDifferenceJacobians(model),
        start,
        GeneralizedAlpha::<3, 2>::new(StepSettings::default(), Default::default()),
    );
    // Inverse dynamics: the crank angle is prescribed.
    let mut solver =
        InverseDynamics::<3, 2, 1, 1>::new([0], start.q, InverseConfig::default()).unwrap();
    let mut sol = InverseSolution::<3, 2, 1>::default();
    let mut t: f64 = 0.0;
    c.bench_function("slider_crank/inverse_dynamics_call", |b| {
        b.iter(|| {
            t += 1e-3;
            let th = 0.3 + 5.0 * t;
            solver
                .solve(
                    &model,
                    t,
                    &SVector::from([th]),
                    &SVector::from([5.0]),
                    &SVector::from([0.0]),
                    &mut sol,
                )
                .unwrap();
            black_box(&sol.tau);
        })
    });
}

fn five_bar(c: &mut Criterion) {
    let model = FiveBar;
    // A consistent pose: theta1 = 2.0, theta2 = 1.1, distal angles by Newton
    // through the inverse-dynamics solver (prescribing the two actuated angles).
    let guess = SVector::from([2.0, 1.1, 0.9, 2.2]);
    let mut solver =
        InverseDynamics::<4, 2, 2, 2>::new([0, 1], guess, InverseConfig::default()).unwrap();
    let mut sol = InverseSolution::<4, 2, 2>::default();
    solver
        .solve(
            &model,
            0.0,
            &SVector::from([2.0, 1.1]),
            &SVector::from([0.5, -0.5]),
            &SVector::zeros(),
            &mut sol,
        )
        .unwrap();
    let start = State::new(sol.q, sol.qd, 0.0);
    terms(c, "five_bar", &model, &start);
    steps(
        c,
        "five_bar/rk4_step",
        &model,
        start,
        Rk4::new(StepSettings::default()),
    );
    steps(
        c,
        "five_bar/semi_implicit_step",
        &model,
        start,
        SemiImplicitEuler::new(StepSettings::default()),
    );
    steps(
        c,
        "five_bar/gauss_legendre4_step",
        &model,
        start,
        GaussLegendre4::new(StepSettings::default()),
    );
    steps(
        c,
        "five_bar/generalized_alpha_step",
        &model,
        start,
        GeneralizedAlpha::<4, 2>::new(StepSettings::default(), Default::default()),
    );
    steps(
        c,
        "five_bar/generalized_alpha_step_fd_jacobians",
        &FiniteDifferenceJacobians(model),
        start,
        GeneralizedAlpha::<4, 2>::new(StepSettings::default(), Default::default()),
    );
    let mut t: f64 = 0.0;
    c.bench_function("five_bar/inverse_dynamics_call", |b| {
        b.iter(|| {
            t += 1e-3;
            let (a, w) = ((3.0 * t).sin(), (3.0 * t).cos());
            let p = SVector::from([2.0 + 0.1 * a, 1.1 - 0.1 * a]);
            let v = SVector::from([0.3 * w, -0.3 * w]);
            let acc = SVector::from([-0.9 * a, 0.9 * a]);
            solver.solve(&model, t, &p, &v, &acc, &mut sol).unwrap();
            black_box(&sol.tau);
        })
    });
}

criterion_group!(benches, slider_crank, five_bar);
criterion_main!(benches);
