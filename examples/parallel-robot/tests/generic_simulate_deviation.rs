//! The paper's Figures 11-13 analogue through the generic `flexdyn
//! simulate` (`flexdyn::cli::simulate::run`): the flexible robot under the
//! rigid robot's torques plus the PD loop on the actuated joints, from the
//! robot's start (`robot::initial_state`), generalized-alpha with
//! `rho_inf = 0` at the paper's 0.005 s step. The end effector's deviation
//! from the circle is the example's (`robot::simulate_rows`, as
//! `parallel-robot simulate --pd`) to 1e-9 m.
//!
//! The inputs are the example's at every step time: the torques and the
//! reference angles as the example's tables sampled at the step times (the
//! CLI's linear interpolation then gives the sampled values there), the
//! reference rates as the example's (central differences of the angle
//! table, interpolated) in columns `th11_dot`, ...; and the integrator
//! starts as the example's, unfiltered (`--unfiltered-start`).

use std::path::{Path, PathBuf};

use flexdyn::cli::simulate::{run, Args};
use flexdyn::table::Table;
use flexdyn_parallel_robot::robot::{
    initial_state, inverse_rows, simulate_rows, Circle, Geometry, Layout, PdSettings, Scheme,
    TorqueTable,
};
use flexdyn_parallel_robot::scenes::parallel_robot_flexible::ParallelRobotFlexible;
use flexdyn_parallel_robot::scenes::parallel_robot_rigid::ParallelRobotRigid;
use flexdyn_parallel_robot::COMPILED_SCENES;

fn here(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(path)
}

/// The scene's PD gains (`pd_kp`, `pd_kd`).
const KP: f64 = 2000.0;
const KD: f64 = 40.0;

#[test]
fn generic_simulate_reproduces_the_flexible_robots_deviation_under_rigid_torques_and_pd() {
    let (t0, dt, steps) = (0.2, 0.005, 60);
    // The CLI's step times.
    let times: Vec<f64> = (0..=steps).map(|k| t0 + k as f64 * dt).collect();
    let circle = Circle::paper(2.0);
    let g = Geometry::SPEC;
    let rigid = inverse_rows(&ParallelRobotRigid, &g, &circle, &times, &mut || {}).unwrap();
    let table = |f: &dyn Fn(usize) -> [f64; 3]| {
        let samples: Vec<(f64, [f64; 3])> = (0..times.len()).map(|k| (times[k], f(k))).collect();
        TorqueTable::from_samples(&samples).unwrap()
    };
    let torques = table(&|k| rigid[k].tau);
    let pd = PdSettings {
        kp: KP,
        kd: KD,
        reference: table(&|k| rigid[k].th),
    };
    let model = ParallelRobotFlexible::default();
    let [p0, v0, _] = circle.at(t0);

    // The example.
    let rows = simulate_rows(
        &model,
        &g,
        Scheme::GeneralizedAlpha,
        (t0, p0, v0),
        &torques,
        Some(&pd),
        (dt, steps, 1),
        &mut || {},
    )
    .unwrap();

    // The generic command, from the example's start, with its inputs.
    let dir = tempfile::tempdir().unwrap();
    let start = initial_state(&model, &Layout::of(&model).unwrap(), &g, t0, p0, v0).unwrap();
    let initial = dir.path().join("start.json");
    let state = serde_json::json!({
        "q": start.q.as_slice(),
        "qd": start.qd.as_slice(),
        "t": t0,
    });
    std::fs::write(&initial, state.to_string()).unwrap();
    let mut inputs = Table::new(&[
        "t", "tau_1", "tau_2", "tau_3", "th11", "th21", "th31", "th11_dot", "th21_dot", "th31_dot",
    ]);
    for &t in &times {
        let mut row = vec![t];
        row.extend(torques.at(t));
        row.extend(pd.reference.at(t));
        row.extend(pd.reference.rate_at(t));
        inputs.push(row);
    }
    let inputs_csv = dir.path().join("inputs.csv");
    inputs.write(&inputs_csv).unwrap();
    let csv = dir.path().join("motion.csv");
    let args = Args {
        scene: here("scenes/parallel_robot_flexible.toml"),
        interpret: false,
        duration: dt * steps as f64,
        dt: Some(dt),
        output_dt: None,
        initial: Some(initial),
        inputs_expr: vec![],
        inputs_csv: Some(inputs_csv),
        pd: (1..=3).map(|j| format!("tau_{j}={KP},{KD}")).collect(),
        target: vec![],
        feedback: None,
        integrator: "gen-alpha".into(),
        tolerance: None,
        rho_inf: Some(0.0),
        unfiltered_start: true,
        max_sweeps: None,
        no_error_estimate: true,
        max_steps: flexdyn::steps::MAX_STEPS,
        csv: csv.clone(),
        plot: None,
        markers: vec!["end_effector".into()],
        columns: vec![],
        quiet: true,
    };
    run(&args, &COMPILED_SCENES).unwrap();
    let out = Table::read(&csv).unwrap();
    let marker: Vec<Vec<f64>> = ["x", "y", "z"]
        .iter()
        .map(|a| out.column(&format!("end_effector_{a}")).unwrap())
        .collect();
    assert_eq!(out.column("t").unwrap().len(), rows.len());

    let (mut largest, mut difference) = (0.0f64, 0.0f64);
    for (k, r) in rows.iter().enumerate() {
        let want = circle.at(r.t)[0];
        for i in 0..3 {
            let example = r.p[i] - want[i];
            let generic = marker[i][k] - want[i];
            largest = largest.max(example.abs());
            difference = difference.max((generic - example).abs());
        }
    }
    println!(
        "deviation from the circle over {t0} .. {} s: largest {largest:.3e} m, generic \
         command vs example {difference:.3e} m",
        times[steps]
    );
    // The deviation is the elastic structure's, not zero.
    assert!(largest > 1e-5, "{largest}");
    assert!(difference <= 1e-9, "{difference}");
}
