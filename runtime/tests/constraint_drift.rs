//! Constraint drift over long runs of the slider-crank (closed loop in
//! redundant coordinates): below 1e-9 with projection, bounded with
//! Baumgarte stabilisation alone, growing without either.

mod models;

use flexdyn_runtime::{
    run, Baumgarte, DynamicsConfig, GeneralizedAlpha, GeneralizedAlphaConfig, Integrator, Rk4,
    State, StepSettings,
};
use models::*;

/// Runs `t_end / dt` steps; returns the largest position and velocity drift
/// over the first and over the last tenth of the run.
fn drift_history<G: Integrator<3, 2, 1>>(g: &mut G, dt: f64, t_end: f64) -> ([f64; 2], [f64; 2]) {
    let model = SliderCrank::default();
    let mut s: State<3> = model.consistent_state(0.3, 8.0);
    let n = (t_end / dt).round() as usize;
    let (mut first, mut last) = ([0.0f64; 2], [0.0f64; 2]);
    let mut k = 0usize;
    run(g, &model, &mut s, &V::<1>::zeros(), dt, n, |_, r| {
        let slot = if k < n / 10 {
            Some(&mut first)
        } else if k >= n - n / 10 {
            Some(&mut last)
        } else {
            None
        };
        if let Some(m) = slot {
            m[0] = m[0].max(r.drift.position);
            m[1] = m[1].max(r.drift.velocity);
        }
        k += 1;
    })
    .expect("run failed");
    (first, last)
}

#[test]
fn projection_keeps_drift_below_1e_9_for_100_s() {
    let (f, l) = drift_history(&mut Rk4::new(StepSettings::with_projection()), 1e-3, 100.0);
    println!(
        "RK4 + projection, dt 1e-3, 100 s: |Phi| <= {:.1e}, |Phi_q qd| <= {:.1e}",
        f[0].max(l[0]),
        f[1].max(l[1])
    );
    assert!(f[0].max(l[0]) < 1e-9 && f[1].max(l[1]) < 1e-9);
    let mut ga = GeneralizedAlpha::<3, 2>::new(
        StepSettings::with_projection(),
        GeneralizedAlphaConfig::default(),
    );
    let (f, l) = drift_history(&mut ga, 2e-3, 100.0);
    println!(
        "generalized-alpha + projection, dt 2e-3, 100 s: |Phi| <= {:.1e}, |Phi_q qd| <= {:.1e}",
        f[0].max(l[0]),
        f[1].max(l[1])
    );
    assert!(f[0].max(l[0]) < 1e-9 && f[1].max(l[1]) < 1e-9);
}

#[test]
fn baumgarte_alone_keeps_drift_bounded() {
    let baumgarte = StepSettings::default(); // alpha = beta = 10 / s, no projection
    assert!(baumgarte.projection.is_none());
    let (f, l) = drift_history(&mut Rk4::new(baumgarte), 1e-3, 100.0);
    println!(
        "RK4 + Baumgarte, dt 1e-3: first 10 s |Phi| <= {:.1e}, last 10 s <= {:.1e}",
        f[0], l[0]
    );
    // Bounded: no growth between the first and the last ten seconds, and small.
    assert!(l[0] <= 3.0 * f[0] && l[0] < 1e-8, "{f:?} {l:?}");
    let mut ga = GeneralizedAlpha::<3, 2>::new(baumgarte, GeneralizedAlphaConfig::default());
    let (f, l) = drift_history(&mut ga, 2e-3, 100.0);
    println!(
        "generalized-alpha + Baumgarte, dt 2e-3: first 10 s |Phi| <= {:.1e}, last 10 s <= {:.1e}",
        f[0], l[0]
    );
    assert!(l[0] <= 3.0 * f[0] && l[0] < 1e-4, "{f:?} {l:?}");

    // Without stabilisation the violation accumulates (this is what the
    // stabilisation is for): larger than with it, and growing.
    let none = StepSettings {
        dynamics: DynamicsConfig {
            baumgarte: Baumgarte::NONE,
            ..Default::default()
        },
        ..Default::default()
    };
    let (fu, lu) = drift_history(&mut Rk4::new(none), 1e-3, 100.0);
    println!(
        "RK4 unstabilised, dt 1e-3: first 10 s |Phi| <= {:.1e}, last 10 s <= {:.1e}",
        fu[0], lu[0]
    );
    assert!(lu[0] > 3.0 * fu[0]);
}
