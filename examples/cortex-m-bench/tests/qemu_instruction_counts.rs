//! The firmware's instruction and stack counts on the emulated Cortex-M4F
//! (QEMU mps2-an386 with `-icount`: deterministic, independent of the host's
//! load) stay within 10 % of the figures recorded in docs/benchmarks.md, the
//! counting method counts a block of 1000 `nop`s as 1000 instructions, and
//! the firmware's inverse dynamics (soft-float f64 and FPU f32 on the
//! emulated core) gives the torques the host computes for the same motion
//! (f32: within a few units in the last place of the host's f32 run and
//! within 1e-5 of the f64 torques).

use flexdyn_cortex_m_bench::{build, parse_bench, qemu, recorded, workspace, Toolchain};

#[path = "../firmware/src/models.rs"]
mod models;
#[path = "../firmware/src/motion.rs"]
mod motion;

/// Allowed growth of a count over its recorded figure.
const GROWTH: f64 = 1.10;

#[test]
fn cortex_m4f_counts_stay_within_ten_percent_of_the_recorded_figures() {
    let tc = Toolchain::find().unwrap_or_else(|e| panic!("{e}"));
    let dir = build(&tc).unwrap_or_else(|e| panic!("{e}"));
    let bench = parse_bench(&qemu(&dir.join("bench")).unwrap_or_else(|e| panic!("{e}"))).unwrap();

    let nops = bench
        .counts
        .iter()
        .find(|m| m.name == "nop1000")
        .expect("the nop check");
    assert_eq!(
        (nops.instructions, nops.stack),
        (1000, 0),
        "the counting method is off"
    );

    let docs = workspace().join("docs/benchmarks.md");
    let record = recorded(&std::fs::read_to_string(&docs).unwrap())
        .unwrap_or_else(|e| panic!("{}: {e}", docs.display()));
    let mut names: Vec<&str> = bench.counts.iter().map(|m| m.name.as_str()).collect();
    let mut recorded_names: Vec<&str> = record.iter().map(|m| m.name.as_str()).collect();
    names.sort_unstable();
    recorded_names.sort_unstable();
    assert_eq!(
        names,
        recorded_names,
        "the measurements and {} differ",
        docs.display()
    );
    let mut grown = Vec::new();
    for m in &bench.counts {
        let r = record.iter().find(|r| r.name == m.name).unwrap();
        for (what, now, then) in [
            ("instructions", m.instructions, r.instructions),
            ("stack", m.stack, r.stack),
        ] {
            if now as f64 > GROWTH * then as f64 {
                grown.push(format!("{} {what}: {now}, recorded {then}", m.name));
            }
        }
    }
    assert!(
        grown.is_empty(),
        "counts grew by more than 10 %: {grown:#?}"
    );
}

/// The host's torques of the last call of the run in `T`.
fn host_torques<T: motion::Real, M: flexdyn_runtime::Model<12, 9, 3, T>>(
    model: &M,
) -> motion::Solution<T> {
    let mut solver = motion::warm_solver(model).expect("the host solves the first pose");
    let mut sol = motion::Solution::default();
    for k in 1..=motion::CALLS {
        assert!(
            motion::call(model, &mut solver, k, &mut sol),
            "host call {k} fails"
        );
    }
    sol
}

#[test]
fn firmware_torques_match_the_host() {
    let tc = Toolchain::find().unwrap_or_else(|e| panic!("{e}"));
    let dir = build(&tc).unwrap_or_else(|e| panic!("{e}"));
    let bench = parse_bench(&qemu(&dir.join("bench")).unwrap_or_else(|e| panic!("{e}"))).unwrap();

    let sol = host_torques(&models::parallel_robot_rigid::ParallelRobotRigid);
    assert_eq!(bench.t, sol.t);
    assert_eq!(bench.tau.len(), 3);
    for (i, (fw, host)) in bench.tau.iter().zip(sol.tau.iter()).enumerate() {
        assert!(
            (fw - host).abs() <= 1e-12 * host.abs().max(1.0),
            "tau_{}: firmware {fw}, host {host}",
            i + 1
        );
    }
    // f32 on the FPU: the host's f32 run to a few units of f32's last
    // place, and the f64 torques to f32's accuracy (3e-7 relative measured).
    let sol32 = host_torques(&models::f32::parallel_robot_rigid::ParallelRobotRigid);
    assert_eq!(bench.tau_f32.len(), 3);
    for (i, ((fw, host), exact)) in bench
        .tau_f32
        .iter()
        .zip(sol32.tau.iter())
        .zip(sol.tau.iter())
        .enumerate()
    {
        assert!(
            (fw - host).abs() <= 4.0 * f32::EPSILON * host.abs().max(1.0),
            "f32 tau_{}: firmware {fw}, host {host}",
            i + 1
        );
        assert!(
            (f64::from(*fw) - exact).abs() <= 1e-5 * exact.abs().max(1.0),
            "f32 tau_{}: firmware {fw}, f64 {exact}",
            i + 1
        );
    }
}
