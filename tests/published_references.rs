//! Mechanisms written from a published problem statement alone, run
//! through the generic `flexdyn simulate` (the scene interpreted), against
//! the published reference solution.
//!
//! Andrews' squeezing mechanism (`tests/references/andrews_squeezer.toml`):
//! seven bodies in closed loops (six constraints), a constant motor torque
//! and a spring between a point of body 3 and a fixed point, from Hairer &
//! Wanner (Solving Ordinary Differential Equations II, sec. VII.7) and the
//! test set for IVP solvers (Mazzia, Magherini, Iavernaro; problem
//! "andrews"), whose reference solution at `t = 0.03 s` is given to 16
//! digits. The crank turns 2.5 times in those 30 ms.

use flexdyn::table::Table;

// Shared helpers; this file runs the binary and uses no refusal check.
#[allow(dead_code)]
#[path = "common/cli.rs"]
mod cli;

const BIN: &str = env!("CARGO_BIN_EXE_flexdyn");

/// The test set's consistent initial positions (velocities zero), digits
/// as published.
#[allow(clippy::excessive_precision)]
const START: [f64; 7] = [
    -0.0617138900142764496358948458001,
    0.0,
    0.455279819163070380255912382449,
    0.222668390165885884674473185609,
    0.487364979543842550225598953530,
    -0.222668390165885884674473185609,
    1.23054744454982119249735015568,
];

/// The test set's reference positions at `t = 0.03`.
const AT_30_MS: [f64; 7] = [
    0.1581077119629904e2,
    -0.1575637105984298e2,
    0.4082224013073101e-1,
    -0.5347301163226948,
    0.5244099658805304,
    0.5347301163226948,
    0.1048080741042263e1,
];

const ANGLES: [&str; 7] = ["beta", "theta", "gamma", "phi", "delta", "omega", "epsilon"];

#[test]
fn andrews_squeezer_reaches_the_test_sets_reference_positions() {
    let dir = tempfile::tempdir().unwrap();
    let initial = dir.path().join("initial.json");
    let q: Vec<String> = START.iter().map(|x| format!("{x:?}")).collect();
    std::fs::write(
        &initial,
        format!(
            "{{\"q\": [{}], \"qd\": [0, 0, 0, 0, 0, 0, 0], \"t\": 0}}",
            q.join(", ")
        ),
    )
    .unwrap();
    let csv = dir.path().join("out.csv");
    let (code, err) = cli::run(&[
        "simulate",
        "--scene",
        "tests/references/andrews_squeezer.toml",
        "--initial",
        &cli::p(dir.path(), "initial.json"),
        "--duration",
        "0.03",
        "--dt",
        "0.001",
        "--tolerance",
        "1e-12",
        "--quiet",
        "--csv",
        &cli::p(dir.path(), "out.csv"),
    ]);
    assert_eq!(code, Some(0), "{err}");
    let table = Table::read(&csv).unwrap();
    let last = |name: &str| *table.column(name).unwrap().last().unwrap();
    assert_eq!(last("t"), 0.03);
    // The test set's own measure: the error of each position relative to
    // 1 + |reference| (its "mixed error"), here below 1e-9 (10 digits).
    let mut worst = 0.0f64;
    for (name, reference) in ANGLES.iter().zip(AT_30_MS) {
        let error = (last(name) - reference).abs() / (1.0 + reference.abs());
        println!(
            "{name}: {:.16e} vs {reference:.16e} ({error:.1e})",
            last(name)
        );
        worst = worst.max(error);
    }
    assert!(worst <= 1e-9, "mixed error {worst:.1e}");
    // The spring's end D is the marker `D`: the test set's
    // `xd = sd cos g + sc sin g + xb`, `yd = sd sin g - sc cos g + yb`.
    let (sd, sc, xb, yb) = (2e-2, 18e-3, -0.03635, 0.03273);
    let g = last("gamma");
    let (xd, yd) = (
        sd * g.cos() + sc * g.sin() + xb,
        sd * g.sin() - sc * g.cos() + yb,
    );
    assert!((last("D_x") - xd).abs() <= 1e-15 && (last("D_y") - yd).abs() <= 1e-15);
    // The constraints hold along the way.
    let drift = table.column("drift").unwrap();
    assert!(drift.iter().all(|d| d.abs() <= 1e-10), "{drift:?}");
}
