//! Command-line misuse of `parallel-robot inverse` and `simulate`: every bad
//! invocation fails with a non-zero exit status and a clear one-line error
//! on stderr (no panic, no usage dump for a value that parsed), and leaves
//! no output file behind, partial or complete. (tests/robot_cli.rs covers
//! the commands' first cases.)

#[path = "../../../tests/common/cli.rs"]
mod cli;

use cli::{p, refused};

const BIN: &str = env!("CARGO_BIN_EXE_parallel-robot");
const ROBOT: &str = "scenes/parallel_robot_rigid.toml";

#[test]
fn inverse_refuses_bad_numbers_and_leaves_no_partial_output() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let csv = p(d, "tau.csv");
    let base = ["inverse", "--scene", ROBOT, "--quiet", "--csv", &csv];
    let cases: [(&[&str], &str); 10] = [
        (&["--dt", "NaN"], "step must be a positive number"),
        (&["--dt=-inf"], "step must be a positive number"),
        (&["--dt", "1e-320"], "at most"),
        (
            &["--duration", "NaN"],
            "duration must be a non-negative number",
        ),
        (
            &["--duration", "inf"],
            "duration must be a non-negative number",
        ),
        (
            &["--duration", "-1"],
            "duration must be a non-negative number",
        ),
        (&["--omega", "NaN"], "--omega must be finite"),
        (&["--radius", "-0.1"], "--radius finite and non-negative"),
        (&["--center", "0,0"], "--center must be three numbers"),
        (&["--center", "0,0,inf"], "--center must be three numbers"),
    ];
    for (extra, needle) in cases {
        let args: Vec<&str> = base.iter().chain(extra).copied().collect();
        refused(d, &[], &args, needle);
    }
    // The plot fails after the table is computed: the CSV, which could be
    // written, is not left behind either.
    refused(
        d,
        &[],
        &[
            "inverse",
            "--scene",
            ROBOT,
            "--duration",
            "0.1",
            "--quiet",
            "--csv",
            &csv,
            "--plot",
            &p(d, "no/plot.png"),
        ],
        "no/plot.png: directory",
    );
    refused(
        d,
        &[],
        &[
            "inverse",
            "--scene",
            ROBOT,
            "--duration",
            "0.1",
            "--quiet",
            "--csv",
            &csv,
            "--plot",
            &p(d, "plot.gif"),
        ],
        ".png or .svg",
    );
    // An output path that is a directory.
    refused(
        d,
        &[],
        &[
            "inverse",
            "--scene",
            ROBOT,
            "--duration",
            "0.1",
            "--quiet",
            "--csv",
            d.to_str().unwrap(),
        ],
        "is a directory",
    );
    // And the same command succeeds once the paths are right, writing both.
    let plot = p(d, "plot.svg");
    let (code, err) = cli::run(&[
        "inverse",
        "--scene",
        ROBOT,
        "--duration",
        "0.1",
        "--quiet",
        "--csv",
        &csv,
        "--plot",
        &plot,
    ]);
    assert_eq!(code, Some(0), "{err}");
    let mut names: Vec<String> = std::fs::read_dir(d)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(names, ["plot.svg", "tau.csv"]);
}

#[test]
fn simulate_refuses_unreadable_or_wrong_torque_tables_and_bad_steps() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let table = p(d, "tq.csv");
    let out = p(d, "sim.csv");
    let good = "t,tau_1,tau_2,tau_3,px,py,pz\n0,1,1,1,0.1,0,0.7\n0.01,1,1,1,0.1,0,0.7\n";
    let sim = [
        "simulate",
        "--scene",
        ROBOT,
        "--torques",
        &table,
        "--csv",
        &out,
        "--quiet",
    ];
    refused(d, &[], &sim, "cannot read");
    let tables: [(&[u8], &str); 8] = [
        (b"\x89PNG\r\n\x1a\n\x00\x00", "cannot read"),
        (b"", "empty file"),
        (b"t,tau_1,tau_2,tau_3,px,py,pz\n", "no rows"),
        (b"time,tau1,tau2,tau3\n0,1,1,1\n", "no column `t`"),
        (
            b"t,tau_1,tau_2,tau_3,px,py,pz\n0,1,NaN,1,0.1,0,0.7\n",
            "column `tau_2`: `NaN` is not a finite number",
        ),
        (
            b"t,tau_1,tau_2,tau_3,px,py,pz\n0,1,1,1,0.1,0,0.7\n0.1,1,1\n",
            ":3: expected 7 values",
        ),
        (
            b"t,tau_1,tau_2,tau_3,px,py,pz\n0,1,1,1,0.1,0,0.7\n-1,1,1,1,0.1,0,0.7\n",
            "increase strictly",
        ),
        (
            b"t,tau_1,tau_2,tau_3,px,py,pz\n0,1,1,1,5,0,0.7\n",
            "out of reach",
        ),
    ];
    for (text, needle) in tables {
        std::fs::write(&table, text).unwrap();
        refused(d, &["tq.csv"], &sim, needle);
    }
    // A directory given as the table.
    refused(
        d,
        &["tq.csv"],
        &[
            "simulate",
            "--scene",
            ROBOT,
            "--torques",
            d.to_str().unwrap(),
            "--csv",
            &out,
        ],
        "cannot read",
    );
    std::fs::write(&table, good).unwrap();
    let steps: [(&[&str], &str); 9] = [
        (&["--dt", "0"], "step must be a positive number"),
        (&["--dt", "-0.001"], "step must be a positive number"),
        (&["--dt", "NaN"], "step must be a positive number"),
        (&["--duration", "1e300"], "at most"),
        (
            &["--duration", "-1"],
            "duration must be a non-negative number",
        ),
        (
            &["--duration", "NaN"],
            "duration must be a non-negative number",
        ),
        (
            &["--output-dt", "0"],
            "--output-dt: the step must be a positive number",
        ),
        (
            &["--output-dt", "NaN"],
            "--output-dt: the step must be a positive number",
        ),
        (&["--output-dt", "0.0015"], "whole multiple of --dt"),
    ];
    for (extra, needle) in steps {
        let args: Vec<&str> = sim.iter().chain(extra).copied().collect();
        refused(d, &["tq.csv"], &args, needle);
    }
    // A plot into a missing directory: refused (the outputs are staged
    // all or nothing), no CSV left either.
    let plot = p(d, "no/plot.png");
    let args: Vec<&str> = sim.iter().chain(&["--plot", &plot]).copied().collect();
    refused(d, &["tq.csv"], &args, "no/plot.png: directory");
}
