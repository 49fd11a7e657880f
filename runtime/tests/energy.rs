//! Energy conservation on conservative scenes (no input, no damping).
//!
//! The reference is the model's own `T + V` at t = 0: no solver output is
//! used as a reference. Fine-step runs must conserve energy to 1e-8 relative
//! over 10 s; coarse-step drifts are printed (`--nocapture`) and only loosely
//! bounded.

mod models;

use flexdyn_runtime::{
    total_energy, GaussLegendre4, GeneralizedAlpha, GeneralizedAlphaConfig, Integrator,
    IntegratorOf, Model, Rk4, SemiImplicitEuler, State, StepSettings,
};
use models::*;

/// Runs `t_end / dt` steps with zero input; returns the largest relative
/// deviation of `T + V` from its initial value and the largest position drift.
fn energy_deviation<M, G, const NQ: usize, const NC: usize, const NU: usize>(
    model: &M,
    integrator: &mut G,
    s0: State<NQ>,
    dt: f64,
    t_end: f64,
) -> (f64, f64)
where
    M: Model<NQ, NC, NU>,
    G: Integrator<NQ, NC, NU>,
{
    let mut s = s0;
    let e0 = total_energy(model, &s);
    let tau = V::<NU>::zeros();
    let steps = (t_end / dt).round() as usize;
    let (mut dev, mut drift) = (0.0f64, 0.0f64);
    for _ in 0..steps {
        let r = integrator
            .step(model, &mut s, &tau, dt)
            .expect("step failed");
        dev = dev.max((total_energy(model, &s) - e0).abs() / e0.abs());
        drift = drift.max(r.drift.position);
    }
    assert!((s.t - t_end).abs() < 1e-9 * t_end);
    (dev, drift)
}

fn double_pendulum_start() -> State<2> {
    State::new(V::<2>::new(0.8, -0.5), V::<2>::zeros(), 0.0)
}

fn gen_alpha<const NQ: usize, const NC: usize>(
    settings: StepSettings,
    rho_inf: f64,
) -> GeneralizedAlpha<NQ, NC> {
    GeneralizedAlpha::new(
        settings,
        GeneralizedAlphaConfig {
            rho_inf,
            ..Default::default()
        },
    )
}

#[test]
fn double_pendulum_energy_fine_step() {
    let model = DoublePendulum::default();
    // E0 = -(m1+m2) g l1 cos(0.8) - m2 g l2 cos(0.5) = -16.45 J.
    let (gl, _) = energy_deviation(
        &model,
        &mut GaussLegendre4::default(),
        double_pendulum_start(),
        1e-3,
        10.0,
    );
    println!("double pendulum, Gauss-Legendre 4, dt = 1e-3: max |dE/E0| = {gl:.2e}");
    assert!(gl < 1e-8, "Gauss-Legendre energy deviation {gl:e}");
    let (ga, _) = energy_deviation(
        &model,
        &mut gen_alpha::<2, 0>(StepSettings::default(), 1.0),
        double_pendulum_start(),
        2e-5,
        10.0,
    );
    println!("double pendulum, generalized-alpha rho=1, dt = 2e-5: max |dE/E0| = {ga:.2e}");
    assert!(ga < 1e-8, "generalized-alpha energy deviation {ga:e}");
}

#[test]
fn slider_crank_energy_fine_step() {
    let model = SliderCrank::default();
    let s0 = model.consistent_state(0.3, 8.0);
    let mut gl = GaussLegendre4::new(StepSettings::with_projection());
    let (dev, drift) = energy_deviation(&model, &mut gl, s0, 2.5e-4, 10.0);
    println!("slider-crank, Gauss-Legendre 4 + projection, dt = 2.5e-4: max |dE/E0| = {dev:.2e}, max |Phi| = {drift:.1e}");
    assert!(dev < 1e-8, "energy deviation {dev:e}");
    assert!(drift < 1e-11);
}

#[test]
fn coarse_step_energy_drift_is_reported() {
    let dp = DoublePendulum::default();
    let sc = SliderCrank::default();
    let sc0 = sc.consistent_state(0.3, 8.0);
    println!("max |dE/E0| over 10 s (coarse steps):");
    for dt in [1e-2, 5e-3] {
        let rk = energy_deviation(&dp, &mut Rk4::default(), double_pendulum_start(), dt, 10.0).0;
        let gl = energy_deviation(
            &dp,
            &mut GaussLegendre4::default(),
            double_pendulum_start(),
            dt,
            10.0,
        )
        .0;
        let ga1 = energy_deviation(
            &dp,
            &mut gen_alpha::<2, 0>(StepSettings::default(), 1.0),
            double_pendulum_start(),
            dt,
            10.0,
        )
        .0;
        let ga8 = energy_deviation(
            &dp,
            &mut gen_alpha::<2, 0>(StepSettings::default(), 0.8),
            double_pendulum_start(),
            dt,
            10.0,
        )
        .0;
        let se = energy_deviation(
            &dp,
            &mut SemiImplicitEuler::default(),
            double_pendulum_start(),
            dt,
            10.0,
        )
        .0;
        println!(
            "  double pendulum dt={dt:.0e}: RK4 {rk:.1e}  GL4 {gl:.1e}  gen-alpha(1) {ga1:.1e}  gen-alpha(0.8) {ga8:.1e}  semi-implicit Euler {se:.1e}"
        );
        // Loose sanity bounds (orders of the schemes), not tuned values.
        assert!(rk < 1e-4 && gl < 1e-4 && ga1 < 1e-2 && ga8 < 1e-1 && se < 0.5);
    }
    for dt in [2e-3, 1e-3] {
        let p = StepSettings::with_projection();
        let rk = energy_deviation(&sc, &mut Rk4::new(p), sc0, dt, 10.0).0;
        let gl = energy_deviation(&sc, &mut GaussLegendre4::new(p), sc0, dt, 10.0).0;
        let ga1 = energy_deviation(&sc, &mut gen_alpha::<3, 2>(p, 1.0), sc0, dt, 10.0).0;
        let ga8 = energy_deviation(&sc, &mut gen_alpha::<3, 2>(p, 0.8), sc0, dt, 10.0).0;
        let se = energy_deviation(&sc, &mut SemiImplicitEuler::new(p), sc0, dt, 10.0).0;
        println!(
            "  slider-crank (projection) dt={dt:.0e}: RK4 {rk:.1e}  GL4 {gl:.1e}  gen-alpha(1) {ga1:.1e}  gen-alpha(0.8) {ga8:.1e}  semi-implicit Euler {se:.1e}"
        );
        // Semi-implicit Euler treats the velocity-dependent (centrifugal)
        // forces explicitly and gains energy here at coarse steps: reported,
        // not bounded.
        assert!(rk < 1e-3 && gl < 1e-3 && ga1 < 1e-1 && ga8 < 1e-1 && se.is_finite());
    }
}

#[test]
fn semi_implicit_euler_is_symplectic_on_a_separable_system() {
    // Constant mass matrix: symplectic Euler has a bounded energy error with
    // no secular drift. Compare the error envelope over the first and the
    // last tenth of a long run, and the O(dt) scaling of its size.
    let chain = SpringChain::<3> {
        m: [1.0, 2.0, 1.5],
        k: [30.0, 50.0, 20.0],
        c: [0.0; 3],
        analytic: false,
    };
    let s0 = State::new(
        V::<3>::new(0.1, -0.05, 0.2),
        V::<3>::new(0.0, 0.3, 0.0),
        0.0,
    );
    let e0 = total_energy(&chain, &s0);
    let envelope = |dt: f64| {
        let n = (200.0 / dt) as usize;
        let mut s = s0;
        let mut g = SemiImplicitEuler::default();
        let (mut first, mut last) = (0.0f64, 0.0f64);
        for k in 0..n {
            g.step(&chain, &mut s, &V::<1>::zeros(), dt).expect("step");
            let d = (total_energy(&chain, &s) - e0).abs() / e0;
            if k < n / 10 {
                first = first.max(d);
            } else if k >= n - n / 10 {
                last = last.max(d);
            }
        }
        (first, last)
    };
    let (f1, l1) = envelope(1e-2);
    let (f2, l2) = envelope(5e-3);
    println!("semi-implicit Euler, spring chain, 200 s: dt=1e-2 envelope {f1:.2e} -> {l1:.2e}; dt=5e-3 {f2:.2e} -> {l2:.2e}");
    assert!(l1 < 1.5 * f1 && l2 < 1.5 * f2, "secular drift");
    let ratio = f1 / f2;
    assert!(
        (1.6..2.5).contains(&ratio),
        "energy error should be O(dt): ratio {ratio}"
    );
}
