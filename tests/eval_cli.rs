//! `flexdyn eval` answers an edited copy of a compiled-in scene with the
//! copy's own terms (interpreted), not with the stale compiled module.

use std::process::Command;

/// The pendulum's mass matrix `m l^2` from `flexdyn eval` on `scene`.
fn pendulum_mass(scene: &std::path::Path, dir: &std::path::Path) -> f64 {
    let states = dir.join("states.json");
    std::fs::write(
        &states,
        r#"{"states": [{"q": [0.3], "qd": [0.0], "t": 0.0}]}"#,
    )
    .unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_flexdyn"))
        .args(["eval", "--scene"])
        .arg(scene)
        .arg("--states")
        .arg(&states)
        .output()
        .expect("run flexdyn");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON");
    json["results"][0]["mass_matrix"][0][0]
        .as_f64()
        .expect("M[0][0]")
}

#[test]
fn an_edited_copy_of_a_compiled_scene_is_evaluated_as_edited() {
    let dir = tempfile::tempdir().unwrap();
    let shipped = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/pendulum.toml");
    // The shipped scene: m = 1, l = 0.5, so M = 0.25 (compiled module).
    assert_eq!(pendulum_mass(&shipped, dir.path()), 0.25);
    let text = std::fs::read_to_string(&shipped).unwrap();
    let edited = text.replace("m = { value = 1.0,", "m = { value = 3.0,");
    assert_ne!(
        edited, text,
        "the pendulum's mass line moved: update this test"
    );
    let copy = dir.path().join("pendulum.toml");
    std::fs::write(&copy, edited).unwrap();
    assert_eq!(pendulum_mass(&copy, dir.path()), 0.75);
}
