//! The paper's circle through the generic `flexdyn inverse`
//! (`flexdyn::cli::inverse::run`, with the shipped motion file
//! `motions/circle.toml`) against the robot's own inverse dynamics
//! (`robot::inverse_rows`): the same torques on the rigid robot to 1e-9 N m;
//! on the flexible robot (too large for the command's padding ladder, so
//! through `flexdyn::inverse::solve` on the compiled model) the difference
//! is printed and bounded: both integrate the elastic coordinates by
//! generalized-alpha under servo constraints from the static equilibrium,
//! with their own servo formulations and settings.

use std::path::{Path, PathBuf};

use flexdyn::cli::eval::Compiled;
use flexdyn::cli::inverse::{run, Args};
use flexdyn::table::Table;
use flexdyn_parallel_robot::robot::{inverse_rows, Circle, Geometry};
use flexdyn_parallel_robot::scenes::parallel_robot_flexible::{ParallelRobotFlexible, NC, NQ};
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

/// The flexible robot (39 coordinates) exceeds the padding ladder of the
/// command (`flexdyn::sized::LADDER`): the same solve,
/// `flexdyn::inverse::solve`, on the compiled model directly.
#[test]
fn flexible_robot_circle_torques_are_close_to_the_robot_inverse() {
    use flexdyn::inverse::{solve, Method, Prescribed, Problem};
    use flexdyn::runtime::Model;
    type M = ParallelRobotFlexible;
    let names = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
    let index = |name: &str| M::COORDINATES.iter().position(|c| *c == name).unwrap();
    let circle = Circle::paper(2.0);
    let axis = |k: usize| move |t: f64| circle.at(t).map(|x| x[k]);
    let (px, py, pz) = (axis(0), axis(1), axis(2));
    let start: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(here("motions/circle_start_flexible.json")).unwrap(),
    )
    .unwrap();
    let (duration, dt) = (0.5, 0.005);
    let t: Vec<f64> = (0..=100).map(|k| k as f64 * dt).collect();
    assert!((t[100] - duration).abs() < 1e-12);
    let problem = Problem {
        coordinates: names(&M::COORDINATES),
        constraints: (0..NC).map(|k| format!("closure_{k}")).collect(),
        actuators: names(&M::ACTUATORS),
        prescribed: vec![
            Prescribed {
                coordinate: index("px"),
                motion: &px,
            },
            Prescribed {
                coordinate: index("py"),
                motion: &py,
            },
            Prescribed {
                coordinate: index("pz"),
                motion: &pz,
            },
        ],
        held_inputs: vec![],
        held_free: vec![],
        guess: start["q"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect(),
        times: t.clone(),
    };
    let model = M::default();
    let out = solve::<_, NQ, NC, 3, 3>(&model, &problem).unwrap();
    assert_eq!(out.method, Method::Servo);
    let tau: Vec<[f64; 3]> = out.tau.iter().map(|x| [x[0], x[1], x[2]]).collect();
    let reference = robot_inverse(&model, &t);
    // The two start from different elastic rates (here: least kinetic
    // energy; the robot: zero), a transient the L-stable scheme damps
    // within a few steps; compared from 0.1 s on.
    let d = largest_difference(&tau[20..], &reference[20..]);
    let scale = reference
        .iter()
        .flat_map(|r| r.iter().map(|x| x.abs()))
        .fold(0.0, f64::max);
    println!("flexible robot: largest torque difference from 0.1 s {d:.3e} N m (largest torque {scale:.3e})");
    assert!(d <= 2e-3 * scale, "{d} vs {scale}");
}
