//! The implicit scheme on stiff models at a 5 ms step: a spring-mass chain
//! with a ~1 Hz mode and modes up to ~3 kHz, and an elastic pendulum with a
//! 2 kHz axial mode.

mod models;

use flexdyn_runtime::nalgebra::SymmetricEigen;
use flexdyn_runtime::{
    total_energy, ErrorKind, GeneralizedAlpha, GeneralizedAlphaConfig, IntegratorOf, Rk4, State,
    StepSettings,
};
use models::*;

const DT: f64 = 0.005;

fn gen_alpha<const NQ: usize>(rho_inf: f64) -> GeneralizedAlpha<NQ, 0> {
    GeneralizedAlpha::new(
        StepSettings::default(),
        GeneralizedAlphaConfig {
            rho_inf,
            ..Default::default()
        },
    )
}

/// Natural frequencies (rad/s) and mass-normalised mode shapes of the chain.
fn modes(chain: &SpringChain<4>) -> (V<4>, Mat<4, 4>) {
    let mh = V::<4>::from_fn(|i, _| chain.m[i].sqrt());
    let kt = Mat::<4, 4>::from_fn(|i, j| chain.stiffness()[(i, j)] / (mh[i] * mh[j]));
    let eig = SymmetricEigen::new(kt);
    let w = eig.eigenvalues.map(f64::sqrt);
    let shapes = Mat::<4, 4>::from_fn(|i, j| eig.eigenvectors[(i, j)] / mh[i]);
    (w, shapes)
}

#[test]
fn chain_modes_span_hz_to_khz() {
    let (w, _) = modes(&SpringChain::<4>::stiff());
    let f = w / (2.0 * core::f64::consts::PI);
    println!("chain natural frequencies (Hz): {:?}", f.as_slice());
    assert!(f.min() < 1.1 && f.max() > 2000.0 && f.max() < 5000.0);
}

#[test]
fn generalized_alpha_is_stable_at_5ms_and_tracks_the_slow_mode() {
    let chain = SpringChain::<4>::stiff();
    let (w, shapes) = modes(&chain);
    let slow = (0..4).min_by(|&a, &b| w[a].total_cmp(&w[b])).unwrap_or(0);
    // Start exactly in the slow mode (amplitude 1 cm on the heavy mass).
    let phi = shapes.column(slow) * (0.01 / shapes[(0, slow)]);
    let s0 = State::new(phi.into_owned(), V::<4>::zeros(), 0.0);
    let e0 = total_energy(&chain, &s0);
    for rho in [1.0, 0.8, 0.5, 0.0] {
        for analytic in [false, true] {
            let model = SpringChain { analytic, ..chain };
            let mut g = gen_alpha::<4>(rho);
            let mut s = s0;
            let (mut emax, mut err, mut iters) = (0.0f64, 0.0f64, 0u32);
            for _ in 0..2000 {
                let r = g.step(&model, &mut s, &V::<1>::zeros(), DT).expect("step");
                iters = iters.max(r.iterations);
                emax = emax.max(total_energy(&model, &s));
                let exact = 0.01 * (w[slow] * s.t).cos();
                err = err.max((s.q[0] - exact).abs() / 0.01);
            }
            println!(
                "rho_inf {rho}, analytic Jacobian {analytic}: 10 s, max E/E0 = {:.8}, max Newton iterations {iters}, \
                 slow-mode error {err:.1e} of amplitude",
                emax / e0
            );
            assert!(emax <= e0 * (1.0 + 1e-6), "energy grew");
            assert!(iters <= 4);
            // Phase error of a second-order scheme at w dt = 0.031 over 10
            // periods: about (w dt)^2 / 12 * w t = 5e-3 for rho_inf near 1;
            // rho_inf = 0 has a larger error constant (and amplitude decay).
            let bound = if rho > 0.4 { 1e-2 } else { 5e-2 };
            assert!(err < bound, "slow mode error {err}");
        }
    }
}

#[test]
fn unresolved_khz_modes_are_damped_not_amplified() {
    let chain = SpringChain::<4>::stiff();
    let (w, shapes) = modes(&chain);
    let fast = (0..4).max_by(|&a, &b| w[a].total_cmp(&w[b])).unwrap_or(0);
    // Excite the fastest mode (w dt ~ 100) with 1 micrometre amplitude.
    let phi = shapes.column(fast) * (1e-6 / shapes.column(fast).amax());
    let s0 = State::new(phi.into_owned(), V::<4>::zeros(), 0.0);
    let e0 = total_energy(&chain, &s0);
    let run = |rho: f64| {
        let mut g = gen_alpha::<4>(rho);
        let mut s = s0;
        let mut emax = 0.0f64;
        for _ in 0..200 {
            g.step(&chain, &mut s, &V::<1>::zeros(), DT).expect("step");
            emax = emax.max(total_energy(&chain, &s));
        }
        (emax / e0, total_energy(&chain, &s) / e0)
    };
    for rho in [1.0, 0.8, 0.5, 0.0] {
        let (emax, efinal) = run(rho);
        println!("fast mode, rho_inf {rho}: max E/E0 {emax:.3e}, E/E0 after 1 s {efinal:.3e}");
        // No start-up overshoot (filtered initial auxiliary acceleration).
        assert!(emax <= 1.0 + 1e-6, "energy overshoot {emax}");
        if rho < 0.9 {
            // Spectral radius rho_inf per step: energy factor rho^(2 n).
            assert!(efinal < 1e-6, "not damped: {efinal}");
        } else {
            assert!(efinal > 0.99, "rho_inf = 1 must not dissipate");
        }
    }
}

#[test]
fn explicit_rk4_refuses_the_same_step() {
    let chain = SpringChain::<4>::stiff();
    let mut s = State::new(V::<4>::new(0.01, 0.01, 0.01, 0.01), V::<4>::zeros(), 0.0);
    let before = s;
    let e = Rk4::default()
        .step(&chain, &mut s, &V::<1>::zeros(), DT)
        .expect_err("must fail");
    match e.kind {
        ErrorKind::StepTooLarge { value, limit, .. } => {
            println!("RK4 at 5 ms: estimated dt*rho = {value:.1} > {limit}");
            assert!(value > limit);
        }
        other => panic!("unexpected {other:?}"),
    }
    assert_eq!(s, before);
}

#[test]
fn elastic_pendulum_at_5ms_matches_rigid_pendulum_period() {
    let model = ElasticPendulum::default();
    let theta0: f64 = 0.5;
    // Static stretch of the spring at the bottom; the swing is that of a rigid
    // pendulum of length L = l0 + m g / k to within ~1e-8.
    let length = model.l0 + model.m * model.g / model.k;
    let exact = 4.0 * (length / model.g).sqrt() * elliptic_k((theta0 / 2.0).sin());
    // Start with the spring at its static stretch for theta0.
    let r0 = model.l0 + model.m * model.g * theta0.cos() / model.k;
    let mut s = State::new(V::<2>::new(r0, theta0), V::<2>::zeros(), 0.0);
    let e0 = total_energy(&model, &s);
    let mut g = gen_alpha::<2>(0.8);
    let mut crossings = Vec::new();
    let mut iters = 0;
    while crossings.len() < 11 {
        let prev = s;
        let r = g.step(&model, &mut s, &V::<1>::zeros(), DT).expect("step");
        iters = iters.max(r.iterations);
        assert!(total_energy(&model, &s) <= e0 + 1e-9 * e0.abs());
        if prev.q[1].signum() != s.q[1].signum() {
            // Linear interpolation is enough at theta = 0 (theta'' = 0 there).
            crossings.push(prev.t + DT * prev.q[1] / (prev.q[1] - s.q[1]));
        }
        assert!(s.t < 60.0);
    }
    let period = (crossings[10] - crossings[0]) / 5.0;
    let rel = (period - exact).abs() / exact;
    println!("elastic pendulum (2 kHz axial mode), dt 5 ms: period {period:.6} s vs {exact:.6} s, rel. error {rel:.1e}, max iterations {iters}");
    assert!(rel < 1e-4);
    assert!(iters <= 5);
}
