//! Servo constraints ([`Servo`], [`servo_run`]) against independent
//! references: the pendulum's closed-form inverse dynamics, the rigid
//! inverse-dynamics solver (slider-crank with a prescribed coordinate or a
//! general output, five-bar platform), a rotating arm whose radial
//! spring-mass and a slider-crank whose absorber mass are not prescribed and
//! must follow their own ODEs; and the set-up and singularity errors.

mod models;

use core::ops::ControlFlow;
use flexdyn_runtime::control::{
    servo_run, Coordinates, OutputTerms, Outputs, Servo, ServoConfig, ServoSample, Target,
    Trajectory,
};
use flexdyn_runtime::nalgebra::Const;
use flexdyn_runtime::{
    Error, ErrorKind, GeneralizedAlpha, InverseConfig, InverseDynamics, InverseSolution, Quantity,
    Rk4, State, StepSettings,
};
use models::*;

/// The error of a set-up or solve that must fail.
fn rejected<T>(r: Result<T, Error>) -> Error {
    match r {
        Ok(_) => panic!("accepted"),
        Err(e) => e,
    }
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * b.abs().max(1.0)
}

// ---------------------------------------------------------------------------
// Pendulum with a prescribed angle: tau = m l^2 th'' + m g l sin th + c th'.
// ---------------------------------------------------------------------------

fn pendulum() -> Pendulum {
    Pendulum {
        m: 1.3,
        l: 0.7,
        g: 9.81,
        c: 0.3,
    }
}

fn swing(t: f64) -> Target<1> {
    let (s, c) = (2.0 * t).sin_cos();
    Target {
        position: V::<1>::new(0.2 + 0.4 * s),
        velocity: V::<1>::new(0.8 * c),
        acceleration: V::<1>::new(-1.6 * s),
    }
}

/// The pendulum's torque for acceleration `a` at `(th, thd)`.
fn pendulum_torque(p: &Pendulum, th: f64, thd: f64, a: f64) -> f64 {
    p.m * p.l * p.l * a + p.m * p.g * p.l * th.sin() + p.c * thd
}

#[test]
fn pendulum_servo_torque_is_the_closed_form_inverse_dynamics() {
    let p = pendulum();
    let config = ServoConfig::default();
    let servo = Servo::new(&p, Coordinates([0]), swing, config).expect("servo");
    for t in [0.0, 0.3, 1.1, 2.5] {
        let d = swing(t);
        // On the path: exactly the prescribed acceleration.
        let (th, thd) = (d.position[0], d.velocity[0]);
        let sol = servo
            .solve(&V::<1>::new(th), &V::<1>::new(thd), t)
            .expect("solve");
        let expected = pendulum_torque(&p, th, thd, d.acceleration[0]);
        assert!(
            close(sol.tau[0], expected, 1e-13),
            "t = {t}: {} vs {expected}",
            sol.tau[0]
        );
        assert!(close(sol.qdd[0], d.acceleration[0], 1e-13));
        assert!(close(sol.condition, 1.0, 1e-14), "{}", sol.condition);
        // Off the path: the stabilised acceleration a + 2 alpha e' + beta^2 e.
        let (th, thd) = (th + 0.05, thd - 0.1);
        let sol = servo
            .solve(&V::<1>::new(th), &V::<1>::new(thd), t)
            .expect("solve");
        let (al, be) = (config.output_gains.alpha, config.output_gains.beta);
        let a =
            d.acceleration[0] + 2.0 * al * (d.velocity[0] - thd) + be * be * (d.position[0] - th);
        let expected = pendulum_torque(&p, th, thd, a);
        assert!(
            close(sol.tau[0], expected, 1e-13),
            "t = {t}: {} vs {expected}",
            sol.tau[0]
        );
    }
}

#[test]
fn servo_run_stops_when_the_record_says_so() {
    let p = pendulum();
    let servo = Servo::new(&p, Coordinates([0]), swing, ServoConfig::default()).expect("servo");
    let d = swing(0.0);
    let mut state = State::new(d.position, d.velocity, 0.0);
    let mut integrator = GeneralizedAlpha::<1, 0>::default();
    let mut samples = 0;
    let summary = servo_run(&servo, &mut integrator, &mut state, 1e-3, 2000, |_| {
        samples += 1;
        match samples {
            10 => ControlFlow::Break(()),
            _ => ControlFlow::Continue(()),
        }
    })
    .expect("servo run");
    // The start and nine steps recorded; the run ends with the tenth sample.
    assert_eq!((summary.steps, samples), (9, 10));
    assert!(close(state.t, 9e-3, 1e-12), "{}", state.t);
}

#[test]
fn pendulum_servo_run_follows_the_path_with_the_closed_form_torque() {
    let p = pendulum();
    let servo = Servo::new(&p, Coordinates([0]), swing, ServoConfig::default()).expect("servo");
    let d = swing(0.0);
    let mut state = State::new(d.position, d.velocity, 0.0);
    let mut integrator = GeneralizedAlpha::<1, 0>::default();
    let (mut path_error, mut torque_error, mut samples) = (0.0f64, 0.0f64, 0);
    let summary = servo_run(&servo, &mut integrator, &mut state, 1e-3, 2000, |s| {
        let d = swing(s.state.t);
        path_error = path_error.max((s.state.q[0] - d.position[0]).abs());
        let expected = pendulum_torque(&p, d.position[0], d.velocity[0], d.acceleration[0]);
        torque_error = torque_error.max((s.tau[0] - expected).abs());
        samples += 1;
        ControlFlow::Continue(())
    })
    .expect("servo run");
    println!("pendulum: path error {path_error:.3e} rad, torque error {torque_error:.3e} N m");
    assert_eq!((summary.steps, samples), (2000, 2001));
    assert!(close(state.t, 2.0, 1e-12));
    assert!(path_error < 5e-7, "{path_error:e}");
    assert!(torque_error < 1e-5, "{torque_error:e}");
}

// ---------------------------------------------------------------------------
// Slider-crank (q = crank, rod, slider; crank torque) against the rigid
// inverse-dynamics solver.
// ---------------------------------------------------------------------------

/// Slider position 0.3 + 0.05 sin(3 t) (between the dead centres at 0.2 and
/// 0.4).
fn slider_path(t: f64) -> Target<1> {
    let (s, c) = (3.0 * t).sin_cos();
    Target {
        position: V::<1>::new(0.3 + 0.05 * s),
        velocity: V::<1>::new(0.15 * c),
        acceleration: V::<1>::new(-0.45 * s),
    }
}

/// The rigid inverse dynamics of `model` along `path` at `t`.
fn rigid_at<M, const NQ: usize, const NC: usize, const NU: usize, const NP: usize>(
    solver: &mut InverseDynamics<NQ, NC, NU, NP>,
    model: &M,
    path: impl Fn(f64) -> Target<NP>,
    t: f64,
) -> InverseSolution<NQ, NC, NU>
where
    M: flexdyn_runtime::Model<NQ, NC, NU>,
{
    let d = path(t);
    let mut out = InverseSolution::default();
    solver
        .solve(
            model,
            t,
            &d.position,
            &d.velocity,
            &d.acceleration,
            &mut out,
        )
        .expect("rigid inverse dynamics");
    out
}

/// The rigid inverse dynamics of the slider-crank with coordinate `index`
/// prescribed.
struct Rigid {
    solver: InverseDynamics<3, 2, 1, 1>,
}

impl Rigid {
    fn new(index: usize) -> Self {
        let guess = SliderCrank::default().consistent_state(1.4, 0.0).q;
        let solver =
            InverseDynamics::new([index], guess, InverseConfig::default()).expect("set-up");
        Rigid { solver }
    }
    fn at(&mut self, path: fn(f64) -> Target<1>, t: f64) -> InverseSolution<3, 2, 1> {
        rigid_at(&mut self.solver, &SliderCrank::default(), path, t)
    }
}

/// The slider-crank servo of [`slider_servo`].
type SliderServo<'a> =
    Servo<'a, SliderCrank, Coordinates<[usize; 1]>, fn(f64) -> Target<1>, Const<1>>;

/// The slider-crank with its slider following [`slider_path`].
fn slider_servo(model: &SliderCrank, config: ServoConfig) -> SliderServo<'_> {
    Servo::new(
        model,
        Coordinates([2]),
        slider_path as fn(f64) -> Target<1>,
        config,
    )
    .expect("servo")
}

#[test]
fn slider_crank_servo_matches_the_rigid_inverse_dynamics() {
    let model = SliderCrank::default();
    let servo = slider_servo(&model, ServoConfig::default());
    let conditions = matches_rigid(&servo, 2, slider_path, (0..20).map(|k| 0.1 * k as f64));
    assert!(
        conditions.0 > 1.0 && conditions.1 < 10.0,
        "servo conditions {conditions:?}"
    );
}

/// Checks the servo's solutions at the states of the rigid inverse dynamics
/// with coordinate `index` following `path`, at `times`: the same torques,
/// accelerations and multipliers. Returns the smallest and largest servo
/// condition.
fn matches_rigid<O, T>(
    servo: &Servo<'_, SliderCrank, O, T, Const<1>>,
    index: usize,
    path: fn(f64) -> Target<1>,
    times: impl Iterator<Item = f64>,
) -> (f64, f64)
where
    O: Outputs<Const<3>, Const<1>>,
    T: Trajectory<Const<1>>,
{
    let mut rigid = Rigid::new(index);
    let mut conditions = (f64::INFINITY, 0.0f64);
    for t in times {
        let reference = rigid.at(path, t);
        let sol = servo
            .solve(&reference.q, &reference.qd, t)
            .expect("servo solve");
        assert!(
            close(sol.tau[0], reference.tau[0], 1e-10),
            "t = {t}: {} vs {}",
            sol.tau[0],
            reference.tau[0]
        );
        for i in 0..3 {
            assert!(
                close(sol.qdd[i], reference.qdd[i], 1e-9),
                "qdd[{i}] at t = {t}"
            );
        }
        for i in 0..2 {
            assert!(
                close(sol.lambda[i], reference.lambda[i], 1e-9),
                "lambda[{i}] at t = {t}"
            );
        }
        conditions = (
            conditions.0.min(sol.condition),
            conditions.1.max(sol.condition),
        );
    }
    conditions
}

#[test]
fn rigid_servo_run_reproduces_the_rigid_inverse_dynamics() {
    let model = SliderCrank::default();
    let servo = slider_servo(&model, ServoConfig::default());
    let mut rigid = Rigid::new(2);
    let start = rigid.at(slider_path, 0.0);
    let mut state = State::new(start.q, start.qd, 0.0);
    let mut integrator =
        GeneralizedAlpha::<3, 2>::new(StepSettings::with_projection(), Default::default());
    let mut samples: Vec<ServoSample<3, 1>> = Vec::new();
    servo_run(&servo, &mut integrator, &mut state, 2e-3, 1000, |s| {
        samples.push(*s);
        ControlFlow::Continue(())
    })
    .expect("servo run");
    let (mut torque_error, mut path_error, mut scale) = (0.0f64, 0.0f64, 0.0f64);
    for s in &samples {
        let reference = rigid.at(slider_path, s.state.t);
        torque_error = torque_error.max((s.tau[0] - reference.tau[0]).abs());
        scale = scale.max(reference.tau[0].abs());
        path_error = path_error.max((s.state.q - reference.q).amax());
    }
    println!(
        "slider-crank: torque error {torque_error:.3e} of {scale:.3e} N m, path {path_error:.3e}"
    );
    assert_eq!(samples.len(), 1001);
    assert!(torque_error < 1e-5 * scale, "{torque_error:e}");
    assert!(path_error < 5e-6, "{path_error:e}");
}

/// The crank pin's height `y = r sin(theta)`: a general output.
struct CrankPinHeight(f64);

impl Outputs<Const<3>, Const<1>> for CrankPinHeight {
    fn count(&self) -> Const<1> {
        Const
    }
    fn evaluate(
        &self,
        q: &V<3>,
        qd: &V<3>,
        _t: f64,
        out: &mut OutputTerms<f64, Const<3>, Const<1>>,
    ) {
        let (s, c) = q[0].sin_cos();
        out.y[0] = self.0 * s;
        out.y_q = Mat::<1, 3>::new(self.0 * c, 0.0, 0.0);
        out.rate[0] = self.0 * c * qd[0];
        out.convective[0] = -self.0 * s * qd[0] * qd[0];
    }
}

/// Crank angle 0.8 + 0.3 sin(2 t).
fn crank_path(t: f64) -> Target<1> {
    let (s, c) = (2.0 * t).sin_cos();
    Target {
        position: V::<1>::new(0.8 + 0.3 * s),
        velocity: V::<1>::new(0.6 * c),
        acceleration: V::<1>::new(-1.2 * s),
    }
}

#[test]
fn general_output_servo_matches_the_prescribed_coordinate_it_implies() {
    let model = SliderCrank::default();
    let r = model.r;
    // y_d = r sin(theta_d) and its derivatives by the chain rule.
    let height = move |t: f64| {
        let d = crank_path(t);
        let (th, w, a) = (d.position[0], d.velocity[0], d.acceleration[0]);
        let (s, c) = th.sin_cos();
        Target {
            position: V::<1>::new(r * s),
            velocity: V::<1>::new(r * c * w),
            acceleration: V::<1>::new(r * (c * a - s * w * w)),
        }
    };
    let servo =
        Servo::new(&model, CrankPinHeight(r), height, ServoConfig::default()).expect("servo");
    matches_rigid(&servo, 0, crank_path, (0..15).map(|k| 0.13 * k as f64));
}

#[test]
fn parallel_robot_platform_servo_matches_the_rigid_inverse_dynamics() {
    // The robot's use: a closed-chain mechanism, the platform coordinates
    // prescribed, one actuator per prescribed coordinate.
    let model = FiveBar::<2>::default();
    let servo = Servo::new(
        &model,
        Coordinates([4, 5]),
        platform_circle,
        ServoConfig::default(),
    )
    .expect("servo");
    let mut rigid = InverseDynamics::<6, 4, 2, 2>::new(
        [4, 5],
        model.assemble(0.04, 0.32),
        InverseConfig::default(),
    )
    .expect("set-up");
    let mut exact = |t: f64| rigid_at(&mut rigid, &model, platform_circle, t);
    let start = exact(0.0);
    let mut state = State::new(start.q, start.qd, 0.0);
    let mut integrator =
        GeneralizedAlpha::<6, 4>::new(StepSettings::with_projection(), Default::default());
    let (mut at_state, mut along, mut scale) = (0.0f64, 0.0f64, 0.0f64);
    servo_run(&servo, &mut integrator, &mut state, 2e-3, 1000, |s| {
        let reference = exact(s.state.t);
        scale = scale.max(reference.tau.amax());
        along = along.max((s.tau - reference.tau).amax());
        // At the rigid solution's own state the servo is exact.
        let sol = servo
            .solve(&reference.q, &reference.qd, reference.t)
            .expect("servo solve");
        at_state = at_state.max((sol.tau - reference.tau).amax());
        ControlFlow::Continue(())
    })
    .expect("servo run");
    println!("five-bar: torque error {along:.3e} along the run, {at_state:.3e} at the same states, of {scale:.3e} N m");
    assert!(at_state < 1e-10 * scale, "{at_state:e}");
    assert!(along < 1e-5 * scale, "{along:e}");
}

// ---------------------------------------------------------------------------
// Rotating arm: hub angle prescribed, the radial spring-mass integrated.
// ---------------------------------------------------------------------------

fn arm() -> RotatingArm {
    RotatingArm {
        c: 0.4,
        ..RotatingArm::default()
    }
}

/// Hub angle 3 t + 0.3 sin(2 t).
fn spin(t: f64) -> Target<1> {
    let (s, c) = (2.0 * t).sin_cos();
    Target {
        position: V::<1>::new(3.0 * t + 0.3 * s),
        velocity: V::<1>::new(3.0 + 0.6 * c),
        acceleration: V::<1>::new(-1.2 * s),
    }
}

/// Solution `y = (x, x')` of `x'' = accel(t, x, x')` from `y0` at `t = k dt`
/// for `k = 0..=steps`, by classical RK4 with 100 substeps per interval.
fn second_order_reference(
    accel: impl Fn(f64, f64, f64) -> f64,
    y0: [f64; 2],
    dt: f64,
    steps: usize,
) -> Vec<[f64; 2]> {
    let f = |t: f64, y: [f64; 2]| [y[1], accel(t, y[0], y[1])];
    let h = dt / 100.0;
    let mut y = y0;
    let mut out = vec![y];
    for k in 0..steps {
        for n in 0..100 {
            let t = k as f64 * dt + n as f64 * h;
            let k1 = f(t, y);
            let k2 = f(
                t + h / 2.0,
                [y[0] + h / 2.0 * k1[0], y[1] + h / 2.0 * k1[1]],
            );
            let k3 = f(
                t + h / 2.0,
                [y[0] + h / 2.0 * k2[0], y[1] + h / 2.0 * k2[1]],
            );
            let k4 = f(t + h, [y[0] + h * k3[0], y[1] + h * k3[1]]);
            for i in 0..2 {
                y[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
            }
        }
        out.push(y);
    }
    out
}

/// `(r, r')` at `t = k * dt` from the slider's own ODE
/// `m r'' = m r w(t)^2 - c r' - k (r - r0)`, `w = theta_d'`.
fn slider_reference(a: &RotatingArm, dt: f64, steps: usize) -> Vec<[f64; 2]> {
    let accel = |t: f64, r: f64, rd: f64| {
        let w = spin(t).velocity[0];
        (a.m * r * w * w - a.c * rd - a.k * (r - a.r0)) / a.m
    };
    second_order_reference(accel, [a.r0, 0.0], dt, steps)
}

/// Largest deviations of `(r, tau)` from the reference over 2 s at 1 ms.
fn arm_errors(integrator: &mut (impl flexdyn_runtime::Integrator<2, 0, 1> + Clone)) -> (f64, f64) {
    let a = arm();
    let servo = Servo::new(&a, Coordinates([0]), spin, ServoConfig::default()).expect("servo");
    let (dt, steps) = (1e-3, 2000);
    let reference = slider_reference(&a, dt, steps);
    let d = spin(0.0);
    let mut state = State::new(
        V::<2>::new(d.position[0], a.r0),
        V::<2>::new(d.velocity[0], 0.0),
        0.0,
    );
    let (mut r_error, mut tau_error, mut k) = (0.0f64, 0.0f64, 0);
    servo_run(&servo, integrator, &mut state, dt, steps, |s| {
        let [r, rd] = reference[k];
        let d = spin(s.state.t);
        let (w, alpha) = (d.velocity[0], d.acceleration[0]);
        let tau = (a.j + a.m * r * r) * alpha + 2.0 * a.m * r * rd * w;
        r_error = r_error.max((s.state.q[1] - r).abs());
        tau_error = tau_error.max((s.tau[0] - tau).abs());
        k += 1;
        ControlFlow::Continue(())
    })
    .expect("servo run");
    assert_eq!(k, steps + 1);
    // The slider does move: the centrifugal load stretches the spring.
    let stretch = reference.iter().map(|x| x[0] - a.r0).fold(0.0, f64::max);
    assert!(stretch > 0.01, "{stretch}");
    (r_error, tau_error)
}

#[test]
fn unprescribed_elastic_coordinate_follows_its_own_ode() {
    let (r_ga, tau_ga) = arm_errors(&mut GeneralizedAlpha::<2, 0>::default());
    let (r_rk, tau_rk) = arm_errors(&mut Rk4::new(StepSettings::default()));
    println!(
        "rotating arm, generalized-alpha: r error {r_ga:.3e} m, torque error {tau_ga:.3e} N m"
    );
    println!("rotating arm, RK4: r error {r_rk:.3e} m, torque error {tau_rk:.3e} N m");
    assert!(r_ga < 1e-4 && tau_ga < 5e-3, "{r_ga:e} {tau_ga:e}");
    assert!(r_rk < 1e-6 && tau_rk < 1e-4, "{r_rk:e} {tau_rk:e}");
}

// ---------------------------------------------------------------------------
// Slider-crank with an absorber: the crank prescribed, the closure
// constraints held, the absorber mass integrated (the flexible robot's case
// in small: constraints plus an unprescribed elastic coordinate).
// ---------------------------------------------------------------------------

/// Crank angle 2 t + 0.2 sin(3 t): full turns.
fn turning(t: f64) -> Target<1> {
    let (s, c) = (3.0 * t).sin_cos();
    Target {
        position: V::<1>::new(2.0 * t + 0.2 * s),
        velocity: V::<1>::new(2.0 + 0.6 * c),
        acceleration: V::<1>::new(-1.8 * s),
    }
}

/// The slider position and velocity for crank angle `th` and rate `w`, in
/// closed form: `x = r cos th + sqrt(l^2 - r^2 sin^2 th)`.
fn slider_kinematics(a: &AbsorberCrank, th: f64, w: f64) -> (f64, f64) {
    let (r, l) = (a.crank.r, a.crank.l);
    let (s, c) = th.sin_cos();
    let root = (l * l - r * r * s * s).sqrt();
    (r * c + root, (-r * s - r * r * s * c / root) * w)
}

/// `(z, z', z'')` at `t = k dt` from the absorber's base-excited ODE
/// `m4 z'' = -k (z - x(t) - d0) - c (z' - x'(t))` with the slider's
/// closed-form motion.
fn absorber_reference(a: &AbsorberCrank, z0: f64, dt: f64, steps: usize) -> Vec<[f64; 3]> {
    let accel = |t: f64, z: f64, zd: f64| {
        let d = turning(t);
        let (x, xd) = slider_kinematics(a, d.position[0], d.velocity[0]);
        (-a.k * (z - x - a.d0) - a.c * (zd - xd)) / a.m4
    };
    second_order_reference(accel, [z0, 0.0], dt, steps)
        .iter()
        .zip(0..)
        .map(|(y, k)| [y[0], y[1], accel(k as f64 * dt, y[0], y[1])])
        .collect()
}

#[test]
fn constrained_mechanism_with_an_unprescribed_absorber() {
    // Absorber tuned to 6 rad/s, between the crank's 2 rad/s and its
    // 4 rad/s harmonic.
    let a = AbsorberCrank {
        k: 12.0,
        c: 0.3,
        ..AbsorberCrank::default()
    };
    let settings = StepSettings::with_projection();
    let config = ServoConfig {
        dynamics: settings.dynamics,
        ..ServoConfig::default()
    };
    let servo = Servo::new(&a, Coordinates([0]), turning, config).expect("servo");
    let (dt, steps) = (1e-3, 2000);
    // Start at the outer dead centre (x = r + l), the absorber relaxed.
    let d = turning(0.0);
    let crank = a.crank.consistent_state(d.position[0], d.velocity[0]);
    let z0 = crank.q[2] + a.d0;
    let reference = absorber_reference(&a, z0, dt, steps);
    let mut state = State::new(
        V::<4>::new(crank.q[0], crank.q[1], crank.q[2], z0),
        V::<4>::new(crank.qd[0], crank.qd[1], crank.qd[2], 0.0),
        0.0,
    );
    // Independent torque: the rigid inverse dynamics with the absorber
    // prescribed to its reference motion as well (one actuator for two
    // prescribed coordinates: exact when z obeys its ODE).
    let mut rigid = InverseDynamics::<4, 2, 1, 2>::new([0, 3], state.q, InverseConfig::default())
        .expect("set-up");
    let mut integrator = GeneralizedAlpha::<4, 2>::new(settings, Default::default());
    let (mut z_error, mut slider_error, mut tau_error, mut scale, mut k) =
        (0.0f64, 0.0f64, 0.0f64, 0.0f64, 0);
    let summary = servo_run(&servo, &mut integrator, &mut state, dt, steps, |s| {
        let [z, zd, zdd] = reference[k];
        let d = turning(s.state.t);
        let (x, _) = slider_kinematics(&a, d.position[0], d.velocity[0]);
        z_error = z_error.max((s.state.q[3] - z).abs());
        slider_error = slider_error.max((s.state.q[2] - x).abs());
        let path = |_t: f64| Target {
            position: V::<2>::new(d.position[0], z),
            velocity: V::<2>::new(d.velocity[0], zd),
            acceleration: V::<2>::new(d.acceleration[0], zdd),
        };
        let exact = rigid_at(&mut rigid, &a, path, s.state.t);
        tau_error = tau_error.max((s.tau[0] - exact.tau[0]).abs());
        scale = scale.max(exact.tau[0].abs());
        k += 1;
        ControlFlow::Continue(())
    })
    .expect("servo run");
    println!(
        "absorber crank: z error {z_error:.3e} m, slider error {slider_error:.3e} m, \
         torque error {tau_error:.3e} of {scale:.3e} N m, drift {:?}",
        summary.max_drift
    );
    assert_eq!(k, steps + 1);
    // The absorber does swing relative to the slider.
    let swing = reference
        .iter()
        .zip(0..)
        .map(|(r, k)| {
            let d = turning(k as f64 * dt);
            (r[0] - slider_kinematics(&a, d.position[0], d.velocity[0]).0 - a.d0).abs()
        })
        .fold(0.0, f64::max);
    assert!(swing > 0.01, "{swing}");
    assert!(z_error < 5e-6, "{z_error:e} of a swing of {swing:e}");
    assert!(slider_error < 2e-7, "{slider_error:e}");
    assert!(tau_error < 1e-5 * scale, "{tau_error:e}");
}

// ---------------------------------------------------------------------------
// Errors.
// ---------------------------------------------------------------------------

fn still(_t: f64) -> Target<1> {
    Target {
        position: V::<1>::new(0.5),
        velocity: V::<1>::zeros(),
        acceleration: V::<1>::zeros(),
    }
}

#[test]
fn servo_set_up_errors_say_what_is_wrong() {
    let two = |_t: f64| Target {
        position: V::<2>::zeros(),
        velocity: V::<2>::zeros(),
        acceleration: V::<2>::zeros(),
    };
    // Two outputs, one actuator.
    let e = rejected(Servo::new(
        &arm(),
        Coordinates([0, 1]),
        two,
        ServoConfig::default(),
    ));
    assert!(
        matches!(e.kind, ErrorKind::InvalidConfiguration { .. }),
        "{e}"
    );
    assert!(e.to_string().contains("NP > NU"), "{e}");
    // One output, two actuators.
    let e = rejected(Servo::new(
        &DoublePendulum::default(),
        Coordinates([0]),
        still,
        ServoConfig::default(),
    ));
    assert!(e.to_string().contains("NP < NU"), "{e}");
    // Index out of range, and repeated.
    let e = rejected(Servo::new(
        &pendulum(),
        Coordinates([1]),
        still,
        ServoConfig::default(),
    ));
    assert_eq!(
        e.kind,
        ErrorKind::InvalidIndex {
            what: "prescribed coordinate",
            entry: 0,
            index: 1,
            len: 1
        }
    );
    let e = rejected(Servo::new(
        &DoublePendulum::default(),
        Coordinates([1, 1]),
        two,
        ServoConfig::default(),
    ));
    assert!(e.to_string().contains("entry 1 repeats index 1"), "{e}");
}

#[test]
fn prescription_the_inputs_cannot_drive_is_a_singular_servo() {
    // The hub torque does not accelerate the slider (only its rate does,
    // through the centrifugal force): prescribing r cannot determine it.
    let a = arm();
    let servo = Servo::new(&a, Coordinates([1]), still, ServoConfig::default()).expect("set-up");
    let e = rejected(servo.solve(&V::<2>::new(0.0, 0.5), &V::<2>::new(2.0, 0.0), 0.7));
    assert_eq!(
        e.kind,
        ErrorKind::SingularServo {
            condition: f64::INFINITY,
            limit: 1e8
        },
        "{e}"
    );
    assert_eq!(e.t, 0.7);
    assert!(
        e.to_string()
            .contains("do not determine the actuator inputs"),
        "{e}"
    );
    // Slider-crank at dead centre (crank and rod aligned) with the slider
    // prescribed: the crank torque cannot accelerate the slider.
    let model = SliderCrank::default();
    let servo = Servo::new(
        &model,
        Coordinates([2]),
        slider_path,
        ServoConfig::default(),
    )
    .expect("set-up");
    let dead = model.consistent_state(0.0, 0.0);
    let e = rejected(servo.solve(&dead.q, &dead.qd, 0.0));
    assert!(
        matches!(e.kind, ErrorKind::SingularServo { condition, .. } if condition > 1e8),
        "{e}"
    );
    // Near it the condition grows like 1 / theta.
    let condition = |th: f64| {
        let s = model.consistent_state(th, 0.0);
        servo.solve(&s.q, &s.qd, 0.0).expect("solvable").condition
    };
    let ratio = condition(1e-3) / condition(1e-2);
    assert!((ratio - 10.0).abs() < 0.1, "{ratio}");
}

#[test]
fn servo_run_reports_the_servo_failure_inside_a_step() {
    // The slider pushed towards the outer dead centre (0.4 at t = pi/2):
    // with a condition limit of 20 the trial step fails there.
    let model = SliderCrank::default();
    let towards_dead_centre = |t: f64| {
        let (s, c) = t.sin_cos();
        Target {
            position: V::<1>::new(0.35 + 0.05 * s),
            velocity: V::<1>::new(0.05 * c),
            acceleration: V::<1>::new(-0.05 * s),
        }
    };
    let config = ServoConfig {
        max_condition: 20.0,
        ..ServoConfig::default()
    };
    let servo = Servo::new(&model, Coordinates([2]), towards_dead_centre, config).expect("set-up");
    let mut rigid = Rigid::new(2);
    let start = rigid.at(towards_dead_centre, 0.0);
    let mut state = State::new(start.q, start.qd, 0.0);
    let mut integrator = Rk4::new(StepSettings::with_projection());
    let mut last = None;
    let e = rejected(servo_run(
        &servo,
        &mut integrator,
        &mut state,
        1e-2,
        200,
        |s| {
            last = Some(*s);
            ControlFlow::Continue(())
        },
    ));
    assert!(
        matches!(e.kind, ErrorKind::SingularServo { condition, limit } if condition > 20.0 && limit == 20.0),
        "{e}"
    );
    let last = last.expect("samples before the failure");
    assert!(e.t > 0.5 && e.t < 1.6, "{e}");
    assert_eq!(state, last.state, "the state is the last one recorded");
    let ok = servo
        .solve(&last.state.q, &last.state.qd, last.state.t)
        .expect("last state solvable");
    assert!(ok.condition <= 20.0);
}

#[test]
fn non_finite_path_is_reported_as_such_through_the_integrator() {
    let p = pendulum();
    let broken = |t: f64| {
        let mut d = swing(t);
        if t > 0.0 {
            d.acceleration[0] = f64::NAN;
        }
        d
    };
    let servo = Servo::new(&p, Coordinates([0]), broken, ServoConfig::default()).expect("set-up");
    let d = swing(0.0);
    let mut state = State::new(d.position, d.velocity, 0.0);
    let e = rejected(servo_run(
        &servo,
        &mut GeneralizedAlpha::<1, 0>::default(),
        &mut state,
        1e-3,
        10,
        |_| ControlFlow::Continue(()),
    ));
    assert_eq!(
        e.kind,
        ErrorKind::NonFiniteInput {
            quantity: Quantity::PrescribedAcceleration,
            index: 0
        },
        "{e}"
    );
    assert_eq!(state.t, 0.0);
}
