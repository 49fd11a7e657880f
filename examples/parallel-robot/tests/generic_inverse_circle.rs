//! The paper's circle through the generic `flexdyn inverse`
//! (`flexdyn::cli::inverse::run`, with the shipped motion file
//! `motions/circle.toml`) against the robot's own inverse dynamics
//! (`robot::inverse_rows`): the same torques on the rigid robot to 1e-9 N m;
//! on the flexible robot the difference is printed and bounded (both
//! integrate the elastic coordinates by generalized-alpha under servo
//! constraints, from the static equilibrium, but with their own servo
//! formulations and settings).

use std::path::{Path, PathBuf};

use flexdyn::cli::eval::Compiled;
use flexdyn::cli::inverse::{run, Args};
use flexdyn::table::Table;
use flexdyn_parallel_robot::robot::{inverse_rows, Circle, Geometry};
use flexdyn_parallel_robot::scenes::parallel_robot_flexible::ParallelRobotFlexible;
use flexdyn_parallel_robot::scenes::parallel_robot_rigid::ParallelRobotRigid;

const ROBOT_SCENES: Compiled = Compiled {
    scenes: flexdyn_parallel_robot::scenes::SCENES,
    model: flexdyn_parallel_robot::scenes::model,
    perturbed_scenes: flexdyn_parallel_robot::perturbed_scenes::SCENES,
    perturbed_model: flexdyn_parallel_robot::perturbed_scenes::model,
};

fn here(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(path)
}

/// The generic command's torques `tau_1..3` and times.
fn generic(scene: &str, duration: f64, dt: f64) -> (Vec<f64>, Vec<[f64; 3]>) {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("inverse.csv");
    let args = Args {
        scene: here(&format!("scenes/parallel_robot_{scene}.toml")),
        interpret: false,
        duration,
        dt,
        prescribe: vec![],
        motion: Some(here("motions/circle.toml")),
        initial: Some(here(&format!("motions/circle_start_{scene}.json"))),
        csv: csv.clone(),
    };
    run(&args, &ROBOT_SCENES).unwrap();
    let table = Table::read(&csv).unwrap();
    let tau: Vec<Vec<f64>> = ["tau_1", "tau_2", "tau_3"]
        .iter()
        .map(|c| table.column(c).unwrap())
        .collect();
    let t = table.column("t").unwrap();
    let rows = (0..t.len())
        .map(|k| [tau[0][k], tau[1][k], tau[2][k]])
        .collect();
    (t, rows)
}

/// The robot's own inverse dynamics (`parallel-robot inverse`) at `t`.
fn robot_inverse<M, const NQ: usize, const NC: usize>(model: &M, t: &[f64]) -> Vec<[f64; 3]>
where
    M: flexdyn::runtime::Model<NQ, NC, 3>,
{
    let rows = inverse_rows(model, &Geometry::SPEC, &Circle::paper(2.0), t, &mut || {}).unwrap();
    rows.iter().map(|r| r.tau).collect()
}

fn largest_difference(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .flat_map(|(x, y)| (0..3).map(move |i| (x[i] - y[i]).abs()))
        .fold(0.0, f64::max)
}

#[test]
fn rigid_robot_circle_torques_match_the_robot_inverse() {
    let (t, tau) = generic("rigid", 3.2, 0.01);
    let reference = robot_inverse(&ParallelRobotRigid, &t);
    let d = largest_difference(&tau, &reference);
    println!("rigid robot: largest torque difference {d:.3e} N m");
    assert!(d <= 1e-9, "{d}");
    // Not trivially zero: the torques vary along the circle.
    let spread = reference.iter().map(|r| r[0]).fold(f64::MIN, f64::max)
        - reference.iter().map(|r| r[0]).fold(f64::MAX, f64::min);
    assert!(spread > 1e-3);
}

#[test]
fn flexible_robot_circle_torques_are_close_to_the_robot_inverse() {
    let (t, tau) = generic("flexible", 0.5, 0.005);
    let reference = robot_inverse(&ParallelRobotFlexible::default(), &t);
    let d = largest_difference(&tau, &reference);
    let scale = reference
        .iter()
        .flat_map(|r| r.iter().map(|x| x.abs()))
        .fold(0.0, f64::max);
    println!("flexible robot: largest torque difference {d:.3e} N m (largest torque {scale:.3e})");
    assert!(d <= 1e-2 * scale, "{d} vs {scale}");
}
