//! Measured accuracy of every integrator on the flexible test mechanism
//! scenes/spring_pendulum.toml (a pendulum carrying a bob on a radial spring
//! with a 1 kHz stretch mode), the figures of the integrator table in
//! runtime/README.md.
//!
//! Two starts, both at swing angle 1 rad at rest: `excited`, the spring
//! stretched by 0.1 mm beyond its rest length (a 0.1 mm, 1 kHz elastic
//! oscillation rides on the swing), and `quasi-static`, the spring at its
//! static stretch (the stretch then follows the swing's slowly changing load,
//! 0.1 to 0.2 µm, and the 1 kHz mode stays nearly at rest). Reference for
//! each: Gauss–Legendre 4 at 2.5 µs over 0.2 s; the same run at 5 µs agrees
//! with it to 3e-13 (theta) and 2e-10 (s) relative (checked below), so its
//! own error is negligible. Errors: the largest difference from the
//! reference at the 1 ms sample times, relative to the largest reference
//! value, separately for the rigid coordinate `theta` and the elastic
//! coordinate `s`. Each integrator must stay within twice the error
//! measured when the table was made (or 1e-12, round-off), and must refuse
//! exactly the steps the table says it refuses.

use flexdyn::runtime::{
    AdaptiveRk4, Error, ErrorKind, GaussLegendre4, GeneralizedAlpha, GeneralizedAlphaConfig,
    Integrator, Rk4, SemiImplicitEuler, State, StepSettings,
};
use flexdyn::scenes::spring_pendulum::SpringPendulum;
use nalgebra::SVector;

const T_END: f64 = 0.2;
const SAMPLE: f64 = 1e-3;
const SAMPLES: usize = 200;

/// Static stretch of the spring under the bob's weight at the start angle:
/// `m g cos(1) / k`.
const STATIC_STRETCH: f64 = 1.0 * 9.81 * 0.540_302_305_868_139_8 / 39_478_417.604_357;

/// The start: swing angle 1 rad at rest, the spring stretched by 0.1 mm
/// beyond its rest length (`excited`: a 0.1 mm, 1 kHz oscillation rides on
/// the swing) or by its static stretch (the stretch follows the swing's
/// slowly changing load quasi-statically, 0.1 to 0.2 µm).
fn start(excited: bool) -> State<2> {
    let s = if excited { 1e-4 } else { STATIC_STRETCH };
    State::new(SVector::from([1.0, s]), SVector::zeros(), 0.0)
}

/// Runs `g` at step `dt` to `T_END`, returning `(theta, s)` at every sample.
fn samples<G: Integrator<2, 0, 0>>(
    g: &mut G,
    dt: f64,
    excited: bool,
) -> Result<Vec<[f64; 2]>, Error> {
    let per_sample = (SAMPLE / dt).round() as usize;
    let mut s = start(excited);
    let mut out = Vec::with_capacity(SAMPLES);
    let none = SVector::<f64, 0>::zeros();
    for _ in 0..SAMPLES {
        for _ in 0..per_sample {
            g.step(&SpringPendulum, &mut s, &none, dt)?;
        }
        out.push([s.q[0], s.q[1]]);
    }
    assert!((s.t - T_END).abs() < 1e-9);
    Ok(out)
}

/// Largest error relative to the largest reference value, per coordinate.
fn relative_errors(run: &[[f64; 2]], reference: &[[f64; 2]]) -> [f64; 2] {
    let mut out = [0.0; 2];
    for (k, o) in out.iter_mut().enumerate() {
        let scale = reference.iter().map(|r| r[k].abs()).fold(0.0, f64::max);
        let err = run
            .iter()
            .zip(reference)
            .map(|(a, b)| (a[k] - b[k]).abs())
            .fold(0.0, f64::max);
        *o = err / scale;
    }
    out
}

fn gen_alpha(rho_inf: f64) -> GeneralizedAlpha<2, 0> {
    GeneralizedAlpha::new(
        StepSettings::default(),
        GeneralizedAlphaConfig {
            rho_inf,
            ..Default::default()
        },
    )
}

/// What the table says for one integrator at one step.
#[derive(Clone, Copy, Debug)]
enum Expected {
    /// Relative errors (theta, s) as measured.
    Errors(f64, f64),
    /// Refused by the explicit stability check.
    StabilityRefusal,
    /// Gauss–Legendre's stage iteration diverges.
    StageDivergence,
}

/// Compares one run with the table; returns what disagrees.
fn check(
    name: &str,
    dt: f64,
    result: Result<Vec<[f64; 2]>, Error>,
    reference: &[[f64; 2]],
    expected: Expected,
) -> Option<String> {
    match (result, expected) {
        (Ok(run), Expected::Errors(theta, s)) => {
            let [et, es] = relative_errors(&run, reference);
            eprintln!("{name:>36} dt {dt:.0e}: theta {et:.2e}, s {es:.2e}");
            // Twice the recorded figure; at least 1e-12 (round-off level).
            let bound = |x: f64| (2.0 * x).max(1e-12);
            (et > bound(theta) || es > bound(s)).then(|| {
                format!(
                    "{name} dt {dt:e}: errors theta {et:e}, s {es:e} above 2 x ({theta:e}, {s:e})"
                )
            })
        }
        (Err(e), Expected::StabilityRefusal)
            if matches!(e.kind, ErrorKind::StepTooLarge { rate: Some(_), .. }) =>
        {
            eprintln!("{name:>36} dt {dt:.0e}: {e}");
            None
        }
        (Err(e), Expected::StageDivergence)
            if matches!(
                e.kind,
                ErrorKind::StageIterationFailed { diverged: true, .. }
            ) =>
        {
            eprintln!("{name:>36} dt {dt:.0e}: {e}");
            None
        }
        (Ok(run), exp) => Some(format!(
            "{name} dt {dt:e}: expected {exp:?}, ran with errors {:?}",
            relative_errors(&run, reference)
        )),
        (Err(e), exp) => Some(format!("{name} dt {dt:e}: expected {exp:?}, failed: {e}")),
    }
}

/// One integrator of the table, by name.
fn run(name: &str, dt: f64, excited: bool) -> Result<Vec<[f64; 2]>, Error> {
    match name {
        "RK4" => samples(&mut Rk4::default(), dt, excited),
        "adaptive RK4" => samples(&mut AdaptiveRk4::default(), dt, excited),
        "semi-implicit Euler" => samples(&mut SemiImplicitEuler::default(), dt, excited),
        "Gauss-Legendre 4" => samples(&mut GaussLegendre4::default(), dt, excited),
        "gen-alpha rho_inf 1" => samples(&mut gen_alpha(1.0), dt, excited),
        "gen-alpha rho_inf 0.8" => samples(&mut gen_alpha(0.8), dt, excited),
        "gen-alpha rho_inf 0.5" => samples(&mut gen_alpha(0.5), dt, excited),
        _ => samples(&mut gen_alpha(0.0), dt, excited),
    }
}

/// The reference for one start, after checking it has converged.
fn reference(excited: bool) -> Vec<[f64; 2]> {
    let fine = samples(&mut GaussLegendre4::default(), 2.5e-6, excited).expect("reference");
    let coarser = samples(&mut GaussLegendre4::default(), 5e-6, excited).expect("at 5 us");
    let [rt, rs] = relative_errors(&coarser, &fine);
    eprintln!("excited {excited}: reference at 5 us vs 2.5 us: theta {rt:.2e}, s {rs:.2e}");
    assert!(
        rt < 1e-10 && rs < 1e-8,
        "reference not converged: {rt:e}, {rs:e}"
    );
    fine
}

#[test]
fn every_integrator_meets_its_recorded_accuracy_on_the_spring_pendulum() {
    use Expected::*;
    // For each integrator, (theta, s) errors or refusal at dt = 1e-3, 1e-4,
    // 1e-5: with the elastic mode excited, then quasi-static; as in
    // runtime/README.md.
    let table: [(&str, [Expected; 3], [Expected; 3]); 8] = [
        (
            "RK4",
            [
                StabilityRefusal,
                Errors(7.24e-08, 9.25e-01),
                Errors(2.86e-11, 8.50e-06),
            ],
            [
                StabilityRefusal,
                Errors(1.98e-14, 8.31e-07),
                Errors(2.32e-14, 7.56e-12),
            ],
        ),
        (
            "adaptive RK4",
            [
                Errors(4.68e-13, 1.30e-05),
                Errors(3.53e-13, 1.11e-05),
                Errors(1.74e-13, 2.84e-07),
            ],
            [
                Errors(2.90e-14, 1.56e-06),
                Errors(3.84e-14, 2.36e-08),
                Errors(1.70e-13, 5.48e-13),
            ],
        ),
        (
            "semi-implicit Euler",
            [
                StabilityRefusal,
                Errors(1.60e-04, 2.05e+00),
                Errors(1.60e-05, 2.77e-02),
            ],
            [
                StabilityRefusal,
                Errors(1.62e-04, 7.40e-05),
                Errors(1.62e-05, 7.49e-06),
            ],
        ),
        (
            "Gauss-Legendre 4",
            [
                StageDivergence,
                Errors(4.63e-08, 3.49e-02),
                Errors(4.76e-12, 3.57e-09),
            ],
            [
                StageDivergence,
                Errors(2.13e-14, 3.14e-08),
                Errors(2.32e-14, 6.39e-14),
            ],
        ),
        (
            "gen-alpha rho_inf 1",
            [
                Errors(7.12e-07, 1.99e+00),
                Errors(1.70e-07, 1.99e+00),
                Errors(7.08e-08, 8.38e-02),
            ],
            [
                Errors(7.65e-07, 2.96e-06),
                Errors(7.65e-09, 1.80e-06),
                Errors(7.66e-11, 7.54e-08),
            ],
        ),
        (
            "gen-alpha rho_inf 0.8",
            [
                Errors(1.85e-06, 1.68e+00),
                Errors(1.39e-07, 1.98e+00),
                Errors(7.45e-08, 9.34e-02),
            ],
            [
                Errors(8.08e-07, 2.28e-06),
                Errors(8.08e-09, 1.78e-06),
                Errors(8.08e-11, 8.41e-08),
            ],
        ),
        (
            "gen-alpha rho_inf 0.5",
            [
                Errors(7.13e-06, 1.39e+00),
                Errors(1.83e-08, 1.77e+00),
                Errors(1.02e-07, 1.90e-01),
            ],
            [
                Errors(1.15e-06, 3.02e-06),
                Errors(1.15e-08, 1.59e-06),
                Errors(1.15e-10, 1.71e-07),
            ],
        ),
        (
            "gen-alpha rho_inf 0",
            [
                Errors(2.52e-05, 1.09e+00),
                Errors(1.92e-08, 1.27e+00),
                Errors(1.27e-07, 1.54e+00),
            ],
            [
                Errors(4.17e-06, 9.61e-06),
                Errors(4.21e-08, 1.14e-06),
                Errors(4.21e-10, 1.38e-06),
            ],
        ),
    ];
    let mut failures = Vec::new();
    for excited in [true, false] {
        let reference = reference(excited);
        for (name, when_excited, when_quasi_static) in table {
            let expected = if excited {
                when_excited
            } else {
                when_quasi_static
            };
            for (dt, exp) in [1e-3, 1e-4, 1e-5].into_iter().zip(expected) {
                let label = format!(
                    "{name} ({})",
                    if excited { "excited" } else { "quasi-static" }
                );
                failures.extend(check(&label, dt, run(name, dt, excited), &reference, exp));
            }
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}
