//! `flexdyn simulate` says when its answer is not to be trusted: every run's
//! error estimate (a companion run at twice the step, or 16 times the
//! tolerance) is compared with the true error, measured against a reference
//! run of the same scene far finer; steps too large for the accuracy give a
//! warning with a step that would do, steps near the stability limit a
//! warning that the companion failed. The integrators' options are refused
//! where the chosen integrator would ignore them, `--output-dt` thins the
//! rows without changing them, and `--rho-inf` and `--max-sweeps` reach the
//! integrators.

use std::path::{Path, PathBuf};
use std::process::Command;

use flexdyn::table::Table;

#[path = "common/cli.rs"]
mod cli;
use cli::{p, refused};

const BIN: &str = env!("CARGO_BIN_EXE_flexdyn");

fn pendulum() -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("scenes/pendulum.toml")
        .to_string_lossy()
        .into_owned()
}

/// A state file starting the pendulum at 1 rad, at rest.
fn swung(dir: &Path) -> PathBuf {
    let path = dir.join("swung.json");
    std::fs::write(&path, r#"{"q": [1.0], "qd": [0.0], "t": 0}"#).unwrap();
    path
}

/// `simulate` of the swung pendulum for 5 s with `args`: the rows and
/// stderr.
fn run(dir: &Path, args: &[&str]) -> (Table, String) {
    let csv = dir.join("out.csv");
    let out = Command::new(BIN)
        .args(["simulate", "--scene", &pendulum(), "--duration", "5"])
        .arg("--initial")
        .arg(swung(dir))
        .args(args)
        .arg("--csv")
        .arg(&csv)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{args:?}: {stderr}");
    (Table::read(&csv).unwrap(), stderr)
}

/// The estimate `simulate` printed: its figure and quantity.
fn estimate(stderr: &str) -> (f64, String) {
    let line = stderr
        .lines()
        .find(|l| l.starts_with("error estimate"))
        .unwrap_or_else(|| panic!("no estimate in {stderr}"));
    let figure = line.split("largest ").nth(1).unwrap();
    let (value, rest) = figure.split_once(' ').unwrap();
    let name = rest.split('`').nth(1).unwrap().to_string();
    (value.parse().unwrap(), name)
}

/// The largest difference of column `name` between `run` and `reference`
/// at the times of `run` (every row of `run` is a row of `reference`),
/// relative to the largest magnitude of the column in `reference`.
fn true_error(run: &Table, reference: &Table, name: &str) -> f64 {
    let (t, r) = (
        reference.column("t").unwrap(),
        reference.column(name).unwrap(),
    );
    let scale = r.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let mut worst = 0.0f64;
    for (s, v) in run
        .column("t")
        .unwrap()
        .iter()
        .zip(run.column(name).unwrap())
    {
        let k = t.partition_point(|x| *x < s - 1e-9);
        assert!((t[k] - s).abs() < 1e-9, "no reference row at {s}");
        worst = worst.max((v - r[k]).abs());
    }
    worst / scale
}

#[test]
fn estimates_track_the_true_error_and_warn_when_it_is_large() {
    let dir = tempfile::tempdir().unwrap();
    // Reference: RK4 at 0.1 ms (error ~1e-12 of the swing), rows every 2 ms.
    let (reference, _) = run(
        dir.path(),
        &[
            "--integrator",
            "rk4",
            "--dt",
            "1e-4",
            "--output-dt",
            "0.002",
            "--quiet",
        ],
    );
    // (integrator, step, warned): the estimate must be within a factor 3
    // of the true error of the quantity it names (the adaptive one, whose
    // factor is chosen conservatively, within a factor 10 above it).
    let cases: [(&[&str], bool); 7] = [
        (&["--integrator", "rk4", "--dt", "0.01"], false),
        (&["--integrator", "rk4", "--dt", "0.2"], true),
        (
            &["--integrator", "semi-implicit-euler", "--dt", "0.01"],
            true,
        ),
        (&["--integrator", "gen-alpha", "--dt", "0.01"], true),
        (&["--integrator", "gen-alpha", "--dt", "0.002"], false),
        (&["--integrator", "gauss-legendre", "--dt", "0.05"], false),
        (&["--dt", "0.1", "--tolerance", "1e-3"], false),
    ];
    for (args, warned) in cases {
        let (table, stderr) = run(dir.path(), args);
        let (estimated, name) = estimate(&stderr);
        let actual = true_error(&table, &reference, &name);
        println!("{args:?}: estimated {estimated:e} of `{name}`, actual {actual:e}");
        let adaptive = !args.contains(&"--integrator");
        let (below, above) = if adaptive { (1.0, 10.0) } else { (3.0, 3.0) };
        assert!(
            estimated > actual / below && estimated < actual * above,
            "{args:?}: estimated {estimated:e}, actual {actual:e}: {stderr}"
        );
        assert_eq!(
            stderr.contains("warning: the estimated error"),
            warned,
            "{args:?}: {stderr}"
        );
        if warned {
            // The advised step brings the error near 1e-4: below 1e-3.
            let step = stderr
                .split("; --dt ")
                .nth(1)
                .unwrap()
                .split(' ')
                .next()
                .unwrap();
            let integrator = &args[..2];
            let (_, stderr) = run(dir.path(), &[integrator, &["--dt", step]].concat());
            let (estimated, _) = estimate(&stderr);
            assert!(estimated < 1e-3, "{args:?} at the advised {step}: {stderr}");
            assert!(!stderr.contains("warning"), "{stderr}");
        }
    }
}

#[test]
fn a_step_near_the_stability_limit_is_a_warning() {
    let dir = tempfile::tempdir().unwrap();
    // The swung pendulum's RK4 limit is near 0.63 s: 0.5 s runs, its
    // companion at 1 s does not.
    let (table, stderr) = run(dir.path(), &["--integrator", "rk4", "--dt", "0.5"]);
    assert_eq!(table.column("t").unwrap().len(), 11);
    assert!(
        stderr.contains("warning: the error estimate's companion run (at 2 x --dt = 1 s) failed")
            && stderr.contains("too large for the explicit scheme"),
        "{stderr}"
    );
    // --quiet: no estimate, nothing printed.
    let (_, stderr) = run(
        dir.path(),
        &["--integrator", "rk4", "--dt", "0.5", "--quiet"],
    );
    assert!(stderr.is_empty(), "{stderr}");
    let (_, stderr) = run(
        dir.path(),
        &["--integrator", "rk4", "--dt", "0.5", "--no-error-estimate"],
    );
    assert!(!stderr.contains("estimate"), "{stderr}");
}

#[test]
fn output_dt_thins_the_rows_of_the_same_run() {
    let dir = tempfile::tempdir().unwrap();
    for integrator in ["rk4", "gen-alpha", "semi-implicit-euler", "gauss-legendre"] {
        let every = ["--integrator", integrator, "--dt", "0.001", "--quiet"];
        let (all, _) = run(dir.path(), &every);
        let (thin, _) = run(dir.path(), &[&every[..], &["--output-dt", "0.01"]].concat());
        assert_eq!(thin.column("t").unwrap().len(), 501);
        for name in ["t", "theta", "theta_dot"] {
            let a = all.column(name).unwrap();
            let kept: Vec<f64> = a.iter().step_by(10).copied().collect();
            assert_eq!(thin.column(name).unwrap(), kept, "{integrator} {name}");
        }
    }
    // Adaptive RK4 takes --output-dt as its output step.
    let (a, _) = run(dir.path(), &["--output-dt", "0.25", "--quiet"]);
    let (b, _) = run(dir.path(), &["--dt", "0.25", "--quiet"]);
    assert_eq!(a.column("theta").unwrap(), b.column("theta").unwrap());
    assert_eq!(a.column("t").unwrap().len(), 21);
}

#[test]
fn rho_inf_and_max_sweeps_reach_the_integrators() {
    let dir = tempfile::tempdir().unwrap();
    let energy = |t: &Table| {
        let e: Vec<f64> = t
            .column("T")
            .unwrap()
            .iter()
            .zip(t.column("V").unwrap())
            .map(|(a, b)| a + b)
            .collect();
        e.iter().fold(0.0f64, |m, x| m.max((x - e[0]).abs()))
    };
    let base = ["--integrator", "gen-alpha", "--dt", "0.05", "--quiet"];
    let (trapezoidal, _) = run(dir.path(), &[&base[..], &["--rho-inf", "1"]].concat());
    let (damped, _) = run(dir.path(), &[&base[..], &["--rho-inf", "0"]].concat());
    // rho_inf = 1 is the trapezoidal rule: energy kept to its (w dt)^2 / 12
    // of the swing's energy (w = 3.1 rad/s, 4.9 J); rho_inf = 0 dissipates.
    let bound = 0.05f64.powi(2) * 9.81 / 12.0 * 4.9;
    println!(
        "energy change: rho_inf 1 {:e}, 0 {:e} (bound {bound:e})",
        energy(&trapezoidal),
        energy(&damped)
    );
    assert!(energy(&trapezoidal) < bound);
    assert!(energy(&damped) > 10.0 * energy(&trapezoidal));
    // One sweep cannot converge Gauss-Legendre's stages: the step fails,
    // naming the stage iteration; the default converges.
    let gl = ["--integrator", "gauss-legendre", "--dt", "0.05", "--quiet"];
    run(dir.path(), &gl);
    let (scene, start, csv) = (
        pendulum(),
        p(dir.path(), "swung.json"),
        p(dir.path(), "gl.csv"),
    );
    let args = [
        &[
            "simulate",
            "--scene",
            &scene,
            "--duration",
            "1",
            "--initial",
            &start,
        ][..],
        &["--csv", &csv, "--max-sweeps", "1"],
        &gl[..],
    ]
    .concat();
    refused(
        dir.path(),
        &["swung.json", "out.csv"],
        &args,
        "stage iteration",
    );
}

#[test]
fn options_an_integrator_would_ignore_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let csv = p(dir.path(), "x.csv");
    let pendulum = pendulum();
    let base = [
        "simulate",
        "--scene",
        &pendulum,
        "--duration",
        "1",
        "--csv",
        &csv,
    ];
    for (args, needle) in [
        (
            &["--integrator", "rk4", "--tolerance", "1e-6"][..],
            "--tolerance is adaptive-rk4's error control",
        ),
        (
            &["--integrator", "gen-alpha", "--max-sweeps", "5"],
            "--max-sweeps is gauss-legendre's",
        ),
        (
            &["--integrator", "gauss-legendre", "--rho-inf", "0.5"],
            "--rho-inf is gen-alpha's",
        ),
        (&["--rho-inf", "0.5"], "`adaptive-rk4` would ignore it"),
        (
            &["--integrator", "gen-alpha", "--rho-inf", "1.5"],
            "--rho-inf must lie in [0, 1]",
        ),
        (
            &["--integrator", "gauss-legendre", "--max-sweeps", "0"],
            "--max-sweeps must lie in 1..=1000",
        ),
        (
            &["--dt", "0.01", "--output-dt", "0.1"],
            "give --output-dt or --dt, not both",
        ),
        (
            &[
                "--integrator",
                "rk4",
                "--dt",
                "0.01",
                "--output-dt",
                "0.015",
            ],
            "--output-dt 0.015 s must be a whole multiple of --dt 0.01 s",
        ),
        (
            &["--integrator", "rk4", "--output-dt", "0"],
            "--output-dt: the step must be a positive",
        ),
    ] {
        refused(dir.path(), &[], &[&base[..], args].concat(), needle);
    }
}
