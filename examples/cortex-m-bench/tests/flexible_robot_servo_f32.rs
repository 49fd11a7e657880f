//! The flexible parallel robot's servo-constrained inverse dynamics along
//! the paper's circle, as `parallel-robot inverse` runs it (servo
//! constraints on the platform centre, generalized-alpha with `rho_inf = 0`,
//! no filtered start, coordinate projection after every step, trial step
//! without it), in f32 against the same runtime code in f64, from the same
//! start (the robot in static equilibrium on the circle at t = 0, the first
//! of `parallel_robot_flexible.states.json`; its velocities scaled to the
//! angular rate):
//!
//! * at the paper's settings (2 rad/s, 5 ms, one turn): the torques and the
//!   platform's path agree to f32's resolution, but the flexible joints'
//!   deflections (about 1e-8 rad, below f32's resolution of the joint
//!   angles they add to, 3e-7 rad) are not resolved at all: the reason the
//!   generator refuses this scene in f32 by default (its stiffness spread,
//!   docs/embedded.md);
//! * faster (10 rad/s) or at a finer step (0.5 ms, where generalized-alpha
//!   damps the joints' modes less) the f32 torques are off by 0.3 % and
//!   21 % of the peak; at a coarse step (50 ms) f32 refuses at the first
//!   step (the Newton iteration matrix's condition beyond f32's limit).
//!
//! The numbers are printed (docs/embedded.md quotes them).

use flexdyn_runtime::control::{servo_run, Coordinates, Servo, ServoConfig, ServoSample, Target};
use flexdyn_runtime::integrate::{GeneralizedAlpha, GeneralizedAlphaConfig, StepSettings};
use flexdyn_runtime::nalgebra::SVector;
use flexdyn_runtime::{Error, ErrorKind, Model, Scalar, State};

#[path = "common/flexible_robot.rs"]
mod flexible;

/// The platform centre's coordinates `px, py, pz`.
const PLATFORM: [usize; 3] = [9, 10, 11];
/// Groups of coordinates: the rigid robot's joint angles, the platform
/// centre, its small rotations, the flexible joints, the links' modes.
const GROUPS: [(&str, std::ops::Range<usize>); 5] = [
    ("joint angles", 0..9),
    ("platform centre", 9..12),
    ("platform rotations", 12..15),
    ("flexible joints", 15..21),
    ("link modes", 21..39),
];

/// The paper's circle at `omega` rad/s (radius 0.1 m about `(0, 0, 0.7)`),
/// computed in `T`.
fn circle<T: Scalar>(omega: T, t: T) -> Target<3, T> {
    let (w, r, z) = (omega, T::of(0.1), T::of(0.7));
    let (s, c) = (w * t).sin_cos();
    let zero = T::zero();
    Target {
        position: SVector::from([r * c, r * s, z]),
        velocity: SVector::from([-r * w * s, r * w * c, zero]),
        acceleration: SVector::from([-r * w * w * c, -r * w * w * s, zero]),
    }
}

/// `steps` servo steps of `dt` from `start` along the circle at `omega`,
/// in `T` with `T`'s default tolerances: the samples recorded and how the
/// run ended.
fn servo_inverse<T: Scalar, M: Model<39, NC, 3, T>, const NC: usize>(
    model: &M,
    start: State<39, T>,
    (omega, dt, steps): (f64, f64, usize),
) -> (Vec<ServoSample<39, 3, T>>, Result<(), Error>) {
    let settings = StepSettings::<T>::with_projection();
    let servo_config = ServoConfig {
        dynamics: settings.dynamics,
        trial_projection: false,
        ..ServoConfig::default()
    };
    let path = move |t: T| circle(T::of(omega), t);
    let servo = Servo::new(model, Coordinates(PLATFORM), path, servo_config).unwrap();
    let config = GeneralizedAlphaConfig {
        rho_inf: T::zero(),
        filter_start: false,
        ..GeneralizedAlphaConfig::default()
    };
    let mut integrator = GeneralizedAlpha::<39, NC, T>::new(settings, config);
    let mut state = start;
    let mut samples = Vec::with_capacity(steps + 1);
    let result = servo_run(&servo, &mut integrator, &mut state, T::of(dt), steps, |s| {
        samples.push(*s);
        std::ops::ControlFlow::Continue(())
    });
    (samples, result.map(|_| ()))
}

/// f32 against f64 on one run.
struct Comparison {
    /// How the f32 run ended (the f64 run must complete).
    f32_result: Result<(), Error>,
    /// Samples the f32 run recorded.
    f32_samples: usize,
    /// Largest torque difference (N m) and the peak f64 torque.
    torque: (f64, f64),
    /// Largest distance of the platform centre from the circle (at the
    /// sample's nominal time `k dt`), f32 and f64 (m).
    path: (f64, f64),
    /// Per group of [`GROUPS`]: largest difference and the f64 peak.
    coordinates: [(f64, f64); 5],
}

/// Runs `(omega, dt, steps)` in both precisions and compares them sample
/// by sample.
fn compare(run: (f64, f64, usize)) -> Comparison {
    let (omega, dt, _) = run;
    let (q0, qd0) = flexible::states()[0];
    let qd0 = qd0 * (omega / 2.0);
    let (s64, r64) = servo_inverse(
        &flexible::f64::ParallelRobotFlexible::default(),
        State::new(q0, qd0, 0.0),
        run,
    );
    r64.unwrap_or_else(|e| panic!("f64 at {omega} rad/s, {dt} s: {e}"));
    let (s32, f32_result) = servo_inverse(
        &flexible::f32::ParallelRobotFlexible::default(),
        State::new(q0.cast::<f32>(), qd0.cast::<f32>(), 0.0f32),
        run,
    );
    let mut c = Comparison {
        f32_samples: s32.len(),
        f32_result,
        torque: (0.0, 0.0),
        path: (0.0, 0.0),
        coordinates: [(0.0, 0.0); 5],
    };
    for (k, (a, b)) in s32.iter().zip(&s64).enumerate() {
        for j in 0..3 {
            c.torque.0 = c.torque.0.max((f64::from(a.tau[j]) - b.tau[j]).abs());
            c.torque.1 = c.torque.1.max(b.tau[j].abs());
        }
        let p = circle(omega, k as f64 * dt).position;
        for (j, &i) in PLATFORM.iter().enumerate() {
            c.path.0 = c.path.0.max((f64::from(a.state.q[i]) - p[j]).abs());
            c.path.1 = c.path.1.max((b.state.q[i] - p[j]).abs());
        }
        for (g, (_, range)) in GROUPS.iter().enumerate() {
            for i in range.clone() {
                let e = &mut c.coordinates[g];
                e.0 = e.0.max((f64::from(a.state.q[i]) - b.state.q[i]).abs());
                e.1 = e.1.max(b.state.q[i].abs());
            }
        }
    }
    println!(
        "{omega} rad/s, step {dt} s, {} steps: f32 {}; torques within {:.3e} N m ({:.2e} of \
         the peak {:.3} N m); platform centre off the circle by {:.3e} m (f64: {:.3e} m)",
        s64.len() - 1,
        match &c.f32_result {
            Ok(()) => "completed".to_string(),
            Err(e) => format!("failed after {} samples: {e}", c.f32_samples),
        },
        c.torque.0,
        c.torque.0 / c.torque.1,
        c.torque.1,
        c.path.0,
        c.path.1
    );
    for ((name, _), (err, peak)) in GROUPS.iter().zip(c.coordinates) {
        println!(
            "  {name}: f32 within {err:.3e} of f64 (peak {peak:.3e}, {:.2e} of it)",
            err / peak
        );
    }
    c
}

/// Index of the flexible joints in [`GROUPS`].
const FLEXIBLE_JOINTS: usize = 3;

#[test]
fn flexible_robot_servo_inverse_dynamics_in_f32_follows_f64_along_the_circle_except_the_joint_deflections(
) {
    // One turn at the paper's rate and step: pi s.
    let c = compare((2.0, 0.005, 629));
    if let Err(e) = &c.f32_result {
        panic!("f32 fails at the paper's settings: {e}");
    }
    let (tau_err, tau_peak) = c.torque;
    // Near f32's resolution of the torques (measured 8.5e-6 of the peak;
    // a margin for the rounding of other generated programs), far below
    // the errors of the faster runs (3e-3 and more).
    assert!(tau_err <= 5e-5 * tau_peak, "{tau_err:e} of {tau_peak}");
    // The path: within f32's position tolerance (the projection's 1e-5 m).
    let tolerance = f64::from(f32::POSITION_TOLERANCE);
    assert!(c.path.0 <= tolerance, "{:e}", c.path.0);
    // The rigid robot's joint angles to f32's resolution of their values.
    let (err, peak) = c.coordinates[0];
    assert!(err <= 1e-5 * peak, "{err:e} of {peak}");
    // The flexible joints' deflections are not resolved: f32's error is as
    // large as the deflections themselves.
    let (err, peak) = c.coordinates[FLEXIBLE_JOINTS];
    assert!(err >= 0.5 * peak, "{err:e} of {peak:e}");
}

#[test]
fn flexible_robot_in_f32_loses_the_torques_faster_or_at_finer_steps_and_refuses_coarse_ones() {
    // 10 rad/s at 5 ms: a turn; at 0.5 ms: two turns.
    for (run, at_least) in [((10.0, 0.005, 126), 1e-3), ((10.0, 0.0005, 1257), 5e-2)] {
        let c = compare(run);
        if let Err(e) = &c.f32_result {
            panic!("f32 fails at {run:?}: {e}");
        }
        let (tau_err, tau_peak) = c.torque;
        assert!(tau_err >= at_least * tau_peak, "{tau_err:e} of {tau_peak}");
        let (err, peak) = c.coordinates[FLEXIBLE_JOINTS];
        assert!(err >= peak, "{err:e} of {peak:e}");
    }
    // 50 ms at 2 rad/s: f64 completes, f32's Newton matrix is beyond its
    // condition limit at the first step.
    let c = compare((2.0, 0.05, 63));
    let Err(e) = c.f32_result else {
        panic!("f32 completes at 50 ms");
    };
    let limit = f64::from(f32::ITERATION_MAX_CONDITION);
    assert!(
        matches!(e.kind, ErrorKind::SingularIterationMatrix { condition } if condition > limit),
        "{e}"
    );
    assert_eq!(c.f32_samples, 1, "{e}");
}
