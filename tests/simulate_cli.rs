//! `flexdyn simulate` end to end, against closed forms: the period of a
//! small-amplitude pendulum, energy conservation, the forced response of a
//! linear oscillator driven by `--input` and by a CSV, PD feedback's static
//! deflection, the constraint drift of a four-bar started off its
//! constraints, an interpreted scene file against the compiled scene; and
//! bad input refused with clear errors, leaving no files.

use std::path::{Path, PathBuf};
use std::process::Command;

use flexdyn::table::Table;

#[path = "common/large_scenes.rs"]
mod large_scenes;
use large_scenes::{hub_beam, spatial_chain};

const BIN: &str = env!("CARGO_BIN_EXE_flexdyn");

fn scene(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("scenes")
        .join(format!("{name}.toml"))
}

/// A linear oscillator `m x'' + k x = f` (m = 2, k = 8: omega = 2).
const OSCILLATOR: &str = r#"
name = "forced_oscillator"
gravity = [0, 0, 0]
[parameters]
m = 2.0
k = 8.0
[[coordinates]]
name = "x"
range = [-1.0, 1.0]
[[components]]
name = "mass"
type = "point_mass"
mass = "m"
position = ["x", 0, 0]
[[components]]
name = "spring"
type = "spring"
stiffness = "k"
expression = "x"
[[actuators]]
name = "f"
coordinate = "x"
"#;

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

/// Run `flexdyn simulate` with `args` plus `--csv dir/out.csv --quiet`:
/// the table, or the error text. On failure, checks that `dir` holds no
/// output (partial or temporary) besides the given `inputs`.
fn simulate(dir: &Path, args: &[&str]) -> Result<(Table, String), String> {
    simulate_noted(dir, &[args, &["--quiet"]].concat())
}

/// [`simulate`] without `--quiet`: the notes on stderr.
fn simulate_noted(dir: &Path, args: &[&str]) -> Result<(Table, String), String> {
    let csv = dir.join("out.csv");
    let before: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    let out = Command::new(BIN)
        .arg("simulate")
        .args(args)
        .arg("--csv")
        .arg(&csv)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    if out.status.success() {
        let table = Table::read(&csv).unwrap();
        std::fs::remove_file(&csv).unwrap();
        return Ok((table, stderr));
    }
    assert!(!stderr.contains("panicked"), "{stderr}");
    let after: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(before, after, "files left behind after: {stderr}");
    Err(stderr)
}

fn column(t: &Table, name: &str) -> Vec<f64> {
    t.column(name).unwrap()
}

fn max_abs(v: impl Iterator<Item = f64>) -> f64 {
    v.fold(0.0, |m, x| m.max(x.abs()))
}

#[test]
fn small_amplitude_pendulum_has_the_closed_form_period() {
    let dir = tempfile::tempdir().unwrap();
    let s = write(
        dir.path(),
        "s.json",
        r#"{"q": [0.01], "qd": [0.0], "t": 0}"#,
    );
    let pendulum = scene("pendulum");
    let args = ["--scene", pendulum.to_str().unwrap(), "--duration", "3"];
    let (t, _) = simulate(
        dir.path(),
        &[
            &args[..],
            &["--dt", "0.001", "--initial", s.to_str().unwrap()],
        ]
        .concat(),
    )
    .unwrap();
    let (time, theta) = (column(&t, "t"), column(&t, "theta"));
    // Downward zero crossings, linearly interpolated.
    let crossings: Vec<f64> = (1..theta.len())
        .filter(|&k| theta[k - 1] > 0.0 && theta[k] <= 0.0)
        .map(|k| time[k - 1] + theta[k - 1] / (theta[k - 1] - theta[k]) * 0.001)
        .collect();
    let period = crossings[1] - crossings[0];
    // T = 2 pi sqrt(l/g) (1 + theta0^2/16 + ...), l = 0.5, g = 9.81.
    let exact =
        2.0 * std::f64::consts::PI * (0.5f64 / 9.81).sqrt() * (1.0 + 0.01f64.powi(2) / 16.0);
    let error = (period - exact).abs() / exact;
    println!("pendulum period {period} vs {exact}: relative error {error:e}");
    assert!(error < 1e-8, "period {period} vs {exact}");
}

#[test]
fn conservative_pendulum_conserves_energy_with_every_integrator() {
    let dir = tempfile::tempdir().unwrap();
    let s = write(dir.path(), "s.json", r#"{"q": [1.0], "qd": [0.5], "t": 0}"#);
    for (integrator, dt, tolerance) in [
        ("adaptive-rk4", "0.01", 1e-9),
        ("rk4", "0.001", 1e-11),
        ("gauss-legendre", "0.001", 1e-11),
        ("semi-implicit-euler", "0.0005", 2e-3),
        ("gen-alpha", "0.001", 5e-6),
    ] {
        let (t, _) = simulate(
            dir.path(),
            &[
                "--scene",
                scene("pendulum").to_str().unwrap(),
                "--duration",
                "2",
                "--dt",
                dt,
                "--initial",
                s.to_str().unwrap(),
                "--integrator",
                integrator,
            ],
        )
        .unwrap();
        let e: Vec<f64> = column(&t, "T")
            .iter()
            .zip(column(&t, "V"))
            .map(|(a, b)| a + b)
            .collect();
        let drift = max_abs(e.iter().map(|x| x - e[0])) / e[0].abs();
        println!("{integrator} at dt {dt}: relative energy drift {drift:e}");
        assert!(drift < tolerance, "{integrator}: energy drift {drift:e}");
    }
}

#[test]
fn forced_oscillator_follows_the_closed_form_response() {
    let dir = tempfile::tempdir().unwrap();
    let sc = write(dir.path(), "osc.toml", OSCILLATOR);
    // f = m sin(3 t) from rest: x = F/(m (w^2 - W^2)) (sin W t - W/w sin w t).
    let exact = |t: f64| 2.0 / (2.0 * (4.0 - 9.0)) * ((3.0 * t).sin() - 1.5 * (2.0 * t).sin());
    let common = [
        "--scene",
        sc.to_str().unwrap(),
        "--duration",
        "5",
        "--dt",
        "0.01",
    ];
    let error_with = |how: &[&str]| {
        let (t, _) = simulate(dir.path(), &[&common[..], how].concat()).unwrap();
        let (time, x) = (column(&t, "t"), column(&t, "x"));
        max_abs(time.iter().zip(x).map(|(&t, x)| x - exact(t)))
    };
    let error = error_with(&["--input", "f=m*sin(3*t)"]);
    println!("forced oscillator, --input: max error {error:e}");
    assert!(error < 1e-7, "{error:e}");
    // The same force as a CSV sampled every millisecond (linear in between).
    let mut csv = String::from("t,f\n");
    for k in 0..=5000 {
        let tk = k as f64 * 1e-3;
        csv += &format!("{tk},{}\n", 2.0 * (3.0 * tk).sin());
    }
    let u = write(dir.path(), "u.csv", &csv);
    let error = error_with(&["--inputs", u.to_str().unwrap()]);
    println!("forced oscillator, --inputs CSV: max error {error:e}");
    assert!(error < 1e-6, "{error:e}");
}

#[test]
fn pd_feedback_settles_at_the_static_deflection() {
    let dir = tempfile::tempdir().unwrap();
    let sc = write(dir.path(), "osc.toml", OSCILLATOR);
    let plot = dir.path().join("pd.svg");
    let (t, _) = simulate(
        dir.path(),
        &[
            "--scene",
            sc.to_str().unwrap(),
            "--duration",
            "10",
            "--pd",
            "f=32,16",
            "--target",
            "x=0.1",
            "--plot",
            plot.to_str().unwrap(),
            "--columns",
            "x,x_dot",
        ],
    )
    .unwrap();
    // k x = kp (0.1 - x): x = 0.1 kp / (k + kp) = 0.08.
    let x = *column(&t, "x").last().unwrap();
    println!("PD static deflection {x} vs 0.08");
    assert!((x - 0.08).abs() < 1e-6, "{x}");
    let svg = std::fs::read_to_string(&plot).unwrap();
    assert!(
        svg.contains("<svg") && svg.contains("x_dot"),
        "plot of x and x_dot"
    );
}

/// An actuator with an open-loop input and PD feedback gets their sum:
/// `k x = 0.8 + kp (0.1 - x)` at rest, `x = 4 / 40 = 0.1` (without the
/// input, 0.08).
#[test]
fn pd_feedback_adds_to_the_open_loop_input() {
    let dir = tempfile::tempdir().unwrap();
    let sc = write(dir.path(), "osc.toml", OSCILLATOR);
    let (t, _) = simulate(
        dir.path(),
        &[
            "--scene",
            sc.to_str().unwrap(),
            "--duration",
            "10",
            "--input",
            "f=0.8",
            "--pd",
            "f=32,16",
            "--target",
            "x=0.1",
        ],
    )
    .unwrap();
    let x = *column(&t, "x").last().unwrap();
    println!("PD with feed-forward: rest at {x} vs 0.1");
    assert!((x - 0.1).abs() < 1e-6, "{x}");
}

/// A PD target's rate column `<coordinate>_dot` in `--inputs` is the
/// velocity reference, not the slope of the target column: a constant
/// target 0.1 with the rate 0.05 given rests where `k x = kp (0.1 - x) +
/// kd 0.05`, `x = 4 / 40 = 0.1` (with the slope, zero: 0.08).
#[test]
fn a_targets_rate_column_is_the_pd_velocity_reference() {
    let dir = tempfile::tempdir().unwrap();
    let sc = write(dir.path(), "osc.toml", OSCILLATOR);
    let u = write(dir.path(), "u.csv", "t,x,x_dot\n0,0.1,0.05\n10,0.1,0.05\n");
    let (t, _) = simulate(
        dir.path(),
        &[
            "--scene",
            sc.to_str().unwrap(),
            "--duration",
            "10",
            "--inputs",
            u.to_str().unwrap(),
            "--pd",
            "f=32,16",
        ],
    )
    .unwrap();
    let x = *column(&t, "x").last().unwrap();
    println!("PD with a rate column: rest at {x} vs 0.1");
    assert!((x - 0.1).abs() < 1e-6, "{x}");
    let u = write(dir.path(), "rate_alone.csv", "t,f,x_dot\n0,0,0\n10,0,0\n");
    let e = simulate(
        dir.path(),
        &[
            "--scene",
            sc.to_str().unwrap(),
            "--duration",
            "1",
            "--inputs",
            u.to_str().unwrap(),
        ],
    )
    .unwrap_err();
    assert!(e.contains("`x_dot`") && e.contains("no column `x`"), "{e}");
}

#[test]
fn four_bar_started_off_its_constraints_is_projected_and_stays_on_them() {
    let dir = tempfile::tempdir().unwrap();
    let s = write(
        dir.path(),
        "s.json",
        // Near the hanging position (th = -pi/2): the parallelogram swings
        // between th1 = -1.13 and -2.01, away from the flat positions
        // (th = 0, -pi), where one rounding can pick the branch.
        r#"{"q": [-1.2, -1.18, 0.01], "qd": [1.0, 0.0, 0.0], "t": 0}"#,
    );
    let four_bar = scene("four_bar");
    let args = [
        "--scene",
        four_bar.to_str().unwrap(),
        "--duration",
        "2",
        "--initial",
        s.to_str().unwrap(),
    ];
    let (t, stderr) = simulate_noted(dir.path(), &args).unwrap();
    assert!(
        stderr.contains("projected onto the constraints: th2 -1.18 ->"),
        "{stderr}"
    );
    assert!(stderr.contains("th1_dot 1.0 ->"), "{stderr}");
    assert!(stderr.contains("integrator: adaptive RK4"), "{stderr}");
    // --quiet: the same run, nothing on stderr.
    let (quiet, stderr) = simulate(dir.path(), &args).unwrap();
    assert!(stderr.is_empty(), "--quiet printed: {stderr}");
    assert_eq!(quiet.column("th2"), t.column("th2"));
    let drift = max_abs(column(&t, "drift").into_iter());
    let e: Vec<f64> = column(&t, "T")
        .iter()
        .zip(column(&t, "V"))
        .map(|(a, b)| a + b)
        .collect();
    let energy = max_abs(e.iter().map(|x| x - e[0]));
    println!("four-bar: max drift {drift:e}, energy change {energy:e}");
    assert!(drift < 1e-10, "{drift:e}");
    // Measured 2.6e-10; semi-implicit Euler at 1 ms gives 6e-3, RK4 at
    // 20 ms 2.4e-7.
    assert!(energy < 1e-8, "{energy:e}");
    assert!(
        column(&t, "th1").iter().any(|&x| (x + 1.2).abs() > 0.5),
        "it moves"
    );
}

#[test]
fn interpreted_scene_file_gives_the_compiled_scenes_csv() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(scene("double_pendulum")).unwrap();
    let copy = text.replace(
        "name = \"double_pendulum\"",
        "name = \"my_double_pendulum\"",
    );
    assert_ne!(copy, text);
    let copied = write(dir.path(), "my.toml", &copy);
    let s = write(
        dir.path(),
        "s.json",
        r#"{"q": [0.7, -0.3], "qd": [0.0, 1.0], "t": 0}"#,
    );
    let run = |path: &Path| {
        let args = [
            "--scene",
            path.to_str().unwrap(),
            "--duration",
            "1",
            "--initial",
        ];
        simulate(dir.path(), &[&args[..], &[s.to_str().unwrap()]].concat())
            .unwrap()
            .0
    };
    let (compiled, interpreted) = (run(&scene("double_pendulum")), run(&copied));
    assert_eq!(compiled.to_csv(), interpreted.to_csv());
    assert_eq!(compiled.rows.len(), 101);
}

#[test]
fn bad_input_is_refused_clearly_and_leaves_no_files() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let sc = write(d, "osc.toml", OSCILLATOR);
    let base = ["--scene", sc.to_str().unwrap(), "--duration", "1"];
    let fails = |extra: &[&str], expected: &str| {
        let e = simulate(d, &[&base[..], extra].concat()).unwrap_err();
        assert!(e.contains(expected), "expected `{expected}` in: {e}");
    };
    fails(&["--input", "g=1"], "unknown actuator `g`");
    fails(&["--input", "f=sin(t"], "--input f: `sin(t`:1:");
    fails(&["--input", "f=x*t"], "not the coordinate `x`");
    fails(&["--input", "f=omega*t"], "undefined symbol `omega`");
    fails(
        &["--pd", "f=1,1", "--pd", "f=2,1", "--target", "x=0"],
        "actuator `f` is given twice",
    );
    fails(&["--dt", "0"], "--dt: the step must be a positive");
    fails(&["--dt=-0.1"], "--dt: the step must be a positive");
    fails(&["--integrator", "euler"], "unknown integrator `euler`");
    fails(&["--pd", "f=1,1"], "no target for coordinate `x`");
    let u = write(d, "bad_column.csv", "t,f,g\n0,1,2\n1,1,2\n");
    fails(
        &["--inputs", u.to_str().unwrap()],
        "bad_column.csv: column `g` is neither",
    );
    let u = write(d, "no_t.csv", "time,f\n0,1\n");
    fails(
        &["--inputs", u.to_str().unwrap()],
        "no_t.csv: no column `t`",
    );
    let u = write(d, "back.csv", "t,f\n0,1\n0.5,1\n0.4,1\n");
    fails(
        &["--inputs", u.to_str().unwrap()],
        "back.csv: line 4: t = 0.4 does not increase",
    );
    let u = write(d, "twice.csv", "t,f\n0,1\n1,1\n");
    fails(
        &["--inputs", u.to_str().unwrap(), "--input", "f=1"],
        "actuator `f` is given twice",
    );
    // An error after the CSV was written (the plot) leaves neither file.
    fails(&["--plot", d.join("p.jpg").to_str().unwrap()], "p.jpg");
    fails(
        &[
            "--plot",
            d.join("p.png").to_str().unwrap(),
            "--columns",
            "x,y",
        ],
        "no column `y`",
    );
    // A step beyond RK4's stability bound: a 1000 rad/s mode started moving.
    let stiff = OSCILLATOR
        .replace("k = 8.0", "k = 2.0e6")
        .replace("range = [-1.0, 1.0]", "range = [-1.0, 1.0]\ninitial = 0.01");
    let st = write(d, "stiff.toml", &stiff);
    let e = simulate(
        d,
        &[
            "--scene",
            st.to_str().unwrap(),
            "--duration",
            "1",
            "--integrator",
            "rk4",
        ],
    )
    .unwrap_err();
    assert!(e.contains("too large"), "{e}");
    // Constraints that no nearby state satisfies: a circle, started at its
    // centre, where the constraint Jacobian vanishes.
    let circle = r#"
name = "circle"
[[coordinates]]
name = "x"
[[coordinates]]
name = "y"
[[components]]
name = "mass"
type = "point_mass"
mass = 1.0
position = ["x", "y", 0]
[[constraints]]
name = "ring"
expression = "x*x + y*y - 1"
"#;
    let c = write(d, "circle.toml", circle);
    let e = simulate(d, &["--scene", c.to_str().unwrap(), "--duration", "1"]).unwrap_err();
    assert!(e.contains("initial state cannot be made consistent"), "{e}");
    let s = write(
        d,
        "s.json",
        r#"{"q": [0.6, 0.8, 0.0], "qd": [0, 0], "t": 0}"#,
    );
    let e = simulate(
        d,
        &[
            "--scene",
            c.to_str().unwrap(),
            "--duration",
            "1",
            "--initial",
            s.to_str().unwrap(),
        ],
    )
    .unwrap_err();
    assert!(e.contains("has 2 coordinates, got 3 positions"), "{e}");
}

/// A 100-link spatial chain with an actuator per joint (far above the old
/// capacity of 64 coordinates and 8 actuators) runs at its own size, under
/// a constant torque on every joint: the energy it gains equals the work of
/// the torques, `T + V - (T0 + V0) = sum_j tau_j (q_j - q_j0)` (each
/// actuator drives its coordinate with unit gain, nothing dissipates).
#[test]
fn hundred_link_chain_with_every_joint_actuated_balances_energy_and_work() {
    let n = 100;
    let dir = tempfile::tempdir().unwrap();
    let scene = write(dir.path(), "chain.toml", &spatial_chain(n));
    let torque = |k: usize| 0.5 * ((k % 7) as f64 - 3.0);
    let inputs: Vec<String> = (0..n).map(|k| format!("tau{k}={}", torque(k))).collect();
    let mut args = vec!["--scene", scene.to_str().unwrap(), "--duration", "0.05"];
    for i in &inputs {
        args.extend(["--input", i.as_str()]);
    }
    let (t, _) = simulate(dir.path(), &args).unwrap();
    let times = column(&t, "t");
    assert_eq!(times.last().copied(), Some(0.05));
    let energy = |r: usize| column(&t, "T")[r] + column(&t, "V")[r];
    let last = times.len() - 1;
    let work: f64 = (0..n)
        .map(|k| {
            let q = column(&t, &format!("q{k}"));
            torque(k) * (q[last] - q[0])
        })
        .sum();
    let gained = energy(last) - energy(0);
    println!("energy gained {gained:e} J, work {work:e} J");
    assert!(work.abs() > 1e-3, "the torques do work: {work:e}");
    assert!(
        (gained - work).abs() <= 1e-6 * (work.abs() + energy(0).abs()),
        "energy gained {gained:e} vs work {work:e}"
    );
    // Everything moves: no coordinate is left at its start.
    for k in 0..n {
        let q = column(&t, &format!("q{k}"));
        assert!(q[last] != q[0], "q{k} did not move");
    }
}

/// A flexible link with the most modes a scene may keep (60; 61
/// coordinates) under gravity and a constant hub torque, with the default
/// integrator: the energy gained equals the torque's work `tau (theta -
/// theta0)` (the modes are undamped).
#[test]
fn sixty_mode_beam_balances_energy_and_work() {
    let dir = tempfile::tempdir().unwrap();
    let scene = write(dir.path(), "beam.toml", &hub_beam(60, 9.81));
    let args = [
        "--scene",
        scene.to_str().unwrap(),
        "--duration",
        "0.05",
        "--input",
        "hub_torque=1",
    ];
    let (t, _) = simulate(dir.path(), &args).unwrap();
    assert!(t.columns.contains(&"beam_eta60".to_string()));
    let last = column(&t, "t").len() - 1;
    let energy = |r: usize| column(&t, "T")[r] + column(&t, "V")[r];
    let theta = column(&t, "theta");
    let work = theta[last] - theta[0];
    let gained = energy(last) - energy(0);
    println!("60 modes: energy gained {gained:e} J, work {work:e} J");
    assert!(work > 1e-4, "the torque does work: {work:e}");
    assert!(
        (gained - work).abs() <= 1e-6 * work,
        "energy gained {gained:e} vs work {work:e}"
    );
}

/// A pendulum released at 0.4 rad with a declared `range` of [-0.3, 0.5]:
/// `simulate` warns once, when the swing leaves it near the closed-form
/// time of the small-amplitude motion (`0.4 cos(w t) = -0.3`, t = 0.546 s
/// for `w = sqrt(g / l)`), and says nothing with `--quiet`.
#[test]
fn leaving_a_declared_range_is_warned_once_with_the_time() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(scene("pendulum")).unwrap().replace(
        "range = [-3.14159, 3.14159]",
        "range = [-0.3, 0.5]\ninitial = 0.4",
    );
    let path = write(dir.path(), "pendulum.toml", &text);
    let args = ["--scene", path.to_str().unwrap(), "--duration", "3"];
    let (_, notes) = simulate_noted(dir.path(), &args).unwrap();
    let warnings: Vec<&str> = notes
        .lines()
        .filter(|l| l.contains("left its declared range"))
        .collect();
    assert_eq!(warnings.len(), 1, "{notes}");
    let t: f64 = warnings[0]
        .split("at t = ")
        .nth(1)
        .and_then(|r| r.split(' ').next())
        .and_then(|x| x.parse().ok())
        .unwrap();
    let w = (9.81f64 / 0.5).sqrt();
    let expected = (-0.75f64).acos() / w;
    assert!(
        t >= expected && t < expected + 0.03,
        "{t} vs {expected}: {notes}"
    );
    let (_, quiet) = simulate(dir.path(), &args).unwrap();
    assert!(quiet.is_empty(), "{quiet}");
}

#[test]
fn a_start_at_a_singular_position_names_the_dependent_constraint_rows() {
    // The four-bar started flat: its closure_x row vanishes there.
    let dir = tempfile::tempdir().unwrap();
    let s = write(
        dir.path(),
        "flat.json",
        r#"{"q": [0, 0, 0], "qd": [-5, -5, 0], "t": 0}"#,
    );
    let four_bar = scene("four_bar");
    let e = simulate(
        dir.path(),
        &[
            "--scene",
            four_bar.to_str().unwrap(),
            "--duration",
            "1",
            "--integrator",
            "rk4",
            "--dt",
            "0.001",
            "--initial",
            s.to_str().unwrap(),
        ],
    )
    .unwrap_err();
    assert!(
        e.contains("condition estimate inf")
            && e.contains("the Jacobian rows of `closure_x` vanish or are combinations"),
        "{e}"
    );
}
