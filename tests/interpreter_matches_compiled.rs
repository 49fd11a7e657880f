//! The interpreter (`flexdyn::interpreted`, any scene file at run time)
//! against the compiled module of every scene in `scenes/` (the checks are
//! in `common/interpreter_matches_compiled.rs`, shared with the
//! parallel-robot example's scenes), plus the interpreter's errors and the
//! command line on a scene that is not compiled in.

mod common;

use flexdyn::scenes as compiled;

include!("common/interpreter_matches_compiled.rs");

#[test]
fn a_state_of_the_wrong_length_is_a_clear_error() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/four_bar.toml");
    let model = InterpretedModel::load(&path).unwrap();
    let s = State {
        q: vec![0.1, 0.2],
        qd: vec![0.0; 3],
        qdd: Vec::new(),
        tau: Vec::new(),
        t: 0.0,
        params: BTreeMap::new(),
    };
    let e = check_state(&model, &s, 4).unwrap_err();
    assert_eq!(
        e,
        "state 4: scene `four_bar` has 3 coordinates, got 2 positions and 3 velocities"
    );
}

#[test]
fn a_scene_file_with_errors_gives_the_generators_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("broken.toml");
    std::fs::write(
        &path,
        "name = \"broken\"\n[[coordinates]]\nname = \"a\"\n\
         [[components]]\nname = \"m\"\ntype = \"point_mass\"\nmass = 1\n\
         position = [\"a + nope\", 0, 0]\n",
    )
    .unwrap();
    let e = InterpretedModel::load(&path).unwrap_err();
    let generator = flexdyn::codegen::generate_scene(&path).unwrap_err();
    assert_eq!(e, generator.to_string());
    assert!(e.contains("broken.toml") && e.contains("nope"), "{e}");
}

/// `flexdyn eval` on a scene that is not compiled in (a renamed copy of
/// `pendulum`) interprets it: the results are the compiled pendulum's.
#[test]
fn eval_interprets_a_scene_that_is_not_compiled_in() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(root.join("scenes/pendulum.toml")).unwrap();
    let copy = dir.path().join("my_pendulum.toml");
    std::fs::write(
        &copy,
        text.replace("name = \"pendulum\"", "name = \"my_pendulum\""),
    )
    .unwrap();
    let states = root.join("scenes/pendulum.states.json");
    let run = |scene: &std::path::Path| -> Value {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_flexdyn"))
            .args(["eval", "--scene"])
            .arg(scene)
            .arg("--states")
            .arg(&states)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        serde_json::from_slice(&out.stdout).unwrap()
    };
    let mine = run(&copy);
    let shipped = run(&root.join("scenes/pendulum.toml"));
    assert_eq!(mine["scene"], "my_pendulum");
    assert_eq!(
        first_difference(&mine["results"], &shipped["results"], ""),
        None
    );
    assert!(mine["results"].as_array().unwrap().len() >= 3);
}
