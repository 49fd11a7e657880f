//! Bad input never panics, hangs or lies: scenes, inputs and output paths
//! a careless or hostile user might give, each refused with a one-line
//! error that names the file, the line or the component, and the limit, or
//! handled correctly. The scenes and inputs are in `tests/bad_input/`.

#[path = "common/cli.rs"]
mod cli;

use cli::{p, refused, run};

const BIN: &str = env!("CARGO_BIN_EXE_flexdyn");

/// `tests/bad_input/<name>`, relative to the crate (where [`run`] runs).
fn data(name: &str) -> String {
    format!("tests/bad_input/{name}")
}

/// `generate --scene tests/bad_input/<scene>` (with `extra` arguments) is
/// refused with every one of `needles` in its error, writing nothing.
fn generate_refused(scene: &str, extra: &[&str], needles: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    let out = p(dir.path(), "out");
    let scene = data(scene);
    let mut args = vec!["generate", "--scene", &scene, "--out", &out];
    args.extend(extra);
    refused(dir.path(), &[], &args, needles[0]);
    let (_, err) = run(&args);
    for n in needles {
        assert!(err.contains(n), "{args:?}: `{err}` should mention `{n}`");
    }
}

#[test]
fn derived_constants_beyond_f64_are_located_errors() {
    // A flexible joint 1e200 m long: its inertia m l^2 / 12 is infinite
    // (this panicked in the graph).
    generate_refused(
        "huge_joint_length.toml",
        &[],
        &[
            "huge_joint_length.toml:9:8",
            "component `j`",
            "1.7976931348623157e308",
        ],
    );
    // m g l = 4.9e308 in the potential energy (was clamped to f64::MAX:
    // the pendulum then swung differently from one of mass 1).
    generate_refused(
        "huge_pendulum_mass.toml",
        &[],
        &[
            "huge_pendulum_mass.toml:10:8",
            "component `bob`",
            "f64's range",
        ],
    );
    // Finite energies, a mass matrix 2e308 (was an empty mass_matrix).
    generate_refused(
        "two_huge_masses.toml",
        &[],
        &["two_huge_masses.toml", "component `p2`", "f64's range"],
    );
    // Every command that loads a scene refuses it alike.
    let scene = data("huge_joint_length.toml");
    let dir = tempfile::tempdir().unwrap();
    let out = p(dir.path(), "e.json");
    for args in [
        vec!["export", "--scene", &scene, "--out", &out],
        vec![
            "eval",
            "--scene",
            &scene,
            "--states",
            "tests/bad_input/one_state.json",
        ],
        vec![
            "simulate",
            "--scene",
            &scene,
            "--duration",
            "1",
            "--csv",
            &out,
        ],
    ] {
        let (code, err) = run(&args);
        assert_eq!(code, Some(1), "{err}");
        assert!(
            err.contains("component `j`") && !err.contains("panicked"),
            "{err}"
        );
    }
}

#[test]
fn a_kinetic_energy_not_quadratic_in_the_velocities_is_refused() {
    // The mass matrix would read the velocities (the module did not compile).
    generate_refused(
        "quartic_kinetic.toml",
        &[],
        &["component `d`", "not quadratic in the velocities", "`x`"],
    );
    let scene = data("quartic_kinetic.toml");
    let states = data("one_state.json");
    let (code, err) = run(&["eval", "--scene", &scene, "--states", &states]);
    assert_eq!(code, Some(1), "the interpreter refuses it too: {err}");
    assert!(err.contains("not quadratic in the velocities"), "{err}");
}

#[test]
fn f32_literals_outside_the_normal_range_are_refused() {
    generate_refused(
        "f32_huge_mass.toml",
        &["--precision", "f32"],
        &["function `mass_matrix`", "1e300", "3.4028235e38"],
    );
    generate_refused(
        "f32_tiny_mass.toml",
        &["--precision", "f32"],
        &["function `mass_matrix`", "1e-300", "1.1754944e-38"],
    );
}

#[test]
fn duplicate_names_and_unphysical_energies_are_refused() {
    generate_refused(
        "duplicate_actuator.toml",
        &[],
        &[
            "duplicate_actuator.toml:13:8",
            "actuator `u`",
            "declared above",
        ],
    );
    generate_refused(
        "duplicate_component.toml",
        &[],
        &[
            "duplicate_component.toml:10:8",
            "component `p`",
            "declared above",
        ],
    );
    generate_refused(
        "negative_dissipation.toml",
        &[],
        &[
            "component `d`",
            "dissipation function decreases",
            "`x`",
            "-2e0",
        ],
    );
    generate_refused(
        "negative_kinetic.toml",
        &[],
        &["component `d`", "kinetic energy decreases", "`x`", "-2e0"],
    );
    generate_refused(
        "triangle_inertia.toml",
        &[],
        &[
            "triangle_inertia.toml:12:11",
            "component `b`",
            "triangle inequality",
            "1e1",
            "2e0",
        ],
    );
}

/// The `"constraints"` values of `eval` at `tests/bad_input/one_state.json`.
fn constraints_at_the_state(scene: &str) -> Vec<f64> {
    let out = std::process::Command::new(BIN)
        .args([
            "eval",
            "--scene",
            scene,
            "--states",
            &data("one_state.json"),
        ])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    json["results"][0]["constraints"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect()
}

#[test]
fn a_coincident_constraint_without_b_holds_a_point_at_the_world_origin() {
    let dir = tempfile::tempdir().unwrap();
    let explicit = dir.path().join("explicit.toml");
    let text = std::fs::read_to_string(data("coincident_world.toml")).unwrap();
    let with_b = text.replace(
        "a = { frame = \"f\", position = [0.1, 0, 0] }",
        "a = { frame = \"f\", position = [0.1, 0, 0] }\nb = { frame = \"world\" }",
    );
    assert_ne!(with_b, text);
    std::fs::write(&explicit, with_b).unwrap();
    // The point (x + 0.1, y, 0) at q = (0.3, -0.2); its `z` row is
    // identically zero (the point moves in a plane) and is dropped.
    let expected = [0.4, -0.2];
    for scene in [
        data("coincident_world.toml"),
        p(dir.path(), "explicit.toml"),
    ] {
        let phi = constraints_at_the_state(&scene);
        assert_eq!(phi.len(), 2, "{scene}");
        for (a, b) in phi.iter().zip(expected) {
            assert!((a - b).abs() < 1e-15, "{scene}: {phi:?}");
        }
    }
}

#[cfg(unix)]
#[test]
fn outputs_follow_links_and_write_through_fifos() {
    use std::os::unix::fs::{symlink, FileTypeExt};
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("target.csv"), "precious").unwrap();
    symlink("target.csv", d.join("link.csv")).unwrap();
    let scene = data("actuated_pendulum.toml");
    let simulate = |csv: &str| {
        run(&[
            "simulate",
            "--scene",
            &scene,
            "--duration",
            "0.1",
            "--csv",
            csv,
            "--quiet",
        ])
    };
    let (code, err) = simulate(&p(d, "link.csv"));
    assert_eq!(code, Some(0), "{err}");
    assert!(std::fs::symlink_metadata(d.join("link.csv"))
        .unwrap()
        .file_type()
        .is_symlink());
    let written = std::fs::read_to_string(d.join("target.csv")).unwrap();
    assert!(written.starts_with("t,theta"), "{written}");
    // A FIFO (like /dev/stdout or /dev/null) is written through, not replaced.
    let fifo = d.join("fifo");
    assert!(std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap()
        .success());
    let reader = {
        let fifo = fifo.clone();
        std::thread::spawn(move || std::fs::read_to_string(fifo).unwrap())
    };
    let (code, err) = simulate(&p(d, "fifo"));
    assert_eq!(code, Some(0), "{err}");
    assert_eq!(reader.join().unwrap(), written);
    assert!(std::fs::symlink_metadata(&fifo)
        .unwrap()
        .file_type()
        .is_fifo());
    // Nothing else (no temporary file) is left.
    assert_eq!(std::fs::read_dir(d).unwrap().count(), 3);
}

#[test]
fn generate_of_several_scenes_writes_all_or_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // The second module's path is taken by a directory.
    std::fs::create_dir(d.join("duplicate_actuator_free.rs")).unwrap();
    std::fs::write(
        d.join("duplicate_actuator_free.toml"),
        std::fs::read_to_string(data("actuated_pendulum.toml"))
            .unwrap()
            .replace("actuated_pendulum", "duplicate_actuator_free"),
    )
    .unwrap();
    let second = p(d, "duplicate_actuator_free.toml");
    let scene = data("actuated_pendulum.toml");
    let out = p(d, "");
    refused(
        d,
        &["duplicate_actuator_free.rs", "duplicate_actuator_free.toml"],
        &[
            "generate", "--scene", &scene, "--scene", &second, "--out", &out,
        ],
        "duplicate_actuator_free.rs: it is a directory",
    );
}

#[test]
fn inputs_and_scenes_are_read_up_to_a_limit() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // 65 MiB of NUL bytes (sparse): refused at the 64 MiB limit, with a
    // short message, and without reading it whole.
    let csv = std::fs::File::create(d.join("u.csv")).unwrap();
    csv.set_len(65 << 20).unwrap();
    let scene = data("actuated_pendulum.toml");
    let o = p(d, "o.csv");
    let u = p(d, "u.csv");
    let args = [
        "simulate",
        "--scene",
        &scene,
        "--duration",
        "1",
        "--inputs",
        &u,
        "--csv",
        &o,
    ];
    refused(
        d,
        &["u.csv"],
        &args,
        "larger than the limit of 67108864 bytes",
    );
    let (_, err) = run(&args);
    assert!(err.len() < 300, "{err}");
    // An endless scene file.
    let out = p(d, "g");
    refused(
        d,
        &["u.csv"],
        &["generate", "--scene", "/dev/zero", "--out", &out],
        "larger than the limit of 4194304 bytes",
    );
}

#[test]
fn unclear_inputs_get_errors_that_say_what_and_where() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = p(d, "s.toml");
    // A URDF without a moving joint.
    refused(
        d,
        &[],
        &["import", "urdf", &data("fixed_only.urdf"), "--out", &out],
        "fixed_only.urdf:2:1: the robot has no moving joint",
    );
    // An output directory that does not exist: refused before the run.
    let scene = data("actuated_pendulum.toml");
    let missing = p(d, "no/such/dir/o.csv");
    let start = std::time::Instant::now();
    refused(
        d,
        &[],
        &[
            "simulate",
            "--scene",
            &scene,
            "--duration",
            "1e5",
            "--csv",
            &missing,
        ],
        "directory",
    );
    assert!(start.elapsed().as_secs_f64() < 5.0, "checked after the run");
    // An inputs CSV with only `t` drives nothing: refused.
    let o = p(d, "o.csv");
    let only_t = data("inputs_only_t.csv");
    refused(
        d,
        &[],
        &[
            "simulate",
            "--scene",
            &scene,
            "--duration",
            "1",
            "--inputs",
            &only_t,
            "--csv",
            &o,
        ],
        "inputs_only_t.csv: no column besides `t`",
    );
    // A byte-order mark (as spreadsheets write) is accepted.
    let bom = data("inputs_with_bom.csv");
    let (code, err) = run(&[
        "simulate",
        "--scene",
        &scene,
        "--duration",
        "1",
        "--inputs",
        &bom,
        "--csv",
        &o,
        "--quiet",
    ]);
    assert_eq!(code, Some(0), "{err}");
}

#[test]
fn inverse_columns_are_unique_when_an_actuator_is_named_like_its_joint() {
    let dir = tempfile::tempdir().unwrap();
    let csv = p(dir.path(), "i.csv");
    let scene = data("actuator_named_like_its_joint.toml");
    let (code, err) = run(&[
        "inverse",
        "--scene",
        &scene,
        "--duration",
        "1",
        "--dt",
        "0.5",
        "--prescribe",
        "theta=t",
        "--csv",
        &csv,
        "--quiet",
    ]);
    assert_eq!((code, err.as_str()), (Some(0), ""));
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("t,tau_theta,theta"));
    // tau = m l^2 theta'' + m g l sin(theta), theta = t: at t = 0.5 s.
    let row: Vec<f64> = lines
        .nth(1)
        .unwrap()
        .split(',')
        .map(|x| x.parse().unwrap())
        .collect();
    let expected = 1.0 * 9.81 * 0.5 * 0.5f64.sin();
    assert!((row[1] - expected).abs() < 1e-9, "{row:?} vs {expected}");
}

#[test]
fn a_diverging_gauss_legendre_step_names_the_fastest_mode_and_a_step() {
    // At 0.2 s the stage iteration of the flexible UR5 (a 1.8 kHz mode)
    // diverges into states whose mass matrix is not positive definite.
    let dir = tempfile::tempdir().unwrap();
    let csv = p(dir.path(), "o.csv");
    let (code, err) = run(&[
        "simulate",
        "--scene",
        "scenes/ur5_flexible.toml",
        "--integrator",
        "gauss-legendre",
        "--duration",
        "0.5",
        "--dt",
        "0.2",
        "--csv",
        &csv,
        "--quiet",
    ]);
    assert_eq!(code, Some(1), "{err}");
    for part in [
        "stage iteration diverged",
        "the fastest mode is at about",
        "steps must be below",
    ] {
        assert!(err.contains(part), "`{part}` not in: {err}");
    }
}

#[test]
fn eval_refuses_non_finite_results_naming_the_entry() {
    // At q = qd = 1e308 the kinetic energy m l^2 qd^2 / 2 overflows (it was
    // written as `null` with exit status 0).
    let scene = data("actuated_pendulum.toml");
    let states = data("huge_state.json");
    let (code, err) = run(&["eval", "--scene", &scene, "--states", &states]);
    assert_eq!(code, Some(1), "{err}");
    assert!(
        err.starts_with("error: state 0: `") && err.contains("is not finite"),
        "{err}"
    );
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn times_in_messages_have_bounded_digits() {
    let dir = tempfile::tempdir().unwrap();
    let csv = p(dir.path(), "o.csv");
    let scene = data("actuated_pendulum.toml");
    let start = data("start_at_1e300.json");
    let (code, err) = run(&[
        "simulate",
        "--scene",
        &scene,
        "--duration",
        "1",
        "--initial",
        &start,
        "--csv",
        &csv,
        "--quiet",
    ]);
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains("t = 1e300 s") && err.len() < 200, "{err}");
}

#[test]
fn constraint_sets_without_a_solution_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let o = p(d, "o.csv");
    // Contradicting rows: refused at generation, located, naming the row
    // that depends on the others.
    let contradicting = data("contradicting_constraints.toml");
    let simulate = |scene: &str| -> Vec<String> {
        ["simulate", "--scene", scene, "--duration", "1", "--csv", &o]
            .map(String::from)
            .to_vec()
    };
    let args = simulate(&contradicting);
    let args: Vec<&str> = args.iter().map(|s| s.as_str()).collect();
    refused(
        d,
        &[],
        &args,
        "contradicting_constraints.toml:17:14: in constraint `c2`: the constraints cannot all hold",
    );
    generate_refused(
        "contradicting_constraints.toml",
        &[],
        &[
            "Jacobian rows of `c2` are combinations",
            "contradicts itself",
        ],
    );
    // One row with no real solution: the start cannot be projected, and
    // the message says the residual stays where the row vanishes.
    let unsolvable = data("unsolvable_constraint.toml");
    let args = simulate(&unsolvable);
    let args: Vec<&str> = args.iter().map(|s| s.as_str()).collect();
    refused(
        d,
        &[],
        &args,
        "the Jacobian rows of `c1` vanish or are combinations of the rows before them, where \
         the residual of `c1` is 1e0, not zero: the constraints have no solution near this state",
    );
}
