//! flexdyn's generated Rust for robots imported from URDF (UR5, Panda,
//! TIAGo as published, Solo12 and TALOS on fixed bases), against Pinocchio
//! on the same URDFs, side by side in one criterion run, on the same 300
//! seeded random states. Pinocchio runs twice: its templated library (C++ at
//! -O3, `src/shim.cpp`) and its algorithms generated to C (instantiated over
//! `casadi::SX` and exported by CasADi's `CodeGenerator` with `cse` on,
//! `src/generate_c.cpp`, compiled at -O3: "pinocchio C"), the anchor of a
//! user of Pinocchio's code generation:
//!
//! * `dynamics_terms` (M and h in one program) against `crba` +
//!   `nonLinearEffects` (templated; generated as one program and as two);
//! * the generated `inverse_dynamics` (`M qdd + h` as one program) against
//!   `rnea`;
//! * forward dynamics (generated terms + the runtime's Cholesky solve,
//!   `flexdyn_runtime::accelerations`) against `aba`;
//! * the generated `inverse_dynamics_derivatives` (`tau`, `d tau/dq`,
//!   `d tau/dqd` in one program) against `computeRNEADerivatives`, and the
//!   runtime's `forward_dynamics_derivatives` (generated terms and
//!   derivatives, a Cholesky factorisation and `2 nq + nu` solves) against
//!   `computeABADerivatives`;
//! * the end effector's pose and Jacobian in `LOCAL_WORLD_ALIGNED` (the
//!   generated `marker_jacobian` of the marker the import puts at the link)
//!   against `computeFrameJacobian` of a frame at the same place (fixed to
//!   the last joint at the placement the two agree on at `q = 0`; the
//!   generated C's frame is the link's frame in Pinocchio's own model).
//!
//! Each robot's operation counts are printed: flexdyn's from its module's
//! header (a `sin_cos` counts once), the C's from CasADi (instructions less
//! inputs, outputs and constants: a sine and a cosine count twice).
//!
//! Pinocchio's model is its own URDF parser's (run in Python by the build
//! script), rebuilt joint by joint in the shim so that all of Pinocchio's
//! code runs compiled with the shim's flags. The URDFs' joint damping is in
//! flexdyn's scenes (dampers) and added on Pinocchio's side by the shim (its
//! algorithms leave `model.damping` out).
//!
//! Before timing, every result of both sides is compared on every state
//! (coordinates matched by joint name); the run stops if they disagree by
//! more than 1e-9 relative to the scale of the term (flexdyn's import
//! snaps angles written as `1.57079632679` to `pi/2`: up to 1e-10 per
//! state).
//!
//! Times are the benchmark thread's CPU time (`CLOCK_THREAD_CPUTIME_ID`),
//! not wall-clock time, so that other jobs on a shared machine, which take
//! the core away for whole time slices, do not count (what they leave
//! behind in the caches still does).
//!
//! With `FLEXDYN_BENCH_INTERLEAVED` set, criterion is not used: each
//! comparison's functions are timed in turn, a batch of each per round, and
//! every ratio is the median of the per-round ratios ([`interleaved`]), so
//! that a host whose speed drifts over minutes slows both sides alike.

use std::ffi::{c_char, c_void, CStr, CString};

/// Largest relative difference to Pinocchio accepted before timing (per
/// state, relative to the larger of 1 and the state's largest magnitude):
/// the import's snapping of angles written to a few digits (4.9e-12 rad for
/// the UR5, up to 4e-10 N m in its bias forces) with room to spare.
const AGREEMENT: f64 = 1e-9;

/// The agreement asked of robot `name`: [`AGREEMENT`], plus ten times the
/// largest change the import's snapping made to an angle (`1.5708` taken as
/// `pi/2` moves it by 3.7e-6 rad, and the terms by as much relative to
/// their scale, where Pinocchio keeps the angle as written).
fn agreement(name: &str) -> f64 {
    AGREEMENT + 10.0 * snapped(name)
}

/// The agreement asked of the derivatives of robot `name`: as
/// [`agreement`], with a hundred times the largest snapped angle (the
/// forward dynamics' derivatives amplify a change of the model by `M`'s
/// conditioning: 25 times for the SO-101 arm's 3.7e-6 rad).
fn derivative_agreement(name: &str) -> f64 {
    AGREEMENT + 100.0 * snapped(name)
}

/// The largest change (rad) the import's snapping made to an angle of
/// robot `name`.
fn snapped(name: &str) -> f64 {
    robots::ROBOTS
        .iter()
        .find(|r| r.0 == name)
        .map_or(0.0, |r| r.3)
}

use criterion::measurement::{Measurement, ValueFormatter, WallTime};
use criterion::{black_box, criterion_group, criterion_main, Criterion};
use flexdyn_runtime::nalgebra::{DMatrix, SMatrix, SVector};
use flexdyn_runtime::{accelerations, forward_dynamics_derivatives, DynamicsConfig, Model};

mod robots {
    /// One joint of Pinocchio's model as its URDF parser built it (see
    /// `dump_model.py`): type by Pinocchio's short name, parent joint index
    /// (0 for the universe), axis (unaligned types), placement in the
    /// parent's frame (rotation row by row, translation), inertia (mass,
    /// centre of mass, rotational inertia about it row by row), damping.
    pub struct Joint {
        pub name: &'static str,
        pub kind: &'static str,
        pub parent: usize,
        pub axis: [f64; 3],
        pub placement: [f64; 12],
        pub inertia: [f64; 13],
        pub damping: f64,
    }
    // `ROBOTS`: per robot, its name, Pinocchio's joints, each flexdyn
    // coordinate with the URDF joint it comes from, and the largest change
    // (rad) that the import's snapping made to an angle.
    include!(concat!(env!("OUT_DIR"), "/robots.rs"));
}
/// The flexdyn module of every robot, and its source (for the operation
/// counts in its header).
macro_rules! flexdyn_modules {
    ($($robot:ident),*) => {
        $(
            #[allow(dead_code)]
            mod $robot {
                include!(concat!(env!("OUT_DIR"), "/flexdyn/", stringify!($robot), ".rs"));
            }
        )*
        const SOURCES: &[(&str, &str)] = &[$((
            stringify!($robot),
            include_str!(concat!(env!("OUT_DIR"), "/flexdyn/", stringify!($robot), ".rs")),
        )),*];
    };
}
// `flexdyn_modules!` of every robot and `robots`, which compares them (the
// robots of `FLEXDYN_BENCH_ROBOTS`, see `build.rs`).
include!(concat!(env!("OUT_DIR"), "/robot_list.rs"));

/// Pinocchio's algorithms generated to C by CasADi (`src/generate_c.cpp`),
/// per robot.
mod pinocchio_c {
    /// CasADi's calling convention: inputs, outputs, integer and real work.
    pub type CasadiFn =
        unsafe extern "C" fn(*const *const f64, *const *mut f64, *mut i64, *mut f64, i32) -> i32;
    /// One generated function: its entry point, operation count (CasADi's
    /// instructions less inputs, outputs and constants) and work sizes.
    pub struct CFunction {
        pub call: CasadiFn,
        pub operations: usize,
        pub sz_arg: usize,
        pub sz_res: usize,
        pub sz_iw: usize,
        pub sz_w: usize,
    }
    /// A robot's functions: `tau = rnea(q, v, a)`, `(M, nle) = crba_nle(q,
    /// v)` (one program), `M = crba(q)`, `nle(q, v)`, `ddq = aba(q, v, tau)`
    /// and, where the robot has a compared link, `(position, rotation,
    /// jacobian) = frame(q)`; all in Pinocchio's coordinate order, damping
    /// included as in the shim.
    pub struct Generated {
        pub rnea: Option<CFunction>,
        pub crba_nle: Option<CFunction>,
        pub crba: Option<CFunction>,
        pub nle: Option<CFunction>,
        pub aba: Option<CFunction>,
        pub frame: Option<CFunction>,
        pub rnea_derivatives: Option<CFunction>,
        pub aba_derivatives: Option<CFunction>,
    }
    include!(concat!(env!("OUT_DIR"), "/pinocchio_c.rs"));
}

extern "C" {
    fn pin_bench_new() -> *mut c_void;
    #[allow(clippy::too_many_arguments)]
    fn pin_bench_add_joint(
        b: *mut c_void,
        name: *const c_char,
        kind: *const c_char,
        parent: i32,
        axis: *const f64,
        placement: *const f64,
        inertia: *const f64,
        damping: f64,
        err: *mut c_char,
        errlen: usize,
    ) -> i32;
    fn pin_bench_finish(b: *mut c_void);
    fn pin_bench_free(b: *mut c_void);
    fn pin_bench_nv(b: *const c_void) -> i32;
    fn pin_bench_joint_name(b: *const c_void, i: i32) -> *const c_char;
    fn pin_bench_crba_nle(b: *mut c_void, q: *const f64, v: *const f64);
    fn pin_bench_rnea(b: *mut c_void, q: *const f64, v: *const f64, a: *const f64);
    fn pin_bench_aba(b: *mut c_void, q: *const f64, v: *const f64, tau: *const f64);
    fn pin_bench_rnea_derivatives(b: *mut c_void, q: *const f64, v: *const f64, a: *const f64);
    fn pin_bench_aba_derivatives(b: *mut c_void, q: *const f64, v: *const f64, tau: *const f64);
    fn pin_bench_read_rnea_derivatives(b: *const c_void, dq: *mut f64, dv: *mut f64);
    fn pin_bench_read_aba_derivatives(b: *const c_void, dq: *mut f64, dv: *mut f64, minv: *mut f64);
    fn pin_bench_joint_placement(b: *mut c_void, q: *const f64, joint: i32, out: *mut f64);
    fn pin_bench_add_frame(b: *mut c_void, joint: i32, placement: *const f64) -> i32;
    fn pin_bench_frame_jacobian(b: *mut c_void, frame: i32, q: *const f64);
    fn pin_bench_read_frame(
        b: *const c_void,
        frame: i32,
        position: *mut f64,
        rotation: *mut f64,
        jacobian: *mut f64,
    );
    fn pin_bench_read(
        b: *const c_void,
        v: *const f64,
        m: *mut f64,
        nle: *mut f64,
        tau: *mut f64,
        ddq: *mut f64,
    );
}

/// Criterion measurement by the CPU time of the calling thread, in
/// nanoseconds (shown as durations, like wall-clock time).
struct ThreadCpuTime;

/// This thread's CPU time in nanoseconds.
fn thread_ns() -> f64 {
    let mut t = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `t` is a valid timespec for the call to fill.
    let status = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut t) };
    assert_eq!(status, 0, "clock_gettime(CLOCK_THREAD_CPUTIME_ID) failed");
    t.tv_sec as f64 * 1e9 + t.tv_nsec as f64
}

/// Wall-clock time's formatter, for durations in nanoseconds.
static DURATIONS: WallTime = WallTime;

impl Measurement for ThreadCpuTime {
    type Intermediate = f64;
    type Value = f64;
    fn start(&self) -> f64 {
        thread_ns()
    }
    fn end(&self, start: f64) -> f64 {
        thread_ns() - start
    }
    fn add(&self, a: &f64, b: &f64) -> f64 {
        a + b
    }
    fn zero(&self) -> f64 {
        0.0
    }
    fn to_f64(&self, value: &f64) -> f64 {
        *value
    }
    fn formatter(&self) -> &dyn ValueFormatter {
        DURATIONS.formatter()
    }
}

/// A Pinocchio model and data, with its velocity order mapped to flexdyn's
/// coordinates: `to_pin[i]` is Pinocchio's index of flexdyn coordinate `i`.
struct Pinocchio {
    handle: *mut c_void,
    to_pin: Vec<usize>,
}

impl Pinocchio {
    fn load(name: &str, coordinates: &[&str]) -> Pinocchio {
        let (_, joints, urdf_joints, _) = robots::ROBOTS
            .iter()
            .find(|r| r.0 == name)
            .expect("robot listed by build.rs");
        // SAFETY: no arguments; freed by `Drop` (or below on error).
        let handle = unsafe { pin_bench_new() };
        let mut err = vec![0 as c_char; 512];
        for (i, joint) in joints.iter().enumerate() {
            let joint_name = CString::new(joint.name).expect("name without NUL");
            let kind = CString::new(joint.kind).expect("type without NUL");
            // SAFETY: `handle` is live, the strings NUL-terminated, the
            // arrays as long as the shim reads, `err` holds `err.len()` bytes.
            let status = unsafe {
                pin_bench_add_joint(
                    handle,
                    joint_name.as_ptr(),
                    kind.as_ptr(),
                    joint.parent as i32,
                    joint.axis.as_ptr(),
                    joint.placement.as_ptr(),
                    joint.inertia.as_ptr(),
                    joint.damping,
                    err.as_mut_ptr(),
                    err.len(),
                )
            };
            if status != 0 {
                // SAFETY: created above, not used again; the shim wrote a
                // NUL-terminated message.
                let msg = unsafe {
                    pin_bench_free(handle);
                    CStr::from_ptr(err.as_ptr())
                };
                panic!(
                    "Pinocchio model of {name}, joint {}: {}",
                    i + 1,
                    msg.to_string_lossy()
                );
            }
        }
        // SAFETY: `handle` is a live model.
        unsafe { pin_bench_finish(handle) };
        // SAFETY: `handle` is a live model.
        let nv = unsafe { pin_bench_nv(handle) } as usize;
        assert_eq!(
            nv,
            coordinates.len(),
            "{name}: Pinocchio has {nv} velocities"
        );
        let names: Vec<String> = (0..nv)
            // SAFETY: the index is in range; the shim returns a NUL-terminated name.
            .map(|i| unsafe { CStr::from_ptr(pin_bench_joint_name(handle, i as i32)) })
            .map(|s| s.to_string_lossy().into_owned())
            .collect();
        // Coordinates by the URDF joint they come from (names that are not
        // identifiers are rewritten by the import).
        let to_pin = coordinates
            .iter()
            .map(|c| {
                let joint = urdf_joints
                    .iter()
                    .find(|(coordinate, _)| coordinate == c)
                    .map_or(*c, |(_, joint)| joint);
                names
                    .iter()
                    .position(|n| n == joint)
                    .unwrap_or_else(|| panic!("{name}: Pinocchio has no joint {c} ({names:?})"))
            })
            .collect();
        Pinocchio { handle, to_pin }
    }

    fn to_pin<const N: usize>(&self, x: &SVector<f64, N>) -> Vec<f64> {
        let mut y = vec![0.0; N];
        for (i, &p) in self.to_pin.iter().enumerate() {
            y[p] = x[i];
        }
        y
    }
}

impl Drop for Pinocchio {
    fn drop(&mut self) {
        // SAFETY: created by `pin_bench_new`, freed once.
        unsafe { pin_bench_free(self.handle) }
    }
}

/// A generated C function with its work arrays, called on slices.
struct CCall {
    f: &'static pinocchio_c::CFunction,
    arg: Vec<*const f64>,
    res: Vec<*mut f64>,
    iw: Vec<i64>,
    w: Vec<f64>,
}

impl CCall {
    fn new(f: &'static Option<pinocchio_c::CFunction>, what: &str) -> CCall {
        let f = f
            .as_ref()
            .unwrap_or_else(|| panic!("no generated C for {what}"));
        CCall {
            f,
            arg: vec![std::ptr::null(); f.sz_arg],
            res: vec![std::ptr::null_mut(); f.sz_res],
            iw: vec![0; f.sz_iw],
            w: vec![0.0; f.sz_w],
        }
    }

    /// Evaluates the function of `inputs` into `outputs`, each as long as
    /// the function's input or output (dense, column-major).
    fn call(&mut self, inputs: &[&[f64]], outputs: &mut [&mut [f64]]) {
        for (k, x) in inputs.iter().enumerate() {
            self.arg[k] = x.as_ptr();
        }
        for (k, y) in outputs.iter_mut().enumerate() {
            self.res[k] = y.as_mut_ptr();
        }
        // SAFETY: the argument and result arrays are as long as the
        // generated code's `sz_arg` and `sz_res`, their first entries point
        // at arrays of the function's input and output sizes, and the work
        // arrays are `sz_iw` and `sz_w` long, as CasADi's convention asks.
        let status = unsafe {
            (self.f.call)(
                self.arg.as_ptr(),
                self.res.as_ptr(),
                self.iw.as_mut_ptr(),
                self.w.as_mut_ptr(),
                0,
            )
        };
        debug_assert_eq!(status, 0);
    }
}

/// The generated C functions of robot `name`.
fn generated_c(name: &str) -> &'static pinocchio_c::Generated {
    &pinocchio_c::GENERATED
        .iter()
        .find(|r| r.0 == name)
        .expect("robot generated by build.rs")
        .1
}

/// Operations (add + mul + div + call) of `function` in flexdyn's module of
/// robot `name`, from the counts in its header (a marker's function is
/// named with its marker: `marker_jacobian (tool0)`).
fn flexdyn_operations(name: &str, function: &str) -> usize {
    generated_operations(name, function)
        .unwrap_or_else(|| panic!("{name}: no operation count of {function}"))
}

/// [`flexdyn_operations`], `None` where the module has no such function
/// (no generated `forward_dynamics` above 40 coordinates or for a singular
/// mass matrix).
fn generated_operations(name: &str, function: &str) -> Option<usize> {
    let source = SOURCES.iter().find(|s| s.0 == name).expect("module").1;
    source
        .lines()
        .take_while(|l| l.starts_with("//"))
        .find_map(|l| {
            let counts = l
                .trim_start_matches("//")
                .trim_start()
                .strip_prefix(function)?;
            let counts: Vec<usize> = counts
                .split_whitespace()
                .map(|w| w.parse().ok())
                .collect::<Option<_>>()?;
            (counts.len() == 4).then(|| counts.iter().sum())
        })
}

/// One random state: `q`, `qd`, `qdd` and `tau`, each in Pinocchio's order
/// too.
struct State<const N: usize> {
    q: SVector<f64, N>,
    qd: SVector<f64, N>,
    qdd: SVector<f64, N>,
    tau: SVector<f64, N>,
    pin: [Vec<f64>; 4],
}

/// `count` states from a fixed-seed generator: angles in [-pi, pi], rates
/// in [-2, 2] rad/s, accelerations in [-5, 5] rad/s^2, torques in [-20, 20].
fn states<const N: usize>(pin: &Pinocchio, count: usize) -> Vec<State<N>> {
    let mut seed: u64 = 0x5EED_F1E7;
    let mut uniform = move |a: f64| {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        a * (2.0 * ((seed >> 11) as f64 / (1u64 << 53) as f64) - 1.0)
    };
    (0..count)
        .map(|_| {
            let q = SVector::<f64, N>::from_fn(|_, _| uniform(std::f64::consts::PI));
            let qd = SVector::<f64, N>::from_fn(|_, _| uniform(2.0));
            let qdd = SVector::<f64, N>::from_fn(|_, _| uniform(5.0));
            let tau = SVector::<f64, N>::from_fn(|_, _| uniform(20.0));
            let pin = [
                pin.to_pin(&q),
                pin.to_pin(&qd),
                pin.to_pin(&qdd),
                pin.to_pin(&tau),
            ];
            State {
                q,
                qd,
                qdd,
                tau,
                pin,
            }
        })
        .collect()
}

/// Largest difference of two equally long slices relative to the larger of
/// their largest magnitudes (or 1).
fn relative_error(a: &[f64], b: &[f64]) -> f64 {
    let scale = a.iter().chain(b).fold(1.0f64, |s, x| s.max(x.abs()));
    a.iter()
        .zip(b)
        .fold(0.0f64, |e, (x, y)| e.max((x - y).abs()))
        / scale
}

/// `cond(M)` of the symmetric positive definite `m` (at least 1).
fn condition<const N: usize>(m: &SMatrix<f64, N, N>) -> f64 {
    let e = DMatrix::from_column_slice(N, N, m.as_slice()).symmetric_eigenvalues();
    let (lo, hi) = e.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), x| {
        (lo.min(x.abs()), hi.max(x.abs()))
    });
    (hi / lo).max(1.0)
}

/// `M qdd + h` by the generated `inverse_dynamics` program.
fn inverse_dynamics<R: Model<N, 0, N>, const N: usize>(r: &R, s: &State<N>) -> SVector<f64, N> {
    let mut tau = SVector::<f64, N>::zeros();
    r.inverse_dynamics(&s.q, &s.qd, &s.qdd, 0.0, &mut tau);
    tau
}

fn compare<R: Model<N, 0, N> + Default, const N: usize>(
    c: &mut Criterion<ThreadCpuTime>,
    name: &str,
) {
    let robot = R::default();
    let pin = Pinocchio::load(name, &R::COORDINATES);
    let states = states::<N>(&pin, 300);
    let config = DynamicsConfig::default();
    let generated = generated_c(name);
    let mut c_rnea = CCall::new(&generated.rnea, "rnea");
    let mut c_crba_nle = CCall::new(&generated.crba_nle, "crba_nle");
    let mut c_crba = CCall::new(&generated.crba, "crba");
    let mut c_nle = CCall::new(&generated.nle, "nle");
    let mut c_aba = CCall::new(&generated.aba, "aba");
    // A robot whose mass matrix is singular (Romeo as published: finger
    // joints that move no mass) has no forward dynamics, on either side
    // (Pinocchio's `aba` is not finite there): compared and timed without.
    let forward = match accelerations(
        &robot,
        &config,
        &states[0].q,
        &states[0].qd,
        0.0,
        &states[0].tau,
    ) {
        Ok(_) => true,
        Err(e) => {
            println!("{name}: no forward dynamics ({e}): not compared, not timed");
            false
        }
    };
    // The accelerations' difference to each side (templated, C) divided by
    // the state's `cond(M)`, and undivided: a forward solve turns the models'
    // difference (the snapped angles, round-off) into up to `cond(M)` times
    // as much (iCub's 1e10; the UR5's 3e2), so its agreement is asked
    // relative to it. `M`, `h` and `rnea`, which check the model itself, are
    // asked `agreement` as they are.
    let (mut aba_raw, mut conditioning) = ([0.0f64; 2], 1.0f64);
    let mut worst = [0.0f64; 4];
    // Pinocchio's generated C against flexdyn: M (fused), h (fused), tau,
    // ddq, M (crba alone), h (nle alone).
    let mut worst_c = [0.0f64; 6];
    for s in &states {
        let mut m = SMatrix::<f64, N, N>::zeros();
        let mut h = SVector::<f64, N>::zeros();
        let mut phi_q = SMatrix::<f64, 0, N>::zeros();
        let mut gamma = SVector::<f64, 0>::zeros();
        robot.dynamics_terms(&s.q, &s.qd, 0.0, &mut m, &mut h, &mut phi_q, &mut gamma);
        let tau = inverse_dynamics(&robot, s);
        let qdd = match forward {
            true => {
                accelerations(&robot, &config, &s.q, &s.qd, 0.0, &s.tau)
                    .expect("forward dynamics")
                    .qdd
            }
            false => SVector::<f64, N>::repeat(f64::NAN),
        };
        let (mut pm, mut ph, mut pt, mut pa) =
            (vec![0.0; N * N], vec![0.0; N], vec![0.0; N], vec![0.0; N]);
        // SAFETY: every array holds N (or N * N) numbers, as the model has N velocities.
        unsafe {
            pin_bench_crba_nle(pin.handle, s.pin[0].as_ptr(), s.pin[1].as_ptr());
            pin_bench_rnea(
                pin.handle,
                s.pin[0].as_ptr(),
                s.pin[1].as_ptr(),
                s.pin[2].as_ptr(),
            );
            pin_bench_aba(
                pin.handle,
                s.pin[0].as_ptr(),
                s.pin[1].as_ptr(),
                s.pin[3].as_ptr(),
            );
            pin_bench_read(
                pin.handle,
                s.pin[1].as_ptr(),
                pm.as_mut_ptr(),
                ph.as_mut_ptr(),
                pt.as_mut_ptr(),
                pa.as_mut_ptr(),
            );
        }
        let p = &pin.to_pin;
        let ours_m: Vec<f64> = (0..N * N).map(|k| m[(k % N, k / N)]).collect();
        let theirs_m: Vec<f64> = (0..N * N).map(|k| pm[p[k % N] + N * p[k / N]]).collect();
        let pick = |v: &[f64]| -> Vec<f64> { p.iter().map(|&i| v[i]).collect() };
        worst[0] = worst[0].max(relative_error(&ours_m, &theirs_m));
        worst[1] = worst[1].max(relative_error(h.as_slice(), &pick(&ph)));
        worst[2] = worst[2].max(relative_error(tau.as_slice(), &pick(&pt)));
        // `cond(M)` once per state (an eigendecomposition), where it is used.
        let cond = match forward {
            true => condition(&m),
            false => 1.0,
        };
        conditioning = conditioning.max(cond);
        if forward {
            let e = relative_error(qdd.as_slice(), &pick(&pa));
            worst[3] = worst[3].max(e / cond);
            aba_raw[0] = aba_raw[0].max(e);
        }
        let (q, v, a, t) = (&s.pin[0][..], &s.pin[1][..], &s.pin[2][..], &s.pin[3][..]);
        let (mut cm, mut ch, mut ct, mut ca, mut cm2, mut ch2) = (
            vec![0.0; N * N],
            vec![0.0; N],
            vec![0.0; N],
            vec![0.0; N],
            vec![0.0; N * N],
            vec![0.0; N],
        );
        c_crba_nle.call(&[q, v], &mut [&mut cm, &mut ch]);
        c_rnea.call(&[q, v, a], &mut [&mut ct]);
        c_aba.call(&[q, v, t], &mut [&mut ca]);
        c_crba.call(&[q], &mut [&mut cm2]);
        c_nle.call(&[q, v], &mut [&mut ch2]);
        let reorder =
            |m: &[f64]| -> Vec<f64> { (0..N * N).map(|k| m[p[k % N] + N * p[k / N]]).collect() };
        for (k, (ours, theirs)) in [
            (&ours_m[..], reorder(&cm)),
            (h.as_slice(), pick(&ch)),
            (tau.as_slice(), pick(&ct)),
            (qdd.as_slice(), pick(&ca)),
            (&ours_m[..], reorder(&cm2)),
            (h.as_slice(), pick(&ch2)),
        ]
        .into_iter()
        .enumerate()
        {
            match k {
                3 if forward => {
                    let e = relative_error(ours, &theirs);
                    worst_c[k] = worst_c[k].max(e / cond);
                    aba_raw[1] = aba_raw[1].max(e);
                }
                3 => {}
                _ => worst_c[k] = worst_c[k].max(relative_error(ours, &theirs)),
            }
        }
    }
    let aba = |e: f64| match forward {
        true => {
            format!("{e:.1e} (cond(M) up to {conditioning:.0e}; accepted: that many times more)")
        }
        false => "none".to_owned(),
    };
    println!(
        "{name}: {N} joints; largest relative difference to Pinocchio over {} states: \
         M {:.1e}, h {:.1e}, rnea {:.1e}, aba {} (accepted: {:.1e})",
        states.len(),
        worst[0],
        worst[1],
        worst[2],
        aba(aba_raw[0]),
        agreement(name)
    );
    // The import snaps angles written to a few digits (UR5's
    // `1.57079632679`) to exact multiples of pi/12, which Pinocchio keeps as
    // written: about 5e-12 of the scale for the UR5 (see `agreement`).
    println!(
        "{name}: largest relative difference to Pinocchio's generated C: M {:.1e} (crba alone \
         {:.1e}), h {:.1e} (nle alone {:.1e}), rnea {:.1e}, aba {}",
        worst_c[0],
        worst_c[4],
        worst_c[1],
        worst_c[5],
        worst_c[2],
        aba(aba_raw[1])
    );
    assert!(
        worst.iter().all(|&e| e < agreement(name)),
        "{name}: flexdyn and Pinocchio disagree"
    );
    assert!(
        worst_c.iter().all(|&e| e < agreement(name)),
        "{name}: flexdyn and Pinocchio's generated C disagree"
    );
    let ops = |f: &Option<pinocchio_c::CFunction>| f.as_ref().map_or(0, |f| f.operations);
    println!(
        "{name}: operations, flexdyn / Pinocchio's generated C: inverse dynamics {} / {} (rnea); \
         M + h {} / {} (crba + nle in one program; {} + {} separately); forward dynamics {} \
         / {} (aba)",
        flexdyn_operations(name, "inverse_dynamics"),
        ops(&generated.rnea),
        flexdyn_operations(name, "dynamics_terms"),
        ops(&generated.crba_nle),
        ops(&generated.crba),
        ops(&generated.nle),
        generated_operations(name, "forward_dynamics").map_or_else(
            || "none generated (the runtime factors `M`)".to_owned(),
            |n| n.to_string()
        ),
        ops(&generated.aba),
    );

    let (robot, states, config, pin) = (&robot, &states, &config, &pin);
    let mut terms = vec![
        vec![
            timed("flexdyn dynamics_terms", {
                let (mut m, mut h) = (SMatrix::<f64, N, N>::zeros(), SVector::<f64, N>::zeros());
                let (mut phi_q, mut gamma) =
                    (SMatrix::<f64, 0, N>::zeros(), SVector::<f64, 0>::zeros());
                let mut i = 0;
                move || {
                    let s = next(states, &mut i);
                    robot.dynamics_terms(&s.q, &s.qd, 0.0, &mut m, &mut h, &mut phi_q, &mut gamma);
                    black_box((&m, &h));
                }
            }),
            timed("pinocchio crba + nonLinearEffects", {
                let mut i = 0;
                move || {
                    let s = next(states, &mut i);
                    // SAFETY: arrays of N numbers for a model of N velocities.
                    unsafe { pin_bench_crba_nle(pin.handle, s.pin[0].as_ptr(), s.pin[1].as_ptr()) }
                }
            }),
            timed("pinocchio C crba + nle", {
                let (mut m, mut h) = (vec![0.0; N * N], vec![0.0; N]);
                let mut i = 0;
                move || {
                    let s = next(states, &mut i);
                    c_crba_nle.call(&[&s.pin[0], &s.pin[1]], &mut [&mut m, &mut h]);
                    black_box((&m, &h));
                }
            }),
            timed("pinocchio C crba, nle", {
                let (mut m, mut h) = (vec![0.0; N * N], vec![0.0; N]);
                let mut i = 0;
                move || {
                    let s = next(states, &mut i);
                    c_crba.call(&[&s.pin[0]], &mut [&mut m]);
                    c_nle.call(&[&s.pin[0], &s.pin[1]], &mut [&mut h]);
                    black_box((&m, &h));
                }
            }),
        ],
        vec![
            timed("flexdyn inverse_dynamics", {
                let mut i = 0;
                move || black_box(inverse_dynamics(robot, next(states, &mut i)))
            }),
            templated("pinocchio rnea", pin, states, pin_bench_rnea, 2),
            c_vector("pinocchio C rnea", c_rnea, states, 2),
        ],
    ];
    if forward {
        terms.push(vec![
            timed("flexdyn forward dynamics", {
                let mut i = 0;
                move || {
                    let s = next(states, &mut i);
                    black_box(accelerations(robot, config, &s.q, &s.qd, 0.0, &s.tau).map(|a| a.qdd))
                }
            }),
            templated("pinocchio aba", pin, states, pin_bench_aba, 3),
            c_vector("pinocchio C aba", c_aba, states, 3),
        ]);
    }
    time_group(c, name, terms);
}

/// The generated `inverse_dynamics_derivatives` (`d tau/dq`, `d tau/dqd`)
/// against `computeRNEADerivatives`, and the runtime's
/// `forward_dynamics_derivatives` (`d qdd/dq`, `d qdd/dqd`, `d qdd/dtau`)
/// against `computeABADerivatives`: checked on every state, then timed side
/// by side.
fn compare_derivatives<R: Model<N, 0, N> + Default, const N: usize>(
    c: &mut Criterion<ThreadCpuTime>,
    name: &str,
) {
    let robot = R::default();
    let pin = Pinocchio::load(name, &R::COORDINATES);
    let states = states::<N>(&pin, 300);
    let p = &pin.to_pin;
    // Pinocchio's column-major n x n matrix in flexdyn's coordinate order.
    let reorder =
        |m: &[f64]| -> Vec<f64> { (0..N * N).map(|k| m[p[k % N] + N * p[k / N]]).collect() };
    let generated = generated_c(name);
    let mut c_rnea = CCall::new(&generated.rnea_derivatives, "rnea derivatives");
    let mut c_aba = CCall::new(&generated.aba_derivatives, "aba derivatives");
    let mut worst = [0.0f64; 5];
    // Pinocchio's generated C against its analytical derivatives (both in
    // Pinocchio's coordinate order).
    let mut worst_c = [0.0f64; 5];
    for s in &states {
        let mut tau = SVector::<f64, N>::zeros();
        let (mut tq, mut tv) = (SMatrix::<f64, N, N>::zeros(), SMatrix::<f64, N, N>::zeros());
        assert!(robot
            .inverse_dynamics_derivatives(&s.q, &s.qd, &s.qdd, 0.0, &mut tau, &mut tq, &mut tv));
        let d =
            forward_dynamics_derivatives(&robot, &s.q, &s.qd, 0.0, &s.tau).unwrap_or_else(|e| {
                panic!(
                "{name}: no forward dynamics to differentiate ({e}); leave `;derivatives` out for \
                 this robot"
            )
            });
        let (mut dq, mut dv, mut fq, mut fv, mut minv) = (
            vec![0.0; N * N],
            vec![0.0; N * N],
            vec![0.0; N * N],
            vec![0.0; N * N],
            vec![0.0; N * N],
        );
        // SAFETY: every array holds N or N * N numbers, as the model has N velocities.
        unsafe {
            pin_bench_rnea_derivatives(
                pin.handle,
                s.pin[0].as_ptr(),
                s.pin[1].as_ptr(),
                s.pin[2].as_ptr(),
            );
            pin_bench_read_rnea_derivatives(pin.handle, dq.as_mut_ptr(), dv.as_mut_ptr());
            pin_bench_aba_derivatives(
                pin.handle,
                s.pin[0].as_ptr(),
                s.pin[1].as_ptr(),
                s.pin[3].as_ptr(),
            );
            pin_bench_read_aba_derivatives(
                pin.handle,
                fq.as_mut_ptr(),
                fv.as_mut_ptr(),
                minv.as_mut_ptr(),
            );
        }
        for (k, (ours, theirs)) in [
            (tq.as_slice(), &dq),
            (tv.as_slice(), &dv),
            (d.qdd_q.as_slice(), &fq),
            (d.qdd_qd.as_slice(), &fv),
            (d.qdd_tau.as_slice(), &minv),
        ]
        .into_iter()
        .enumerate()
        {
            worst[k] = worst[k].max(relative_error(ours, &reorder(theirs)));
        }
        let mut c = [vec![0.0; N], vec![0.0; N * N], vec![0.0; N * N]];
        let [c_tau, c_tq, c_tv] = &mut c;
        c_rnea.call(
            &[&s.pin[0], &s.pin[1], &s.pin[2]],
            &mut [c_tau.as_mut_slice(), c_tq, c_tv],
        );
        let mut f = [
            vec![0.0; N],
            vec![0.0; N * N],
            vec![0.0; N * N],
            vec![0.0; N * N],
        ];
        let [c_ddq, c_fq, c_fv, c_minv] = &mut f;
        c_aba.call(
            &[&s.pin[0], &s.pin[1], &s.pin[3]],
            &mut [c_ddq.as_mut_slice(), c_fq, c_fv, c_minv],
        );
        for (k, (c, theirs)) in [
            (&c[1], &dq),
            (&c[2], &dv),
            (&f[1], &fq),
            (&f[2], &fv),
            (&f[3], &minv),
        ]
        .into_iter()
        .enumerate()
        {
            worst_c[k] = worst_c[k].max(relative_error(c, theirs));
        }
    }
    println!(
        "{name}: Pinocchio's generated C (CasADi's Jacobians of rnea and aba) against its analytical \
         derivatives: dtau/dq {:.1e}, dtau/dv {:.1e}, ddq/dq {:.1e}, ddq/dv {:.1e}, ddq/dtau {:.1e}; \
         operations, flexdyn inverse_dynamics_derivatives / C: {} / {}; C aba derivatives: {}",
        worst_c[0],
        worst_c[1],
        worst_c[2],
        worst_c[3],
        worst_c[4],
        flexdyn_operations(name, "inverse_dynamics_derivatives"),
        c_rnea.f.operations,
        c_aba.f.operations
    );
    assert!(
        worst_c.iter().all(|&e| e < 1e-9),
        "{name}: Pinocchio's generated derivatives disagree with its analytical ones"
    );
    println!(
        "{name}: largest relative difference to Pinocchio's derivatives over {} states: \
         dtau/dq {:.1e}, dtau/dv {:.1e}, ddq/dq {:.1e}, ddq/dv {:.1e}, ddq/dtau {:.1e} \
         (accepted: {:.1e})",
        states.len(),
        worst[0],
        worst[1],
        worst[2],
        worst[3],
        worst[4],
        derivative_agreement(name)
    );
    assert!(
        worst.iter().all(|&e| e < derivative_agreement(name)),
        "{name}: flexdyn's and Pinocchio's derivatives disagree"
    );
    let (robot, states, pin) = (&robot, &states, &pin);
    let terms = vec![
        vec![
            timed("flexdyn inverse_dynamics_derivatives", {
                let mut tau = SVector::<f64, N>::zeros();
                let (mut tq, mut tv) =
                    (SMatrix::<f64, N, N>::zeros(), SMatrix::<f64, N, N>::zeros());
                let mut i = 0;
                move || {
                    let s = next(states, &mut i);
                    robot.inverse_dynamics_derivatives(
                        &s.q, &s.qd, &s.qdd, 0.0, &mut tau, &mut tq, &mut tv,
                    );
                    black_box((&tau, &tq, &tv));
                }
            }),
            templated(
                "pinocchio computeRNEADerivatives",
                pin,
                states,
                pin_bench_rnea_derivatives,
                2,
            ),
            timed("pinocchio C rnea derivatives", {
                let mut out = [vec![0.0; N], vec![0.0; N * N], vec![0.0; N * N]];
                let mut i = 0;
                move || {
                    let s = next(states, &mut i);
                    let [tau, tq, tv] = &mut out;
                    c_rnea.call(
                        &[&s.pin[0], &s.pin[1], &s.pin[2]],
                        &mut [tau.as_mut_slice(), tq, tv],
                    );
                    black_box(&out);
                }
            }),
        ],
        vec![
            timed("flexdyn forward_dynamics_derivatives", {
                let mut i = 0;
                move || {
                    let s = next(states, &mut i);
                    black_box(
                        forward_dynamics_derivatives(robot, &s.q, &s.qd, 0.0, &s.tau)
                            .map(|d| d.qdd),
                    )
                }
            }),
            timed("pinocchio C aba derivatives", {
                let mut out = [
                    vec![0.0; N],
                    vec![0.0; N * N],
                    vec![0.0; N * N],
                    vec![0.0; N * N],
                ];
                let mut i = 0;
                move || {
                    let s = next(states, &mut i);
                    let [ddq, fq, fv, minv] = &mut out;
                    c_aba.call(
                        &[&s.pin[0], &s.pin[1], &s.pin[3]],
                        &mut [ddq.as_mut_slice(), fq, fv, minv],
                    );
                    black_box(&out);
                }
            }),
            templated(
                "pinocchio computeABADerivatives",
                pin,
                states,
                pin_bench_aba_derivatives,
                3,
            ),
        ],
    ];
    time_group(c, &format!("{name} derivatives"), terms);
}

/// The generated pose and Jacobian of marker `marker` against Pinocchio's
/// `computeFrameJacobian` of a frame fixed to its last joint at the same
/// place: checked on every state, then timed side by side.
fn compare_marker<R: Model<N, 0, N> + Default, const N: usize>(
    c: &mut Criterion<ThreadCpuTime>,
    name: &str,
    marker: &str,
) {
    let robot = R::default();
    let pin = Pinocchio::load(name, &R::COORDINATES);
    let k = R::MARKERS
        .iter()
        .position(|m| *m == marker)
        .unwrap_or_else(|| panic!("{name} has no marker {marker}"));
    let states = states::<N>(&pin, 300);
    let (mut p, mut r, mut j) = (
        SVector::<f64, 3>::zeros(),
        SMatrix::<f64, 3, 3>::zeros(),
        SMatrix::<f64, 6, N>::zeros(),
    );
    // The marker in the last joint's frame, from both poses at q = 0.
    let zero = SVector::<f64, N>::zeros();
    assert!(robot.marker_jacobian(k, &zero, 0.0, &mut p, &mut r, &mut j));
    let mut joint = [0.0; 12];
    // SAFETY: `q` holds N numbers, `joint` 12; the joint index is the last.
    unsafe { pin_bench_joint_placement(pin.handle, zero.as_ptr(), N as i32, joint.as_mut_ptr()) };
    let rj = SMatrix::<f64, 3, 3>::from_row_slice(&joint[..9]);
    let pj = SVector::<f64, 3>::from_column_slice(&joint[9..]);
    let (rel_r, rel_p) = (rj.transpose() * r, rj.transpose() * (p - pj));
    let mut placement = [0.0; 12];
    for i in 0..3 {
        for c in 0..3 {
            placement[3 * i + c] = rel_r[(i, c)];
        }
        placement[9 + i] = rel_p[i];
    }
    // SAFETY: 12 numbers; the joint exists.
    let frame = unsafe { pin_bench_add_frame(pin.handle, N as i32, placement.as_ptr()) };
    let mut c_frame = CCall::new(&generated_c(name).frame, "frame");
    let mut worst = 0.0f64;
    let mut worst_c = 0.0f64;
    for s in &states {
        assert!(robot.marker_jacobian(k, &s.q, 0.0, &mut p, &mut r, &mut j));
        let (mut pp, mut pr, mut pjac) = ([0.0; 3], [0.0; 9], vec![0.0; 6 * N]);
        // SAFETY: N numbers in, 3, 9 and 6 N out.
        unsafe {
            pin_bench_frame_jacobian(pin.handle, frame, s.pin[0].as_ptr());
            pin_bench_read_frame(
                pin.handle,
                frame,
                pp.as_mut_ptr(),
                pr.as_mut_ptr(),
                pjac.as_mut_ptr(),
            );
        }
        let ours: Vec<f64> = p
            .iter()
            .chain(r.transpose().iter())
            .chain((0..6 * N).map(|e| &j[(e % 6, e / 6)]))
            .copied()
            .collect();
        let to_pin = &pin.to_pin;
        let theirs: Vec<f64> = pp
            .iter()
            .chain(&pr)
            .copied()
            .chain((0..6 * N).map(|e| pjac[e % 6 + 6 * to_pin[e / 6]]))
            .collect();
        worst = worst.max(relative_error(&ours, &theirs));
        let (mut cp, mut cr, mut cj) = ([0.0; 3], [0.0; 9], vec![0.0; 6 * N]);
        c_frame.call(&[&s.pin[0]], &mut [&mut cp, &mut cr, &mut cj]);
        // The generated rotation is column-major: transposed to rows.
        let theirs_c: Vec<f64> = cp
            .iter()
            .copied()
            .chain((0..9).map(|e| cr[3 * (e % 3) + e / 3]))
            .chain((0..6 * N).map(|e| cj[e % 6 + 6 * to_pin[e / 6]]))
            .collect();
        worst_c = worst_c.max(relative_error(&ours, &theirs_c));
    }
    println!(
        "{name}: marker {marker}: largest relative difference of position, rotation and \
         Jacobian to Pinocchio's computeFrameJacobian over {} states: {worst:.1e}",
        states.len()
    );
    println!(
        "{name}: marker {marker}: largest relative difference to Pinocchio's generated C: \
         {worst_c:.1e}; operations, flexdyn / C: {} / {}",
        flexdyn_operations(name, &format!("marker_jacobian ({marker})")),
        c_frame.f.operations
    );
    assert!(
        worst < agreement(name),
        "{name}: flexdyn and Pinocchio disagree"
    );
    assert!(
        worst_c < agreement(name),
        "{name}: flexdyn and Pinocchio's generated C disagree"
    );
    let (robot, states, pin) = (&robot, &states, &pin);
    let terms = vec![vec![
        timed("flexdyn marker_jacobian", {
            let mut i = 0;
            move || {
                let s = next(states, &mut i);
                robot.marker_jacobian(k, &s.q, 0.0, &mut p, &mut r, &mut j);
                black_box((&p, &r, &j));
            }
        }),
        timed("pinocchio computeFrameJacobian", {
            let mut i = 0;
            move || {
                let s = next(states, &mut i);
                // SAFETY: N numbers for a model of N velocities.
                unsafe { pin_bench_frame_jacobian(pin.handle, frame, s.pin[0].as_ptr()) }
            }
        }),
        timed("pinocchio C frame Jacobian", {
            let (mut cp, mut cr, mut cj) = ([0.0; 3], [0.0; 9], vec![0.0; 6 * N]);
            let mut i = 0;
            move || {
                let s = next(states, &mut i);
                c_frame.call(&[&s.pin[0]], &mut [&mut cp, &mut cr, &mut cj]);
                black_box((&cp, &cr, &cj));
            }
        }),
    ]];
    time_group(c, &format!("{name} {marker}"), terms);
}

/// One timed function: its name and a call of it on the next state.
type Timed<'a> = (&'static str, Box<dyn FnMut() + 'a>);

/// `f` named `name`, its result kept from the optimiser.
fn timed<'a, O>(name: &'static str, mut f: impl FnMut() -> O + 'a) -> Timed<'a> {
    (
        name,
        Box::new(move || {
            black_box(f());
        }),
    )
}

/// Times the functions of `terms` as the criterion group `group`; each
/// term is flexdyn's function first, then Pinocchio's that it is compared
/// with. Where `FLEXDYN_BENCH_INTERLEAVED` is set, [`interleaved`] times
/// them instead.
fn time_group(c: &mut Criterion<ThreadCpuTime>, group: &str, terms: Vec<Vec<Timed>>) {
    if std::env::var_os("FLEXDYN_BENCH_INTERLEAVED").is_some() {
        terms.into_iter().for_each(|term| interleaved(group, term));
        return;
    }
    let mut g = c.benchmark_group(group);
    for (name, mut f) in terms.into_iter().flatten() {
        g.bench_function(name, |b| b.iter(&mut f));
    }
    g.finish();
}

/// Rounds of batches in [`interleaved`].
const ROUNDS: usize = 201;

/// Thread CPU time of one batch, in nanoseconds.
const BATCH_NS: f64 = 2e6;

/// Times the functions of one term in turn, a batch of each (about
/// [`BATCH_NS`]) per round, so that a machine whose speed drifts over
/// minutes slows every side of a round alike, and prints for each its
/// median time per call and the median over the rounds of its batch's time
/// per call relative to the first function's (flexdyn's) in the same round.
fn interleaved(group: &str, mut term: Vec<Timed>) {
    let calls: Vec<usize> = term
        .iter_mut()
        .map(|(_, f)| {
            // Doubling until a quarter batch: the warm-up, and the rate.
            let (mut n, mut took) = (1usize, 0.0);
            while took < BATCH_NS / 4.0 {
                n *= 2;
                let start = thread_ns();
                (0..n).for_each(|_| f());
                took = thread_ns() - start;
            }
            ((n as f64 * BATCH_NS / took).ceil() as usize).max(1)
        })
        .collect();
    let mut per_call = vec![Vec::with_capacity(ROUNDS); term.len()];
    for _ in 0..ROUNDS {
        for (((_, f), &n), times) in term.iter_mut().zip(&calls).zip(&mut per_call) {
            let start = thread_ns();
            (0..n).for_each(|_| f());
            times.push((thread_ns() - start) / n as f64);
        }
    }
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    for ((name, _), times) in term.iter().zip(&per_call) {
        let relative = times
            .iter()
            .zip(&per_call[0])
            .map(|(t, first)| t / first)
            .collect();
        println!(
            "interleaved {group} / {name}: median {:.1} ns; per round {:.4} times the first",
            median(times.clone()),
            median(relative)
        );
    }
}

/// Pinocchio's templated function `f` (`rnea`, `aba` or their derivatives:
/// the model, `q`, `v`, then the state's array `third`, the accelerations 2
/// or the torques 3) named `name`, on the next state.
fn templated<'a, const N: usize>(
    name: &'static str,
    pin: &'a Pinocchio,
    states: &'a [State<N>],
    f: unsafe extern "C" fn(*mut c_void, *const f64, *const f64, *const f64),
    third: usize,
) -> Timed<'a> {
    let mut i = 0;
    timed(name, move || {
        let s = next(states, &mut i);
        // SAFETY: arrays of N numbers for a model of N velocities.
        unsafe {
            f(
                pin.handle,
                s.pin[0].as_ptr(),
                s.pin[1].as_ptr(),
                s.pin[third].as_ptr(),
            )
        }
    })
}

/// Pinocchio's generated C `f` of one vector of N numbers (`rnea` or
/// `aba`: `q`, `v`, then the state's array `third`, as for [`templated`])
/// named `name`, on the next state.
fn c_vector<'a, const N: usize>(
    name: &'static str,
    mut f: CCall,
    states: &'a [State<N>],
    third: usize,
) -> Timed<'a> {
    let mut out = vec![0.0; N];
    let mut i = 0;
    timed(name, move || {
        let s = next(states, &mut i);
        f.call(&[&s.pin[0], &s.pin[1], &s.pin[third]], &mut [&mut out]);
        black_box(&out);
    })
}

/// The state after the `i`-th, cycling.
fn next<'a, T>(states: &'a [T], i: &mut usize) -> &'a T {
    *i = (*i + 1) % states.len();
    &states[*i]
}

criterion_group! {
    name = benches;
    config = Criterion::default().with_measurement(ThreadCpuTime);
    targets = robots
}
criterion_main!(benches);
