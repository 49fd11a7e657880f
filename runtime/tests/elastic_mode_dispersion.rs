//! What each integrator does to a fast elastic mode: the per-step amplitude
//! factor `|lambda|` and phase `phi` of its discrete solution on a 1 kHz
//! linear oscillator (`SpringChain<1>`, analytic bias Jacobians), fitted from the computed trajectory
//! (the two-term recurrence `x_{n+1} = 2 Re(lambda) x_n - |lambda|^2
//! x_{n-1}` by least squares), against the closed forms of the schemes'
//! amplification at `W = omega dt`:
//!
//! * RK4: `lambda = 1 + iW - W^2/2 - iW^3/6 + W^4/24`;
//! * semi-implicit Euler: `|lambda| = 1`, `cos(phi) = 1 - W^2/2`;
//! * Gauss–Legendre 4: `lambda = (1 + iW/2 - W^2/12) / (1 - iW/2 - W^2/12)`;
//! * generalized-α with `rho_inf = 1` (trapezoidal): `|lambda| = 1`,
//!   `phi = 2 atan(W/2)`; with `rho_inf < 1`: the recorded eigenvalues of
//!   the scheme's amplification matrix, computed by a separate
//!   implementation of the recurrence (the figures of runtime/README.md).
//!
//! The period ratio (computed / true period) is `W / phi`, the amplitude
//! factor per true period `|lambda|^(2 pi / W)`.

mod models;

use flexdyn_runtime::{
    GaussLegendre4, GeneralizedAlpha, GeneralizedAlphaConfig, Integrator, Rk4, SemiImplicitEuler,
    State, StepSettings,
};
use models::*;

const OMEGA: f64 = 2.0 * core::f64::consts::PI * 1000.0;

fn oscillator() -> SpringChain<1> {
    SpringChain {
        m: [1.0],
        k: [OMEGA * OMEGA],
        c: [0.0],
        analytic: true,
    }
}

/// `(|lambda|, phi)` fitted from `steps` steps of `g` at `dt` from `x = 1`
/// at rest, skipping the first `skip` (start-up transients).
fn fitted<G: Integrator<1, 0, 1>>(g: &mut G, dt: f64, steps: usize, skip: usize) -> (f64, f64) {
    let model = oscillator();
    let mut s = State::new(V::<1>::new(1.0), V::<1>::zeros(), 0.0);
    let mut x = vec![s.q[0]];
    for _ in 0..steps {
        g.step(&model, &mut s, &V::<1>::zeros(), dt)
            .unwrap_or_else(|e| panic!("dt {dt:e}: {e}"));
        x.push(s.q[0]);
    }
    // x[n+1] = a x[n] + b x[n-1]: normal equations.
    let (mut s11, mut s12, mut s22, mut r1, mut r2) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for n in (skip + 1)..steps {
        let (u, v, y) = (x[n], x[n - 1], x[n + 1]);
        s11 += u * u;
        s12 += u * v;
        s22 += v * v;
        r1 += u * y;
        r2 += v * y;
    }
    let det = s11 * s22 - s12 * s12;
    let a = (r1 * s22 - r2 * s12) / det;
    let b = (s11 * r2 - s12 * r1) / det;
    let mag = (-b).sqrt();
    let cos = (a / (2.0 * mag)).clamp(-1.0, 1.0);
    (mag, cos.acos())
}

fn assert_mode(name: &str, got: (f64, f64), expected: (f64, f64), tol: f64) {
    let w = got.1;
    eprintln!(
        "{name}: |lambda| {:.6} (expected {:.6}), phase {:.6} (expected {:.6})",
        got.0, expected.0, w, expected.1
    );
    assert!(
        (got.0 - expected.0).abs() < tol && (got.1 - expected.1).abs() < tol,
        "{name}: {got:?} vs {expected:?}"
    );
}

fn gen_alpha(rho_inf: f64) -> GeneralizedAlpha<1, 0> {
    GeneralizedAlpha::new(
        StepSettings::default(),
        GeneralizedAlphaConfig {
            rho_inf,
            rtol: 1e-12,
            atol: 1e-14,
            ..Default::default()
        },
    )
}

#[test]
fn explicit_and_symplectic_schemes_match_their_amplification() {
    for dt in [1e-4, 2e-4] {
        let w: f64 = OMEGA * dt;
        let (re, im) = (1.0 - w * w / 2.0 + w.powi(4) / 24.0, w - w.powi(3) / 6.0);
        let rk4 = ((re * re + im * im).sqrt(), im.atan2(re));
        assert_mode(
            &format!("RK4 W {w:.3}"),
            fitted(&mut Rk4::default(), dt, 400, 0),
            rk4,
            1e-9,
        );
        let se = (1.0, (1.0 - w * w / 2.0).acos());
        let mut sie = SemiImplicitEuler::default();
        assert_mode(
            &format!("semi-implicit Euler W {w:.3}"),
            fitted(&mut sie, dt, 400, 0),
            se,
            1e-9,
        );
        let gl = (1.0, 2.0 * (w / 2.0).atan2(1.0 - w * w / 12.0));
        let mut g = GaussLegendre4::default();
        assert_mode(
            &format!("Gauss-Legendre W {w:.3}"),
            fitted(&mut g, dt, 400, 0),
            gl,
            1e-9,
        );
    }
}

#[test]
fn generalized_alpha_matches_its_amplification() {
    // rho_inf = 1: the trapezoidal rule, closed form.
    for dt in [1e-4, 1e-3] {
        let w = OMEGA * dt;
        let expected = (1.0, 2.0 * (w / 2.0).atan());
        assert_mode(
            &format!("gen-alpha 1 W {w:.3}"),
            fitted(&mut gen_alpha(1.0), dt, 400, 0),
            expected,
            1e-8,
        );
    }
    // rho_inf < 1 at W = 0.628 (1e-4 s) and 6.28 (1e-3 s): |lambda| and
    // phase recorded from the eigenvalues of the amplification matrix.
    for (rho, dt, expected) in [
        (0.8, 1e-4, (0.999_904_421, 0.607_759_012)),
        (0.5, 1e-4, (0.997_733_498, 0.600_276_426)),
        (0.0, 1e-4, (0.969_708_167, 0.559_397_553)),
        (0.8, 1e-3, (0.956_279_260, 2.465_329_017)),
        (0.5, 1e-3, (0.748_527_490, 2.319_312_376)),
        (0.0, 1e-3, (0.339_225_813, 1.702_301_709)),
    ] {
        let got = fitted(&mut gen_alpha(rho), dt, 400, 100);
        assert_mode(&format!("gen-alpha {rho} dt {dt:e}"), got, expected, 2e-6);
    }
}
