//! Long runs of the robot's `inverse` and `simulate` stream their rows: with
//! the address space limited to well below what their rows took in memory,
//! 10^5 steps of `inverse` (the CSV, `--states`, the plot) and 2 10^5 of
//! `simulate` (the CSV, the plot) run through and write every row. Before
//! they streamed, these runs took 430 MB and 114 MB and aborted under the
//! limit; now they take about 12 MB.

#[path = "../../../tests/common/limits.rs"]
mod limits;

use flexdyn::table::Table;

const BIN: &str = env!("CARGO_BIN_EXE_parallel-robot");
const ROBOT: &str = "scenes/parallel_robot_rigid.toml";

/// The most address space a run here may take: a streaming run needs less
/// than 32 MB of it, whatever its length.
const SMALL: u64 = 48 << 20;

/// Seconds of processor and of wall-clock time a run here may take (the
/// longest needs ~3).
const SECONDS: u64 = 60;

/// Runs the binary with `args` within [`SMALL`] and [`SECONDS`]; it must
/// succeed.
fn run(args: &[&str]) {
    let out = limits::limited(BIN, SMALL, SECONDS)
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{args:?}: {}: {}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The CSV at `path`, checked to be the text of its table (as the command
/// wrote it when it kept the table in memory), with rows at `t = k dt`,
/// `k = 0..rows`.
fn every_row(path: &str, rows: usize, dt: f64) -> Table {
    let text = std::fs::read_to_string(path).unwrap();
    let table = Table::parse(&text).unwrap();
    assert!(text == table.to_csv(), "{path} is not Table::to_csv");
    let t = table.column("t").unwrap();
    assert_eq!(t.len(), rows, "{path}");
    let gap = (0..rows).find(|&k| (t[k] - k as f64 * dt).abs() > 1e-9 * (1.0 + t[k]));
    assert_eq!(gap, None, "{path}: a row out of place");
    table
}

#[test]
fn long_inverse_and_simulate_runs_write_every_row_in_bounded_memory() {
    let dir = tempfile::tempdir().unwrap();
    let path = |name: &str| dir.path().join(name).to_string_lossy().into_owned();
    let (tau, states, plot) = (path("tau.csv"), path("states.json"), path("tau.png"));
    // 10^5 steps of 5 ms: 21 MB of CSV, 48 MB of states.
    run(&[
        "inverse",
        "--scene",
        ROBOT,
        "--duration",
        "500",
        "--csv",
        &tau,
        "--states",
        &states,
        "--plot",
        &plot,
        "--quiet",
    ]);
    let table = every_row(&tau, 100_001, 0.005);
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&states).unwrap()).unwrap();
    let states = json["states"].as_array().unwrap();
    let t = table.column("t").unwrap();
    assert_eq!(states.len(), t.len());
    // (serde_json reads the times back to within rounding.)
    let near = |s: &serde_json::Value, t: f64| (s["t"].as_f64().unwrap() - t).abs() <= 1e-12 * t;
    assert!(states.iter().zip(&t).all(|(s, &t)| near(s, t)));
    assert!(std::fs::metadata(&plot).unwrap().len() > 0);
    // 2 10^5 steps of 1 ms under the first second's torques (held after
    // it), the PD loop keeping the robot in place: 56 MB of CSV.
    let (short, sim, plot) = (path("short.csv"), path("sim.csv"), path("sim.png"));
    run(&[
        "inverse",
        "--scene",
        ROBOT,
        "--duration",
        "1",
        "--csv",
        &short,
        "--quiet",
    ]);
    run(&[
        "simulate",
        "--scene",
        ROBOT,
        "--torques",
        &short,
        "--pd",
        "--duration",
        "200",
        "--output-dt",
        "0.001",
        "--csv",
        &sim,
        "--plot",
        &plot,
        "--quiet",
    ]);
    let table = every_row(&sim, 200_001, 0.001);
    let dz = table.column("dz").unwrap();
    assert!(dz.iter().all(|d| d.abs() < 1e-3), "the PD loop let go");
    assert!(std::fs::metadata(&plot).unwrap().len() > 0);
}
