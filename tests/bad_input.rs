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
    // The point (x + 0.1, y, 0) at q = (0.3, -0.2).
    let expected = [0.4, -0.2, 0.0];
    for scene in [
        data("coincident_world.toml"),
        p(dir.path(), "explicit.toml"),
    ] {
        let phi = constraints_at_the_state(&scene);
        assert_eq!(phi.len(), 3, "{scene}");
        for (a, b) in phi.iter().zip(expected) {
            assert!((a - b).abs() < 1e-15, "{scene}: {phi:?}");
        }
    }
}
