//! Issue 4: the command-line contract of the robot (`inverse`, `simulate`),
//! the inverse-then-forward round trip, and clear errors for bad input.

use std::path::Path;
use std::process::Command;

use flexdyn::table::Table;

fn flexdyn(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_parallel-robot"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("run flexdyn");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

const SCENE: &str = "scenes/parallel_robot_rigid.toml";

fn path(dir: &Path, name: &str) -> String {
    dir.join(name).to_string_lossy().into_owned()
}

#[test]
fn inverse_writes_the_contracted_columns_and_a_plot() {
    let dir = tempfile::tempdir().unwrap();
    let (csv, png) = (path(dir.path(), "out.csv"), path(dir.path(), "out.png"));
    let (ok, _, err) = flexdyn(&[
        "inverse",
        "--scene",
        SCENE,
        "--omega",
        "2",
        "--duration",
        "5",
        "--dt",
        "0.005",
        "--csv",
        &csv,
        "--plot",
        &png,
        "--quiet",
    ]);
    assert!(ok, "{err}");
    let t = Table::read(Path::new(&csv)).unwrap();
    for c in ["t", "tau_1", "tau_2", "tau_3", "px", "py", "pz"] {
        assert!(t.columns.iter().any(|x| x == c), "missing column {c}");
    }
    assert_eq!(t.rows.len(), 1001);
    let px = t.column("px").unwrap();
    let times = t.column("t").unwrap();
    for (x, time) in px.iter().zip(&times) {
        assert!((x - 0.1 * (2.0 * time).cos()).abs() < 1e-12);
    }
    let png_bytes = std::fs::read(&png).unwrap();
    assert!(png_bytes.starts_with(b"\x89PNG"), "not a PNG");
}

#[test]
fn inverse_torques_fed_forward_keep_the_platform_on_the_circle() {
    let dir = tempfile::tempdir().unwrap();
    let (tq, sim) = (path(dir.path(), "tq.csv"), path(dir.path(), "sim.csv"));
    let (ok, _, err) = flexdyn(&[
        "inverse",
        "--scene",
        SCENE,
        "--duration",
        "1",
        "--dt",
        "0.0005",
        "--csv",
        &tq,
        "--quiet",
    ]);
    assert!(ok, "{err}");
    for integrator in ["rk4", "gen-alpha"] {
        let (ok, _, err) = flexdyn(&[
            "simulate",
            "--scene",
            SCENE,
            "--torques",
            &tq,
            "--dt",
            "0.0005",
            "--output-dt",
            "0.005",
            "--integrator",
            integrator,
            "--csv",
            &sim,
            "--quiet",
        ]);
        assert!(ok, "{err}");
        let t = Table::read(Path::new(&sim)).unwrap();
        let (ts, px, py, pz) = (
            t.column("t").unwrap(),
            t.column("px").unwrap(),
            t.column("py").unwrap(),
            t.column("pz").unwrap(),
        );
        assert!((ts[ts.len() - 1] - 1.0).abs() < 1e-9);
        let worst = (0..ts.len())
            .map(|k| {
                let (c, s) = ((2.0 * ts[k]).cos(), (2.0 * ts[k]).sin());
                (px[k] - 0.1 * c)
                    .abs()
                    .max((py[k] - 0.1 * s).abs())
                    .max((pz[k] - 0.7).abs())
            })
            .fold(0.0, f64::max);
        assert!(
            worst < 1e-6,
            "{integrator}: platform left the circle by {worst} m"
        );
    }
}

fn fails_cleanly(args: &[&str], needle: &str, no_file: Option<&str>) {
    let (ok, _, err) = flexdyn(args);
    assert!(!ok, "{args:?} should fail");
    assert!(
        err.contains(needle),
        "{args:?}: `{err}` should mention `{needle}`"
    );
    assert!(!err.contains("panicked"), "{err}");
    if let Some(f) = no_file {
        assert!(!Path::new(f).exists(), "{f} must not be written on failure");
    }
}

#[test]
fn bad_input_gives_clear_errors_and_no_output() {
    let dir = tempfile::tempdir().unwrap();
    let out = path(dir.path(), "never.csv");
    fails_cleanly(
        &[
            "inverse", "--scene", SCENE, "--center", "0,0,1.6", "--csv", &out,
        ],
        "out of reach",
        Some(&out),
    );
    fails_cleanly(
        &["inverse", "--scene", SCENE, "--dt", "0", "--csv", &out],
        "step must be a positive number",
        Some(&out),
    );
    fails_cleanly(
        &["inverse", "--scene", SCENE, "--dt", "-0.1", "--csv", &out],
        "step must be a positive number",
        Some(&out),
    );
    fails_cleanly(
        &[
            "inverse",
            "--scene",
            SCENE,
            "--duration",
            "1e300",
            "--csv",
            &out,
        ],
        "at most",
        Some(&out),
    );
    fails_cleanly(
        &["inverse", "--scene", "scenes/none.toml"],
        "cannot read scene file",
        None,
    );
    fails_cleanly(
        &["inverse", "--scene", "../../scenes/pendulum.toml"],
        "drives the parallel robot",
        None,
    );
    fails_cleanly(
        &[
            "inverse",
            "--scene",
            SCENE,
            "--plot",
            &path(dir.path(), "x.jpg"),
        ],
        ".png or .svg",
        None,
    );
    let bad = path(dir.path(), "bad.csv");
    std::fs::write(
        &bad,
        "t,tau_1,tau_2,tau_3,px,py,pz\n0,1,2,3,0.1,0,0.7\n0.1,1,x,3,0.1,0,0.7\n",
    )
    .unwrap();
    fails_cleanly(
        &[
            "simulate",
            "--scene",
            SCENE,
            "--torques",
            &bad,
            "--csv",
            &out,
        ],
        ":3: column `tau_2`",
        Some(&out),
    );
    std::fs::write(&bad, "t,torque\n0,1\n").unwrap();
    fails_cleanly(
        &[
            "simulate",
            "--scene",
            SCENE,
            "--torques",
            &bad,
            "--csv",
            &out,
        ],
        "no column `tau_1`",
        Some(&out),
    );
    std::fs::write(
        &bad,
        "t,tau_1,tau_2,tau_3,px,py,pz\n0,1,2,3,0.1,0,0.7\n0,1,2,3,0.1,0,0.7\n",
    )
    .unwrap();
    fails_cleanly(
        &["simulate", "--scene", SCENE, "--torques", &bad],
        "increase strictly",
        None,
    );
    fails_cleanly(
        &[
            "simulate",
            "--scene",
            SCENE,
            "--torques",
            &path(dir.path(), "missing.csv"),
        ],
        "cannot read",
        None,
    );
}

/// `inverse --states` writes consistent working states: the generated
/// constraints vanish there and the velocities lie in the null space of the
/// constraint Jacobian (both evaluated by `parallel-robot eval`, independently of
/// the solver that produced the states), for the rigid and a flexible scene.
#[test]
fn inverse_states_are_consistent_working_states() {
    let dir = tempfile::tempdir().unwrap();
    for scene in [SCENE, "scenes/parallel_robot_flexible_m1.toml"] {
        let (states, results) = (path(dir.path(), "s.json"), path(dir.path(), "r.json"));
        let (ok, _, err) = flexdyn(&[
            "inverse",
            "--scene",
            scene,
            "--duration",
            "1",
            "--dt",
            "0.1",
            "--states",
            &states,
            "--quiet",
        ]);
        assert!(ok, "{scene}: {err}");
        let (ok, _, err) = flexdyn(&[
            "eval", "--scene", scene, "--states", &states, "--out", &results,
        ]);
        assert!(ok, "{scene}: {err}");
        let read = |p: &str| -> serde_json::Value {
            serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
        };
        let (input, output) = (read(&states), read(&results));
        let input = input["states"].as_array().unwrap();
        let output = output["results"].as_array().unwrap();
        assert_eq!(input.len(), 11, "{scene}: one state per output step");
        let vec = |v: &serde_json::Value| -> Vec<f64> {
            v.as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect()
        };
        for (s, r) in input.iter().zip(output) {
            let qd = vec(&s["qd"]);
            let phi = vec(&r["constraints"]);
            assert!(phi.iter().all(|x| x.abs() < 1e-9), "{scene}: Phi = {phi:?}");
            for row in r["constraint_jacobian"].as_array().unwrap() {
                let v: f64 = vec(row).iter().zip(&qd).map(|(a, b)| a * b).sum();
                assert!(v.abs() < 1e-9, "{scene}: Phi_q qd = {v}");
            }
        }
    }
}
