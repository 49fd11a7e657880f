//! Issue 2: the formatted copies in `generated/` match a fresh generation of
//! every scene, and `generated/` holds nothing else. To update them run
//! `cargo run --release -- generate --all --out generated`.

use std::path::Path;

#[test]
fn checked_in_generated_code_is_fresh() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let report = flexdyn_codegen::Builder::new()
        .scenes_in(root.join("scenes"))
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
            "generated/{file} is stale or missing: run `cargo run --release -- generate --all --out generated`"
        );
        expected.push(file);
    }
    let mut present: Vec<String> = std::fs::read_dir(root.join("generated"))
        .expect("generated/ exists")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".rs"))
        .collect();
    present.sort();
    expected.sort();
    assert_eq!(
        present, expected,
        "generated/ has files for scenes that no longer exist"
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
