//! State feedback through [`Feedback`] and [`JointPd`], with every
//! integrator, against the closed-form response of a linear second-order
//! system; and the PD set-up errors.

mod models;

use flexdyn_runtime::control::{Feedback, FeedbackLaw, JointPd, Target};
use flexdyn_runtime::{
    run, AdaptiveRk4, ErrorKind, GaussLegendre4, GeneralizedAlpha, Integrator, Rk4,
    SemiImplicitEuler, State, StepSettings,
};
use models::*;

/// Actuator `j` acts on cart `JOINTS[j]` (the crossed carts' actuator map).
const JOINTS: [usize; 2] = [1, 0];
/// Gains per actuator: cart 1 (0.5 kg) at 4 rad/s, cart 0 (2 kg) at
/// 5 rad/s, both with damping ratio 0.2.
const KP: [f64; 2] = [8.0, 50.0];
const KD: [f64; 2] = [0.8, 4.0];
/// References per actuator: a constant and a ramp `r0 + rate t`.
const R0: [f64; 2] = [0.3, -0.5];
const RATE: [f64; 2] = [0.0, 0.2];
/// Feed-forward force per actuator (the integrator's input).
const FF: [f64; 2] = [0.4, -1.0];

fn reference(t: f64) -> Target<2> {
    Target {
        position: V::<2>::new(R0[0] + RATE[0] * t, R0[1] + RATE[1] * t),
        velocity: V::<2>::new(RATE[0], RATE[1]),
        acceleration: V::<2>::zeros(),
    }
}

/// Closed form: `m x'' + kd x' + kp x = kp r(t) + kd rate + f` with
/// `r = r0 + rate t` has the particular solution `r(t) + f / kp`; the rest
/// decays as an underdamped oscillator, `exp(-zeta w t) (a cos + b sin)(w_d t)`.
#[allow(clippy::too_many_arguments)]
fn closed_form(
    m: f64,
    kp: f64,
    kd: f64,
    r0: f64,
    rate: f64,
    f: f64,
    x0: f64,
    v0: f64,
    t: f64,
) -> f64 {
    let w = (kp / m).sqrt();
    let zeta = kd / (2.0 * (kp * m).sqrt());
    assert!(zeta < 1.0);
    let wd = w * (1.0 - zeta * zeta).sqrt();
    let particular = |t: f64| r0 + rate * t + f / kp;
    let (a, adot) = (x0 - particular(0.0), v0 - rate);
    let b = (adot + zeta * w * a) / wd;
    particular(t) + (-zeta * w * t).exp() * (a * (wd * t).cos() + b * (wd * t).sin())
}

/// Largest deviation from the closed form over a 4 s run of `steps` steps.
fn max_error<G: Integrator<2, 0, 2>>(mut integrator: G, steps: usize) -> f64 {
    let carts = CrossedCarts::default();
    let pd = JointPd::<_, 2, 2>::new(JOINTS, KP, KD, reference).expect("valid PD");
    let closed = Feedback::new(&carts, pd);
    let (x0, v0) = (V::<2>::new(0.1, -0.2), V::<2>::new(0.2, -0.1));
    let mut state = State::new(x0, v0, 0.0);
    let ff = V::<2>::new(FF[0], FF[1]);
    let masses = [carts.m0, carts.m1];
    let mut worst = 0.0f64;
    let dt = 4.0 / steps as f64;
    run(
        &mut integrator,
        &closed,
        &mut state,
        &ff,
        dt,
        steps,
        |s, _| {
            for (j, &i) in JOINTS.iter().enumerate() {
                let x = closed_form(
                    masses[i], KP[j], KD[j], R0[j], RATE[j], FF[j], x0[i], v0[i], s.t,
                );
                worst = worst.max((s.q[i] - x).abs());
            }
        },
    )
    .expect("closed loop runs");
    worst
}

#[test]
fn pd_loop_follows_the_closed_form_response_with_every_integrator() {
    let s = StepSettings::default();
    let cases: [(&str, f64, f64); 5] = [
        ("rk4", max_error(Rk4::new(s), 4000), 1e-10),
        ("adaptive rk4", max_error(AdaptiveRk4::default(), 400), 1e-9),
        (
            "gauss-legendre",
            max_error(GaussLegendre4::new(s), 4000),
            1e-11,
        ),
        (
            "generalized-alpha",
            max_error(GeneralizedAlpha::<2, 0>::default(), 4000),
            2e-5,
        ),
        (
            "semi-implicit euler",
            max_error(SemiImplicitEuler::new(s), 40000),
            1e-3,
        ),
    ];
    for (name, error, tol) in cases {
        println!("{name}: max deviation {error:.3e} (tolerance {tol:.0e})");
        assert!(error < tol, "{name}: {error:e}");
    }
}

#[test]
fn pd_input_is_the_gain_weighted_error_of_each_actuator_joint() {
    let pd = JointPd::<_, 2, 2>::new(JOINTS, KP, KD, reference).expect("valid PD");
    let (q, qd, t) = (V::<2>::new(0.7, -0.1), V::<2>::new(0.3, 0.9), 1.5);
    let u = pd.input(&q, &qd, t);
    let r = reference(t);
    for (j, &i) in JOINTS.iter().enumerate() {
        let expected = KP[j] * (r.position[j] - q[i]) + KD[j] * (r.velocity[j] - qd[i]);
        assert!(
            (u[j] - expected).abs() < 1e-14,
            "actuator {j}: {} vs {expected}",
            u[j]
        );
    }
    // The closed loop's bias forces are the model's minus B u.
    let carts = CrossedCarts::default();
    let closed = Feedback::new(&carts, pd);
    let mut h = V::<2>::zeros();
    flexdyn_runtime::Equations::bias(&closed, &q, &qd, t, &mut h);
    assert_eq!(h, -V::<2>::new(u[1], u[0]));
}

/// The error of a set-up that must be rejected.
fn rejected<T>(r: Result<T, flexdyn_runtime::Error>) -> flexdyn_runtime::Error {
    match r {
        Ok(_) => panic!("set-up accepted"),
        Err(e) => e,
    }
}

#[test]
fn pd_set_up_errors_name_the_entry() {
    let e = rejected(JointPd::<_, 2, 2>::new([0, 2], KP, KD, reference));
    assert_eq!(
        e.kind,
        ErrorKind::InvalidIndex {
            what: "PD joint coordinate",
            entry: 1,
            index: 2,
            len: 2
        }
    );
    assert!(e.to_string().contains("entry 1 is 2, outside 0..2"), "{e}");
    let e = rejected(JointPd::<_, 2, 2>::new(JOINTS, [1.0, -2.0], KD, reference));
    assert!(
        matches!(e.kind, ErrorKind::InvalidParameter { index: 1, value, .. } if value == -2.0),
        "{e}"
    );
    let e = rejected(JointPd::<_, 2, 2>::new(
        JOINTS,
        KP,
        [f64::NAN, 0.0],
        reference,
    ));
    assert!(e.to_string().contains("derivative gain kd"), "{e}");
    // Two actuators on one coordinate are allowed.
    assert!(JointPd::<_, 2, 2>::new([0, 0], KP, KD, reference).is_ok());
}
