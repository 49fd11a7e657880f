//! URDF robots imported with `flexdyn import urdf` and evaluated with
//! `flexdyn eval --scene` (the interpreter, no rebuild), compared with
//! Pinocchio (`crba`, `nonLinearEffects`, `rnea`) at 1000 seeded random
//! states by `tests/pinocchio/validate.py`: UR5, Panda (arm joints; the
//! fingers held fixed), Baxter (a tree with prismatic joints), xArm7,
//! Unitree Z1, and the humanoids Romeo (inertias that break the triangle
//! inequality, as published) and iCub, to 1e-12
//! of each term's scale, with the kinematics of a marker at every link
//! (position, rotation, `LOCAL_WORLD_ALIGNED` Jacobian, velocity, classical
//! acceleration) against Pinocchio's frames; and `flexdyn inverse` with every joint of Baxter
//! (19) and a fixed-base TALOS (32) prescribed, its torques against `rnea`
//! along the motion. Every URDF file of example-robot-data as published
//! (69 files, robots the project does not name among them) is checked the
//! same way at 20 states, derivatives included, and its default import
//! (angles snapped, round-off of zero dropped) within ten times its largest
//! snapped angle, or refused with the expected error. Plus a negative run: with one inertia entry of
//! each imported scene changed by a relative 1e-6 and its last marker moved
//! by 1e-6 m, the comparison must fail.
//! The shipped `scenes/ur5.toml` must be the import of today. The Python
//! environment is the CasADi validation's (`common/python_env.rs`).

#[path = "common/python_env.rs"]
mod python_env;

use std::path::PathBuf;
use std::process::Command;

/// The script's exit status and output; `None` when Python is missing.
fn validate(extra: &[&str]) -> Option<(Option<i32>, String)> {
    let repo = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let python = python_env::test_python(&repo, "pinocchio_validation")?;
    let dir = tempfile::tempdir().expect("temporary directory");
    let out = python_env::run(
        Command::new(python)
            .arg(repo.join("tests/pinocchio/validate.py"))
            .arg("--flexdyn")
            .arg(env!("CARGO_BIN_EXE_flexdyn"))
            .arg("--work")
            .arg(dir.path())
            .args(extra)
            .env("PYTHONDONTWRITEBYTECODE", "1"),
        "running the Pinocchio validation",
    );
    Some((out.status.code(), python_env::output_text(&out)))
}

/// The validation with `extra` arguments must pass (where Python is there).
fn validation_passes(extra: &[&str]) {
    let Some((code, text)) = validate(extra) else {
        return;
    };
    println!("{text}");
    assert_eq!(code, Some(0), "the Pinocchio validation failed:\n{text}");
}

#[test]
fn imported_robots_match_pinocchio() {
    validation_passes(&["--shipped", concat!(env!("CARGO_MANIFEST_DIR"), "/scenes")]);
}

#[test]
fn every_urdf_of_example_robot_data_matches_pinocchio() {
    validation_passes(&["--every", "--states", "20"]);
}

#[test]
fn a_perturbed_inertia_fails_the_comparison() {
    let Some((code, text)) = validate(&["--states", "50", "--perturb"]) else {
        return;
    };
    println!("{text}");
    assert_eq!(code, Some(1), "expected the comparison to fail:\n{text}");
    for robot in [
        "ur5",
        "panda",
        "baxter",
        "xarm7",
        "z1",
        "romeo_small",
        "icub",
    ] {
        for term in ["M", "marker position"] {
            assert!(
                text.lines()
                    .any(|l| l.starts_with(&format!("{robot}: {term}:")) && l.ends_with("FAILED")),
                "the perturbed {robot}'s {term} passed:\n{text}"
            );
        }
    }
    for robot in ["baxter", "talos"] {
        assert!(
            text.lines()
                .any(|l| l.starts_with(&format!("{robot}: inverse")) && l.ends_with("FAILED")),
            "the perturbed {robot}'s inverse dynamics passed:\n{text}"
        );
    }
}
