//! The crate builds without `std`.
//!
//! No bare-metal target is installed here, so the check builds a
//! `#![no_std]` library crate (`tests/no_std_crate/lib.rs`) that depends on
//! this runtime with default features and defines its own
//! `#[panic_handler]`. That only compiles if nothing in the dependency graph
//! links `std` (otherwise: error E0152, duplicate lang item `panic_impl`).
//! The crate is generated in a temporary directory as its own workspace, so
//! the runtime's dev-dependencies (criterion enables `num-traits/std`) cannot
//! leak `std` into it through feature unification.

use std::path::Path;
use std::process::Command;

#[test]
fn runtime_builds_in_a_no_std_crate_graph() {
    let runtime = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("no_std_crate");
    std::fs::create_dir_all(dir.join("src")).expect("create crate dir");
    std::fs::copy(
        runtime.join("tests/no_std_crate/lib.rs"),
        dir.join("src/lib.rs"),
    )
    .expect("copy source");
    let manifest = format!(
        "[package]\nname = \"flexdyn-runtime-no-std-check\"\nversion = \"0.0.0\"\nedition = \"2021\"\npublish = false\n\n\
         [lib]\npath = \"src/lib.rs\"\n\n\
         [dependencies]\nflexdyn-runtime = {{ path = {:?} }}\n\n\
         [profile.dev]\npanic = \"abort\"\n\n[workspace]\n",
        runtime.display().to_string()
    );
    std::fs::write(dir.join("Cargo.toml"), manifest).expect("write manifest");
    // Reuse the workspace's lock file so that the same (cached) versions are
    // resolved without network access.
    if let Some(lock) = runtime
        .parent()
        .map(|p| p.join("Cargo.lock"))
        .filter(|p| p.exists())
    {
        let _ = std::fs::copy(lock, dir.join("Cargo.lock"));
    }
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let build = |offline: bool| {
        let mut cmd = Command::new(&cargo);
        cmd.arg("build")
            .arg("--quiet")
            .arg("--manifest-path")
            .arg(dir.join("Cargo.toml"));
        cmd.arg("--target-dir").arg(dir.join("target"));
        if offline {
            cmd.arg("--offline");
        }
        cmd.env_remove("RUSTFLAGS").env_remove("CARGO_TARGET_DIR");
        cmd.output().expect("run cargo")
    };
    let mut out = build(true);
    if !out.status.success() && String::from_utf8_lossy(&out.stderr).contains("offline") {
        out = build(false);
    }
    assert!(
        out.status.success(),
        "no_std build failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
}
