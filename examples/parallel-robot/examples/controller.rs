//! A controller-style loop: at a fixed rate of 1 kHz, evaluate the actuator
//! torques that make the rigid robot's platform follow the paper's circle.
//! Only the generated equations (`flexdyn_parallel_robot::scenes::parallel_robot_rigid`) and
//! the no_std runtime (`InverseDynamics`) are in the timed evaluation path;
//! nothing allocates there.
//!
//! Run with `cargo run --release -p flexdyn-parallel-robot --example controller`.

use std::time::{Duration, Instant};

use flexdyn::runtime::nalgebra::SVector;
use flexdyn::runtime::{InverseConfig, InverseDynamics, InverseSolution};
use flexdyn_parallel_robot::robot::{inverse_kinematics, Circle, Geometry};
use flexdyn_parallel_robot::scenes::parallel_robot_rigid::ParallelRobotRigid;

const RATE_HZ: u32 = 1000;
const TICKS: usize = 3000;

fn main() {
    let model = ParallelRobotRigid;
    let circle = Circle::paper(2.0);
    // Set-up, outside the loop: the closed-form inverse kinematics gives the
    // first Newton starting point.
    let q0 = inverse_kinematics(&Geometry::SPEC, circle.at(0.0)[0]).expect("start reachable");
    let mut solver = InverseDynamics::<12, 9, 3, 3>::new(
        [9, 10, 11],
        SVector::from(q0),
        InverseConfig::default(),
    )
    .expect("valid configuration");
    let mut solution = InverseSolution::<12, 9, 3>::default();
    let mut times = Vec::with_capacity(TICKS);
    let period = Duration::from_secs(1) / RATE_HZ;
    let start = Instant::now();
    let mut peak = [0.0f64; 3];
    for tick in 0..TICKS {
        let t = tick as f64 / f64::from(RATE_HZ);
        let [p, v, a] = circle.at(t);
        let begin = Instant::now();
        let result = solver.solve(
            &model,
            t,
            &SVector::from(p),
            &SVector::from(v),
            &SVector::from(a),
            &mut solution,
        );
        times.push(begin.elapsed());
        if let Err(e) = result {
            eprintln!("tick {tick}: {e}; holding the previous torques");
        }
        for (p, tau) in peak.iter_mut().zip(solution.tau.iter()) {
            *p = p.max(tau.abs());
        }
        // Sleep until the next tick, as a real-time loop would.
        let next = start + period * (tick as u32 + 1);
        if let Some(wait) = next.checked_duration_since(Instant::now()) {
            std::thread::sleep(wait);
        }
    }
    times.sort();
    let median = times[times.len() / 2];
    let worst = times[times.len() - 1];
    let p99 = times[times.len() * 99 / 100];
    println!("{TICKS} torque evaluations at {RATE_HZ} Hz");
    println!("time per call: median {median:?}, 99th percentile {p99:?}, worst {worst:?}");
    println!(
        "peak torques: {:.3} / {:.3} / {:.3} N m",
        peak[0], peak[1], peak[2]
    );
}
