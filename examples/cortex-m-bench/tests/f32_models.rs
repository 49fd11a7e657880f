//! The firmware's f32 modules (`firmware/src/f32/`) are a fresh generation
//! of their scenes with `precision = f32`, and they agree with the f64
//! modules of `generated/` to f32's resolution: at 32 poses of the rigid robot
//! along the paper's circle (solved by the runtime's f64 inverse dynamics)
//! and at seeded states of the spin-up beam, every entry of `M`, `h`,
//! `Phi_q` and `gamma` from `dynamics_terms` is within `2e-6` of the
//! largest entry of its term (f32's unit roundoff is 6e-8; the terms sum
//! hundreds of rounded products). The worst relative errors are printed.

use std::path::Path;

use flexdyn_codegen::{Builder, Precision};
use flexdyn_cortex_m_bench::workspace;
use flexdyn_runtime::nalgebra::{SMatrix, SVector};
use flexdyn_runtime::Model;

#[path = "../firmware/src/models.rs"]
mod models;
// Shared with the firmware; this test does not use the call count.
#[allow(dead_code)]
#[path = "../firmware/src/motion.rs"]
mod motion;

/// The f32 modules and their scenes.
const F32_MODULES: [(&str, &str); 2] = [
    (
        "parallel_robot_rigid",
        "examples/parallel-robot/scenes/parallel_robot_rigid.toml",
    ),
    ("spin_up_beam", "scenes/spin_up_beam.toml"),
];

#[test]
fn f32_modules_match_a_fresh_generation() {
    let dir = tempfile::tempdir().unwrap();
    let mut builder = Builder::new().precision(Precision::F32).out_dir(dir.path());
    for (_, scene) in F32_MODULES {
        builder = builder.scene(workspace().join(scene));
    }
    builder.generate().unwrap_or_else(|e| panic!("{e}"));
    let checked_in = Path::new(env!("CARGO_MANIFEST_DIR")).join("firmware/src/f32");
    for (name, _) in F32_MODULES {
        let file = format!("{name}.rs");
        assert!(
            std::fs::read_to_string(checked_in.join(&file)).ok()
                == std::fs::read_to_string(dir.path().join(&file)).ok(),
            "{} is stale: run `cargo run --release -- generate --precision f32 --out \
             examples/cortex-m-bench/firmware/src/f32 {}`",
            checked_in.join(&file).display(),
            F32_MODULES.map(|(_, s)| format!("--scene {s}")).join(" ")
        );
    }
}

/// Largest `|a - b| / max |b|` over the entries of one term.
fn relative<const R: usize, const C: usize>(a: &SMatrix<f32, R, C>, b: &SMatrix<f64, R, C>) -> f64 {
    let scale = b.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let diff = a
        .iter()
        .zip(b.iter())
        .fold(0.0f64, |m, (x, y)| m.max((f64::from(*x) - y).abs()));
    if scale == 0.0 {
        diff
    } else {
        diff / scale
    }
}

/// The worst relative error of each of `M`, `h`, `Phi_q`, `gamma` between
/// the f32 model `$f32` and the f64 model `$f64` (module `$m`) at `q`, `qd`.
macro_rules! worst_errors {
    ($f32:expr, $f64:expr, $m:ident, $q:expr, $qd:expr, $worst:expr) => {{
        use models::$m::{NC, NQ};
        let (q, qd): (SVector<f64, NQ>, SVector<f64, NQ>) = ($q, $qd);
        let mut m = SMatrix::<f64, NQ, NQ>::zeros();
        let mut h = SVector::<f64, NQ>::zeros();
        let mut phi_q = SMatrix::<f64, NC, NQ>::zeros();
        let mut gamma = SVector::<f64, NC>::zeros();
        $f64.dynamics_terms(&q, &qd, 0.0, &mut m, &mut h, &mut phi_q, &mut gamma);
        let (q, qd) = (q.cast::<f32>(), qd.cast::<f32>());
        let mut m32 = SMatrix::<f32, NQ, NQ>::zeros();
        let mut h32 = SVector::<f32, NQ>::zeros();
        let mut phi_q32 = SMatrix::<f32, NC, NQ>::zeros();
        let mut gamma32 = SVector::<f32, NC>::zeros();
        $f32.dynamics_terms(&q, &qd, 0.0, &mut m32, &mut h32, &mut phi_q32, &mut gamma32);
        let w: &mut [f64; 4] = $worst;
        for (k, e) in [
            relative(&m32, &m),
            relative(&h32, &h),
            relative(&phi_q32, &phi_q),
            relative(&gamma32, &gamma),
        ]
        .into_iter()
        .enumerate()
        {
            w[k] = w[k].max(e);
        }
    }};
}

#[test]
fn f32_terms_agree_with_f64_to_f32_resolution() {
    let limit = 2e-6;
    let robot = models::parallel_robot_rigid::ParallelRobotRigid;
    let robot32 = models::f32::parallel_robot_rigid::ParallelRobotRigid;
    let mut solver = motion::warm_solver(&robot).unwrap();
    let mut sol = motion::Solution::default();
    let mut worst = [0.0f64; 4];
    // 32 poses 0.1 s apart: more than a full turn of the circle at 2 rad/s.
    for k in (100..=3200).step_by(100) {
        assert!(
            motion::call(&robot, &mut solver, k, &mut sol),
            "no pose at call {k}"
        );
        worst_errors!(
            robot32,
            robot,
            parallel_robot_rigid,
            sol.q,
            sol.qd,
            &mut worst
        );
    }
    println!(
        "rigid robot, worst relative errors of M, h, Phi_q, gamma: {:.2e} {:.2e} {:.2e} {:.2e}",
        worst[0], worst[1], worst[2], worst[3]
    );
    assert!(worst.iter().all(|e| *e <= limit), "{worst:?}");

    let beam = models::spin_up_beam::SpinUpBeam::default();
    let beam32 = models::f32::spin_up_beam::SpinUpBeam::default();
    let mut worst = [0.0f64; 4];
    let mut seed = 0x2545_f491_4f6c_dd1du64;
    let mut uniform = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    for _ in 0..100 {
        let q = SVector::<f64, 5>::from_fn(|i, _| uniform() * if i == 0 { 3.0 } else { 0.05 });
        let qd = SVector::<f64, 5>::from_fn(|_, _| uniform() * 2.0);
        worst_errors!(beam32, beam, spin_up_beam, q, qd, &mut worst);
    }
    println!(
        "spin-up beam, worst relative errors of M, h, Phi_q, gamma: {:.2e} {:.2e} {:.2e} {:.2e}",
        worst[0], worst[1], worst[2], worst[3]
    );
    assert!(worst.iter().all(|e| *e <= limit), "{worst:?}");
}
