//! Issue 2: the checked-in generated modules (`generated/*.rs`) are usable by
//! an embedded user as they are: a `#![no_std]` crate with its own panic
//! handler that includes every one of them, depending only on
//! `flexdyn-runtime` without `std`, builds. (A duplicate `panic_impl` lang
//! item would fail the build if anything linked `std`.)

use std::fmt::Write as _;
use std::path::Path;
use std::process::Command;

#[test]
fn generated_modules_build_in_a_no_std_crate() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("generated_no_std");
    std::fs::create_dir_all(dir.join("src")).expect("create crate dir");
    let mut lib = String::from(
        "#![no_std]\n#![allow(dead_code)]\n\
         #[panic_handler]\nfn panic(_: &core::panic::PanicInfo) -> ! { loop {} }\n",
    );
    let mut names: Vec<String> = std::fs::read_dir(root.join("generated"))
        .expect("generated/")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|x| x == "rs"))
        .map(|p| p.file_stem().unwrap().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert!(!names.is_empty());
    for n in &names {
        let path = root.join("generated").join(format!("{n}.rs"));
        writeln!(
            lib,
            "pub mod {n} {{ include!({:?}); }}",
            path.display().to_string()
        )
        .unwrap();
    }
    std::fs::write(dir.join("src/lib.rs"), lib).expect("write lib");
    let manifest = format!(
        "[package]\nname = \"flexdyn-generated-no-std-check\"\nversion = \"0.0.0\"\nedition = \"2021\"\npublish = false\n\n\
         [dependencies]\nflexdyn-runtime = {{ path = {:?} }}\n\n[profile.dev]\npanic = \"abort\"\n\n[workspace]\n",
        root.join("runtime").display().to_string()
    );
    std::fs::write(dir.join("Cargo.toml"), manifest).expect("write manifest");
    let _ = std::fs::copy(root.join("Cargo.lock"), dir.join("Cargo.lock"));
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let out = Command::new(cargo)
        .args(["build", "--quiet", "--manifest-path"])
        .arg(dir.join("Cargo.toml"))
        .arg("--target-dir")
        .arg(dir.join("target"))
        .env_remove("RUSTFLAGS")
        .env_remove("CARGO_TARGET_DIR")
        .output()
        .expect("run cargo");
    assert!(
        out.status.success(),
        "no_std build of the generated modules failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
}
