//! The Python package (`python/`): built by `pip install ./python` (maturin,
//! its own Cargo target folder `target/python-package`) into the test
//! environment (`common/python_env.rs`: CasADi's, with Pinocchio, maturin
//! and pytest), then `pytest python/tests`: its terms against `flexdyn
//! eval` bitwise and against Pinocchio, closed forms, batch against loop,
//! bad input.

#[path = "common/python_env.rs"]
mod python_env;

use std::path::PathBuf;
use std::process::Command;

#[test]
fn python_package_builds_and_passes_its_tests() {
    let repo = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let Some(python) = python_env::test_python(&repo, "python_package") else {
        return;
    };
    let bin = python
        .parent()
        .expect("the environment's bin folder")
        .to_path_buf();
    let path = std::env::join_paths(std::iter::once(bin).chain(std::env::split_paths(
        &std::env::var_os("PATH").unwrap_or_default(),
    )))
    .expect("PATH");
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let install = python_env::run(
        Command::new(&python)
            .current_dir(&repo)
            .args([
                "-m",
                "pip",
                "install",
                "--quiet",
                "--no-build-isolation",
                "--force-reinstall",
                "--no-deps",
            ])
            .arg(repo.join("python"))
            .env("PATH", &path)
            .env("CARGO", &cargo)
            .env("CARGO_TARGET_DIR", repo.join("target/python-package"))
            .env_remove("RUSTFLAGS"),
        "building the Python package (pip install ./python)",
    );
    assert!(
        install.status.success(),
        "pip install ./python failed:\n{}",
        python_env::output_text(&install)
    );
    let tests = python_env::run(
        Command::new(&python)
            .current_dir(&repo)
            .args(["-m", "pytest", "-q", "-p", "no:cacheprovider"])
            .arg(repo.join("python/tests"))
            .env("FLEXDYN_BIN", env!("CARGO_BIN_EXE_flexdyn"))
            .env("PYTHONDONTWRITEBYTECODE", "1"),
        "running pytest on python/tests",
    );
    let text = python_env::output_text(&tests);
    println!("{text}");
    assert!(
        tests.status.success(),
        "pytest python/tests failed:\n{text}"
    );
    assert!(
        !text.contains("skipped"),
        "no test may be skipped here:\n{text}"
    );
}
