//! Markers (`[[markers]]`: named points of frames) against closed forms: a
//! planar two-link arm on a base that moves with time, its tip marker's
//! position, rotation, Jacobian, velocity (with the base's explicit time
//! term) and acceleration bias from `flexdyn eval`'s evaluation, the
//! positions `flexdyn simulate` writes, and the errors of bad markers.

use std::path::{Path, PathBuf};
use std::process::Command;

use flexdyn::dynamic::DynModel;
use flexdyn::eval::{evaluate, State};
use flexdyn::interpreted::InterpretedModel;
use flexdyn::table::Table;
use nalgebra::{Matrix3, Vector3};

const BIN: &str = env!("CARGO_BIN_EXE_flexdyn");

/// A two-link arm turning about y (angles `a`, `b`) on a base sliding
/// along x as `X(t) = 0.1 sin(3 t)`, with a marker off the forearm's axis.
const ARM: &str = r#"
name = "sliding_arm"
[[coordinates]]
name = "a"
[[coordinates]]
name = "b"
[[frames]]
name = "base"
translation = ["0.1*sin(3*t)", 0, 0]
[[frames]]
name = "upper"
parent = "base"
rotation = [{ axis = "y", angle = "a" }]
[[frames]]
name = "fore"
parent = "upper"
translation = [0.5, 0, 0]
rotation = [{ axis = "y", angle = "b" }]
[[components]]
name = "l1"
type = "rigid_body"
frame = "upper"
mass = 1.0
position = [0.25, 0, 0]
inertia = [0.02, 0.02, 0.02]
[[components]]
name = "l2"
type = "rigid_body"
frame = "fore"
mass = 0.8
position = [0.2, 0, 0]
inertia = [0.01, 0.01, 0.01]
[[markers]]
name = "tip"
frame = "fore"
position = [0.4, 0, 0.05]
[[markers]]
name = "elbow"
frame = "fore"
"#;

/// The tip marker's point in the forearm's axes.
const TIP: [f64; 2] = [0.4, 0.05];

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

/// `flexdyn simulate --scene scene --csv csv` with `args`: the table
/// written, or the error text.
fn simulate(scene: &Path, csv: &Path, args: &[&str]) -> Result<Table, String> {
    let out = Command::new(BIN)
        .arg("simulate")
        .args(args)
        .arg("--scene")
        .arg(scene)
        .arg("--csv")
        .arg(csv)
        .output()
        .unwrap();
    match out.status.success() {
        true => Ok(Table::read(csv).unwrap()),
        false => Err(String::from_utf8_lossy(&out.stderr).into_owned()),
    }
}

/// Rotation by `th` about y.
fn ry(th: f64) -> Matrix3<f64> {
    let (s, c) = th.sin_cos();
    Matrix3::new(c, 0.0, s, 0.0, 1.0, 0.0, -s, 0.0, c)
}

/// The tip's closed forms at `(a, b, ad, bd, t)`: position, Jacobian
/// (6 x 2), velocity and acceleration bias.
fn tip(
    a: f64,
    b: f64,
    ad: f64,
    bd: f64,
    t: f64,
) -> (Vector3<f64>, [[f64; 2]; 6], [f64; 6], [f64; 6]) {
    let p = Vector3::new(TIP[0], 0.0, TIP[1]);
    let phi = a + b;
    let x = 0.1 * (3.0 * t).sin();
    let position = Vector3::new(x, 0.0, 0.0) + ry(a) * Vector3::new(0.5, 0.0, 0.0) + ry(phi) * p;
    // d/dth of Ry(th) [px, 0, pz].
    let d = |th: f64, v: Vector3<f64>| {
        let (s, c) = th.sin_cos();
        Vector3::new(-s * v.x + c * v.z, 0.0, -c * v.x - s * v.z)
    };
    let col_b = d(phi, p);
    let col_a = d(a, Vector3::new(0.5, 0.0, 0.0)) + col_b;
    let mut jacobian = [[0.0; 2]; 6];
    for k in 0..3 {
        jacobian[k] = [col_a[k], col_b[k]];
    }
    jacobian[4] = [1.0, 1.0];
    let mut velocity = [0.0; 6];
    for k in 0..3 {
        velocity[k] = col_a[k] * ad + col_b[k] * bd;
    }
    velocity[0] += 0.3 * (3.0 * t).cos();
    velocity[4] = ad + bd;
    // Second derivatives at zero accelerations: -Ry(th) v th_dot^2.
    let bias = -ry(a) * Vector3::new(0.5, 0.0, 0.0) * ad * ad - ry(phi) * p * (ad + bd).powi(2);
    let mut acceleration_bias = [0.0; 6];
    acceleration_bias[..3].copy_from_slice(bias.as_slice());
    acceleration_bias[0] += -0.9 * (3.0 * t).sin();
    (position, jacobian, velocity, acceleration_bias)
}

fn close(got: f64, want: f64, scale: f64, what: &str) {
    assert!(
        (got - want).abs() <= 1e-14 * scale,
        "{what}: {got:e} vs {want:e}"
    );
}

#[test]
fn a_marker_has_the_closed_form_kinematics_with_explicit_time_terms() {
    let dir = tempfile::tempdir().unwrap();
    let scene = write(dir.path(), "sliding_arm.toml", ARM);
    let mut model = InterpretedModel::load(&scene).unwrap();
    assert_eq!(model.markers(), ["tip", "elbow"]);
    for (k, &(a, b, ad, bd, t)) in [
        (0.3, 0.5, 1.0, -2.0, 0.0),
        (-1.2, 2.4, -0.7, 3.1, 0.45),
        (2.9, -0.4, 4.0, 0.2, 1.7),
    ]
    .iter()
    .enumerate()
    {
        let state = State {
            q: vec![a, b],
            qd: vec![ad, bd],
            qdd: Vec::new(),
            tau: Vec::new(),
            t,
            params: Default::default(),
        };
        let terms = evaluate(&mut model, &state).unwrap();
        let got = &terms.markers["tip"];
        let (position, jacobian, velocity, bias) = tip(a, b, ad, bd, t);
        let what = |term: &str| format!("state {k}: tip {term}");
        for i in 0..3 {
            close(got.position[i], position[i], 1.0, &what("position"));
            for j in 0..3 {
                close(
                    got.rotation[i][j],
                    ry(a + b)[(i, j)],
                    1.0,
                    &what("rotation"),
                );
            }
        }
        for (i, row) in jacobian.iter().enumerate() {
            for (j, want) in row.iter().enumerate() {
                close(got.jacobian[i][j], *want, 1.0, &what("jacobian"));
            }
            close(got.velocity[i], velocity[i], 5.0, &what("velocity"));
            close(
                got.acceleration_bias[i],
                bias[i],
                25.0,
                &what("acceleration bias"),
            );
        }
        // The pose alone is the pose of the combined call.
        let (mut p, mut r) = ([0.0; 3], [0.0; 9]);
        assert!(model.marker_pose(0, &state.q, t, &mut p, &mut r));
        assert_eq!(p, got.position);
        assert!(!model.marker_pose(2, &state.q, t, &mut p, &mut r));
    }
}

#[test]
fn simulate_writes_the_marker_positions_of_every_row() {
    let dir = tempfile::tempdir().unwrap();
    let scene = write(dir.path(), "sliding_arm.toml", ARM);
    let csv = dir.path().join("out.csv");
    let table = simulate(
        &scene,
        &csv,
        &["--duration", "0.3", "--dt", "0.01", "--quiet"],
    )
    .unwrap();
    let tail: Vec<&str> = table.columns.iter().map(String::as_str).skip(8).collect();
    assert_eq!(
        tail,
        ["tip_x", "tip_y", "tip_z", "elbow_x", "elbow_y", "elbow_z"]
    );
    let col = |c: &str| table.column(c).unwrap();
    let (t, a, b) = (col("t"), col("a"), col("b"));
    assert_eq!(t.len(), 31);
    let tips = ["tip_x", "tip_y", "tip_z"].map(col);
    for k in 0..t.len() {
        let (position, ..) = tip(a[k], b[k], 0.0, 0.0, t[k]);
        for (axis, want) in position.iter().enumerate() {
            close(
                tips[axis][k],
                *want,
                1.0,
                &format!("row {k} tip axis {axis}"),
            );
        }
    }
    // Only the markers asked for; none at all.
    for (choice, columns) in [("elbow", 11), ("none", 8)] {
        let args = ["--duration", "0.02", "--quiet", "--markers", choice];
        let table = simulate(&scene, &csv, &args).unwrap();
        assert_eq!(table.columns.len(), columns, "{choice}");
    }
}

#[test]
fn bad_markers_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let cases = [
        (
            ARM.replace(
                "frame = \"fore\"\nposition = [0.4",
                "frame = \"hand\"\nposition = [0.4",
            ),
            "frame `hand` is not defined above",
        ),
        (
            ARM.replace("name = \"elbow\"", "name = \"tip\""),
            "marker is defined twice",
        ),
        (
            ARM.replace("position = [0.4, 0, 0.05]", "position = [\"a\", 0, 0]"),
            "a marker's `position` may depend on parameters only",
        ),
        (
            ARM.replace("name = \"elbow\"", "name = \"2nd\""),
            "is not a valid name",
        ),
        (
            ARM.replace("name = \"elbow\"\nframe = \"fore\"\n", "name = \"elbow\"\n"),
            "missing field `frame`",
        ),
    ];
    for (k, (text, needle)) in cases.iter().enumerate() {
        assert_ne!(text, ARM, "case {k} changes the scene");
        let scene = write(dir.path(), "bad.toml", text);
        let e = InterpretedModel::load(&scene).unwrap_err();
        assert!(
            e.contains(needle) && e.contains("bad.toml"),
            "case {k}: {e}"
        );
    }
    let scene = write(dir.path(), "sliding_arm.toml", ARM);
    let csv = dir.path().join("out.csv");
    let e = simulate(
        &scene,
        &csv,
        &["--duration", "0.02", "--markers", "tip,hand"],
    )
    .unwrap_err();
    assert!(
        e.contains("no marker `hand` (markers: tip, elbow)") && !csv.exists(),
        "{e}"
    );
}

/// A point mass moving in 3-D on coordinates `x`, `y`, `z`, hung from the
/// point (0.2, 0, 1) of the world by a spring and a damper; `ENDS` gives
/// them as two ends, the expression form as the distance written out.
const HUNG: &str = r#"
name = "hung_mass"
[[coordinates]]
name = "x"
[[coordinates]]
name = "y"
[[coordinates]]
name = "z"
[[frames]]
name = "body"
translation = ["x", "y", "z"]
[[components]]
name = "mass"
type = "point_mass"
mass = 1.5
frame = "body"
position = [0, 0, 0]
[[markers]]
name = "hook"
frame = "body"
position = [0, 0, 0.1]
"#;

const ENDS: &str = r#"
[[components]]
name = "spring"
type = "spring"
stiffness = 40.0
rest = 0.5
a = { frame = "body", position = [0, 0, 0.1] }
b = { position = [0.2, 0, 1] }
[[components]]
name = "damper"
type = "damper"
damping = 0.7
a = { frame = "body", position = [0, 0, 0.1] }
b = { position = [0.2, 0, 1] }
[[constraints]]
name = "plane"
expression = "hook.y - 0.1*hook.x"
"#;

const WRITTEN_OUT: &str = r#"
[[components]]
name = "spring"
type = "spring"
stiffness = 40.0
rest = 0.5
expression = "sqrt(powi(x - 0.2, 2) + powi(y, 2) + powi(z + 0.1 - 1, 2))"
[[components]]
name = "damper"
type = "damper"
damping = 0.7
expression = "sqrt(powi(x - 0.2, 2) + powi(y, 2) + powi(z + 0.1 - 1, 2))"
[[constraints]]
name = "plane"
expression = "y - 0.1*x"
"#;

/// A spring and a damper between two points act on their distance, and an
/// expression reads a marker's coordinates: every term equals the scene
/// with the distance and the constraint written out.
#[test]
fn springs_dampers_and_expressions_between_points_are_their_written_out_forms() {
    let dir = tempfile::tempdir().unwrap();
    let ends = write(dir.path(), "ends.toml", &format!("{HUNG}{ENDS}"));
    let written = write(dir.path(), "written.toml", &format!("{HUNG}{WRITTEN_OUT}"));
    let (mut a, mut b) = (
        InterpretedModel::load(&ends).unwrap(),
        InterpretedModel::load(&written).unwrap(),
    );
    for (k, (q, qd)) in [
        ([0.3, -0.2, 0.1], [0.5, 1.0, -2.0]),
        ([-1.0, 0.4, 2.5], [-0.3, 0.2, 0.9]),
    ]
    .into_iter()
    .enumerate()
    {
        let state = State {
            q: q.to_vec(),
            qd: qd.to_vec(),
            qdd: vec![0.1, 0.2, 0.3],
            tau: Vec::new(),
            t: 0.0,
            params: Default::default(),
        };
        let (x, y) = (
            evaluate(&mut a, &state).unwrap(),
            evaluate(&mut b, &state).unwrap(),
        );
        let pairs: [(&str, Vec<f64>, Vec<f64>); 6] = [
            (
                "mass_matrix",
                x.mass_matrix.concat(),
                y.mass_matrix.concat(),
            ),
            ("bias", x.bias.clone(), y.bias.clone()),
            ("constraints", x.constraints.clone(), y.constraints.clone()),
            (
                "constraint_jacobian",
                x.constraint_jacobian.concat(),
                y.constraint_jacobian.concat(),
            ),
            (
                "constraint_rhs",
                x.constraint_rhs.clone(),
                y.constraint_rhs.clone(),
            ),
            (
                "potential_energy",
                vec![x.potential_energy],
                vec![y.potential_energy],
            ),
        ];
        for (term, got, want) in pairs {
            let scale = want.iter().fold(1.0f64, |m, v| m.max(v.abs()));
            for (g, w) in got.iter().zip(&want) {
                close(*g, *w, scale, &format!("state {k}: {term}"));
            }
        }
        assert!(x.bias.iter().any(|h| h.abs() > 1.0), "the spring pulls");
    }
}

#[test]
fn bad_ends_and_marker_coordinates_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let cases = [
        (ENDS.replace("rest = 0.5\na =", "rest = 0.5\nexpression = \"x\"\na ="), "not both"),
        (ENDS.replace("a = { frame = \"body\", position = [0, 0, 0.1] }\nb = { position = [0.2, 0, 1] }\n[[components]]\nname = \"damper\"", "b = { position = [0.2, 0, 1] }\n[[components]]\nname = \"damper\""), "`b` needs `a`"),
        (ENDS.replace("b = { position = [0.2, 0, 1] }\n[[constraints]]", "b = { axis = \"x\" }\n[[constraints]]"), "give `position`, not `axis`"),
        (ENDS.replace("hook.y", "hook.w"), "coordinates `x`, `y` and `z`, not `w`"),
        (ENDS.replace("hook.y", "hand.y"), "no marker `hand` above (markers: hook)"),
    ];
    for (k, (text, needle)) in cases.iter().enumerate() {
        assert_ne!(text, ENDS, "case {k} changes the scene");
        let scene = write(dir.path(), "bad.toml", &format!("{HUNG}{text}"));
        let e = InterpretedModel::load(&scene).unwrap_err();
        assert!(
            e.contains(needle) && e.contains("bad.toml"),
            "case {k}: {e}"
        );
    }
}

/// `flexdyn inverse` with a marker's path prescribed (task space) gives the
/// torques of the joint-space motion that traces it: the arm's joints
/// follow `a(t)`, `b(t)`, the tip's path is written out from them, and the
/// two runs agree; an unreachable path is an error naming the marker's
/// constraint and the time.
#[test]
fn a_prescribed_marker_path_gives_the_joint_space_torques() {
    let dir = tempfile::tempdir().unwrap();
    let text = format!(
        "{ARM}\n[[actuators]]\nname = \"ta\"\ncoordinate = \"a\"\n\
         [[actuators]]\nname = \"tb\"\ncoordinate = \"b\"\n"
    );
    let scene = write(dir.path(), "sliding_arm.toml", &text);
    let guess = write(
        dir.path(),
        "guess.json",
        r#"{"q": [0.3, 1.3], "qd": [0, 0]}"#,
    );
    let (a, b) = ("(0.3 + 0.2*sin(2*t))", "(1.0 + 0.3*cos(3*t))");
    let tip_x =
        format!("tip_x=0.1*sin(3*t) + 0.5*cos({a}) + 0.4*cos({a} + {b}) + 0.05*sin({a} + {b})");
    let tip_z = format!("tip_z=-0.5*sin({a}) - 0.4*sin({a} + {b}) + 0.05*cos({a} + {b})");
    let run = |csv: &str, prescribe: [&str; 2]| -> Result<Table, String> {
        let path = dir.path().join(csv);
        let out = Command::new(BIN)
            .args([
                "inverse",
                "--duration",
                "1",
                "--dt",
                "0.05",
                "--quiet",
                "--scene",
            ])
            .arg(&scene)
            .arg("--initial")
            .arg(&guess)
            .args(prescribe.iter().flat_map(|p| ["--prescribe", p]))
            .arg("--csv")
            .arg(&path)
            .output()
            .unwrap();
        match out.status.success() {
            true => Ok(Table::read(&path).unwrap()),
            false => Err(String::from_utf8_lossy(&out.stderr).into_owned()),
        }
    };
    let joints = run("joints.csv", [&format!("a={a}"), &format!("b={b}")]).unwrap();
    let task = run("task.csv", [&tip_x, &tip_z]).unwrap();
    assert_eq!(
        task.columns,
        ["t", "ta", "tb", "a", "b", "tip_x", "tip_z", "lambda_0", "lambda_1"]
    );
    for c in ["ta", "tb", "a", "b"] {
        let (want, got) = (joints.column(c).unwrap(), task.column(c).unwrap());
        assert_eq!(got.len(), 21);
        let scale = want.iter().fold(1.0f64, |m, v| m.max(v.abs()));
        for (k, (g, w)) in got.iter().zip(&want).enumerate() {
            assert!((g - w).abs() <= 1e-9 * scale, "{c} at row {k}: {g} vs {w}");
        }
    }
    // The servo constraints carry no force.
    for c in ["lambda_0", "lambda_1"] {
        assert!(
            task.column(c).unwrap().iter().all(|l| l.abs() < 1e-9),
            "{c}"
        );
    }
    let e = run("far.csv", ["tip_x=0.5 + t", "tip_z=0"]).unwrap_err();
    assert!(
        e.contains("tip_x_servo") && e.contains("at t = ") && e.contains("condition"),
        "{e}"
    );
    assert!(!dir.path().join("far.csv").exists());
}

/// A steel cantilever (a `flexible_link`, 12 elements, 6 modes) clamped at
/// a hub turning about the vertical, with a marker at its tip's station.
const CANTILEVER: &str = r#"
name = "cantilever"
gravity = [0, 0, -9.81]
[[coordinates]]
name = "theta"
[[frames]]
name = "root"
rotation = [{ axis = "z", angle = "theta" }]
[[components]]
name = "beam"
type = "flexible_link"
frame = "root"
length = 1.0
material = { youngs_modulus = 2.1e11, poisson = 0.3, density = 7850.0 }
section = { radius = 0.01 }
elements = 12
modes = 6
boundary = "clamped_free"
[[frames]]
name = "tip_frame"
parent = "root"
station = "end"
[[markers]]
name = "tip"
frame = "tip_frame"
"#;

/// The tip marker of a cantilever sagging under its own weight, at the
/// static equilibrium of its modal coordinates (`K eta = -g`, from the
/// bias forces at rest), against Euler-Bernoulli: deflection
/// `q L^4 / (8 E I)` and slope `q L^3 / (6 E I)` with `q = rho A g`. The
/// six modes leave 1.6e-4 of the deflection and 1.2e-3 of the slope.
#[test]
fn a_cantilevers_tip_marker_sags_as_euler_bernoulli_says() {
    let dir = tempfile::tempdir().unwrap();
    let scene = write(dir.path(), "cantilever.toml", CANTILEVER);
    let mut model = InterpretedModel::load(&scene).unwrap();
    let n = model.nq();
    assert_eq!(n, 7);
    let bias = |model: &mut InterpretedModel, q: Vec<f64>| {
        let state = State {
            q,
            qd: vec![0.0; n],
            qdd: Vec::new(),
            tau: Vec::new(),
            t: 0.0,
            params: Default::default(),
        };
        evaluate(model, &state).unwrap()
    };
    let h0 = bias(&mut model, vec![0.0; n]).bias;
    let mut k = nalgebra::DMatrix::zeros(n - 1, n - 1);
    for j in 1..n {
        let mut q = vec![0.0; n];
        q[j] = 1.0;
        let h = bias(&mut model, q).bias;
        for i in 1..n {
            k[(i - 1, j - 1)] = h[i] - h0[i];
        }
    }
    let g = nalgebra::DVector::from_iterator(n - 1, h0[1..].iter().map(|h| -h));
    let eta = k.lu().solve(&g).unwrap();
    let at_rest: Vec<f64> = std::iter::once(0.0).chain(eta.iter().copied()).collect();
    let tip = &bias(&mut model, at_rest).markers["tip"];
    let (e, r) = (2.1e11, 0.01);
    let (area, inertia) = (
        std::f64::consts::PI * r * r,
        std::f64::consts::PI * r.powi(4) / 4.0,
    );
    let q = 7850.0 * area * 9.81;
    let deflection = q / (8.0 * e * inertia);
    let slope = q / (6.0 * e * inertia);
    assert!(
        (tip.position[2] / -deflection - 1.0).abs() < 5e-4,
        "tip z {} vs {}",
        tip.position[2],
        -deflection
    );
    // The tip frame's x axis tilts down by the slope.
    assert!(
        (tip.rotation[2][0] / -slope - 1.0).abs() < 3e-3,
        "tip slope {} vs {}",
        -tip.rotation[2][0],
        slope
    );
    assert!((tip.position[0] - 1.0).abs() < 1e-12 && tip.position[1] == 0.0);
}

/// A wrapper model (`forward_model!`) keeps the wrapped model's markers:
/// the same names and the same bits.
#[test]
fn wrapper_models_forward_the_markers() {
    use flexdyn::runtime::{FiniteDifferenceJacobians, Model};
    use nalgebra::{SMatrix, SVector};
    let model = flexdyn::scenes::four_bar::FourBar;
    let wrapped = FiniteDifferenceJacobians(model);
    assert_eq!(
        <FiniteDifferenceJacobians<flexdyn::scenes::four_bar::FourBar> as Model<3, 2, 1>>::MARKERS,
        ["coupler_mid"]
    );
    let q = SVector::<f64, 3>::new(0.3, 1.2, 0.5);
    let (mut p, mut r, mut j) = (SVector::zeros(), SMatrix::zeros(), SMatrix::zeros());
    assert!(model.marker_jacobian(0, &q, 0.0, &mut p, &mut r, &mut j));
    let a = (p, r, j);
    assert!(wrapped.marker_jacobian(0, &q, 0.0, &mut p, &mut r, &mut j));
    assert_eq!(a, (p, r, j));
    // The pose by the default method, from the forwarded Jacobian.
    let (mut p2, mut r2) = (SVector::zeros(), SMatrix::zeros());
    assert!(wrapped.marker_pose(0, &q, 0.0, &mut p2, &mut r2));
    assert_eq!((p2, r2), (a.0, a.1));
    assert!(!wrapped.marker_pose(1, &q, 0.0, &mut p2, &mut r2));
    assert!(a.2[(0, 0)] != 0.0);
}

/// A carriage on the sliding base of [`ARM`] (`X(t) = 0.1 sin(3 t)`),
/// moved along x and z by its coordinates and actuators, carrying a steel
/// cantilever (6 modes, free: integrated by the servo) and a marker off its
/// origin: the marker's world coordinates are `X(t) + x + 0.1` and
/// `z + 0.05`.
const CARRIAGE: &str = r#"
name = "carriage"
gravity = [0, 0, -9.81]
[[coordinates]]
name = "x"
[[coordinates]]
name = "z"
[[frames]]
name = "base"
translation = ["0.1*sin(3*t)", 0, 0]
[[frames]]
name = "carriage"
parent = "base"
translation = ["x", 0, "z"]
[[components]]
name = "body"
type = "rigid_body"
frame = "carriage"
mass = 2.0
inertia = [0.01, 0.01, 0.01]
[[components]]
name = "beam"
type = "flexible_link"
frame = "carriage"
length = 0.6
material = { youngs_modulus = 2.1e11, poisson = 0.3, density = 7850.0 }
section = { radius = 0.005 }
elements = 8
modes = 6
boundary = "clamped_free"
[[markers]]
name = "tool"
frame = "carriage"
position = [0.1, 0, 0.05]
[[actuators]]
name = "fx"
coordinate = "x"
[[actuators]]
name = "fz"
coordinate = "z"
"#;

/// `flexdyn inverse` with the marker's path prescribed where elastic
/// coordinates are left free (servo outputs, generalized-alpha) gives the
/// run of the same motion prescribed on the coordinates: the base's motion
/// enters the marker's rate and acceleration bias as explicit time terms,
/// and the two runs agree on the forces and on every coordinate, the
/// cantilever's modes included, to rounding.
#[test]
fn a_marker_path_with_elastic_coordinates_gives_the_coordinate_prescriptions_run() {
    let dir = tempfile::tempdir().unwrap();
    let scene = write(dir.path(), "carriage.toml", CARRIAGE);
    let (x, z) = ("0.2*sin(2*t)", "0.1*cos(3*t)");
    let run = |csv: &str, prescribe: [String; 2]| -> Result<Table, String> {
        let path = dir.path().join(csv);
        let out = Command::new(BIN)
            .args(["inverse", "--duration", "0.5", "--dt", "0.005", "--quiet"])
            .arg("--scene")
            .arg(&scene)
            .args(prescribe.iter().flat_map(|p| ["--prescribe", p]))
            .arg("--csv")
            .arg(&path)
            .output()
            .unwrap();
        match out.status.success() {
            true => Ok(Table::read(&path).unwrap()),
            false => Err(String::from_utf8_lossy(&out.stderr).into_owned()),
        }
    };
    let joints = run("joints.csv", [format!("x={x}"), format!("z={z}")]).unwrap();
    let task = run(
        "task.csv",
        [
            format!("tool_x=0.1*sin(3*t) + {x} + 0.1"),
            format!("tool_z={z} + 0.05"),
        ],
    )
    .unwrap();
    assert_eq!(task.columns, joints.columns);
    // t, the forces, x, z and the six modal coordinates.
    assert_eq!(task.columns.len(), 11, "{:?}", task.columns);
    let mut moved = 0.0f64;
    for c in task.columns.iter().skip(1) {
        let (want, got) = (joints.column(c).unwrap(), task.column(c).unwrap());
        assert_eq!(got.len(), 101);
        let scale = want.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for (k, (g, w)) in got.iter().zip(&want).enumerate() {
            assert!((g - w).abs() <= 1e-9 * scale, "{c} at row {k}: {g} vs {w}");
        }
        if !["fx", "fz", "x", "z"].contains(&c.as_str()) {
            moved = moved.max(scale);
        }
    }
    // The modes move: the elastic coordinates are integrated, not at rest.
    assert!(moved > 0.0);
    // `tool_x` and `x` move together: they do not determine the inputs.
    let e = run("same.csv", [format!("tool_x={x}"), format!("x={x}")]).unwrap_err();
    assert!(
        e.contains("at t = 0 s") && e.contains("`tool_x`") && e.contains("singular"),
        "{e}"
    );
    assert!(!dir.path().join("same.csv").exists());
}
