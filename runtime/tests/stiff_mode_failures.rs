//! What the integrators say when a step is too large for a kHz elastic
//! mode: the elastic pendulum (a point mass on a radial spring, axial mode
//! at 2 kHz, i.e. `omega = 1.2566e4` rad/s) at steps beyond each scheme's
//! bound. Gauss–Legendre's stage iteration diverges (it used to surface as
//! "model returned a non-finite mass matrix M"), semi-implicit Euler grows
//! without bound (it used to diverge silently), and a failing projection
//! names itself and its tolerance. Every refusal leaves the state as it was.

mod models;

use flexdyn_runtime::{
    ErrorKind, FromFn, GaussLegendre4, IntegratorOf, ProjectionConfig, SemiImplicitEuler, Stage,
    State, StepSettings, GAUSS_LEGENDRE_CONTRACTION_LIMIT,
};
use models::*;

/// Axial circular frequency of the default elastic pendulum.
fn omega(p: &ElasticPendulum) -> f64 {
    (p.k / p.m).sqrt()
}

/// A swinging start with the spring stretched by `stretch` beyond its rest length.
fn start(p: &ElasticPendulum, stretch: f64) -> State<2> {
    State::new(V::<2>::new(p.l0 + stretch, 1.0), V::<2>::zeros(), 0.0)
}

fn assert_names(msg: &str, parts: &[&str]) {
    for part in parts {
        assert!(msg.contains(part), "`{part}` not in: {msg}");
    }
}

#[test]
fn gauss_legendre_reports_a_diverging_stage_iteration_with_the_step() {
    let p = ElasticPendulum::default();
    let w = omega(&p);
    let s0 = start(&p, 1e-4);
    let mut s = s0;
    let e = GaussLegendre4::default()
        .step(&p, &mut s, &V::<1>::zeros(), 1e-3)
        .expect_err("dt omega = 12.6 is far beyond sqrt(12)");
    assert_eq!(s, s0, "a failed step leaves the state");
    let ErrorKind::StageIterationFailed {
        dt,
        sweeps,
        diverged: true,
        rate: Some(rate),
        ..
    } = e.kind
    else {
        panic!("expected a diverged stage iteration, got {e}");
    };
    assert_eq!(dt, 1e-3);
    // Growth by (omega dt)^2 / 12 = 13 per sweep: caught after a few sweeps,
    // long before the stage values overflow.
    assert!(sweeps <= 4, "{e}");
    // The linearised model's fastest mode is the axial one (the centrifugal
    // and gravity terms shift it by far less than 1e-3).
    assert!((rate / w - 1.0).abs() < 1e-3, "{rate} vs {w}");
    let stable = GAUSS_LEGENDRE_CONTRACTION_LIMIT / rate;
    assert_names(
        &e.to_string(),
        &[
            "Gauss-Legendre stage iteration diverged at step size 1e-3",
            "2.000e3 Hz",
            &format!("below {stable:.3e} s"),
        ],
    );
    // At half the contraction limit the same step converges.
    GaussLegendre4::default()
        .step(&p, &mut s, &V::<1>::zeros(), 0.5 * stable)
        .expect("contracting step");
}

#[test]
fn gauss_legendre_evaluation_errors_name_the_sweep() {
    // An input that is not finite after the step's start: the first sweep
    // evaluates the stages inside the step and says so.
    let p = ElasticPendulum::default();
    let s0 = start(&p, 1e-4);
    let mut s = s0;
    let input = FromFn(|t: f64| V::<1>::new(if t > 0.0 { f64::NAN } else { 0.0 }));
    let e = GaussLegendre4::default()
        .step(&p, &mut s, &input, 1e-5)
        .expect_err("the input is NaN at the stage times");
    assert_eq!(s, s0);
    assert!(matches!(e.kind, ErrorKind::NonFiniteInput { .. }), "{e}");
    assert_eq!(e.stage, Some(Stage::StageIteration { dt: 1e-5, sweep: 1 }));
    assert!(
        e.to_string().contains(
            "Gauss-Legendre stage iteration at step size 1e-5, sweep 1: non-finite input"
        ),
        "{e}"
    );
}

#[test]
fn semi_implicit_euler_refuses_steps_beyond_its_stability_bound() {
    let p = ElasticPendulum::default();
    let w = omega(&p);
    // dt omega = 12.6 with the axial mode excited: refused at once, naming
    // the mode and the stable step 2 / omega.
    let s0 = start(&p, 1e-4);
    let mut s = s0;
    let e = SemiImplicitEuler::default()
        .step(&p, &mut s, &V::<1>::zeros(), 1e-3)
        .expect_err("unstable step");
    assert_eq!(s, s0);
    let ErrorKind::StepTooLarge {
        limit,
        rate: Some(rate),
        ..
    } = e.kind
    else {
        panic!("expected the stability check, got {e}");
    };
    assert_eq!(limit, 2.0);
    assert!((rate / w - 1.0).abs() < 1e-3, "{rate} vs {w}");
    assert_names(
        &e.to_string(),
        &[
            "step size 1e-3",
            "2.000e3 Hz",
            &format!("{:.3e} s", 2.0 / rate),
        ],
    );
    // dt omega = 2.5 with the axial mode at rest (the spring at its rest
    // length; gravity and the swing excite it): without the check the mode
    // grows by about 4x per step and the run diverges; with it the run stops
    // once the mode dominates the step, while the stretch is still small.
    let dt = 2.5 / w;
    let mut s = start(&p, 0.0);
    let mut unchecked = SemiImplicitEuler {
        stability_limit: f64::INFINITY,
        ..Default::default()
    };
    let mut diverged = false;
    for _ in 0..200 {
        match unchecked.step(&p, &mut s, &V::<1>::zeros(), dt) {
            Ok(_) if (s.q[0] - p.l0).abs() < 1.0 => {}
            _ => {
                diverged = true;
                break;
            }
        }
    }
    assert!(diverged, "the unchecked run stays bounded: {:?}", s);
    let mut s = start(&p, 0.0);
    let mut checked = SemiImplicitEuler::default();
    let mut refused = None;
    for n in 0..200 {
        if let Err(e) = checked.step(&p, &mut s, &V::<1>::zeros(), dt) {
            refused = Some((n, e));
            break;
        }
    }
    let (n, e) = refused.expect("the check refuses the unstable step");
    assert!(matches!(e.kind, ErrorKind::StepTooLarge { .. }), "{e}");
    assert!(
        (s.q[0] - p.l0).abs() < 1e-3,
        "refused after {n} steps with the stretch at {:e}",
        s.q[0] - p.l0
    );
    // Below the bound the run goes on.
    let mut s = start(&p, 1e-4);
    for _ in 0..100 {
        let r = checked
            .step(&p, &mut s, &V::<1>::zeros(), 1.5 / w)
            .expect("stable step");
        assert!(r.stability_estimate <= 2.0);
    }
}

#[test]
fn projection_failure_after_a_step_names_the_projection_and_its_tolerance() {
    let sc = SliderCrank::default();
    let mut s = sc.consistent_state(0.4, 1.0);
    let s0 = s;
    let mut se = SemiImplicitEuler::new(StepSettings {
        projection: Some(ProjectionConfig {
            max_iterations: 0,
            ..Default::default()
        }),
        ..Default::default()
    });
    let e = se
        .step(&sc, &mut s, &V::<1>::zeros(), 1e-3)
        .expect_err("no projection iterations allowed");
    assert_eq!(s, s0);
    assert_eq!(
        e.stage,
        Some(Stage::PositionProjection {
            tolerance: 1e-12,
            after_step: true
        })
    );
    assert!(
        matches!(e.kind, ErrorKind::NewtonNotConverged { iterations: 0, residual, tolerance: 1e-12 } if residual > 1e-12),
        "{e}"
    );
    assert_names(
        &e.to_string(),
        &[
            "position projection after the step (tolerance max |Phi| <= 1e-12): Newton \
             iteration did not converge in 0 iterations",
            "> tolerance 1e-12",
        ],
    );
}
