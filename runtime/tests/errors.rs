//! Every error class is provoked, reported with its time, and leaves the
//! state (and the solver) as it was before the failed call.

mod models;

use flexdyn_runtime::{
    accelerations, project, AdaptiveRk4, DynamicsConfig, Error, ErrorKind, GaussLegendre4,
    GeneralizedAlpha, GeneralizedAlphaConfig, Input, Integrator, InverseConfig, InverseDynamics,
    InverseSolution, Model, ProjectionConfig, Quantity, Rk4, SemiImplicitEuler, State,
    StepSettings,
};
use models::*;

fn bits<const N: usize>(s: &State<N>) -> Vec<u64> {
    s.q.iter()
        .chain(s.qd.iter())
        .map(|x| x.to_bits())
        .chain([s.t.to_bits()])
        .collect()
}

/// Steps `g` from `s0` and returns the error, checking the state is unchanged.
fn step_err<M, G, I, const NQ: usize, const NC: usize, const NU: usize>(
    g: &mut G,
    model: &M,
    s0: State<NQ>,
    input: &I,
    dt: f64,
) -> Error
where
    M: Model<NQ, NC, NU>,
    G: Integrator<NQ, NC, NU>,
    I: Input<NU>,
{
    let mut s = s0;
    let e = g
        .step(model, &mut s, input, dt)
        .expect_err("the step must fail");
    assert_eq!(bits(&s), bits(&s0), "state modified by a failed step ({e})");
    // The message says what and when.
    let msg = e.to_string();
    assert!(msg.starts_with("at t = ") && msg.len() > 15, "{msg}");
    e
}

/// Runs the same failing step through every integrator.
fn all_integrators<M, I, const NQ: usize, const NC: usize, const NU: usize>(
    model: &M,
    s0: State<NQ>,
    input: &I,
    dt: f64,
    check: impl Fn(&Error),
) where
    M: Model<NQ, NC, NU>,
    I: Input<NU>,
{
    check(&step_err(&mut Rk4::default(), model, s0, input, dt));
    check(&step_err(
        &mut SemiImplicitEuler::default(),
        model,
        s0,
        input,
        dt,
    ));
    check(&step_err(
        &mut GaussLegendre4::default(),
        model,
        s0,
        input,
        dt,
    ));
    check(&step_err(
        &mut GeneralizedAlpha::<NQ, NC>::default(),
        model,
        s0,
        input,
        dt,
    ));
    check(&step_err(&mut AdaptiveRk4::default(), model, s0, input, dt));
}

fn pendulum_state() -> State<1> {
    State::new(V::<1>::new(1.0), V::<1>::new(0.5), 2.5)
}

#[test]
fn non_finite_state() {
    let p = Pendulum::default();
    let tau = V::<1>::zeros();
    let mut s = pendulum_state();
    s.q[0] = f64::NAN;
    all_integrators(&p, s, &tau, 1e-3, |e| {
        assert_eq!(
            e.kind,
            ErrorKind::NonFiniteState {
                quantity: Quantity::Position,
                index: 0
            }
        );
        assert_eq!(e.t, 2.5);
    });
    let mut s = pendulum_state();
    s.qd[0] = f64::INFINITY;
    all_integrators(&p, s, &tau, 1e-3, |e| {
        assert_eq!(
            e.kind,
            ErrorKind::NonFiniteState {
                quantity: Quantity::Velocity,
                index: 0
            }
        )
    });
    let mut s = pendulum_state();
    s.t = f64::NAN;
    all_integrators(&p, s, &tau, 1e-3, |e| {
        assert_eq!(
            e.kind,
            ErrorKind::NonFiniteState {
                quantity: Quantity::Time,
                index: 0
            }
        )
    });
}

#[test]
fn non_finite_input() {
    let dp = DoublePendulum::default();
    let s = State::new(V::<2>::new(0.3, 0.1), V::<2>::zeros(), 1.0);
    all_integrators(&dp, s, &V::<2>::new(0.0, f64::NAN), 1e-3, |e| {
        assert_eq!(
            e.kind,
            ErrorKind::NonFiniteInput {
                quantity: Quantity::Input,
                index: 1
            }
        )
    });
    // Prescribed motion in inverse dynamics.
    let sc = SliderCrank::default();
    let q0 = sc.consistent_state(0.5, 0.0).q;
    let mut id =
        InverseDynamics::<3, 2, 1, 1>::new([0], q0, InverseConfig::default()).expect("set-up");
    let before = id;
    let mut out = InverseSolution::default();
    let e = id
        .solve(
            &sc,
            0.7,
            &V::<1>::new(0.5),
            &V::<1>::new(f64::INFINITY),
            &V::<1>::zeros(),
            &mut out,
        )
        .expect_err("must fail");
    assert_eq!(
        e.kind,
        ErrorKind::NonFiniteInput {
            quantity: Quantity::PrescribedVelocity,
            index: 0
        }
    );
    assert_eq!(e.t, 0.7);
    assert_eq!(id, before);
}

#[test]
fn non_finite_model_output() {
    let faulty = Faulty {
        nan_bias: true,
        ..Faulty::new(Pendulum::default())
    };
    all_integrators(&faulty, pendulum_state(), &V::<1>::zeros(), 1e-3, |e| {
        assert_eq!(
            e.kind,
            ErrorKind::NonFiniteModelOutput {
                quantity: Quantity::Bias
            }
        )
    });
}

#[test]
fn non_finite_actuator_map() {
    // Named as the actuator map, not as the accelerations it spoils, with
    // the input zero (NaN times zero is NaN) or not.
    let faulty = Faulty {
        nan_actuation: true,
        ..Faulty::new(Pendulum::default())
    };
    for tau in [0.0, 1.0] {
        all_integrators(&faulty, pendulum_state(), &V::<1>::new(tau), 1e-3, |e| {
            assert_eq!(
                e.kind,
                ErrorKind::NonFiniteModelOutput {
                    quantity: Quantity::ActuatorMap
                }
            )
        });
    }
}

#[test]
fn non_finite_result_from_overflow() {
    // Finite inputs and model outputs whose solve overflows: tiny mass, large
    // torque. (The adaptive integrator first retries with smaller steps,
    // then reports the last failure.)
    let faulty = Faulty {
        mass_scale: 1e-300,
        ..Faulty::new(Pendulum::default())
    };
    all_integrators(&faulty, pendulum_state(), &V::<1>::new(1e10), 1e-3, |e| {
        assert_eq!(
            e.kind,
            ErrorKind::NonFiniteResult {
                quantity: Quantity::Acceleration
            }
        )
    });
}

#[test]
fn mass_matrix_not_positive_definite() {
    let faulty = Faulty {
        mass_scale: -1.0,
        ..Faulty::new(DoublePendulum::default())
    };
    let s = State::new(V::<2>::new(0.3, 0.1), V::<2>::zeros(), 0.0);
    all_integrators(&faulty, s, &V::<2>::zeros(), 1e-3, |e| match e.kind {
        ErrorKind::MassMatrixNotPositiveDefinite { pivot, value } => {
            assert!(pivot == 0 && value < 0.0)
        }
        other => panic!("unexpected {other:?}"),
    });
}

#[test]
fn singular_constraint_jacobian() {
    // Cartesian pendulum at the origin: Phi_q = [2x, 2y] = 0.
    let cp = CartesianPendulum::default();
    let s = State::new(V::<2>::zeros(), V::<2>::zeros(), 3.0);
    all_integrators(&cp, s, &V::<1>::zeros(), 1e-3, |e| {
        assert!(
            matches!(e.kind, ErrorKind::SingularConstraintJacobian { condition, .. } if condition == f64::INFINITY)
        );
        assert_eq!(e.t, 3.0);
    });
    // Nearly singular: close to the origin the condition estimate exceeds a
    // tight limit.
    let cfg = DynamicsConfig {
        max_condition: 10.0,
        ..Default::default()
    };
    let e = accelerations(
        &cp,
        &cfg,
        &V::<2>::new(1e-3, 1.0),
        &V::<2>::zeros(),
        0.0,
        &V::<1>::zeros(),
    );
    assert!(e.is_ok(), "well conditioned with one constraint");
    // Ill-conditioned, not singular: two constraint spheres that touch, at
    // 1e-7 from the contact point. The condition of Phi_q M^-1 Phi_q^T is
    // 1 / (1e-7)^2 = 1e14 (eigenvalues 8 and 8e-14), above the default limit
    // of 1e12 but finite; every integrator refuses the step and names it.
    let spheres = TouchingSpheres::default();
    let near = State::new(V::<3>::new(1.0, 1e-7, 0.0), V::<3>::zeros(), 4.5);
    all_integrators(&spheres, near, &V::<1>::zeros(), 1e-3, |e| {
        match e.kind {
            ErrorKind::SingularConstraintJacobian { condition, limit } => {
                assert!(condition.is_finite() && condition > 1e13, "{e}");
                assert_eq!(limit, DynamicsConfig::default().max_condition);
            }
            other => panic!("unexpected {other:?}"),
        }
        assert_eq!(e.t, 4.5);
        assert!(e.to_string().contains("at t = 4.5"), "{e}");
    });
    // Away from the contact (d = 1e-3, condition 1e6) the same model is fine.
    let fine = accelerations(
        &spheres,
        &DynamicsConfig::default(),
        &V::<3>::new(1.0, 1e-3, 0.0),
        &V::<3>::zeros(),
        0.0,
        &V::<1>::zeros(),
    );
    assert!(fine.is_ok(), "{fine:?}");
    // Inverse dynamics: slider-crank driven through the slider at the dead
    // centre (x = r + l, theta = phi = 0): the crank angle is not determined
    // by x there, the Jacobian of the free coordinates is singular.
    let sc = SliderCrank::default();
    let dead = V::<3>::new(0.0, 0.0, sc.r + sc.l);
    let mut id =
        InverseDynamics::<3, 2, 1, 1>::new([2], dead, InverseConfig::default()).expect("set-up");
    let mut out = InverseSolution::default();
    let e = id
        .solve(
            &sc,
            1.0,
            &V::<1>::new(sc.r + sc.l),
            &V::<1>::zeros(),
            &V::<1>::zeros(),
            &mut out,
        )
        .expect_err("dead centre");
    assert!(
        matches!(e.kind, ErrorKind::SingularConstraintJacobian { condition, .. } if condition == f64::INFINITY),
        "{e}"
    );
    assert_eq!(e.t, 1.0);
    // Approaching it from a nearby guess, Newton converges slowly towards the
    // singular point: ill-conditioned beyond a tight limit.
    let cfg = InverseConfig {
        max_condition: 1e4,
        ..Default::default()
    };
    let mut id = InverseDynamics::<3, 2, 1, 1>::new([2], sc.consistent_state(0.05, 0.0).q, cfg)
        .expect("set-up");
    let e = id
        .solve(
            &sc,
            1.0,
            &V::<1>::new(sc.r + sc.l),
            &V::<1>::zeros(),
            &V::<1>::zeros(),
            &mut out,
        )
        .expect_err("ill-conditioned");
    assert!(
        matches!(e.kind, ErrorKind::SingularConstraintJacobian { condition, limit } if condition > limit),
        "{e}"
    );
}

#[test]
fn singular_iteration_matrix() {
    // One mass on a negative spring tuned so that M + c_q K = 0 exactly for
    // the trapezoidal rule (c_q = dt^2 / 4), with analytic bias Jacobians.
    let dt = 1.0 / 128.0;
    let model = SpringChain::<1> {
        m: [1.0],
        k: [-4.0 / (dt * dt)],
        c: [0.0],
        analytic: true,
    };
    let mut g = GeneralizedAlpha::<1, 0>::new(
        StepSettings::default(),
        GeneralizedAlphaConfig {
            rho_inf: 1.0,
            ..Default::default()
        },
    );
    let s = State::new(V::<1>::new(0.1), V::<1>::zeros(), 0.0);
    let e = step_err(&mut g, &model, s, &V::<1>::zeros(), dt);
    assert!(
        matches!(e.kind, ErrorKind::SingularIterationMatrix { .. }),
        "{e}"
    );
}

#[test]
fn singular_actuation() {
    let faulty = Faulty {
        zero_actuation: true,
        ..Faulty::new(FiveBar::<2>::default())
    };
    let q0 = faulty.inner.assemble(0.0, 0.32);
    let mut id =
        InverseDynamics::<6, 4, 2, 2>::new([4, 5], q0, InverseConfig::default()).expect("set-up");
    let mut out = InverseSolution::default();
    let e = id
        .solve(
            &faulty,
            0.0,
            &V::<2>::new(0.0, 0.32),
            &V::<2>::zeros(),
            &V::<2>::zeros(),
            &mut out,
        )
        .expect_err("no actuation");
    assert!(
        matches!(e.kind, ErrorKind::SingularActuation { condition, .. } if condition == f64::INFINITY),
        "{e}"
    );
}

#[test]
fn newton_not_converged() {
    // Implicit step with a one-iteration cap: the first correction is never
    // within tolerance.
    let dp = DoublePendulum::default();
    let s = State::new(V::<2>::new(0.8, -0.5), V::<2>::new(1.0, 2.0), 0.0);
    let cfg = GeneralizedAlphaConfig {
        max_iterations: 1,
        ..Default::default()
    };
    let e = step_err(
        &mut GeneralizedAlpha::<2, 0>::new(StepSettings::default(), cfg),
        &dp,
        s,
        &V::<2>::zeros(),
        1e-2,
    );
    assert!(
        matches!(e.kind, ErrorKind::NewtonNotConverged { iterations: 1, residual, tolerance: 1.0 } if residual > 1.0),
        "{e}"
    );
    // Gauss-Legendre stage iteration: out of sweeps while contracting.
    let mut gl = GaussLegendre4 {
        max_iterations: 2,
        ..Default::default()
    };
    let e = step_err(&mut gl, &dp, s, &V::<2>::zeros(), 1e-2);
    assert!(
        matches!(
            e.kind,
            ErrorKind::StageIterationFailed {
                sweeps: 2,
                diverged: false,
                dt: 1e-2,
                ..
            }
        ),
        "{e}"
    );
    assert!(
        e.to_string()
            .contains("stage iteration did not converge in 2 sweeps at step size 1e-2"),
        "{e}"
    );
    // Position projection with a zero iteration cap.
    let sc = SliderCrank::default();
    let mut st = sc.consistent_state(0.4, 1.0);
    st.q[2] += 1e-3;
    let before = st;
    let e = project(
        &sc,
        &mut st,
        &ProjectionConfig {
            max_iterations: 0,
            ..Default::default()
        },
    )
    .expect_err("cap");
    assert!(matches!(
        e.kind,
        ErrorKind::NewtonNotConverged { iterations: 0, .. }
    ));
    assert!(
        e.to_string().contains(
            "position projection (tolerance max |Phi| <= 1e-12): Newton iteration did not \
             converge in 0 iterations"
        ),
        "{e}"
    );
    assert_eq!(st, before);
    // Inverse kinematics towards an unreachable platform position.
    let fb = FiveBar::<2>::default();
    let mut id = InverseDynamics::<6, 4, 2, 2>::new(
        [4, 5],
        fb.assemble(0.0, 0.32),
        InverseConfig::default(),
    )
    .expect("set-up");
    let mut out = InverseSolution::default();
    let e = id
        .solve(
            &fb,
            0.0,
            &V::<2>::new(0.0, 0.8),
            &V::<2>::zeros(),
            &V::<2>::zeros(),
            &mut out,
        )
        .expect_err("unreachable");
    assert!(
        matches!(
            e.kind,
            ErrorKind::NewtonNotConverged { .. } | ErrorKind::SingularConstraintJacobian { .. }
        ),
        "{e}"
    );
    let e = InverseDynamics::<6, 4, 2, 2>::new(
        [4, 5],
        fb.assemble(0.0, 0.32),
        InverseConfig {
            max_iterations: 1,
            ..Default::default()
        },
    )
    .expect("set-up")
    .solve(
        &fb,
        0.0,
        &V::<2>::new(0.05, 0.30),
        &V::<2>::zeros(),
        &V::<2>::zeros(),
        &mut out,
    )
    .expect_err("one iteration is not enough from afar");
    assert!(
        matches!(e.kind, ErrorKind::NewtonNotConverged { iterations: 1, .. }),
        "{e}"
    );
}

#[test]
fn decomposition_not_converged() {
    // The SVD path (forced here: the five-bar is square and well posed, so
    // the fast path needs no SVD and succeeds).
    let fb = FiveBar::<2>::default();
    let cfg = InverseConfig {
        max_sweeps: 0,
        fast_path: false,
        ..Default::default()
    };
    let mut id =
        InverseDynamics::<6, 4, 2, 2>::new([4, 5], fb.assemble(0.0, 0.32), cfg).expect("set-up");
    let mut out = InverseSolution::default();
    let e = id
        .solve(
            &fb,
            0.0,
            &V::<2>::new(0.0, 0.32),
            &V::<2>::zeros(),
            &V::<2>::zeros(),
            &mut out,
        )
        .expect_err("no sweeps allowed");
    assert_eq!(e.kind, ErrorKind::DecompositionNotConverged { sweeps: 0 });
    let before = id;
    id.config.fast_path = true;
    id.solve(
        &fb,
        0.0,
        &V::<2>::new(0.0, 0.32),
        &V::<2>::zeros(),
        &V::<2>::zeros(),
        &mut out,
    )
    .expect("the fast path needs no SVD");
    assert_ne!(id, before);
    // With the fast path on, redundant actuation still needs the SVD (the
    // force system is 6 x 7): the fallback reports the non-convergence.
    let fb3 = FiveBar::<3>::default();
    let cfg = InverseConfig {
        max_sweeps: 0,
        ..Default::default()
    };
    let mut id =
        InverseDynamics::<6, 4, 3, 2>::new([4, 5], fb3.assemble(0.0, 0.32), cfg).expect("set-up");
    let before = id;
    let mut out3 = InverseSolution::default();
    let e = id
        .solve(
            &fb3,
            0.0,
            &V::<2>::new(0.0, 0.32),
            &V::<2>::zeros(),
            &V::<2>::zeros(),
            &mut out3,
        )
        .expect_err("no sweeps allowed");
    assert_eq!(e.kind, ErrorKind::DecompositionNotConverged { sweeps: 0 });
    assert_eq!(id, before, "solver unchanged on error");
    assert_eq!(
        out3,
        InverseSolution::default(),
        "output unchanged on error"
    );
}

#[test]
fn invalid_step_size() {
    let p = Pendulum::default();
    for dt in [0.0, -1e-3, f64::NAN, f64::INFINITY] {
        all_integrators(&p, pendulum_state(), &V::<1>::zeros(), dt, |e| {
            assert!(matches!(e.kind, ErrorKind::InvalidStepSize { .. }), "{e}")
        });
    }
}

#[test]
fn step_too_large() {
    let p = Pendulum::default();
    let settings = StepSettings {
        max_step: 1e-2,
        ..Default::default()
    };
    let check = |e: &Error| {
        assert_eq!(
            e.kind,
            ErrorKind::StepTooLarge {
                dt: 0.1,
                value: 0.1,
                limit: 1e-2,
                rate: None,
            }
        )
    };
    check(&step_err(
        &mut Rk4::new(settings),
        &p,
        pendulum_state(),
        &V::<1>::zeros(),
        0.1,
    ));
    check(&step_err(
        &mut SemiImplicitEuler::new(settings),
        &p,
        pendulum_state(),
        &V::<1>::zeros(),
        0.1,
    ));
    check(&step_err(
        &mut GaussLegendre4::new(settings),
        &p,
        pendulum_state(),
        &V::<1>::zeros(),
        0.1,
    ));
    check(&step_err(
        &mut GeneralizedAlpha::<1, 0>::new(settings, GeneralizedAlphaConfig::default()),
        &p,
        pendulum_state(),
        &V::<1>::zeros(),
        0.1,
    ));
    // Explicit stability estimate on a stiff chain (~3 kHz mode at 5 ms).
    let chain = SpringChain::<4>::stiff();
    let s = State::new(V::<4>::from_element(0.01), V::<4>::zeros(), 0.0);
    let e = step_err(&mut Rk4::default(), &chain, s, &V::<1>::zeros(), 5e-3);
    assert!(matches!(e.kind, ErrorKind::StepTooLarge { value, limit, .. } if value > limit));
}

#[test]
fn adaptive_step_failures() {
    let p = Pendulum::default();
    let s0 = pendulum_state();
    // Tolerance unreachable above the minimum step.
    let mut g = AdaptiveRk4 {
        rtol: 1e-20,
        atol: 0.0,
        min_step: 1e-3,
        ..Default::default()
    };
    let mut s = s0;
    let e = g
        .step_adaptive(&p, &mut s, &V::<1>::zeros(), 1e-2)
        .expect_err("underflow");
    assert!(
        matches!(e.kind, ErrorKind::StepSizeUnderflow { dt, min_step } if dt < min_step),
        "{e}"
    );
    assert_eq!(s, s0);
    // No rejection allowed.
    let mut g = AdaptiveRk4 {
        rtol: 1e-20,
        atol: 0.0,
        max_rejections: 0,
        ..Default::default()
    };
    let e = g
        .step_adaptive(&p, &mut s, &V::<1>::zeros(), 1e-2)
        .expect_err("rejected");
    assert!(
        matches!(e.kind, ErrorKind::TooManyRejections { rejections: 1, .. }),
        "{e}"
    );
    assert_eq!(s, s0);
    // Fixed interval with too small a substep budget.
    let mut g = AdaptiveRk4 {
        rtol: 1e-12,
        atol: 1e-14,
        max_substeps: 2,
        ..Default::default()
    };
    let e = step_err(&mut g, &p, s0, &V::<1>::zeros(), 1.0);
    assert!(
        matches!(e.kind, ErrorKind::SubstepLimit { substeps: 2, .. }),
        "{e}"
    );
    assert_eq!(g.dt_next, None, "step-size memory restored");
}

#[test]
fn invalid_configuration() {
    let q = V::<3>::zeros();
    let cfg = InverseConfig::default();
    let e = InverseDynamics::<3, 2, 1, 1>::new([3], q, cfg).expect_err("out of range");
    assert_eq!(
        e.kind,
        ErrorKind::InvalidIndex {
            what: "prescribed coordinate",
            entry: 0,
            index: 3,
            len: 3
        },
        "{e}"
    );
    let e = InverseDynamics::<3, 2, 1, 2>::new([1, 1], q, cfg).expect_err("repeated");
    assert_eq!(
        e.kind,
        ErrorKind::InvalidIndex {
            what: "prescribed coordinate",
            entry: 1,
            index: 1,
            len: 3
        },
        "{e}"
    );
    assert!(e.to_string().contains("entry 1 repeats index 1"), "{e}");
    let e = InverseDynamics::<3, 2, 1, 0>::new([], q, cfg).expect_err("under-determined");
    assert!(
        matches!(e.kind, ErrorKind::InvalidConfiguration { .. }),
        "{e}"
    );
}

#[test]
fn times_are_printed_with_bounded_digits() {
    for (t, shown) in [
        (0.0, "0"),
        (0.5, "0.5"),
        (4.5, "4.5"),
        (1e300, "1e300"),
        (-2.5e-7, "-2.5e-7"),
        (f64::MAX, "1.7976931348623157e308"),
    ] {
        assert_eq!(std::format!("{}", flexdyn_runtime::Time(t)), shown);
    }
    let e = Error::new(ErrorKind::InvalidStepSize { dt: 0.0 }, 1e300);
    assert_eq!(std::format!("{e}"), "at t = 1e300 s: invalid step size 0e0");
}
