//! The paper's circle through the generic `flexdyn inverse`
//! (`flexdyn::cli::inverse::run`, with the shipped motion file
//! `motions/circle.toml`) against the robot's own inverse dynamics
//! (`robot::inverse_rows`): the same torques to 1e-9 N m on the rigid robot
//! (exact inverse dynamics both) and on the flexible robot, where both
//! integrate the elastic coordinates by the runtime's `servo_run`
//! (generalized-alpha, trial step unprojected) from the static equilibrium,
//! the generic command with `--free-rates zero` (the robot's start); there
//! also with the circle prescribed on the platform's marker `end_effector`
//! (task space).

use std::path::{Path, PathBuf};

use flexdyn::cli::inverse::{run, Args};
use flexdyn::prescribed_motion::FreeRates;
use flexdyn::table::Table;
use flexdyn_parallel_robot::robot::{inverse_rows, Circle, Geometry};
use flexdyn_parallel_robot::scenes::parallel_robot_flexible::ParallelRobotFlexible;
use flexdyn_parallel_robot::scenes::parallel_robot_rigid::ParallelRobotRigid;
use flexdyn_parallel_robot::COMPILED_SCENES;

fn here(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(path)
}

/// The generic command's torques `tau_1..3` and times, the circle from the
/// motion file.
fn generic(
    scene: &str,
    duration: f64,
    dt: f64,
    free_rates: FreeRates,
) -> (Vec<f64>, Vec<[f64; 3]>) {
    generic_prescribed(scene, duration, dt, free_rates, &[])
}

/// [`generic`] with `prescribe` given (`NAME=EXPR`) in place of the motion
/// file, when not empty.
fn generic_prescribed(
    scene: &str,
    duration: f64,
    dt: f64,
    free_rates: FreeRates,
    prescribe: &[&str],
) -> (Vec<f64>, Vec<[f64; 3]>) {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("inverse.csv");
    let args = Args {
        scene: here(&format!("scenes/parallel_robot_{scene}.toml")),
        interpret: false,
        duration,
        dt,
        max_steps: flexdyn::steps::MAX_STEPS,
        prescribe: prescribe.iter().map(|p| p.to_string()).collect(),
        motion: prescribe.is_empty().then(|| here("motions/circle.toml")),
        prescriptions: None,
        initial: Some(here(&format!("motions/circle_start_{scene}.json"))),
        free_rates,
        csv: csv.clone(),
        quiet: true,
    };
    run(&args, &COMPILED_SCENES).unwrap();
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
    let (t, tau) = generic("rigid", 3.2, 0.01, FreeRates::LeastEnergy);
    let reference = robot_inverse(&ParallelRobotRigid, &t);
    let d = largest_difference(&tau, &reference);
    println!("rigid robot: largest torque difference {d:.3e} N m");
    assert!(d <= 1e-9, "{d}");
    // Not trivially zero: the torques vary along the circle.
    let spread = reference.iter().map(|r| r[0]).fold(f64::MIN, f64::max)
        - reference.iter().map(|r| r[0]).fold(f64::MAX, f64::min);
    assert!(spread > 1e-3);
}

/// The flexible robot (39 coordinates, the largest rung of the padding
/// ladder) with its elastic rates starting at zero (`--free-rates zero`),
/// as the robot's servo starts them: the same torques to 1e-9 N m at every
/// sample of the first 0.2 s (40 steps of the paper's 0.005 s), start
/// transient included.
#[test]
fn flexible_robot_circle_torques_match_the_robot_inverse() {
    let (t, tau) = generic("flexible", 0.2, 0.005, FreeRates::Zero);
    assert_eq!(t.len(), 41);
    let reference = robot_inverse(&ParallelRobotFlexible::default(), &t);
    let d = largest_difference(&tau, &reference);
    println!("flexible robot: largest torque difference {d:.3e} N m");
    assert!(d <= 1e-9, "{d}");
}

/// The same circle prescribed on the platform's marker `end_effector` (at
/// the platform's centre: its world coordinates are `px`, `py`, `pz`, so the
/// prescription is the same motion) in task space, the elastic coordinates
/// integrated as servo outputs are: the robot's torques to 1e-9 N m.
#[test]
fn flexible_robot_circle_on_the_end_effector_marker_matches_the_robot_inverse() {
    let (t, tau) = generic_prescribed(
        "flexible",
        0.2,
        0.005,
        FreeRates::Zero,
        &[
            "end_effector_x=0.1*cos(2*t)",
            "end_effector_y=0.1*sin(2*t)",
            "end_effector_z=0.7",
        ],
    );
    assert_eq!(t.len(), 41);
    let reference = robot_inverse(&ParallelRobotFlexible::default(), &t);
    let d = largest_difference(&tau, &reference);
    println!("flexible robot, marker circle: largest torque difference {d:.3e} N m");
    assert!(d <= 1e-9, "{d}");
}

/// The generic command's own default, elastic rates of least kinetic
/// energy, starts differently: a transient the L-stable scheme damps within
/// a few steps, so the torques differ at the start and agree to well under
/// a percent after 0.1 s.
#[test]
fn flexible_robot_least_energy_start_differs_by_a_transient() {
    let (t, tau) = generic("flexible", 0.2, 0.005, FreeRates::LeastEnergy);
    let reference = robot_inverse(&ParallelRobotFlexible::default(), &t);
    let start = largest_difference(&tau[..5], &reference[..5]);
    let after = largest_difference(&tau[20..], &reference[20..]);
    let scale = reference
        .iter()
        .flat_map(|r| r.iter().map(|x| x.abs()))
        .fold(0.0, f64::max);
    println!(
        "least-energy start: largest torque difference {start:.3e} N m in the first 5 steps, \
         {after:.3e} N m from 0.1 s (largest torque {scale:.3e})"
    );
    assert!(start > 1e-6, "{start}");
    assert!(after <= 2e-3 * scale, "{after} vs {scale}");
}
