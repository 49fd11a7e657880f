//! `flexdyn linearize`: the cart-pole's upright linearization against its
//! closed form, and the worked example of docs/derivatives.md (an LQR gain
//! from it, `flexdyn simulate --feedback` recovering from a push); the
//! five-bar's linearization in independent coordinates
//! against central differences of its reduced dynamics, built here from the
//! runtime's constrained accelerations and a Newton solve of the
//! constraints (independent of the tool's reduction); and the refusals.

#[path = "common/cli.rs"]
mod cli;
#[path = "common/python_env.rs"]
mod python_env;
const BIN: &str = env!("CARGO_BIN_EXE_flexdyn");

use flexdyn::dynamic::DynModel;
use flexdyn::interpreted::InterpretedModel;
use flexdyn_runtime::{accelerations, Baumgarte, DynamicsConfig};
use nalgebra::{DMatrix, DVector};
use serde_json::Value;
use std::process::Command;

/// Runs `flexdyn linearize` with `args` (after the command), returns the JSON.
fn linearize(args: &[&str]) -> Value {
    let out = Command::new(BIN)
        .arg("linearize")
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("run flexdyn");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    match out.stdout.is_empty() {
        true => Value::Null,
        false => serde_json::from_slice(&out.stdout).expect("JSON"),
    }
}

fn matrix(v: &Value) -> DMatrix<f64> {
    let rows: Vec<Vec<f64>> = serde_json::from_value(v.clone()).expect("rows");
    DMatrix::from_fn(rows.len(), rows[0].len(), |i, j| rows[i][j])
}

fn numbers(v: &Value) -> Vec<f64> {
    serde_json::from_value(v.clone()).expect("numbers")
}

#[test]
fn cart_pole_upright_matches_its_closed_form() {
    let dir = tempfile::tempdir().unwrap();
    let state = dir.path().join("upright.json");
    std::fs::write(&state, r#"{"q": [0.3, 0], "qd": [0, 0], "t": 0}"#).unwrap();
    let state = state.to_string_lossy().into_owned();
    let out = linearize(&["--scene", "scenes/cart_pole.toml", "--state", &state]);
    // Cart mc = 1, uniform pole mp = 0.1 of length l = 1 hinged at the cart,
    // theta from the upward vertical, g = 9.81: about the upright,
    // [[mc + mp, mp l/2], [mp l/2, mp l^2/3]] [x''; theta''] = [F; mp g l/2 theta].
    let (mc, mp, l, g) = (1.0, 0.1, 1.0, 9.81);
    let m = nalgebra::Matrix2::new(mc + mp, mp * l / 2.0, mp * l / 2.0, mp * l * l / 3.0);
    let inv = m.try_inverse().unwrap();
    let stiffness = nalgebra::Matrix2::new(0.0, 0.0, 0.0, mp * g * l / 2.0);
    let k = inv * stiffness;
    let b = inv * nalgebra::Vector2::new(1.0, 0.0);
    let mut a_ref = DMatrix::zeros(4, 4);
    a_ref[(0, 2)] = 1.0;
    a_ref[(1, 3)] = 1.0;
    for i in 0..2 {
        for j in 0..2 {
            a_ref[(2 + i, j)] = k[(i, j)];
        }
    }
    let a = matrix(&out["A"]);
    let bm = matrix(&out["B"]);
    assert!(
        (&a - &a_ref).amax() <= 1e-13 * a_ref.amax(),
        "A = {a}, closed form {a_ref}"
    );
    assert!((bm[(2, 0)] - b[0]).abs() <= 1e-14 && (bm[(3, 0)] - b[1]).abs() <= 1e-14);
    assert_eq!(numbers(&out["f0"]), vec![0.0; 4]);
    // Eigenvalues 0, 0, +-sqrt(k22).
    let root = k[(1, 1)].sqrt();
    let eig: Vec<[f64; 2]> = serde_json::from_value(out["eigenvalues_A"].clone()).unwrap();
    let re: Vec<f64> = eig.iter().map(|e| e[0]).collect();
    assert!((re[0] + root).abs() <= 1e-12 * root && (re[3] - root).abs() <= 1e-12 * root);
    assert!(re[1].abs() <= 1e-12 && re[2].abs() <= 1e-12, "{eig:?}");
    assert!(eig.iter().all(|e| e[1].abs() <= 1e-12), "{eig:?}");
}

/// The five-bar's reduced dynamics `zdd(z, zd, u)` with independent
/// coordinates `z`: the dependent ones from a Newton solve of the
/// constraints, their rates from the velocity constraint, the
/// accelerations from the runtime (no Baumgarte terms).
struct Reduced<'a> {
    model: &'a InterpretedModel,
    z: Vec<usize>,
    w: Vec<usize>,
    q0: DVector<f64>,
}

impl Reduced<'_> {
    fn rates(&self, z: &[f64], zd: &[f64], u: &[f64]) -> Vec<f64> {
        let (nq, nc) = (self.model.nq(), self.model.nc());
        let mut q = self.q0.clone();
        for (k, &i) in self.z.iter().enumerate() {
            q[i] = z[k];
        }
        let (mut phi, mut phi_q) = (DVector::zeros(nc), DMatrix::zeros(nc, nq));
        for _ in 0..50 {
            self.model
                .constraints(q.as_slice(), 0.0, phi.as_mut_slice());
            if phi.amax() < 1e-15 {
                break;
            }
            self.model
                .constraint_jacobian(q.as_slice(), 0.0, phi_q.as_mut_slice());
            let step = phi_q.select_columns(&self.w).lu().solve(&phi).unwrap();
            for (k, &i) in self.w.iter().enumerate() {
                q[i] -= step[k];
            }
        }
        self.model
            .constraint_jacobian(q.as_slice(), 0.0, phi_q.as_mut_slice());
        let mut qd = DVector::zeros(nq);
        for (k, &i) in self.z.iter().enumerate() {
            qd[i] = zd[k];
        }
        let rhs = -(&phi_q * &qd);
        let wd = phi_q.select_columns(&self.w).lu().solve(&rhs).unwrap();
        for (k, &i) in self.w.iter().enumerate() {
            qd[i] = wd[k];
        }
        let config = DynamicsConfig {
            baumgarte: Baumgarte::NONE,
            ..Default::default()
        };
        let model: &dyn DynModel = self.model;
        let tau = DVector::from_column_slice(u);
        let a = accelerations(model, &config, &q, &qd, 0.0, &tau).unwrap();
        self.z.iter().map(|&i| a.qdd[i]).collect()
    }
}

#[test]
fn five_bar_in_independent_coordinates_matches_central_differences() {
    let dir = tempfile::tempdir().unwrap();
    let state = dir.path().join("state.json");
    // Off the constraints: the tool projects it (positions and velocities).
    std::fs::write(
        &state,
        r#"{"q": [1.2, 1.9, 0.5, 2.6], "qd": [0.5, -0.3, 0.2, 0.4], "t": 0, "tau": [0.3, -0.2]}"#,
    )
    .unwrap();
    let state = state.to_string_lossy().into_owned();
    let model = InterpretedModel::load(std::path::Path::new("scenes/five_bar.toml")).unwrap();
    for independent in [None, Some("theta1,phi2"), Some("phi1,phi2")] {
        let mut args = vec!["--scene", "scenes/five_bar.toml", "--state", &state];
        if let Some(names) = independent {
            args.extend(["--independent", names]);
        }
        let out = linearize(&args);
        let names: Vec<String> = serde_json::from_value(out["states"].clone()).unwrap();
        let coordinates = model.coordinates();
        let z: Vec<usize> = names[..2]
            .iter()
            .map(|n| coordinates.iter().position(|c| c == n).unwrap())
            .collect();
        if let Some(given) = independent {
            assert_eq!(names[..2].join(","), given);
        }
        let w: Vec<usize> = (0..4).filter(|i| !z.contains(i)).collect();
        let q0 = DVector::from_vec(numbers(&out["reduction"]["q"]));
        let x0 = numbers(&out["x0"]);
        let u0 = numbers(&out["u0"]);
        let reduced = Reduced {
            model: &model,
            z,
            w,
            q0,
        };
        let f = |x: &[f64], u: &[f64]| reduced.rates(&x[..2], &x[2..], u);
        let (f0, again) = (numbers(&out["f0"]), f(&x0, &u0));
        for i in 0..2 {
            assert!((f0[2 + i] - again[i]).abs() <= 1e-12 * again[i].abs().max(1.0));
        }
        let (a, b) = (matrix(&out["A"]), matrix(&out["B"]));
        let h = 1e-6;
        for j in 0..4 {
            let (mut up, mut down) = (x0.clone(), x0.clone());
            up[j] += h;
            down[j] -= h;
            let (fu, fd) = (f(&up, &u0), f(&down, &u0));
            for i in 0..2 {
                let diff = (fu[i] - fd[i]) / (2.0 * h);
                let err = (a[(2 + i, j)] - diff).abs();
                assert!(
                    err <= 1e-6 * a.amax(),
                    "{independent:?}: A[{}, {j}] = {} vs central difference {diff}",
                    2 + i,
                    a[(2 + i, j)]
                );
            }
        }
        for j in 0..2 {
            let (mut up, mut down) = (u0.clone(), u0.clone());
            up[j] += h;
            down[j] -= h;
            let (fu, fd) = (f(&x0, &up), f(&x0, &down));
            for i in 0..2 {
                let diff = (fu[i] - fd[i]) / (2.0 * h);
                assert!((b[(2 + i, j)] - diff).abs() <= 1e-6 * b.amax());
            }
        }
    }
}

#[test]
fn linearize_refuses_what_it_cannot_do() {
    let dir = tempfile::tempdir().unwrap();
    let state = dir.path().join("s.json");
    std::fs::write(&state, r#"{"q": [1.2, 1.9, 0.5, 2.6], "qd": [0, 0, 0, 0]}"#).unwrap();
    let s = cli::p(dir.path(), "s.json");
    let keep = ["s.json"];
    let five_bar = [
        "linearize",
        "--scene",
        "scenes/five_bar.toml",
        "--state",
        &s,
    ];
    let with = |extra: &[&'static str]| -> Vec<String> {
        five_bar
            .iter()
            .map(|a| a.to_string())
            .chain(extra.iter().map(|a| a.to_string()))
            .collect()
    };
    for (extra, needle) in [
        (
            &["--independent", "theta1"][..],
            "so 2 independent coordinates; 1 named",
        ),
        (
            &["--independent", "theta1,nope"][..],
            "no coordinate `nope`",
        ),
        (
            &["--independent", "theta1,theta1"][..],
            "`theta1` is named twice",
        ),
        (&["--input", "tau9=1"][..], "no actuator `tau9`"),
        (&["--input", "tau1=inf"][..], "not a finite number"),
    ] {
        let args = with(extra);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        cli::refused(dir.path(), &keep, &args, needle);
    }
    // A scene without the generated derivatives.
    std::fs::write(dir.path().join("s.json"), r#"{"q": [0.1], "qd": [0]}"#).unwrap();
    cli::refused(
        dir.path(),
        &keep,
        &[
            "linearize",
            "--scene",
            "scenes/pendulum.toml",
            "--state",
            &s,
        ],
        "add `outputs = [\"dynamics_derivatives\"]`",
    );
}

/// Reads a CSV written by `flexdyn simulate`: its header and rows.
fn read_csv(path: &std::path::Path) -> (Vec<String>, Vec<Vec<f64>>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header = lines
        .next()
        .unwrap()
        .split(',')
        .map(str::to_owned)
        .collect();
    let rows = lines
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    (header, rows)
}

#[test]
fn an_lqr_gain_from_the_linearization_recovers_the_cart_pole_from_a_push() {
    let repo = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let Some(python) = python_env::test_python(&repo, "linearize (LQR example)") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let file = |name: &str| dir.path().join(name).to_string_lossy().into_owned();
    std::fs::write(
        file("upright.json"),
        r#"{"q": [0, 0], "qd": [0, 0], "t": 0}"#,
    )
    .unwrap();
    std::fs::write(
        file("pushed.json"),
        r#"{"q": [0, 0.2], "qd": [0, 0], "t": 0}"#,
    )
    .unwrap();
    let lin = linearize(&[
        "--scene",
        "scenes/cart_pole.toml",
        "--state",
        &file("upright.json"),
        "--out",
        &file("lin.json"),
    ]);
    assert_eq!(lin, Value::Null, "with --out nothing on standard output");
    let out = python_env::run(
        Command::new(python)
            .arg(repo.join("docs/derivatives/lqr.py"))
            .args([
                file("lin.json"),
                file("k.json"),
                "--q".into(),
                "1,10,1,1".into(),
            ])
            .env("PYTHONDONTWRITEBYTECODE", "1"),
        "the LQR design",
    );
    assert!(out.status.success(), "{}", python_env::output_text(&out));
    let k: Value = serde_json::from_str(&std::fs::read_to_string(file("k.json")).unwrap()).unwrap();
    // The closed loop A - B K is stable.
    let (a, b, gain) = (matrix(&k["A"]), matrix(&k["B"]), matrix(&k["K"]));
    let closed = &a - &b * &gain;
    let eig = closed.complex_eigenvalues();
    assert!(eig.iter().all(|z| z.re < -0.1), "closed loop {eig}");
    // The nonlinear cart-pole under u = -K x from theta = 0.2 rad.
    let run = |feedback: bool, csv: &str| {
        let mut args = vec![
            "simulate".to_owned(),
            "--scene".into(),
            "scenes/cart_pole.toml".into(),
            "--initial".into(),
            file("pushed.json"),
            "--duration".into(),
            "8".into(),
            "--dt".into(),
            "0.01".into(),
            "--quiet".into(),
            "--csv".into(),
            file(csv),
        ];
        if feedback {
            args.extend(["--feedback".into(), file("k.json")]);
        }
        let out = Command::new(BIN)
            .args(&args)
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let (header, rows) = read_csv(&dir.path().join(csv));
        let theta = header.iter().position(|c| c == "theta").unwrap();
        rows.iter().map(|r| r[theta]).collect::<Vec<f64>>()
    };
    let closed = run(true, "closed.csv");
    let open = run(false, "open.csv");
    assert!(
        closed.iter().all(|t| t.abs() <= 0.2 + 1e-9),
        "the push grows"
    );
    assert!(closed.last().unwrap().abs() < 2e-3, "{:?}", closed.last());
    assert!(
        open.iter().any(|t| t.abs() > 1.5),
        "without feedback the pole falls"
    );
}

#[test]
fn a_feedback_file_that_does_not_fit_the_scene_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let k = cli::p(dir.path(), "k.json");
    let csv = cli::p(dir.path(), "out.csv");
    let args = [
        "simulate",
        "--scene",
        "scenes/cart_pole.toml",
        "--duration",
        "0.1",
        "--feedback",
        &k,
        "--csv",
        &csv,
    ];
    for (text, needle) in [
        (
            r#"{"states": ["x", "psi"], "inputs": ["force"], "K": [[1, 2]]}"#,
            "state `psi` is neither",
        ),
        (
            r#"{"states": ["x"], "inputs": ["push"], "K": [[1]]}"#,
            "input `push` is not an actuator",
        ),
        (
            r#"{"states": ["x", "x_dot"], "inputs": ["force"], "K": [[1]]}"#,
            "one row per input (1) of one gain per state (2)",
        ),
        (
            r#"{"states": ["x"], "inputs": ["force"], "K": [[1]], "x0": [0, 0]}"#,
            "`x0` has 2 entries, expected 1",
        ),
        (
            r#"{"states": ["x"], "inputs": ["force", "force"], "K": [[1], [2]]}"#,
            "listed twice",
        ),
        (
            r#"{"states": ["x"], "inputs": ["force"], "K": [[1e999]]}"#,
            "k.json",
        ),
    ] {
        std::fs::write(&k, text).unwrap();
        cli::refused(dir.path(), &["k.json"], &args, needle);
    }
}
