//! The emitted code names the runtime crate by the builder's
//! `runtime_path`: two scenes generated for the paths `rt` (the runtime
//! renamed in Cargo.toml) and `crate::runtime` (a re-export) compile, in a
//! throwaway crate, against the runtime's `Model` trait, and the pendulum's
//! terms match their closed forms `M = m l^2`, `h = m g l sin(theta)`.
//! Generated for the default path, the same crate does not compile.

use std::path::{Path, PathBuf};
use std::process::Command;

use flexdyn_codegen::Builder;

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the codegen crate lies in the workspace")
        .to_path_buf()
}

/// The scenes and the paths they are generated for.
const SCENES: [(&str, &str); 2] = [("pendulum", "rt"), ("four_bar", "crate::runtime")];

const MAIN: &str = r#"
mod runtime {
    pub use rt::*;
}
mod pendulum {
    include!("pendulum.rs");
}
mod four_bar {
    include!("four_bar.rs");
}

use rt::nalgebra::{SMatrix, SVector};
use rt::Model;

fn main() {
    let p = pendulum::Pendulum { m: 2.0, l: 0.7, c: 0.0 };
    let q = SVector::<f64, 1>::new(0.4);
    let mut m = SMatrix::<f64, 1, 1>::zeros();
    p.mass_matrix(&q, 0.0, &mut m);
    let mut h = SVector::<f64, 1>::zeros();
    p.bias(&q, &SVector::zeros(), 0.0, &mut h);
    let f = four_bar::FourBar;
    let mut phi = SVector::<f64, 2>::zeros();
    f.constraints(&SVector::<f64, 3>::new(0.1, 0.2, 0.3), 0.0, &mut phi);
    println!("mass {:e}", m[(0, 0)]);
    println!("bias {:e}", h[0]);
    println!("name {}", <four_bar::FourBar as Model<3, 2, 1>>::NAME);
    println!("finite {}", phi.iter().all(|x| x.is_finite()));
}
"#;

/// Writes the throwaway crate into `dir`, its scenes generated for the
/// runtime paths `paths` (one per scene of [`SCENES`]).
fn write_crate(dir: &Path, paths: [&str; 2]) {
    let runtime = workspace().join("runtime");
    let manifest = format!(
        "[package]\nname = \"runtime_path_check\"\nversion = \"0.0.0\"\nedition = \"2021\"\n\
         publish = false\n\n[dependencies]\nrt = {{ package = \"flexdyn-runtime\", path = {:?} }}\n\n\
         [workspace]\n",
        runtime.display().to_string()
    );
    std::fs::create_dir_all(dir.join("src")).unwrap();
    std::fs::write(dir.join("Cargo.toml"), manifest).unwrap();
    // The workspace's lock file pins the versions already downloaded.
    std::fs::copy(workspace().join("Cargo.lock"), dir.join("Cargo.lock")).unwrap();
    std::fs::write(dir.join("src/main.rs"), MAIN).unwrap();
    for ((scene, _), path) in SCENES.iter().zip(paths) {
        Builder::new()
            .scene(workspace().join(format!("scenes/{scene}.toml")))
            .runtime_path(path)
            .out_dir(dir.join("src"))
            .generate()
            .unwrap_or_else(|e| panic!("{e}"));
    }
}

/// `cargo run` in `dir`, with the target directory `target` of its own
/// under the workspace's (cargo identifies a package by its path relative to
/// its workspace, the same for every throwaway crate: two crates sharing a
/// target directory could take each other's build for fresh); the command's
/// output.
fn cargo_run(dir: &Path, target: &str) -> std::process::Output {
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    Command::new(cargo)
        .args(["run", "--quiet", "--offline", "--manifest-path"])
        .arg(dir.join("Cargo.toml"))
        .env(
            "CARGO_TARGET_DIR",
            workspace()
                .join("target")
                .join("runtime_path_check")
                .join(target),
        )
        .env_remove("RUSTFLAGS")
        .output()
        .expect("cargo runs")
}

fn value(stdout: &str, key: &str) -> String {
    stdout
        .lines()
        .find_map(|l| l.strip_prefix(key).map(|v| v.trim().to_owned()))
        .unwrap_or_else(|| panic!("no `{key}` in the output:\n{stdout}"))
}

#[test]
fn emitted_code_compiles_against_the_runtime_at_the_given_path() {
    let dir = tempfile::tempdir().unwrap();
    write_crate(dir.path(), [SCENES[0].1, SCENES[1].1]);
    let out = cargo_run(dir.path(), "given_path");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "the generated crate does not build or run:\n{}\n{stdout}",
        String::from_utf8_lossy(&out.stderr)
    );
    let (m, l, theta, g) = (2.0f64, 0.7f64, 0.4f64, 9.81f64);
    let mass: f64 = value(&stdout, "mass").parse().unwrap();
    let bias: f64 = value(&stdout, "bias").parse().unwrap();
    assert!((mass - m * l * l).abs() <= 1e-14, "M = {mass}");
    assert!(
        (bias - m * g * l * theta.sin()).abs() <= 1e-13,
        "h = {bias}"
    );
    assert_eq!(value(&stdout, "name"), "four_bar");
    assert_eq!(value(&stdout, "finite"), "true");
}

#[test]
fn emitted_code_for_another_runtime_path_does_not_compile_there() {
    // The crate has no `flexdyn_runtime`: code generated for the default
    // path cannot find the runtime.
    let dir = tempfile::tempdir().unwrap();
    write_crate(dir.path(), ["flexdyn_runtime", "flexdyn_runtime"]);
    let out = cargo_run(dir.path(), "default_path");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "built although the path is wrong");
    assert!(stderr.contains("flexdyn_runtime"), "{stderr}");
}

#[test]
fn a_runtime_path_that_is_not_a_path_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    for bad in ["", "flexdyn runtime", "rt::<f64>", "1rt", "rt::"] {
        let e = Builder::new()
            .scene(workspace().join("scenes/pendulum.toml"))
            .runtime_path(bad)
            .out_dir(dir.path().join("out"))
            .generate()
            .unwrap_err();
        assert!(
            e.message
                .contains(&format!("`{bad}` is not a path to the runtime crate")),
            "{e}"
        );
    }
    assert!(!dir.path().join("out").exists(), "nothing is written");
}
