//! The grammar's switches (`abs`, `sign`, `step`, `min`, `max`) in scenes,
//! against closed forms:
//!
//! * `scenes/spin_up_hub.toml` prescribes its hub angle with the classic
//!   spin-up profile written with `step`; the generated constraint terms
//!   and an integrated run give the closed-form angle, rate and
//!   acceleration before and after the switch at `Ts`, and at `Ts` itself;
//! * `scenes/coulomb_block.toml` has the Coulomb friction dissipation
//!   `mu m g |xd|`: pushed off at `v0`, the block decelerates at `mu g` and
//!   stops at `v0 / (mu g)` after `v0^2 / (2 mu g)`; the step across the
//!   stop, where the force switches, is refused.

use std::f64::consts::PI;

use flexdyn::runtime::{ErrorKind, GaussLegendre4, IntegratorOf, Model, Rk4, State};
use flexdyn::scenes::coulomb_block::CoulombBlock;
use flexdyn::scenes::spin_up_hub::SpinUpHub;
use nalgebra::SVector;

// Parameters exactly as written in scenes/spin_up_hub.toml.
const TS: f64 = 2.0;
const WS: f64 = 3.0;
const R0: f64 = 0.3;

/// The spin-up profile's angle, rate and acceleration at `t`.
fn spin_up(t: f64) -> [f64; 3] {
    if t < TS {
        let (s, c) = (2.0 * PI * t / TS).sin_cos();
        let k = TS / (2.0 * PI);
        [
            WS / TS * (t * t / 2.0 + k * k * (c - 1.0)),
            WS / TS * (t - k * s),
            WS / TS * (1.0 - c),
        ]
    } else {
        [WS * (t - TS / 2.0), WS, 0.0]
    }
}

#[test]
fn spin_up_profile_written_with_step_has_the_closed_form_angle_rate_and_acceleration() {
    let model = SpinUpHub;
    let mut worst = [0.0f64; 3];
    // Both sides of the switch, and the switch itself (both steps 1/2).
    for t in [0.0, 0.1, 0.7, 1.3, 1.999, TS, 2.001, 2.6, 4.0, 7.5] {
        let [theta, omega, alpha] = spin_up(t);
        let q = SVector::from([theta, R0]);
        let qd = SVector::from([omega, 0.0]);
        let (mut phi, mut phi_t, mut gamma) = (
            SVector::<f64, 1>::zeros(),
            SVector::<f64, 1>::zeros(),
            SVector::<f64, 1>::zeros(),
        );
        model.constraints(&q, t, &mut phi);
        model.constraint_time_derivative(&q, t, &mut phi_t);
        model.constraint_rhs(&q, &qd, t, &mut gamma);
        // Phi_q = [1, 0]: the rate is -Phi_t, the acceleration gamma.
        let errors = [
            phi[0].abs(),
            (phi_t[0] + omega).abs(),
            (gamma[0] - alpha).abs(),
        ];
        for (w, e) in worst.iter_mut().zip(errors) {
            *w = w.max(e);
        }
        assert!(
            errors[0] <= 1e-14 * theta.abs().max(1.0)
                && errors[1] <= 1e-14 * WS
                && errors[2] <= 1e-14 * WS,
            "t = {t}: errors {errors:?}"
        );
    }
    eprintln!(
        "spin-up profile: max |Phi| {:.1e} rad, |Phi_t + omega| {:.1e} rad/s, |gamma - alpha| {:.1e} rad/s^2",
        worst[0], worst[1], worst[2]
    );
}

#[test]
fn spin_up_hub_integrates_to_the_closed_form_angle_and_rate_before_and_after_ts() {
    let model = SpinUpHub;
    let none = SVector::<f64, 0>::zeros();
    let mut s = State::new(SVector::from([0.0, R0]), SVector::from([0.0, 0.0]), 0.0);
    let mut gl = GaussLegendre4::default();
    let dt = 1e-3;
    // Worst angle and rate errors before and after Ts.
    let mut before = [0.0f64; 2];
    let mut after = [0.0f64; 2];
    for n in 1..=4000 {
        gl.step(&model, &mut s, &none, dt).expect("step");
        let t = f64::from(n) * dt;
        let [theta, omega, _] = spin_up(t);
        let e = [(s.q[0] - theta).abs(), (s.qd[0] - omega).abs()];
        let side = if t < TS { &mut before } else { &mut after };
        side[0] = side[0].max(e[0]);
        side[1] = side[1].max(e[1]);
        assert!(s.q[1].is_finite() && s.qd[1].is_finite(), "bead at t = {t}");
    }
    eprintln!(
        "spin-up hub, Gauss-Legendre 1 ms: before Ts angle {:.1e} rad, rate {:.1e} rad/s; \
         after Ts (to 4 s) angle {:.1e} rad, rate {:.1e} rad/s",
        before[0], before[1], after[0], after[1]
    );
    assert!(before[0] < 1e-9 && before[1] < 1e-9, "{before:?}");
    assert!(after[0] < 1e-9 && after[1] < 1e-9, "{after:?}");
    // The hub reached the final speed: the run really crossed the switch.
    assert!((s.qd[0] - WS).abs() < 1e-9 && s.t > 2.0 * TS - dt);
}

// Parameters exactly as written in scenes/coulomb_block.toml.
const MU: f64 = 0.3;
const G0: f64 = 9.81;

#[test]
fn coulomb_block_decelerates_at_mu_g_and_stops_after_v0_squared_over_2_mu_g() {
    let model = CoulombBlock;
    let v0 = 2.0;
    let a = MU * G0;
    let (t_stop, d_stop) = (v0 / a, v0 * v0 / (2.0 * a));
    let push = SVector::from([0.0]);
    let mut s = State::new(SVector::from([0.0]), SVector::from([v0]), 0.0);
    let mut rk4 = Rk4::default();
    let dt = 1e-3;
    let (mut worst_x, mut worst_v) = (0.0f64, 0.0f64);
    // Up to the last step that ends before the stop: a constant force,
    // which RK4 integrates exactly.
    while s.t + dt < t_stop {
        rk4.step(&model, &mut s, &push, dt).expect("step");
        let t = s.t;
        worst_x = worst_x.max((s.q[0] - (v0 * t - a * t * t / 2.0)).abs());
        worst_v = worst_v.max((s.qd[0] - (v0 - a * t)).abs());
    }
    eprintln!(
        "Coulomb block, RK4 1 ms: sliding to t = {:.4} s (stop at {t_stop:.4} s): \
         max |x - closed form| {worst_x:.1e} m, |v - closed form| {worst_v:.1e} m/s; \
         x there {:.6} m, stop distance {d_stop:.6} m",
        s.t, s.q[0]
    );
    assert!(
        worst_x < 1e-12 && worst_v < 1e-12,
        "{worst_x:e} {worst_v:e}"
    );
    // The last step before the stop ends within dt of it: the block is
    // within mu g dt of rest and mu g dt^2 / 2 of the stop distance.
    assert!(t_stop - s.t <= dt);
    assert!(s.qd[0] > 0.0 && s.qd[0] <= a * dt, "{}", s.qd[0]);
    assert!((d_stop - s.q[0]).abs() <= a * dt * dt / 2.0 + 1e-12);
    // The step across the stop lands near rest (its last stage sees the
    // force switch). The next one, at rest, sees it switch between its
    // stages (-mu g, +mu g, -mu g, +mu g: a "mode" of any rate) and is
    // refused, the state left as it was, rather than chattering on.
    rk4.step(&model, &mut s, &push, dt)
        .expect("the step across the stop");
    eprintln!(
        "across the stop: t = {:.4} s, x = {:.6} m, v = {:.1e} m/s",
        s.t, s.q[0], s.qd[0]
    );
    assert!(s.qd[0].abs() <= a * dt && (d_stop - s.q[0]).abs() <= a * dt * dt);
    let before = s;
    let e = rk4
        .step(&model, &mut s, &push, dt)
        .expect_err("the switch at rest is refused");
    eprintln!("the step at rest: {e}");
    assert_eq!(s, before);
    // Gauss-Legendre at the same state: its stage iteration fails, and the
    // message blames the switch, not a mode or too few sweeps.
    let mut gl_state = before;
    let gl = GaussLegendre4::default()
        .step(&model, &mut gl_state, &push, dt)
        .expect_err("the switch at rest stops Gauss-Legendre too");
    eprintln!("Gauss-Legendre at rest: {gl}");
    assert!(
        matches!(gl.kind, ErrorKind::StageIterationFailed { .. })
            && gl
                .to_string()
                .contains("the forces change abruptly within the step"),
        "{gl}"
    );
    // Named for what it is: no mode of the model linearised at rest is near
    // the stages' rate, so the message blames the switch, not a mode.
    assert!(
        matches!(e.kind, ErrorKind::AbruptForces { .. })
            && e.to_string()
                .contains("the forces change abruptly within the step"),
        "{e}"
    );
}

#[test]
fn gen_alpha_stopping_at_a_switch_names_the_switching_component() {
    let dir = tempfile::tempdir().unwrap();
    let start = dir.path().join("start.json");
    std::fs::write(&start, r#"{"q": [0], "qd": [1], "t": 0}"#).unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_flexdyn"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args([
            "simulate",
            "--scene",
            "scenes/coulomb_block.toml",
            "--initial",
        ])
        .arg(&start)
        .args([
            "--duration",
            "1",
            "--dt",
            "0.01",
            "--integrator",
            "gen-alpha",
            "--csv",
        ])
        .arg(dir.path().join("out.csv"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    // The block stops at v0/(mu g) = 0.34 s; Newton fails at the switch.
    assert!(
        err.contains("Newton iteration did not converge")
            && err.contains("the forces of `friction` switch with the state")
            && err.contains("smooth the switch"),
        "{err}"
    );
    assert!(
        !dir.path().join("out.csv").exists(),
        "nothing written half-way"
    );
}
