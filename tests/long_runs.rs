//! Long runs of `simulate` and `inverse`: step counts beyond `--max-steps`
//! (10^7 unless given) refused at once with bounded memory, never a panic
//! or an endless run (the reproducers of D02 and D03); `--max-steps`
//! raising the limit; rows streamed to the CSV (the text the table in
//! memory gives, the same through a device, nothing left by a run that
//! fails after writing rows, memory independent of the number of rows);
//! progress lines on a piped stderr (`FLEXDYN_PROGRESS_INTERVAL`), none
//! with `--quiet`.
//!
//! The runs have their address space limited ([`limited`]): a command that
//! kept every row in memory would abort.

#[path = "common/cli.rs"]
mod cli;
#[path = "common/limits.rs"]
mod limits;

use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use cli::{p, refused, refused_by, run, run_with};
use flexdyn::table::Table;

const BIN: &str = env!("CARGO_BIN_EXE_flexdyn");

/// A pendulum swinging from 1 rad (the D03 reproducer's scene).
const SWINGING: &str = r#"
name = "swinging"
[parameters]
m = 1.0
l = 0.5
[[coordinates]]
name = "theta"
initial = 1.0
[[components]]
name = "bob"
type = "point_mass"
mass = "m"
position = ["l*sin(theta)", 0, "-l*cos(theta)"]
[[actuators]]
name = "tau"
coordinate = "theta"
"#;

/// The most address space a run here may take: the binary streaming any
/// number of rows needs less than half of it; keeping 5 10^5 rows of a
/// pendulum in memory (as the commands did) needs more.
const SMALL: u64 = 48 << 20;

/// Seconds of processor and of wall-clock time a run here may take (the
/// longest needs ~3).
const SECONDS: u64 = 30;

/// The binary, its address space limited to [`SMALL`] (an allocation
/// beyond fails: the run aborts) and its time to [`SECONDS`] (an endless
/// or stuck run is killed).
fn limited() -> Command {
    limits::limited(BIN, SMALL, SECONDS)
}

fn swinging(dir: &Path) -> String {
    let path = dir.join("swinging.toml");
    std::fs::write(&path, SWINGING).unwrap();
    path.to_string_lossy().into_owned()
}

/// `args` refused at once, naming every one of `needles`, leaving nothing
/// in `dir` but the scene, within [`SMALL`] memory.
fn refused_at_once(dir: &Path, args: &[&str], needles: &[&str]) {
    let start = Instant::now();
    let result = run_with(limited(), args);
    refused_by(result, dir, &["swinging.toml"], args, needles[0]);
    assert!(
        start.elapsed() < Duration::from_secs(5),
        "{args:?} took {:?}",
        start.elapsed()
    );
    let (_, err) = run(args);
    for n in needles {
        assert!(err.contains(n), "{args:?}: `{err}` should mention `{n}`");
    }
}

#[test]
fn step_counts_beyond_the_limit_are_refused_at_once_naming_the_limit() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (scene, csv) = (swinging(d), p(d, "out.csv"));
    let inverse = ["inverse", "--scene", &scene, "--prescribe", "theta=sin(t)"];
    // D02: a panic (capacity overflow), an abort (an 800 TB allocation),
    // 8 GB of output times before the first step.
    for (duration, dt, shown) in [
        (
            "1",
            "1e-300",
            "--duration 1 s at --dt 1e-300 s is 1.000e300 steps",
        ),
        (
            "1e12",
            "0.01",
            "--duration 1e12 s at --dt 0.01 s is 1.000e14 steps",
        ),
        (
            "1e7",
            "0.01",
            "--duration 10000000 s at --dt 0.01 s is 1.000e9 steps",
        ),
    ] {
        let mut args = inverse.to_vec();
        args.extend(["--duration", duration, "--dt", dt, "--csv", &csv]);
        refused_at_once(d, &args, &[shown, "at most 10000000", "--max-steps N"]);
    }
    // D03: rows kept in memory without end (3.8 GB after 30 s).
    for (extra, shown) in [
        (&["--dt", "1e-300"][..], "is 1.000e300 steps"),
        (
            &[][..],
            "--duration 1e12 s at --dt 0.01 s is 1.000e14 steps",
        ),
    ] {
        let duration = if extra.is_empty() { "1e12" } else { "1" };
        let mut args = vec!["simulate", "--scene", &scene, "--duration", duration];
        args.extend(extra);
        args.extend(["--csv", &csv]);
        refused_at_once(d, &args, &[shown, "at most 10000000", "--max-steps N"]);
    }
    // Zero, negative, non-finite steps and durations name the option.
    for (duration, dt, needle) in [
        ("1", "0", "--dt: the step must be a positive number"),
        ("1", "inf", "--dt: the step must be a positive number"),
        ("NaN", "0.1", "--duration: the duration must be a"),
    ] {
        let times = ["--duration", duration, "--dt", dt, "--csv", &csv];
        let simulate = [&["simulate", "--scene", &scene][..], &times].concat();
        refused_at_once(d, &simulate, &[needle]);
        let inverse = [&inverse[..], &times].concat();
        refused_at_once(d, &inverse, &[needle]);
    }
}

#[test]
fn max_steps_raises_the_limit() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (scene, csv) = (swinging(d), p(d, "out.csv"));
    for command in ["simulate", "inverse"] {
        let mut args = vec![
            command,
            "--scene",
            &scene,
            "--duration",
            "1",
            "--dt",
            "1e-3",
        ];
        if command == "inverse" {
            args.extend(["--prescribe", "theta=sin(t)"]);
        }
        args.extend(["--csv", &csv, "--quiet", "--max-steps"]);
        refused_at_once(
            d,
            &[&args[..], &["999"]].concat(),
            &["is 1.000e3 steps; at most 999 are allowed"],
        );
        let (code, err) = run(&[&args[..], &["1000"]].concat());
        assert_eq!((code, err.as_str()), (Some(0), ""), "{command}");
        let table = Table::read(Path::new(&csv)).unwrap();
        assert_eq!(table.rows.len(), 1001, "{command}");
        std::fs::remove_file(&csv).unwrap();
    }
}

#[test]
fn adaptive_steps_beyond_the_limit_stop_the_run_naming_the_time_and_leave_no_file() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (scene, csv) = (swinging(d), p(d, "out.csv"));
    // 20000 output steps are allowed; adaptive RK4 takes ~50 steps a second
    // of the swing: past the limit after ~1000 s and ~2000 rows (more
    // than the writer buffers: the temporary file had rows).
    let args = [
        "simulate",
        "--scene",
        &scene,
        "--duration",
        "10000",
        "--dt",
        "0.5",
        "--csv",
        &csv,
        "--quiet",
        "--max-steps",
        "50000",
    ];
    refused_at_once(
        d,
        &args,
        &[
            "adaptive-rk4 took 50",
            "steps to reach t = ",
            "s of 10000 s, more than --max-steps 50000",
        ],
    );
    // An existing output is left as it was.
    std::fs::write(&csv, "old\n").unwrap();
    let (code, _) = run(&args);
    assert_eq!(code, Some(1));
    assert_eq!(std::fs::read_to_string(&csv).unwrap(), "old\n");
}

#[test]
fn an_inverse_run_failing_after_many_rows_leaves_no_file() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(
        d.join("s.json"),
        r#"{"q": [0.8, 0.2, 0.35], "qd": [0, 0, 0]}"#,
    )
    .unwrap();
    let (start, csv) = (p(d, "s.json"), p(d, "out.csv"));
    // The slider pushed beyond the reach of crank and rod (0.4 m) at
    // t = 0.1 s, after 10^4 rows.
    refused(
        d,
        &["s.json"],
        &[
            "inverse",
            "--scene",
            "scenes/slider_crank.toml",
            "--prescribe",
            "x=0.3+t",
            "--initial",
            &start,
            "--duration",
            "1",
            "--dt",
            "1e-5",
            "--csv",
            &csv,
        ],
        "at t = 0.1",
    );
}

/// Runs `args` with `extra_env`, [`limited`]: exit status, stdout, stderr.
fn output(args: &[&str], extra_env: &[(&str, &str)]) -> (Option<i32>, Vec<u8>, String) {
    let out = limited()
        .args(args)
        .envs(extra_env.iter().copied())
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    (out.status.code(), out.stdout, err)
}

#[test]
fn long_runs_stream_the_same_csv_with_bounded_memory() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (scene, csv) = (swinging(d), p(d, "out.csv"));
    // 5 10^5 rows: 18 MB of CSV; as a table in memory (the rows, then
    // their text) they took more than [`SMALL`].
    let base = [
        "simulate",
        "--scene",
        &scene,
        "--duration",
        "5",
        "--dt",
        "1e-5",
        "--integrator",
        "rk4",
        "--quiet",
    ];
    let (code, _, err) = output(&[&base[..], &["--csv", &csv]].concat(), &[]);
    assert_eq!(code, Some(0), "{err}");
    let text = std::fs::read_to_string(&csv).unwrap();
    let table = Table::parse(&text).unwrap();
    assert_eq!(table.rows.len(), 500_001);
    // The text of the table in memory, as the command wrote it before it
    // streamed; the last row at the end of the run.
    assert!(
        text == table.to_csv(),
        "the streamed CSV is not Table::to_csv"
    );
    assert_eq!(table.rows.last().unwrap()[0], 5.0);
    // Written through a device, as it comes: the same bytes.
    let (code, stdout, err) = output(&[&base[..], &["--csv", "/dev/stdout"]].concat(), &[]);
    assert_eq!(code, Some(0), "{err}");
    assert!(stdout == text.as_bytes(), "/dev/stdout got other bytes");
    // A plot of the run keeps at most 4096 rows and the last: it is drawn.
    let plot = p(d, "p.svg");
    let (code, _, err) = output(
        &[&base[..], &["--csv", &csv, "--plot", &plot]].concat(),
        &[],
    );
    assert_eq!(code, Some(0), "{err}");
    let svg = std::fs::read_to_string(&plot).unwrap();
    assert!(
        svg.contains("<polyline") || svg.contains("<path"),
        "no curve"
    );
}

#[test]
fn progress_lines_appear_on_a_piped_stderr_unless_quiet() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (scene, csv) = (swinging(d), p(d, "out.csv"));
    let every = [("FLEXDYN_PROGRESS_INTERVAL", "0.02")];
    // 2 10^5 steps: well over 0.02 s.
    let simulate = [
        "simulate",
        "--scene",
        &scene,
        "--duration",
        "2",
        "--dt",
        "1e-5",
        "--integrator",
        "rk4",
        "--csv",
        &csv,
    ];
    let inverse = [
        "inverse",
        "--scene",
        &scene,
        "--prescribe",
        "theta=sin(t)",
        "--duration",
        "2",
        "--dt",
        "1e-5",
        "--csv",
        &csv,
    ];
    for (args, line) in [
        (&simulate[..], "simulate: t = "),
        (&inverse[..], "inverse: t = "),
    ] {
        let (code, _, err) = output(args, &every);
        assert_eq!(code, Some(0), "{err}");
        let lines: Vec<&str> = err.lines().filter(|l| l.starts_with(line)).collect();
        assert!(!lines.is_empty(), "no progress line in: {err}");
        assert!(
            lines.iter().all(|l| l.contains(" s of 2 s (")
                && l.contains("steps, ")
                && l.ends_with("s elapsed")),
            "{lines:?}"
        );
        let (code, _, err) = output(&[args, &["--quiet"]].concat(), &every);
        assert_eq!((code, err.as_str()), (Some(0), ""));
    }
}
