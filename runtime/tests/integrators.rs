//! Accuracy of the integrators against closed-form solutions: convergence
//! order on a linear oscillator, the period of a large-amplitude pendulum
//! (complete elliptic integral), an adaptive run against the modal solution
//! of a two-mass chain; plus the input types and the implicit integrator's
//! history handling.

mod models;

use flexdyn_runtime::nalgebra::SymmetricEigen;
use flexdyn_runtime::{
    AdaptiveRk4, FromFn, GaussLegendre4, GeneralizedAlpha, GeneralizedAlphaConfig, Integrator,
    IntegratorOf, Linear, Model, Rk4, SemiImplicitEuler, State, StepSettings,
};
use models::*;

fn gen_alpha<const NQ: usize>(rho_inf: f64) -> GeneralizedAlpha<NQ, 0> {
    GeneralizedAlpha::new(
        StepSettings::default(),
        GeneralizedAlphaConfig {
            rho_inf,
            ..Default::default()
        },
    )
}

/// Error at t = 2 of x(t) for m x'' + k x = 0, x(0) = 0.3, x'(0) = -0.4.
fn oscillator_error<G: Integrator<1, 0, 1>>(g: &mut G, dt: f64) -> f64 {
    let model = SpringChain::<1> {
        m: [2.0],
        k: [50.0],
        c: [0.0],
        analytic: false,
    };
    let w = 5.0f64;
    let (x0, v0) = (0.3, -0.4);
    let mut s = State::new(V::<1>::new(x0), V::<1>::new(v0), 0.0);
    let n = (2.0 / dt).round() as usize;
    for _ in 0..n {
        g.step(&model, &mut s, &V::<1>::zeros(), dt).expect("step");
    }
    let exact = x0 * (w * s.t).cos() + v0 / w * (w * s.t).sin();
    (s.q[0] - exact).abs()
}

#[test]
fn convergence_orders_on_a_linear_oscillator() {
    let ratio = |mk: &mut dyn FnMut(f64) -> f64, dt: f64| {
        let (e1, e2) = (mk(dt), mk(dt / 2.0));
        (e1 / e2).log2()
    };
    let p_rk4 = ratio(&mut |dt| oscillator_error(&mut Rk4::default(), dt), 0.02);
    let p_gl = ratio(
        &mut |dt| oscillator_error(&mut GaussLegendre4::default(), dt),
        0.04,
    );
    let p_ga1 = ratio(
        &mut |dt| oscillator_error(&mut gen_alpha::<1>(1.0), dt),
        0.01,
    );
    let p_ga8 = ratio(
        &mut |dt| oscillator_error(&mut gen_alpha::<1>(0.8), dt),
        0.01,
    );
    let p_se = ratio(
        &mut |dt| oscillator_error(&mut SemiImplicitEuler::default(), dt),
        0.002,
    );
    println!("observed orders: RK4 {p_rk4:.2}, GL4 {p_gl:.2}, gen-alpha(1) {p_ga1:.2}, gen-alpha(0.8) {p_ga8:.2}, semi-implicit Euler {p_se:.2}");
    assert!((3.7..4.4).contains(&p_rk4));
    assert!((3.7..4.4).contains(&p_gl));
    assert!((1.8..2.3).contains(&p_ga1));
    assert!((1.8..2.3).contains(&p_ga8));
    assert!((0.8..1.3).contains(&p_se));
}

/// Measures the period of the pendulum released from rest at `theta0` from
/// the zero crossings of theta (cubic Hermite interpolation between steps).
fn pendulum_period<G: Integrator<1, 0, 1>>(g: &mut G, dt: f64, theta0: f64) -> f64 {
    let model = Pendulum::default();
    let mut s = State::new(V::<1>::new(theta0), V::<1>::zeros(), 0.0);
    let mut crossings = [0.0f64; 3];
    let mut found = 0;
    while found < 3 {
        let prev = s;
        g.step(&model, &mut s, &V::<1>::zeros(), dt).expect("step");
        if prev.q[0].signum() != s.q[0].signum() {
            let h = s.t - prev.t;
            let p = |x: f64| {
                let (x2, x3) = (x * x, x * x * x);
                (2.0 * x3 - 3.0 * x2 + 1.0) * prev.q[0]
                    + (x3 - 2.0 * x2 + x) * h * prev.qd[0]
                    + (-2.0 * x3 + 3.0 * x2) * s.q[0]
                    + (x3 - x2) * h * s.qd[0]
            };
            let (mut lo, mut hi) = (0.0, 1.0);
            for _ in 0..60 {
                let mid = 0.5 * (lo + hi);
                if p(mid).signum() == p(lo).signum() {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            crossings[found] = prev.t + 0.5 * (lo + hi) * h;
            found += 1;
        }
        assert!(s.t < 100.0);
    }
    crossings[2] - crossings[0]
}

#[test]
fn large_amplitude_pendulum_period_matches_elliptic_integral() {
    let p = Pendulum::default();
    let theta0: f64 = 2.0;
    let exact = 4.0 * (p.l / p.g).sqrt() * elliptic_k((theta0 / 2.0).sin());
    let rel = |t: f64| (t - exact).abs() / exact;
    let e_rk4 = rel(pendulum_period(&mut Rk4::default(), 1e-3, theta0));
    let e_gl = rel(pendulum_period(
        &mut GaussLegendre4::default(),
        1e-3,
        theta0,
    ));
    let mut adaptive = AdaptiveRk4::new(1e-10, 1e-12);
    let e_ad = rel(pendulum_period(&mut adaptive, 1e-2, theta0));
    let e_ga = rel(pendulum_period(&mut gen_alpha::<1>(1.0), 1e-4, theta0));
    let e_se = rel(pendulum_period(
        &mut SemiImplicitEuler::default(),
        1e-4,
        theta0,
    ));
    println!(
        "period {exact:.12} s, relative errors: RK4(1e-3) {e_rk4:.1e}, GL4(1e-3) {e_gl:.1e}, adaptive RK4(rtol 1e-10) {e_ad:.1e}, \
         gen-alpha(1e-4) {e_ga:.1e}, semi-implicit Euler(1e-4) {e_se:.1e}"
    );
    assert!(e_rk4 < 1e-10 && e_gl < 1e-10 && e_ad < 1e-9);
    assert!(e_ga < 1e-7 && e_se < 1e-4);
}

#[test]
fn adaptive_rk4_meets_tolerance_against_modal_solution() {
    let chain = SpringChain::<2> {
        m: [1.0, 0.5],
        k: [40.0, 300.0],
        c: [0.0; 2],
        analytic: false,
    };
    let (x0, v0) = (V::<2>::new(0.05, -0.02), V::<2>::new(0.0, 0.3));
    // Exact solution by modal decomposition (nalgebra's symmetric eigensolver,
    // not used by the runtime): y = M^1/2 x, y'' + M^-1/2 K M^-1/2 y = 0.
    let mh = V::<2>::new(chain.m[0].sqrt(), chain.m[1].sqrt());
    let kt = Mat::<2, 2>::from_fn(|i, j| chain.stiffness()[(i, j)] / (mh[i] * mh[j]));
    let eig = SymmetricEigen::new(kt);
    let exact = |t: f64| {
        let y0 = eig.eigenvectors.transpose() * x0.component_mul(&mh);
        let yd0 = eig.eigenvectors.transpose() * v0.component_mul(&mh);
        let mut y = V::<2>::zeros();
        for i in 0..2 {
            let w = eig.eigenvalues[i].sqrt();
            y[i] = y0[i] * (w * t).cos() + yd0[i] / w * (w * t).sin();
        }
        (eig.eigenvectors * y).component_div(&mh)
    };
    let mut steps_at = Vec::new();
    for rtol in [1e-6, 1e-9] {
        let mut g = AdaptiveRk4::new(rtol, rtol * 1e-2);
        let mut s = State::new(x0, v0, 0.0);
        let r = g
            .advance_to(&chain, &mut s, &V::<1>::zeros(), 5.0, 1e-3, 100_000)
            .expect("advance");
        assert!(r.reached && (s.t - 5.0).abs() < 1e-12);
        let err = (s.q - exact(5.0)).amax() / x0.amax();
        println!(
            "adaptive RK4 rtol {rtol:.0e}: {} steps, {} rejections, relative error {err:.1e}",
            r.steps, r.rejections
        );
        assert!(err < 100.0 * rtol, "error {err:e} for rtol {rtol:e}");
        steps_at.push(r.steps);
    }
    assert!(steps_at[1] > steps_at[0]);
    // As an Integrator it advances by exactly the requested interval.
    let mut g = AdaptiveRk4::new(1e-8, 1e-10);
    let mut s = State::new(x0, v0, 0.0);
    let rep = g
        .step(&chain, &mut s, &V::<1>::zeros(), 0.25)
        .expect("step");
    assert_eq!(s.t, 0.25);
    assert!(rep.iterations >= 1);
    assert!((s.q - exact(0.25)).amax() < 1e-7);
}

#[test]
fn time_varying_inputs_are_sampled_at_stage_times() {
    // Pendulum driven by tau(t) = 0.5 + 2 t. Linear and closure inputs agree
    // and differ from a zero-order hold.
    let model = Pendulum {
        c: 0.2,
        ..Default::default()
    };
    let s0 = State::new(V::<1>::new(0.3), V::<1>::new(0.1), 0.0);
    let dt = 0.01;
    let f = |t: f64| V::<1>::new(0.5 + 2.0 * t);
    let lin = Linear {
        t0: 0.0,
        tau0: f(0.0),
        t1: dt,
        tau1: f(dt),
    };
    let (mut a, mut b, mut c) = (s0, s0, s0);
    Rk4::default().step(&model, &mut a, &lin, dt).expect("step");
    Rk4::default()
        .step(&model, &mut b, &FromFn(f), dt)
        .expect("step");
    Rk4::default()
        .step(&model, &mut c, &f(0.0), dt)
        .expect("step");
    assert!((a.q - b.q).amax() < 1e-15 && (a.qd - b.qd).amax() < 1e-15);
    assert!((a.qd - c.qd).amax() > 1e-5);
}

#[test]
fn generalized_alpha_reinitialises_when_handed_a_different_state() {
    let model = DoublePendulum::default();
    let tau = V::<2>::new(0.1, -0.2);
    let mut g = gen_alpha::<2>(0.8);
    let mut s = State::new(V::<2>::new(0.4, 0.2), V::<2>::zeros(), 0.0);
    for _ in 0..5 {
        g.step(&model, &mut s, &tau, 1e-3).expect("step");
    }
    // Externally modified state: must behave exactly like a fresh integrator.
    s.qd[0] += 0.1;
    let (mut s1, mut s2) = (s, s);
    g.step(&model, &mut s1, &tau, 1e-3).expect("step");
    gen_alpha::<2>(0.8)
        .step(&model, &mut s2, &tau, 1e-3)
        .expect("step");
    assert_eq!(s1, s2);
    // Continuing with the same integrator uses its history: different from restarting.
    let (mut s3, mut s4) = (s1, s1);
    g.step(&model, &mut s3, &tau, 1e-3).expect("step");
    gen_alpha::<2>(0.8)
        .step(&model, &mut s4, &tau, 1e-3)
        .expect("step");
    assert!(s3 != s4 && (s3.q - s4.q).amax() < 1e-6);
    let _ = DoublePendulum::NAME;
}
