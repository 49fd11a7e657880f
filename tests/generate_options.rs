//! `flexdyn generate`'s options for embedded use: `--c-header` writes the
//! module with its `extern "C"` wrappers and the header `<name>.h` that the
//! builder produces, `--precision f32` an f32 module; asking for both is a
//! clear error that writes nothing, and so is f32 for a scene whose
//! stiffness spread f32 does not resolve, unless `--allow-unresolved-f32`.

use std::process::Command;

use flexdyn_codegen::Builder;

const BIN: &str = env!("CARGO_BIN_EXE_flexdyn");

fn generate(out: &std::path::Path, extra: &[&str]) -> std::process::Output {
    Command::new(BIN)
        .args([
            "generate",
            "--quiet",
            "--scene",
            "scenes/pendulum.toml",
            "--out",
        ])
        .arg(out)
        .args(extra)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("flexdyn runs")
}

#[test]
fn c_header_and_precision_options() {
    let dir = tempfile::tempdir().unwrap();
    let c = dir.path().join("c");
    let out = generate(&c, &["--c-header"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let expected = Builder::new()
        .scene(concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/pendulum.toml"))
        .c_interface(true)
        .out_dir(dir.path().join("builder"))
        .generate()
        .unwrap();
    let header = std::fs::read_to_string(c.join("pendulum.h")).unwrap();
    assert_eq!(Some(&header), expected.scenes[0].c_header.as_ref());
    let module = std::fs::read_to_string(c.join("pendulum.rs")).unwrap();
    assert_eq!(module, expected.scenes[0].source);
    assert!(module.contains("pub unsafe extern \"C\" fn pendulum_mass_matrix("));

    let f32 = dir.path().join("f32");
    let out = generate(&f32, &["--precision", "f32"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let module = std::fs::read_to_string(f32.join("pendulum.rs")).unwrap();
    assert!(module.contains("use flexdyn_runtime::math::f32 as math;"));
    assert!(!f32.join("pendulum.h").exists());

    let both = dir.path().join("both");
    let out = generate(&both, &["--precision", "f32", "--c-header"]);
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("the C interface is generated for f64 models only"),
        "{stderr}"
    );
    assert!(!both.exists(), "nothing is written");

    let out = generate(&both, &["--precision", "f16"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("f16"));
}

#[test]
fn f32_of_a_stiff_scene_is_refused_unless_allowed() {
    // The spring pendulum: its 1 kHz stretch mode against the swing, a
    // stiffness spread of 8.9e7 over f32's 1 / eps = 8.4e6.
    let dir = tempfile::tempdir().unwrap();
    let run = |extra: &[&str]| {
        Command::new(BIN)
            .args(["generate", "--quiet", "--precision", "f32", "--out"])
            .arg(dir.path())
            .args(["--scene", "scenes/spring_pendulum.toml"])
            .args(extra)
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .output()
            .expect("flexdyn runs")
    };
    let out = run(&[]);
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    for part in [
        "scene `spring_pendulum` cannot be computed in f32",
        "(mostly s, theta)",
        "limit 1/eps = 8.389e6",
        "--allow-unresolved-f32",
    ] {
        assert!(stderr.contains(part), "`{part}` not in: {stderr}");
    }
    assert!(!dir.path().join("spring_pendulum.rs").exists());
    let out = run(&["--allow-unresolved-f32"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let module = std::fs::read_to_string(dir.path().join("spring_pendulum.rs")).unwrap();
    assert!(module.contains("use flexdyn_runtime::math::f32 as math;"));
}
