//! The Python environment of the validations against CasADi and Pinocchio
//! (`tests/common/casadi.rs`, `tests/pinocchio_validation.rs`).
//!
//! It lives in `target/casadi-venv` of the repository and is created on
//! first use from `tests/casadi/requirements.txt` (a one-time download; a
//! stamp file holding the requirements skips it afterwards). A validation
//! is skipped only when `python3` itself is missing, and fails even then
//! when the `CI` environment variable is set. A lock directory guards
//! against concurrent builds of the environment.

use std::io::{ErrorKind, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant, SystemTime};

const REQUIREMENTS: &str = "tests/casadi/requirements.txt";
const VENV: &str = "target/casadi-venv";
const STAMP: &str = "flexdyn-requirements.stamp";
/// A lock older than this is left over from a killed run.
const STALE_LOCK: Duration = Duration::from_secs(30 * 60);

pub fn output_text(out: &Output) -> String {
    format!(
        "--- stdout ---\n{}\n--- stderr ---\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

/// Run a command to completion, panicking with a clear message if it cannot start.
pub fn run(cmd: &mut Command, what: &str) -> Output {
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
/// missing or was built from other requirements. `None`: no `python3`
/// (`test` names the test that is then skipped).
pub fn test_python(repo: &Path, test: &str) -> Option<PathBuf> {
    match Command::new("python3").arg("--version").output() {
        Ok(out) if out.status.success() => {}
        Ok(out) => panic!("`python3 --version` failed:\n{}", output_text(&out)),
        Err(e) if e.kind() == ErrorKind::NotFound => {
            assert!(
                std::env::var_os("CI").is_none(),
                "python3 is not installed, and CI is set: {test} cannot be skipped in CI"
            );
            // Straight to the process's stderr, past the test harness's
            // capture, so that the skip is visible in a normal `cargo test`.
            let _ = writeln!(
                std::io::stderr(),
                "SKIPPED {test}: python3 is not installed; it did not run (set CI to make this a \
                 failure)"
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
            .args(["-c", "import casadi, numpy, pinocchio"])
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
