//! Issue 7: `parallel-robot report` end to end (its quick study), checked against
//! what the numerics must show whatever the machine: generalized-alpha's
//! second-order convergence towards the reference, the explicit scheme's
//! refusal on the stiff elastic modes, a rigid model whose path error is the
//! flexible one's static sag, and a page that names every run and writes its
//! plots. No timing is asserted.

use std::path::Path;
use std::process::Command;

/// One row of `runs.csv`.
#[derive(Debug)]
struct Run {
    study: String,
    scene: String,
    integrator: String,
    dt: f64,
    error: Option<f64>,
    failure: String,
}

fn runs(csv: &str) -> Vec<Run> {
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    let col = |name: &str| header.iter().position(|c| *c == name).expect(name);
    let (study, scene, integ, dt, error, failure) = (
        col("study"),
        col("scene"),
        col("integrator"),
        col("dt"),
        col("error"),
        col("failure"),
    );
    lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            assert_eq!(f.len(), header.len(), "row `{l}`");
            Run {
                study: f[study].into(),
                scene: f[scene].into(),
                integrator: f[integ].into(),
                dt: f[dt].parse().expect("dt"),
                error: f[error].parse().ok(),
                failure: f[failure].into(),
            }
        })
        .collect()
}

#[test]
fn quick_report_shows_convergence_refusals_and_every_run() {
    let dir = tempfile::tempdir().unwrap();
    let page = dir.path().join("perf.md");
    let out = Command::new(env!("CARGO_BIN_EXE_parallel-robot"))
        .args(["report", "--quick", "--quiet", "--out"])
        .arg(&page)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("run flexdyn");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let folder = dir.path().join("perf");
    let text = std::fs::read_to_string(folder.join("runs.csv")).expect("runs.csv");
    let runs = runs(&text);
    let find = |study: &str, scene: &str, integ: &str, dt: f64| {
        runs.iter()
            .find(|r| {
                r.study == study
                    && r.scene == scene
                    && r.integrator == integ
                    && (r.dt - dt).abs() < 1e-12
            })
            .unwrap_or_else(|| panic!("no run {study} {scene} {integ} {dt}"))
    };

    // Generalized-alpha is second-order accurate: halving the step divides
    // the full model's distance from its own fine reference by about four.
    let full = "parallel_robot_flexible";
    let e = |dt| find("forward", full, "gen-alpha", dt).error.expect("ran");
    let (e1, e2, e4) = (e(0.0025), e(0.005), e(0.01));
    for (coarse, fine) in [(e2, e1), (e4, e2)] {
        let ratio = coarse / fine;
        assert!(
            (2.5..6.5).contains(&ratio),
            "order check: {coarse:e} / {fine:e} = {ratio}"
        );
    }

    // RK4 cannot step the elastic modes (kHz) at these steps: refused, not NaN.
    for dt in [0.0025, 0.005, 0.01] {
        let r = find("forward", full, "rk4", dt);
        assert!(r.error.is_none(), "{r:?}");
        assert!(r.failure.contains("too large"), "{r:?}");
    }

    // The rigid model lacks the six joint members (6 x 0.07 kg): its path
    // sits higher than the flexible reference by their weight over the PD
    // loop's stiffness, a tenth of a millimetre or more, whatever the step;
    // the flexible model with one mode per link is far closer.
    let rigid = find("forward", "parallel_robot_rigid", "rk4", 0.005)
        .error
        .unwrap();
    let m1 = find("forward", "parallel_robot_flexible_m1", "gen-alpha", 0.005)
        .error
        .unwrap();
    assert!(
        (5e-5..1e-3).contains(&rigid),
        "rigid path error {rigid:e} m"
    );
    assert!(
        m1 < rigid / 10.0,
        "1-mode error {m1:e} m against rigid {rigid:e} m"
    );

    // Every run is on the page, and the plots were drawn.
    let md = std::fs::read_to_string(&page).expect("page");
    let table_rows = md
        .lines()
        .filter(|l| l.starts_with("| `parallel_robot"))
        .count();
    assert_eq!(table_rows, runs.len(), "one table row per run");
    assert!(md.contains("Cheapest under 0.1 mm"), "{md}");
    assert!(md.contains("Pareto front"), "{md}");
    for png in ["pareto_path.png", "pareto_torque.png"] {
        let bytes = std::fs::read(folder.join(png)).expect(png);
        assert!(
            bytes.starts_with(b"\x89PNG") && bytes.len() > 10_000,
            "{png}"
        );
    }
    assert!(Path::new(&page).is_file());
}

#[test]
fn report_rejects_bad_repeats_without_writing() {
    let dir = tempfile::tempdir().unwrap();
    let page = dir.path().join("perf.md");
    let out = Command::new(env!("CARGO_BIN_EXE_parallel-robot"))
        .args(["report", "--quick", "--quiet", "--repeats", "0", "--out"])
        .arg(&page)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("run flexdyn");
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--repeats"));
    assert_eq!(
        std::fs::read_dir(dir.path()).unwrap().count(),
        0,
        "nothing written"
    );
}
