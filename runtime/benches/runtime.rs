//! Per-call timings of the runtime with the hand-written test models.
//! Run with `cargo bench -p flexdyn-runtime`.

#[path = "../tests/models/mod.rs"]
mod models;

use criterion::{criterion_group, criterion_main, Criterion};
use flexdyn_runtime::{
    accelerations, DynamicsConfig, GaussLegendre4, GeneralizedAlpha, GeneralizedAlphaConfig,
    IntegratorOf, InverseConfig, InverseDynamics, InverseSolution, Rk4, State, StepSettings,
};
use models::*;
use std::hint::black_box;

fn forward(c: &mut Criterion) {
    let sc = SliderCrank::default();
    let s = sc.consistent_state(0.7, 5.0);
    let cfg = DynamicsConfig::default();
    c.bench_function("accelerations/slider_crank", |b| {
        b.iter(|| accelerations(black_box(&sc), &cfg, &s.q, &s.qd, 0.0, &V::<1>::new(0.1)))
    });
}

fn steps(c: &mut Criterion) {
    let dp = DoublePendulum::default();
    let dp0 = State::new(V::<2>::new(0.8, -0.5), V::<2>::zeros(), 0.0);
    let tau2 = V::<2>::zeros();
    c.bench_function("rk4_step/double_pendulum", |b| {
        let mut g = Rk4::default();
        let mut s = dp0;
        b.iter(|| {
            s = dp0;
            g.step(black_box(&dp), &mut s, &tau2, 1e-3)
        })
    });
    c.bench_function("gauss_legendre4_step/double_pendulum", |b| {
        let mut g = GaussLegendre4::default();
        let mut s = dp0;
        b.iter(|| {
            s = dp0;
            g.step(black_box(&dp), &mut s, &tau2, 1e-3)
        })
    });
    let sc = SliderCrank::default();
    let sc0 = sc.consistent_state(0.3, 8.0);
    let tau1 = V::<1>::zeros();
    c.bench_function("rk4_step_projected/slider_crank", |b| {
        let mut g = Rk4::new(StepSettings::with_projection());
        let mut s = sc0;
        b.iter(|| {
            s = sc0;
            g.step(black_box(&sc), &mut s, &tau1, 1e-3)
        })
    });
    c.bench_function(
        "gen_alpha_step_projected/slider_crank (continuing run)",
        |b| {
            let mut g = GeneralizedAlpha::<3, 2>::new(
                StepSettings::with_projection(),
                GeneralizedAlphaConfig::default(),
            );
            let mut s = sc0;
            b.iter(|| g.step(black_box(&sc), &mut s, &tau1, 1e-3))
        },
    );
    let chain = SpringChain::<4>::stiff();
    let ch0 = State::new(V::<4>::from_element(0.01), V::<4>::zeros(), 0.0);
    c.bench_function("gen_alpha_step/stiff_chain_5ms (continuing run)", |b| {
        let mut g = GeneralizedAlpha::<4, 0>::default();
        let mut s = ch0;
        b.iter(|| g.step(black_box(&chain), &mut s, &tau1, 5e-3))
    });
}

fn inverse(c: &mut Criterion) {
    let fb = FiveBar::<2>::default();
    let mut id = InverseDynamics::<6, 4, 2, 2>::new(
        [4, 5],
        fb.assemble(0.04, 0.32),
        InverseConfig::default(),
    )
    .expect("set-up");
    let mut out = InverseSolution::default();
    let mut t = 0.0f64;
    c.bench_function("inverse_dynamics_tick/five_bar", |b| {
        b.iter(|| {
            t += 1e-3;
            let w = std::f64::consts::PI;
            let (s, co) = (w * t).sin_cos();
            let p = V::<2>::new(0.04 * co, 0.32 + 0.04 * s);
            let v = V::<2>::new(-0.04 * w * s, 0.04 * w * co);
            let a = V::<2>::new(-0.04 * w * w * co, -0.04 * w * w * s);
            id.solve(black_box(&fb), t, &p, &v, &a, &mut out)
        })
    });
}

criterion_group!(benches, forward, steps, inverse);
criterion_main!(benches);
