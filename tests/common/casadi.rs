//! The CasADi validation shared by the crates that compile scenes in (the
//! root's `tests/casadi_validation.rs` and the parallel-robot example's):
//! every generated term of every scene of a folder, validated against
//! CasADi's automatic differentiation by `tests/casadi/validate.py` (see
//! `docs/export-format.md`) through a binary's `export` and `eval`, plus
//! negative runs proving that a perturbed coefficient is caught.
//!
//! The Python environment is the one of `python_env.rs` (which the test
//! crate including this file includes as `python_env`).

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use crate::python_env::{output_text, run, test_python};

/// What one crate validates.
pub struct Suite {
    /// The repository root (holding `tests/casadi/` and `target/`).
    pub repo: PathBuf,
    /// The binary whose `export` and `eval` commands the script calls.
    pub binary: &'static str,
    /// The folder of the scenes compiled into that binary.
    pub scenes: PathBuf,
    /// The test-only builds the binary's `eval --perturbed` evaluates, with
    /// one emitted coefficient multiplied by 1 + 1e-6: (the scene file,
    /// relative to `repo`; the terms it makes wrong, as the script's table
    /// names them: the function's, or a marker's `markers.<name>.<term>`,
    /// first the one holding the coefficient). The validation must fail on
    /// exactly those terms: the fused `dynamics_terms` and every other
    /// function are emitted from their own programs and stay right.
    pub negative: &'static [(&'static str, &'static [&'static str])],
}

const SCRIPT: &str = "tests/casadi/validate.py";

/// Every scene file in `dir`, sorted.
fn scene_files(dir: &Path) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", dir.display()))
        .map(|e| e.expect("readable directory entry").path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    files.sort();
    assert!(!files.is_empty(), "no scenes in {}", dir.display());
    files
}

/// One run of the script: its exit code, output, and JSON report (if written).
struct Run {
    code: Option<i32>,
    text: String,
    report: Option<serde_json::Value>,
}

fn validate(suite: &Suite, python: &Path, scenes: &[PathBuf], extra: &[String]) -> Run {
    let dir = tempfile::tempdir().expect("temporary directory");
    let report_path = dir.path().join("report.json");
    let out = run(
        Command::new(python)
            .current_dir(&suite.repo)
            .arg(suite.repo.join(SCRIPT))
            .arg("--flexdyn")
            .arg(suite.binary)
            .arg("--json-report")
            .arg(&report_path)
            .args(extra)
            .arg("--scenes")
            .args(scenes)
            .env("PYTHONDONTWRITEBYTECODE", "1"),
        "running the CasADi validation",
    );
    let report = std::fs::read_to_string(&report_path)
        .ok()
        .map(|s| serde_json::from_str(&s).unwrap_or_else(|e| panic!("bad JSON report: {e}\n{s}")));
    Run {
        code: out.status.code(),
        text: output_text(&out),
        report,
    }
}

fn failed_terms(report: &serde_json::Value) -> Vec<String> {
    report["failed"]
        .as_array()
        .expect("report lists failed terms")
        .iter()
        .map(|v| v.as_str().expect("term name").to_owned())
        .collect()
}

/// Validate every term of every scene of `suite.scenes` with `suite.binary`,
/// then its negative runs; panics listing every problem.
pub fn validate_every_scene(suite: &Suite) {
    let Some(python) = test_python(&suite.repo, "casadi_validation") else {
        return;
    };
    let scenes = scene_files(&suite.scenes);
    let start = Instant::now();
    let mut problems = Vec::new();

    // (a) Every scene, every term, unperturbed.
    let full = validate(suite, &python, &scenes, &[]);
    println!("{}", full.text);
    if full.code != Some(0) {
        problems.push(format!(
            "the CasADi validation of {} scene(s) failed (exit status {:?}); see the table above",
            scenes.len(),
            full.code
        ));
    }

    // (b) A wrong emitted coefficient must be caught, and named.
    for &(path, terms) in suite.negative {
        let term = terms[0];
        let file = suite.repo.join(path);
        let scene = file
            .file_stem()
            .unwrap_or_default()
            .to_string_lossy()
            .into_owned();
        if !file.is_file() {
            problems.push(format!(
                "negative test: {} is missing; update NEGATIVE",
                file.display()
            ));
            continue;
        }
        let run = validate(
            suite,
            &python,
            &[file],
            &["--states".into(), "50".into(), "--perturbed".into()],
        );
        println!("negative test, perturbed {term} of {scene}:\n{}", run.text);
        let mut expected: Vec<String> = terms.iter().map(|t| format!("{scene}/{t}")).collect();
        expected.sort();
        let named = run.text.lines().any(|l| {
            let mut words = l.split_whitespace();
            words.next() == Some(term) && l.contains("FAIL")
        });
        let mut failed = run.report.as_ref().map(failed_terms);
        if let Some(f) = failed.as_mut() {
            f.sort();
        }
        if run.code != Some(1) || !named || failed.as_ref() != Some(&expected) {
            problems.push(format!(
                "negative test: with a perturbed coefficient of {term} in {scene}, expected exit status 1 with \
                 exactly {expected:?} failing and its table row marked FAIL; got exit status {:?}, \
                 failed terms {failed:?}, row marked FAIL: {named}",
                run.code
            ));
        }
    }

    println!(
        "CasADi validation: {} scene(s) and {} negative run(s) in {:.1} s",
        scenes.len(),
        suite.negative.len(),
        start.elapsed().as_secs_f64()
    );
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}
