//! The rigid robot's hard case (docs/hard-cases.md of the repository): the
//! circle at 10 rad/s through `parallel-robot inverse`, checked against the
//! time-scaling law of a rigid, undamped model (torques along a fixed path
//! at rate omega are `tau_g + omega^2 tau_v`), and a circle leaving the
//! workspace at that speed stopping with a clear error and no output; and
//! the robot driven towards the edge of its workspace, its reported
//! condition checked against the exact one (SVD).

use flexdyn::runtime::nalgebra::{DMatrix, SMatrix, SVector};
use flexdyn::runtime::Model;

/// `parallel-robot inverse` on the rigid robot; the CSV's torque rows, or the error.
fn robot_torques(omega: f64, dt: f64, extra: &[&str]) -> Result<Vec<[f64; 3]>, String> {
    let dir = tempfile::tempdir().expect("temporary directory");
    let csv = dir.path().join("tau.csv");
    let (omega, dt) = (omega.to_string(), dt.to_string());
    let duration = (std::f64::consts::TAU / omega.parse::<f64>().expect("number")).to_string();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_parallel-robot"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args([
            "inverse",
            "--scene",
            "scenes/parallel_robot_rigid.toml",
            "--quiet",
        ])
        .args([
            "--omega",
            &omega,
            "--dt",
            &dt,
            "--duration",
            &duration,
            "--csv",
        ])
        .arg(&csv)
        .args(extra)
        .output()
        .expect("run parallel-robot");
    if !out.status.success() {
        assert!(!csv.exists(), "a failed run left its CSV");
        return Err(String::from_utf8_lossy(&out.stderr).into_owned());
    }
    let t = flexdyn::table::Table::read(&csv)?;
    let cols = [t.column("tau_1")?, t.column("tau_2")?, t.column("tau_3")?];
    Ok((0..cols[0].len())
        .map(|k| [cols[0][k], cols[1][k], cols[2][k]])
        .collect())
}

#[test]
fn rigid_robot_at_10_rad_per_s_obeys_the_time_scaling_law() {
    // Along a fixed path traversed at rate omega, a rigid, undamped model has
    // qd = q' omega, qdd = q'' omega^2, so tau = tau_g + omega^2 tau_v at the
    // same point of the path: tau(10) = tau(1) + 33 (tau(2) - tau(1)).
    // Sampled every 0.01 rad of the circle in each run.
    let t1 = robot_torques(1.0, 0.01, &[]).expect("omega 1");
    let t2 = robot_torques(2.0, 0.005, &[]).expect("omega 2");
    let t10 = robot_torques(10.0, 0.001, &[]).expect("omega 10");
    let n = t1.len().min(t2.len()).min(t10.len());
    assert!(n > 600, "{n} samples");
    let peak = t10.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
    let worst = (0..n)
        .flat_map(|k| (0..3).map(move |i| (k, i)))
        .map(|(k, i)| (t10[k][i] - (t1[k][i] + 33.0 * (t2[k][i] - t1[k][i]))).abs())
        .fold(0.0f64, f64::max);
    println!(
        "rigid robot, omega = 10 rad/s: peak |tau| = {peak:.3} N m; time-scaling law holds to \
         {worst:.2e} N m"
    );
    assert!(
        peak > 30.0,
        "the fast circle should need large torques: {peak}"
    );
    assert!(worst < 1e-8 * peak, "{worst:e}");

    // A circle that leaves the workspace at that speed stops with the time
    // and the chain, and writes nothing.
    let err = robot_torques(10.0, 0.001, &["--center=-0.7,0,0.7"]).unwrap_err();
    println!("rigid robot, circle leaving the workspace: {}", err.trim());
    assert!(
        err.contains("at t = ") && err.contains("out of reach of chain"),
        "{err}"
    );
}

// ---------------------------------------------------------------------------
// The rigid robot driven towards the edge of its workspace.
// ---------------------------------------------------------------------------

#[test]
fn rigid_robot_towards_the_workspace_edge_reports_growing_condition() {
    use flexdyn::runtime::{InverseConfig, InverseDynamics, InverseSolution};
    use flexdyn_parallel_robot::robot::{inverse_kinematics, Geometry};
    use flexdyn_parallel_robot::scenes::parallel_robot_rigid::ParallelRobotRigid;
    let model = ParallelRobotRigid;
    let parsed =
        flexdyn::codegen::Model::load(std::path::Path::new("scenes/parallel_robot_rigid.toml"))
            .unwrap_or_else(|e| panic!("{e}"));
    let g = Geometry::from_parameters(&parsed.parameters).expect("robot geometry");
    let zero = SVector::<f64, 3>::zeros();
    let mut worst_ratio = (f64::INFINITY, 0.0f64);
    // Quasi-static inverse dynamics at platform position (x, 0, 0.7). Ok:
    // the exact condition of the
    // free-coordinate Jacobian; Err: the error that stopped it.
    let mut solver: Option<InverseDynamics<12, 9, 3, 3>> = None;
    let mut solve_at = |x: f64| -> Result<f64, String> {
        let p = [x, 0.0, 0.7];
        let q_ik = inverse_kinematics(&g, p).map_err(|e| e.to_string())?;
        let q_ik = SVector::<f64, 12>::from_column_slice(&q_ik);
        let ind = solver.get_or_insert_with(|| {
            InverseDynamics::new([9, 10, 11], q_ik, InverseConfig::default()).expect("solver")
        });
        // Newton starts from the closed-form solution: warm-started from the
        // previous position, it can cross the fold near the edge and land on
        // the other (elbow-flipped) assembly mode.
        ind.set_guess(q_ik);
        let mut sol = InverseSolution::default();
        let p_vec = SVector::<f64, 3>::from_column_slice(&p);
        let report = ind
            .solve(&model, 0.0, &p_vec, &zero, &zero, &mut sol)
            .map_err(|e| e.to_string())?;
        // Independent: the exact 2-norm condition of the Jacobian of the
        // nine free coordinates, by SVD.
        let mut phi_q = SMatrix::<f64, 9, 12>::zeros();
        model.constraint_jacobian(&sol.q, 0.0, &mut phi_q);
        let sv = DMatrix::from_fn(9, 9, |r, c| phi_q[(r, c)]).singular_values();
        let exact = sv.max() / sv.min();
        let ratio = report.jacobian_condition / exact;
        worst_ratio = (worst_ratio.0.min(ratio), worst_ratio.1.max(ratio));
        assert!((sol.q - q_ik).amax() < 1e-8, "x = {x}: left the IK branch");
        assert!(sol
            .tau
            .iter()
            .chain(sol.lambda.iter())
            .all(|t| t.is_finite()));
        Ok(exact)
    };
    // March outwards along +x (chains 2 and 3 stretch) until a position
    // fails, then bisect towards the edge.
    let mut x_ok = 0.0;
    let mut cond_ok = solve_at(x_ok).expect("home position");
    let mut x_bad = x_ok;
    let mut why = String::new();
    while why.is_empty() {
        x_bad += 0.01;
        match solve_at(x_bad) {
            Ok(c) => (x_ok, cond_ok) = (x_bad, c),
            Err(e) => why = e,
        }
    }
    let mut conditions = vec![(x_ok, cond_ok)];
    while x_bad - x_ok > 1e-13 {
        let mid = 0.5 * (x_ok + x_bad);
        match solve_at(mid) {
            Ok(c) => {
                (x_ok, cond_ok) = (mid, c);
                conditions.push((mid, c));
            }
            Err(e) => (x_bad, why) = (mid, e),
        }
    }
    for (x, c) in conditions.iter().step_by(8) {
        println!("  x = {x:.12} m: cond J_f = {c:.3e}");
    }
    println!(
        "rigid robot towards the workspace edge: last solved x = {x_ok:.12} m, cond J_f = \
         {cond_ok:.3e} (runtime's reported bound / exact in [{:.2}, {:.2}]); refused at x = \
         {x_bad:.12} m: {why}",
        worst_ratio.0, worst_ratio.1
    );
    // The runtime's condition is the documented upper bound: at least the
    // exact one, at most NC = 9 times it.
    assert!(
        worst_ratio.0 >= 1.0 - 1e-9 && worst_ratio.1 <= 9.0,
        "{worst_ratio:?}"
    );
    // Approaching the edge, the conditioning grows, and the refusal names
    // the chain and its condition number or missing reach.
    assert!(cond_ok > 1e3, "condition did not grow: {cond_ok:e}");
    assert!(
        why.contains("chain") && (why.contains("condition") || why.contains("out of reach")),
        "{why}"
    );
}
