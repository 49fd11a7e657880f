//! The firmware's instruction and stack counts on the emulated Cortex-M4F
//! (QEMU mps2-an386 with `-icount`: deterministic, independent of the host's
//! load) stay within the allowance of the figures recorded in
//! docs/benchmarks.md (10 % with the compiler that recorded them, 25 % and a
//! few stack bytes with another build: see `Allowance`), the counting method
//! counts a block of 1000 `nop`s as 1000 instructions, and the firmware's
//! inverse dynamics (soft-float f64 and FPU f32 on the emulated core) gives
//! the torques the host computes for the same motion (f32: within a few
//! units in the last place of the host's f32 run and within 1e-5 of the f64
//! torques).

use flexdyn_cortex_m_bench::{
    build, parse_bench, qemu, recorded, recorded_compiler, workspace, Allowance, Measurement,
    Toolchain,
};

#[path = "../firmware/src/models.rs"]
mod models;
#[path = "../firmware/src/motion.rs"]
mod motion;

/// docs/benchmarks.md: the recorded figures and the compiler that made them.
fn record() -> (Vec<Measurement>, String) {
    let docs = workspace().join("docs/benchmarks.md");
    let text = std::fs::read_to_string(&docs).unwrap();
    let fail = |e: String| -> ! { panic!("{}: {e}", docs.display()) };
    (
        recorded(&text).unwrap_or_else(|e| fail(e)),
        recorded_compiler(&text).unwrap_or_else(|e| fail(e)),
    )
}

#[test]
fn cortex_m4f_counts_stay_within_the_allowance_of_the_recorded_figures() {
    let tc = Toolchain::find().unwrap_or_else(|e| panic!("{e}"));
    let compiler = tc.version().unwrap_or_else(|e| panic!("{e}"));
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

    let (record, recorded_with) = record();
    let mut names: Vec<&str> = bench.counts.iter().map(|m| m.name.as_str()).collect();
    let mut recorded_names: Vec<&str> = record.iter().map(|m| m.name.as_str()).collect();
    names.sort_unstable();
    recorded_names.sort_unstable();
    assert_eq!(
        names, recorded_names,
        "the measurements and docs/benchmarks.md differ"
    );
    let same = compiler == recorded_with;
    let allowance = Allowance::for_compiler(same);
    if !same {
        eprintln!(
            "note: the counts were recorded with `{recorded_with}`, this is `{compiler}`: \
             compared with the wider allowance {allowance:?} (re-record with \
             `cargo run --release -p flexdyn-cortex-m-bench`)"
        );
    }
    let grown: Vec<String> = bench
        .counts
        .iter()
        .flat_map(|m| {
            let r = record.iter().find(|r| r.name == m.name).unwrap();
            allowance.exceeded(m, r)
        })
        .collect();
    assert!(
        grown.is_empty(),
        "counts grew beyond the allowance {allowance:?} (compiler `{compiler}`, recorded with \
         `{recorded_with}`): {grown:#?}"
    );
}

/// The allowances accept the recorded figures and a little growth, and catch
/// a doubled instruction count or stack depth of any recorded measurement,
/// with the recording compiler and with another.
#[test]
fn a_doubled_count_exceeds_either_allowance() {
    let (record, _) = record();
    for same in [true, false] {
        let a = Allowance::for_compiler(same);
        for r in record.iter().filter(|r| r.name != "nop1000") {
            assert!(a.exceeded(r, r).is_empty(), "{r:?} exceeds itself");
            let slightly = Measurement {
                instructions: r.instructions + r.instructions / 20,
                stack: r.stack + 8,
                ..r.clone()
            };
            assert!(
                a.exceeded(&slightly, r).is_empty(),
                "{slightly:?} under {a:?}"
            );
            for doubled in [
                Measurement {
                    instructions: 2 * r.instructions,
                    ..r.clone()
                },
                Measurement {
                    stack: 2 * r.stack,
                    ..r.clone()
                },
            ] {
                assert_eq!(
                    a.exceeded(&doubled, r).len(),
                    1,
                    "{doubled:?} passes {a:?} against {r:?}"
                );
            }
        }
    }
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
