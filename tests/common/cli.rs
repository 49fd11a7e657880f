//! Command-line misuse checks shared by the crates' `cli_misuse` tests: run
//! the crate's binary (`super::BIN`) from the crate's folder and require a
//! clean refusal.

use std::path::Path;
use std::process::Command;

/// Runs the binary with `args`: its exit status and standard error.
pub fn run(args: &[&str]) -> (Option<i32>, String) {
    run_with(Command::new(super::BIN), args)
}

/// Runs `command` (the binary, with limits or an environment of its own)
/// with `args`: its exit status and standard error.
pub fn run_with(mut command: Command, args: &[&str]) -> (Option<i32>, String) {
    let out = command
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("run the binary");
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Runs `args`, expecting failure with `needle` in the error and no file
/// left in `dir` besides those listed in `keep`.
pub fn refused(dir: &Path, keep: &[&str], args: &[&str], needle: &str) {
    refused_by(run(args), dir, keep, args, needle);
}

/// [`refused`] on the exit status and standard error of a run of `args`
/// (by [`run`] or [`run_with`]).
pub fn refused_by(
    (code, err): (Option<i32>, String),
    dir: &Path,
    keep: &[&str],
    args: &[&str],
    needle: &str,
) {
    assert_eq!(code, Some(1), "{args:?} should fail with status 1: {err}");
    assert!(
        err.starts_with("error: ") && err.contains(needle),
        "{args:?}: `{err}` should mention `{needle}`"
    );
    assert!(!err.contains("panicked"), "{args:?}: {err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{args:?}: {err}");
    let left: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| !keep.contains(&n.as_str()))
        .collect();
    assert!(left.is_empty(), "{args:?} left {left:?} behind");
}

/// `dir/name` as a string argument.
pub fn p(dir: &Path, name: &str) -> String {
    dir.join(name).to_string_lossy().into_owned()
}
