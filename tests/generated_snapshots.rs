//! The formatted snapshots in `generated/` (a few scenes worth reading and
//! diffing; every scene is generated again at build time into `OUT_DIR`)
//! match a fresh generation of their scene files, and `generated/` holds
//! nothing else. To update them after a change of the generator, run
//! `cargo run --release -- generate --out generated` with one `--scene` per
//! entry of `SNAPSHOTS` (the command is in the failure message).

use std::path::Path;

/// The scene files whose generated modules are checked in, relative to the
/// repository root.
const SNAPSHOTS: [&str; 5] = [
    "scenes/pendulum.toml",
    "scenes/four_bar.toml",
    "scenes/slider_crank.toml",
    "scenes/spin_up_beam.toml",
    "examples/parallel-robot/scenes/parallel_robot_rigid.toml",
];

/// The command that regenerates every snapshot.
fn update_command() -> String {
    let scenes: Vec<String> = SNAPSHOTS.iter().map(|s| format!("--scene {s}")).collect();
    format!(
        "cargo run --release -- generate --out generated {}",
        scenes.join(" ")
    )
}

#[test]
fn generated_snapshots_match_a_fresh_generation() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let report = SNAPSHOTS
        .iter()
        .fold(flexdyn_codegen::Builder::new(), |b, s| {
            b.scene(root.join(s))
        })
        .out_dir(tempfile::tempdir().expect("temp dir").path())
        .generate()
        .unwrap_or_else(|e| panic!("{e}"));
    let mut expected: Vec<String> = Vec::new();
    for s in &report.scenes {
        let file = format!("{}.rs", s.name);
        let path = root.join("generated").join(&file);
        let checked_in = std::fs::read_to_string(&path).unwrap_or_default();
        assert!(
            checked_in == s.source,
            "generated/{file} is stale or missing: run `{}`",
            update_command()
        );
        expected.push(file);
    }
    let mut present: Vec<String> = std::fs::read_dir(root.join("generated"))
        .expect("generated/ exists")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    present.sort();
    expected.sort();
    assert_eq!(
        present,
        expected,
        "generated/ must hold exactly the snapshots of SNAPSHOTS (update with `{}`)",
        update_command()
    );
}

#[test]
fn generated_code_is_safe_and_allocation_free_by_construction() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    for entry in std::fs::read_dir(root.join("generated")).expect("generated/ exists") {
        let path = entry.expect("entry").path();
        let text = std::fs::read_to_string(&path).expect("readable");
        assert!(
            text.starts_with("// @generated"),
            "{}: no @generated header",
            path.display()
        );
        for banned in [
            "unsafe", "Vec<", "Box<", "vec!", "String", "unwrap", "expect(", "panic!", "loop",
            "while",
        ] {
            assert!(
                !text.contains(banned),
                "{}: contains `{banned}`",
                path.display()
            );
        }
    }
}
