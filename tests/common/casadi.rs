//! The CasADi validation shared by the crates that compile scenes in (the
//! root's `tests/casadi_validation.rs` and the parallel-robot example's):
//! every generated term of every scene of a folder, validated against
//! CasADi's automatic differentiation by `tests/casadi/validate.py` (see
//! `docs/export-format.md`) through a binary's `export` and `eval`, plus
//! negative runs proving that a perturbed coefficient is caught.
//!
//! The Python environment lives in `target/casadi-venv` of the repository
//! and is created on first use from `tests/casadi/requirements.txt` (a
//! one-time download; a stamp file holding the requirements skips it
//! afterwards). The validation is skipped only when `python3` itself is
//! missing, and fails even then when the `CI` environment variable is set.
//! A lock directory guards against concurrent builds of the environment
//! (each crate's test runs everything in one test function).

use std::io::{ErrorKind, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant, SystemTime};

/// What one crate validates.
pub struct Suite {
    /// The repository root (holding `tests/casadi/` and `target/`).
    pub repo: PathBuf,
    /// The binary whose `export` and `eval` commands the script calls.
    pub binary: &'static str,
    /// The folder of the scenes compiled into that binary.
    pub scenes: PathBuf,
    /// The test-only builds the binary's `eval --perturbed` evaluates, with
    /// one emitted coefficient multiplied by 1 + 1e-6: (scene, the function
    /// holding it). The validation must fail on exactly that function's
    /// term: the fused `dynamics_terms` and every other function are emitted
    /// from their own programs and stay right.
    pub negative: &'static [(&'static str, &'static str)],
}

const REQUIREMENTS: &str = "tests/casadi/requirements.txt";
const SCRIPT: &str = "tests/casadi/validate.py";
const VENV: &str = "target/casadi-venv";
const STAMP: &str = "flexdyn-requirements.stamp";
/// A lock older than this is left over from a killed run.
const STALE_LOCK: Duration = Duration::from_secs(30 * 60);

fn output_text(out: &Output) -> String {
    format!(
        "--- stdout ---\n{}\n--- stderr ---\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

/// Run a command to completion, panicking with a clear message if it cannot start.
fn run(cmd: &mut Command, what: &str) -> Output {
    cmd.output()
        .unwrap_or_else(|e| panic!("{what}: cannot run {cmd:?}: {e}"))
}

/// Held while the virtual environment is checked or built.
struct Lock(PathBuf);

impl Lock {
    fn acquire(path: PathBuf) -> Lock {
        let start = Instant::now();
        let mut told = false;
        loop {
            match std::fs::create_dir(&path) {
                Ok(()) => return Lock(path),
                Err(e) if e.kind() == ErrorKind::AlreadyExists => {
                    let age = std::fs::metadata(&path)
                        .and_then(|m| m.modified())
                        .ok()
                        .and_then(|t| SystemTime::now().duration_since(t).ok());
                    if age.is_some_and(|a| a > STALE_LOCK) {
                        eprintln!("removing stale lock {}", path.display());
                        let _ = std::fs::remove_dir(&path);
                        continue;
                    }
                    assert!(
                        start.elapsed() < STALE_LOCK,
                        "timed out waiting for {} (another test run building the CasADi environment?)",
                        path.display()
                    );
                    if !told {
                        eprintln!("waiting for {} ...", path.display());
                        told = true;
                    }
                    std::thread::sleep(Duration::from_millis(500));
                }
                Err(e) => panic!("cannot create lock {}: {e}", path.display()),
            }
        }
    }
}

impl Drop for Lock {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir(&self.0);
    }
}

fn venv_python(venv: &Path) -> PathBuf {
    if cfg!(windows) {
        venv.join("Scripts").join("python.exe")
    } else {
        venv.join("bin").join("python")
    }
}

/// The virtual environment's interpreter, creating the environment if it is
/// missing or was built from other requirements. `None`: no `python3`.
fn casadi_python(repo: &Path) -> Option<PathBuf> {
    match Command::new("python3").arg("--version").output() {
        Ok(out) if out.status.success() => {}
        Ok(out) => panic!("`python3 --version` failed:\n{}", output_text(&out)),
        Err(e) if e.kind() == ErrorKind::NotFound => {
            assert!(
                std::env::var_os("CI").is_none(),
                "python3 is not installed, and CI is set: the CasADi validation cannot be skipped in CI"
            );
            // Straight to the process's stderr, past the test harness's
            // capture, so that the skip is visible in a normal `cargo test`.
            let _ = writeln!(
                std::io::stderr(),
                "SKIPPED casadi_validation: python3 is not installed; the CasADi validation of \
                 the generated terms did not run (set CI to make this a failure)"
            );
            return None;
        }
        Err(e) => panic!("cannot run python3: {e}"),
    }
    let root = repo;
    let requirements = root.join(REQUIREMENTS);
    let wanted = std::fs::read_to_string(&requirements)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", requirements.display()));
    let venv = root.join(VENV);
    std::fs::create_dir_all(venv.parent().expect("venv has a parent"))
        .unwrap_or_else(|e| panic!("cannot create target/: {e}"));
    let _lock = Lock::acquire(root.join(format!("{VENV}.lock")));
    let python = venv_python(&venv);
    let stamp = venv.join(STAMP);
    let up_to_date = std::fs::read_to_string(&stamp).is_ok_and(|s| s == wanted)
        && Command::new(&python)
            .args(["-c", "import casadi, numpy"])
            .output()
            .is_ok_and(|o| o.status.success());
    if up_to_date {
        return Some(python);
    }

    let start = Instant::now();
    eprintln!(
        "creating the CasADi environment {} from {REQUIREMENTS} (one-time)",
        venv.display()
    );
    let out = run(
        Command::new("python3")
            .args(["-m", "venv", "--clear"])
            .arg(&venv),
        "creating the virtual environment",
    );
    assert!(
        out.status.success(),
        "`python3 -m venv --clear {}` failed (on Debian/Ubuntu: install python3-venv):\n{}",
        venv.display(),
        output_text(&out)
    );
    let out = run(
        Command::new(&python)
            .args([
                "-m",
                "pip",
                "install",
                "--disable-pip-version-check",
                "--no-input",
                "-r",
            ])
            .arg(&requirements)
            .env("PIP_DISABLE_PIP_VERSION_CHECK", "1"),
        "installing the requirements",
    );
    assert!(
        out.status.success(),
        "pip install -r {REQUIREMENTS} into {} failed (network access to PyPI is needed once):\n{}",
        venv.display(),
        output_text(&out)
    );
    std::fs::write(&stamp, &wanted)
        .unwrap_or_else(|e| panic!("cannot write {}: {e}", stamp.display()));
    eprintln!(
        "CasADi environment ready in {:.1} s",
        start.elapsed().as_secs_f64()
    );
    Some(python)
}

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
    let Some(python) = casadi_python(&suite.repo) else {
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
    for &(scene, term) in suite.negative {
        let file = suite.scenes.join(format!("{scene}.toml"));
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
        let expected = format!("{scene}/{term}");
        let named = run.text.lines().any(|l| {
            let mut words = l.split_whitespace();
            words.next() == Some(term) && l.contains("FAIL")
        });
        let failed = run.report.as_ref().map(failed_terms);
        if run.code != Some(1)
            || !named
            || failed.as_deref() != Some(std::slice::from_ref(&expected))
        {
            problems.push(format!(
                "negative test: with a perturbed coefficient of {term} in {scene}, expected exit status 1 with \
                 exactly `{expected}` failing and its table row marked FAIL; got exit status {:?}, \
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
