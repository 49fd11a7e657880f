//! `flexdyn::prescribed_motion` on compiled-in scenes against independent references:
//! the pendulum's closed-form torque, the slider-crank's closed-form
//! kinematics and its power balance, the cart-pole's free pole integrated
//! under the servo against an independent integration of its equation,
//! sampled prescriptions (CSV) against the closed form, and clear errors
//! for prescriptions that do not determine the inputs.

use flexdyn::dynamic::{erase, DynModel};
use flexdyn::interpreted::InterpretedModel;
use flexdyn::runtime::nalgebra::{DMatrix, DVector};

#[path = "common/large_scenes.rs"]
mod large_scenes;
use flexdyn::prescribed_motion::{
    solve, FreeRates, Method, Output, Prescribed, Problem, Sample, Sink,
};
use flexdyn::runtime::nalgebra::SVector;
use flexdyn::runtime::Model;
use flexdyn::scenes::{cart_pole::CartPole, pendulum::Pendulum, slider_crank::SliderCrank};

fn names(v: &[&str]) -> Vec<String> {
    v.iter().map(|s| s.to_string()).collect()
}

/// Steps of `dt` in `duration`.
fn steps(duration: f64, dt: f64) -> usize {
    (duration / dt).round() as usize
}

/// Every sample of a solve, collected (the library streams them to a sink).
#[derive(Debug)]
struct Solution {
    method: Method,
    t: Vec<f64>,
    tau: Vec<Vec<f64>>,
    q: Vec<Vec<f64>>,
    lambda: Vec<Vec<f64>>,
}

/// Runs `solve` with a sink that keeps every sample.
fn collect(solve: impl FnOnce(Sink<'_>) -> Result<Method, String>) -> Result<Solution, String> {
    let (mut t, mut tau, mut q, mut lambda) = (vec![], vec![], vec![], vec![]);
    let method = solve(&mut |s: &Sample<'_>| {
        t.push(s.t);
        tau.push(s.tau.to_vec());
        q.push(s.q.to_vec());
        lambda.push(s.lambda.to_vec());
        Ok(())
    })?;
    Ok(Solution {
        method,
        t,
        tau,
        q,
        lambda,
    })
}

#[test]
fn pendulum_torque_is_the_closed_form() {
    let (a, w) = (0.8, 3.0);
    let motion = move |t: f64| {
        let (s, c) = (w * t).sin_cos();
        [a * s, a * w * c, -a * w * w * s]
    };
    let problem = Problem {
        coordinates: names(&["theta"]),
        constraints: vec![],
        actuators: names(&["tau"]),
        prescribed: vec![Prescribed {
            output: Output::Coordinate(0),
            motion: &motion,
        }],
        guess: vec![0.0],
        dt: 0.01,
        steps: steps(2.0, 0.01),
        free_rates: FreeRates::LeastEnergy,
    };
    let out = collect(|sink| solve(&*erase(Pendulum::default()), &problem, sink)).unwrap();
    assert_eq!(out.method, Method::Determined);
    let (m, l, g) = (1.0, 0.5, 9.81);
    for (k, &t) in out.t.iter().enumerate() {
        let [th, _, thdd] = motion(t);
        let want = m * l * l * thdd + m * g * l * th.sin();
        assert!(
            (out.tau[k][0] - want).abs() < 1e-10,
            "t = {t}: {} vs {want}",
            out.tau[k][0]
        );
        assert!((out.q[k][0] - th).abs() < 1e-14);
    }
}

/// Closed-form slider-crank kinematics: `phi = asin(r sin(theta) / lr)`,
/// `x = r cos(theta) + lr cos(phi)`.
fn crank_pose(theta: f64) -> [f64; 3] {
    let (r, lr) = (0.1, 0.3);
    let phi = (r * theta.sin() / lr).asin();
    [theta, phi, r * theta.cos() + lr * phi.cos()]
}

/// The compiled slider-crank with `theta` prescribed, over 1 s at 0.01 s.
fn crank_solve(motion: &dyn Fn(f64) -> [f64; 3]) -> Solution {
    let problem = Problem {
        coordinates: names(&["theta", "phi", "x"]),
        constraints: names(&["closure_x", "closure_y"]),
        actuators: names(&["tau"]),
        prescribed: vec![Prescribed {
            output: Output::Coordinate(0),
            motion,
        }],
        guess: vec![0.3, 0.1, 0.4],
        dt: 0.01,
        steps: steps(1.0, 0.01),
        free_rates: FreeRates::LeastEnergy,
    };
    collect(|sink| solve(&*erase(SliderCrank), &problem, sink)).unwrap()
}

#[test]
fn slider_crank_matches_closed_form_kinematics_and_power_balance() {
    let w = 4.0;
    let motion = move |t: f64| [0.3 + w * t + 0.5 * t * t, w + t, 1.0];
    let model = SliderCrank;
    let out = crank_solve(&motion);
    // Energy along the closed-form motion, velocities by central differences.
    let energy = |t: f64| {
        let h = 1e-5;
        let q = SVector::<f64, 3>::from(crank_pose(motion(t)[0]));
        let (qp, qm) = (crank_pose(motion(t + h)[0]), crank_pose(motion(t - h)[0]));
        let qd = SVector::<f64, 3>::from_fn(|i, _| (qp[i] - qm[i]) / (2.0 * h));
        model.kinetic_energy(&q, &qd, t) + model.potential_energy(&q, t)
    };
    for (k, &t) in out.t.iter().enumerate().skip(1).take(out.t.len() - 2) {
        let want = crank_pose(motion(t)[0]);
        for (i, w) in want.iter().enumerate() {
            assert!((out.q[k][i] - w).abs() < 1e-12, "t = {t}, q[{i}]");
        }
        // The constraints are scleronomic: tau theta' = dE/dt.
        let h = 1e-4;
        let power = (energy(t + h) - energy(t - h)) / (2.0 * h);
        let tau = out.tau[k][0];
        assert!(
            (tau * motion(t)[1] - power).abs() < 1e-5 * (1.0 + power.abs()),
            "t = {t}: tau theta' = {} vs dE/dt = {power}",
            tau * motion(t)[1]
        );
    }
}

/// `theta'' = 3/(2 l) (g sin(theta) - x'' cos(theta))` of the cart-pole's
/// uniform pole (from its Lagrangian), by RK4 at a fine step.
fn pole_angle(x: impl Fn(f64) -> [f64; 3], until: f64) -> [f64; 2] {
    let (l, g) = (1.0, 9.81);
    let f = |t: f64, y: [f64; 2]| {
        let xdd = x(t)[2];
        [y[1], 1.5 / l * (g * y[0].sin() - xdd * y[0].cos())]
    };
    let steps = (until / 1e-5).round() as usize;
    let h = until / steps as f64;
    let mut y = [std::f64::consts::PI, 0.0];
    for k in 0..steps {
        let t = k as f64 * h;
        let add = |y: [f64; 2], d: [f64; 2], c: f64| [y[0] + c * d[0], y[1] + c * d[1]];
        let k1 = f(t, y);
        let k2 = f(t + h / 2.0, add(y, k1, h / 2.0));
        let k3 = f(t + h / 2.0, add(y, k2, h / 2.0));
        let k4 = f(t + h, add(y, k3, h));
        for i in 0..2 {
            y[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        }
    }
    y
}

#[test]
fn cart_pole_servo_integrates_the_free_pole_and_gives_the_cart_force() {
    // The cart follows x(t); the pole (not prescribed, not actuated) swings
    // from rest hanging down (its static equilibrium from a guess near it).
    let motion = |t: f64| {
        let (s, c) = (3.0 * t).sin_cos();
        [0.2 * (1.0 - c), 0.6 * s, 1.8 * c]
    };
    let problem = Problem {
        coordinates: names(&["x", "theta"]),
        constraints: vec![],
        actuators: names(&["force"]),
        prescribed: vec![Prescribed {
            output: Output::Coordinate(0),
            motion: &motion,
        }],
        guess: vec![0.0, 3.0],
        dt: 0.001,
        steps: steps(1.0, 0.001),
        free_rates: FreeRates::LeastEnergy,
    };
    let out = collect(|sink| solve(&*erase(CartPole), &problem, sink)).unwrap();
    assert_eq!(out.method, Method::Servo);
    assert_eq!(out.t.len(), 1001);
    let (mc, m, l) = (1.0, 0.1, 1.0);
    let scale = (mc + m) * 1.8;
    for k in (0..=1000).step_by(100) {
        let t = out.t[k];
        assert!((out.q[k][0] - motion(t)[0]).abs() < 1e-6, "t = {t}: x");
        let [th, thd] = pole_angle(motion, t);
        assert!(
            (out.q[k][1] - th).abs() < 1e-4,
            "t = {t}: theta {} vs {th}",
            out.q[k][1]
        );
        // F = (mc + m) x'' + m l/2 (theta'' cos - theta'^2 sin).
        let xdd = motion(t)[2];
        let thdd = 1.5 / l * (9.81 * th.sin() - xdd * th.cos());
        let force = (mc + m) * xdd + m * l / 2.0 * (thdd * th.cos() - thd * thd * th.sin());
        assert!(
            (out.tau[k][0] - force).abs() < 1e-3 * scale,
            "t = {t}: force {} vs {force}",
            out.tau[k][0]
        );
    }
}

#[test]
fn prescriptions_that_do_not_determine_the_inputs_are_refused() {
    let motion = |t: f64| [t, 1.0, 0.0];
    let base = || Problem {
        coordinates: names(&["theta", "phi", "x"]),
        constraints: names(&["closure_x", "closure_y"]),
        actuators: names(&["tau"]),
        prescribed: vec![],
        guess: vec![0.3, 0.1, 0.4],
        dt: 0.01,
        steps: steps(0.1, 0.01),
        free_rates: FreeRates::LeastEnergy,
    };
    // No prescription at all: fewer than the actuators.
    let e = collect(|sink| solve(&*erase(SliderCrank), &base(), sink)).unwrap_err();
    assert!(e.contains("does not determine the actuator inputs"), "{e}");
    // Two prescriptions for one actuator.
    let mut two = base();
    two.prescribed = vec![
        Prescribed {
            output: Output::Coordinate(0),
            motion: &motion,
        },
        Prescribed {
            output: Output::Coordinate(2),
            motion: &motion,
        },
    ];
    let e = collect(|sink| solve(&*erase(SliderCrank), &two, sink)).unwrap_err();
    assert!(e.contains("2 prescribed") && e.contains("`x`"), "{e}");
    // The slider's position prescribed: it determines the pose (two
    // branches), but at the dead centre the crank's torque cannot move it.
    let mut slider = base();
    let dead_centre = |_: f64| [0.4, 0.0, 0.0];
    slider.prescribed = vec![Prescribed {
        output: Output::Coordinate(2),
        motion: &dead_centre,
    }];
    slider.guess = vec![0.0, 0.0, 0.4];
    let e = collect(|sink| solve(&*erase(SliderCrank), &slider, sink)).unwrap_err();
    assert!(e.contains("at t = 0 s"), "{e}");
    println!("{e}");
}

/// A sink's error (a full disk under the CSV) stops the solve with that
/// error, after the samples before it, in both cases (exact inverse
/// dynamics and servo integration).
#[test]
fn an_error_of_the_sink_stops_the_solve() {
    let motion = |t: f64| [0.1 * t, 0.1, 0.0];
    let problem = |coordinates: &[&str], actuator: &str| Problem {
        coordinates: names(coordinates),
        constraints: vec![],
        actuators: names(&[actuator]),
        prescribed: vec![Prescribed {
            output: Output::Coordinate(0),
            motion: &motion,
        }],
        guess: vec![0.0, 3.0],
        dt: 0.01,
        steps: 1000,
        free_rates: FreeRates::LeastEnergy,
    };
    let mut seen = Vec::new();
    let mut sink = |s: &Sample<'_>| {
        seen.push(s.t);
        match seen.len() {
            3 => Err(format!("disk full at t = {}", s.t)),
            _ => Ok(()),
        }
    };
    let e = solve(
        &*erase(Pendulum::default()),
        &problem(&["theta"], "tau"),
        &mut sink,
    )
    .unwrap_err();
    assert_eq!(e, "disk full at t = 0.02");
    assert_eq!(seen, [0.0, 0.01, 0.02]);
    seen.clear();
    let mut sink = |s: &Sample<'_>| {
        seen.push(s.t);
        match seen.len() {
            3 => Err(format!("disk full at t = {}", s.t)),
            _ => Ok(()),
        }
    };
    let e = solve(
        &*erase(CartPole),
        &problem(&["x", "theta"], "force"),
        &mut sink,
    )
    .unwrap_err();
    assert_eq!(e, "disk full at t = 0.02");
    assert_eq!(seen, [0.0, 0.01, 0.02]);
}

const BIN: &str = env!("CARGO_BIN_EXE_flexdyn");

fn scene(name: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("scenes/{name}.toml"))
}

/// Runs `flexdyn inverse` with `args` writing `out.csv` in `dir`: the CSV
/// text, or the error output.
fn inverse(dir: &std::path::Path, args: &[&str]) -> Result<String, String> {
    let csv = dir.join("out.csv");
    let out = std::process::Command::new(BIN)
        .arg("inverse")
        .args(args)
        .arg("--csv")
        .arg(&csv)
        .output()
        .unwrap();
    match out.status.success() {
        true => Ok(std::fs::read_to_string(&csv).unwrap()),
        false => {
            assert!(!csv.exists(), "a failed run left {}", csv.display());
            Err(String::from_utf8_lossy(&out.stderr).into_owned())
        }
    }
}

#[test]
fn command_on_the_interpreted_slider_crank_matches_the_compiled_solve() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(
        d.join("motion.toml"),
        "[prescribe]\ntheta = \"0.3 + 4*t + t*t/2\"\n",
    )
    .unwrap();
    std::fs::write(
        d.join("s.json"),
        r#"{"q": [0.3, 0.1, 0.4], "qd": [0, 0, 0]}"#,
    )
    .unwrap();
    let sc = scene("slider_crank");
    let motion = d.join("motion.toml");
    let start = d.join("s.json");
    let text = inverse(
        d,
        &[
            "--scene",
            sc.to_str().unwrap(),
            "--interpret",
            "--duration",
            "1",
            "--dt",
            "0.01",
            "--motion",
            motion.to_str().unwrap(),
            "--initial",
            start.to_str().unwrap(),
        ],
    )
    .unwrap();
    let table = flexdyn::table::Table::parse(&text).unwrap();
    let direct = crank_solve(&|t: f64| [0.3 + 4.0 * t + t * t / 2.0, 4.0 + t, 1.0]);
    let tau = table.column("tau").unwrap();
    let x = table.column("x").unwrap();
    let lambda = table.column("lambda_1").unwrap();
    assert_eq!(tau.len(), 101);
    for k in 0..101 {
        assert!((tau[k] - direct.tau[k][0]).abs() < 1e-9, "{k}");
        assert!((x[k] - direct.q[k][2]).abs() < 1e-12, "{k}");
        assert!((lambda[k] - direct.lambda[k][1]).abs() < 1e-9, "{k}");
    }
}

#[test]
fn command_refuses_bad_prescriptions_clearly_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let sc = scene("slider_crank");
    let run = |extra: &[&str]| {
        let mut args = vec![
            "--scene",
            sc.to_str().unwrap(),
            "--duration",
            "0.1",
            "--dt",
            "0.01",
        ];
        args.extend_from_slice(extra);
        inverse(d, &args).unwrap_err()
    };
    let e = run(&["--prescribe", "alpha=t"]);
    assert!(
        e.contains("`alpha` is not a coordinate") && e.contains("theta, phi, x"),
        "{e}"
    );
    let e = run(&["--prescribe", "theta=2*+t"]);
    assert!(e.contains("--prescribe theta"), "{e}");
    let e = run(&["--prescribe", "theta=phi"]);
    assert!(e.contains("not the coordinate `phi`"), "{e}");
    let e = run(&["--prescribe", "theta=t", "--prescribe", "x=0.4"]);
    assert!(e.contains("does not determine the actuator inputs"), "{e}");
    let e = run(&[]);
    assert!(e.contains("0 prescribed"), "{e}");
    let e = run(&["--prescribe", "theta=t", "--dt", "0"]);
    assert!(e.contains("--dt"), "{e}");
    // The slider beyond the reach of crank and rod (0.4 m).
    let e = run(&["--prescribe", "x=0.5"]);
    assert!(
        e.contains("at t = 0 s") && e.contains("`theta`, `phi`") && e.contains("condition"),
        "{e}"
    );
    std::fs::write(d.join("m.toml"), "[prescribe]\ntheta = 3\n").unwrap();
    let m = d.join("m.toml");
    let e = run(&["--motion", m.to_str().unwrap()]);
    assert!(e.contains("prescribe.theta") && e.contains("string"), "{e}");
}

#[test]
fn command_on_an_interpreted_pendulum_gives_the_closed_form_torque() {
    let dir = tempfile::tempdir().unwrap();
    let sc = scene("pendulum");
    let text = inverse(
        dir.path(),
        &[
            "--scene",
            sc.to_str().unwrap(),
            "--interpret",
            "--duration",
            "1",
            "--dt",
            "0.05",
            "--prescribe",
            "theta=0.8*sin(3*t)",
        ],
    )
    .unwrap();
    let table = flexdyn::table::Table::parse(&text).unwrap();
    let (t, tau) = (table.column("t").unwrap(), table.column("tau").unwrap());
    for k in 0..t.len() {
        let th = 0.8 * (3.0 * t[k]).sin();
        let want = 0.25 * (-7.2 * (3.0 * t[k]).sin()) + 9.81 * 0.5 * th.sin();
        assert!(
            (tau[k] - want).abs() < 1e-10,
            "t = {}: {} vs {want}",
            t[k],
            tau[k]
        );
    }
}

/// `--prescriptions P.csv`: the pendulum's `theta = 0.8 sin 3t` sampled at
/// 101 points over `[0, pi/3]` (zero curvature at both ends, where the
/// natural spline is exact to fourth order) gives the closed-form torque to
/// the spline's accuracy (its acceleration error `O(h^2)`); unknown columns
/// and samples that do not cover the run are refused, naming the file.
#[test]
fn command_follows_sampled_prescriptions_from_a_csv() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut table = flexdyn::table::Table::new(&["t", "theta"]);
    for k in 0..=100 {
        let t = std::f64::consts::PI / 3.0 * k as f64 / 100.0;
        table.push(vec![t, 0.8 * (3.0 * t).sin()]);
    }
    let samples = d.join("p.csv");
    table.write(&samples).unwrap();
    let sc = scene("pendulum");
    let run = |csv: &std::path::Path, duration: &str| {
        inverse(
            d,
            &[
                "--scene",
                sc.to_str().unwrap(),
                "--duration",
                duration,
                "--dt",
                "0.05",
                "--prescriptions",
                csv.to_str().unwrap(),
            ],
        )
    };
    let text = run(&samples, "1").unwrap();
    std::fs::remove_file(d.join("out.csv")).unwrap();
    let out = flexdyn::table::Table::parse(&text).unwrap();
    let (t, tau) = (out.column("t").unwrap(), out.column("tau").unwrap());
    let mut worst = 0.0f64;
    for k in 0..t.len() {
        let th = 0.8 * (3.0 * t[k]).sin();
        let want = 0.25 * (-7.2 * (3.0 * t[k]).sin()) + 9.81 * 0.5 * th.sin();
        worst = worst.max((tau[k] - want).abs());
    }
    println!("sampled prescription: largest torque error {worst:.3e} N m");
    assert!(worst < 1e-3, "{worst}");
    assert!(worst > 0.0, "sampled, not exact");
    let e = run(&samples, "1.2").unwrap_err();
    assert!(
        e.contains("p.csv") && e.contains("`theta`") && e.contains("cover"),
        "{e}"
    );
    std::fs::write(d.join("bad.csv"), "t,thta\n0,0\n1,1\n").unwrap();
    let e = run(&d.join("bad.csv"), "1").unwrap_err();
    assert!(
        e.contains("column `thta` of") && e.contains("is not a coordinate") && e.contains("theta"),
        "{e}"
    );
    std::fs::write(d.join("time.csv"), "t,theta\n0,0\n0,1\n").unwrap();
    let e = run(&d.join("time.csv"), "1").unwrap_err();
    assert!(
        e.contains("line 3") && e.contains("does not increase"),
        "{e}"
    );
}

/// A 100-link spatial chain, interpreted, with every joint prescribed
/// (`q_k = a_k sin(w t + p_k)`; far above the 8 actuators and 64
/// coordinates the command once took): at every output time the torques
/// are `M qdd + h` from the model's mass matrix and bias programs (the
/// solver uses its inverse-dynamics program), and the coordinates are the
/// prescription.
#[test]
fn hundred_link_chain_with_every_joint_prescribed_gives_m_qdd_plus_h() {
    let n = 100;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("chain.toml");
    std::fs::write(&path, large_scenes::spatial_chain(n)).unwrap();
    let model = InterpretedModel::load(&path).unwrap();
    let motion = |k: usize| {
        move |t: f64| {
            let (a, w, p) = (0.1 + 0.001 * k as f64, 2.0, 0.1 * k as f64);
            let (s, c) = (w * t + p).sin_cos();
            [a * s, a * w * c, -a * w * w * s]
        }
    };
    let motions: Vec<_> = (0..n).map(motion).collect();
    let problem = Problem {
        coordinates: (0..n).map(|k| format!("q{k}")).collect(),
        constraints: vec![],
        actuators: (0..n).map(|k| format!("tau{k}")).collect(),
        prescribed: motions
            .iter()
            .enumerate()
            .map(|(k, f)| Prescribed {
                output: Output::Coordinate(k),
                motion: f,
            })
            .collect(),
        guess: vec![0.0; n],
        dt: 0.05,
        steps: 4,
        free_rates: FreeRates::LeastEnergy,
    };
    let dynamic: &dyn DynModel = &model;
    let out = collect(|sink| solve(dynamic, &problem, sink)).unwrap();
    assert_eq!(out.method, Method::Determined);
    assert_eq!(out.t.len(), 5);
    let mut worst = 0.0f64;
    for (k, &t) in out.t.iter().enumerate() {
        let x: Vec<[f64; 3]> = motions.iter().map(|f| f(t)).collect();
        let q = DVector::from_fn(n, |i, _| x[i][0]);
        let qd = DVector::from_fn(n, |i, _| x[i][1]);
        let qdd = DVector::from_fn(n, |i, _| x[i][2]);
        let (mut m, mut h) = (DMatrix::zeros(n, n), DVector::zeros(n));
        flexdyn::runtime::Equations::mass_matrix(dynamic, &q, t, &mut m);
        flexdyn::runtime::Equations::bias(dynamic, &q, &qd, t, &mut h);
        let want = m * qdd + h;
        let scale = want.amax();
        for i in 0..n {
            assert_eq!(out.q[k][i], q[i], "q{i} at t = {t}");
            worst = worst.max((out.tau[k][i] - want[i]).abs() / scale);
        }
    }
    println!("100-link chain: largest torque error {worst:.3e} of the scale");
    assert!(worst < 1e-12, "{worst:e}");
}

/// The servo case at the most modes a scene may keep: the hub of a 60-mode
/// flexible link (no gravity, so it starts at rest undeformed) follows
/// `theta = t^2 / 2` under `flexdyn inverse`; simulating the scene forward
/// (adaptive RK4, an independent integrator) under the torques it reports
/// reproduces the prescribed hub angle to 1e-3 of its range.
#[test]
fn sixty_mode_beam_torques_drive_the_prescribed_hub_angle() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = d.join("beam.toml");
    std::fs::write(&scene, large_scenes::hub_beam(60, 0.0)).unwrap();
    let sc = scene.to_str().unwrap();
    let text = inverse(
        d,
        &[
            "--scene",
            sc,
            "--duration",
            "0.05",
            "--dt",
            "0.001",
            "--prescribe",
            "theta=t*t/2",
        ],
    )
    .unwrap();
    let table = flexdyn::table::Table::parse(&text).unwrap();
    let (t, tau) = (
        table.column("t").unwrap(),
        table.column("hub_torque").unwrap(),
    );
    assert_eq!(t.len(), 51);
    let inputs: String = std::iter::once("t,hub_torque\n".to_string())
        .chain(t.iter().zip(&tau).map(|(t, u)| format!("{t},{u}\n")))
        .collect();
    let inputs_csv = d.join("u.csv");
    std::fs::write(&inputs_csv, inputs).unwrap();
    let motion = d.join("motion.csv");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_flexdyn"))
        .args([
            "simulate",
            "--scene",
            sc,
            "--duration",
            "0.05",
            "--dt",
            "0.001",
        ])
        .arg("--inputs")
        .arg(&inputs_csv)
        .arg("--csv")
        .arg(&motion)
        .arg("--quiet")
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let sim = flexdyn::table::Table::read(&motion).unwrap();
    let (ts, theta) = (sim.column("t").unwrap(), sim.column("theta").unwrap());
    let range = 0.05f64 * 0.05 / 2.0;
    let worst = ts
        .iter()
        .zip(&theta)
        .map(|(t, th)| (th - t * t / 2.0).abs())
        .fold(0.0, f64::max);
    println!("60 modes: hub angle off the prescription by {worst:.3e} rad of {range:.3e}");
    assert!(worst < 1e-3 * range, "{worst:e}");
}
