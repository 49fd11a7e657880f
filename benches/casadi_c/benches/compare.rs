//! flexdyn's generated Rust against CasADi's generated C (CSE on, -O3), for
//! the terms a solver evaluates together: `M`, `h`, `Phi_q`, `gamma`. Both
//! sides are timed in one criterion group per scene; the outputs are
//! compared first (the run stops if they disagree), and the operation counts
//! are printed: flexdyn's fused `dynamics_terms` program against CasADi's
//! arithmetic instructions.

use criterion::{black_box, criterion_group, criterion_main, Criterion};
use flexdyn_runtime::nalgebra::{SMatrix, SVector};
use flexdyn_runtime::Model;

#[allow(dead_code)]
mod slider_crank {
    include!(concat!(env!("OUT_DIR"), "/flexdyn/slider_crank.rs"));
}
#[allow(dead_code)]
mod five_bar {
    include!(concat!(env!("OUT_DIR"), "/flexdyn/five_bar.rs"));
}
#[allow(dead_code)]
mod parallel_robot_rigid {
    include!(concat!(env!("OUT_DIR"), "/flexdyn/parallel_robot_rigid.rs"));
}
mod casadi_ops {
    include!(concat!(env!("OUT_DIR"), "/casadi_ops.rs"));
}

type CasadiFn =
    unsafe extern "C" fn(*const *const f64, *const *mut f64, *mut i64, *mut f64, i32) -> i32;
type WorkFn = unsafe extern "C" fn(*mut i64, *mut i64, *mut i64, *mut i64) -> i32;

extern "C" {
    fn slider_crank_terms(
        arg: *const *const f64,
        res: *const *mut f64,
        iw: *mut i64,
        w: *mut f64,
        mem: i32,
    ) -> i32;
    fn slider_crank_terms_work(a: *mut i64, r: *mut i64, iw: *mut i64, w: *mut i64) -> i32;
    fn five_bar_terms(
        arg: *const *const f64,
        res: *const *mut f64,
        iw: *mut i64,
        w: *mut f64,
        mem: i32,
    ) -> i32;
    fn five_bar_terms_work(a: *mut i64, r: *mut i64, iw: *mut i64, w: *mut i64) -> i32;
    fn parallel_robot_rigid_terms(
        arg: *const *const f64,
        res: *const *mut f64,
        iw: *mut i64,
        w: *mut f64,
        mem: i32,
    ) -> i32;
    fn parallel_robot_rigid_terms_work(a: *mut i64, r: *mut i64, iw: *mut i64, w: *mut i64) -> i32;
}

/// Outputs of one evaluation, column-major like CasADi's dense outputs.
struct Terms<const NQ: usize, const NC: usize> {
    m: SMatrix<f64, NQ, NQ>,
    h: SVector<f64, NQ>,
    phi_q: SMatrix<f64, NC, NQ>,
    gamma: SVector<f64, NC>,
}

impl<const NQ: usize, const NC: usize> Terms<NQ, NC> {
    fn zeros() -> Self {
        Terms {
            m: SMatrix::zeros(),
            h: SVector::zeros(),
            phi_q: SMatrix::zeros(),
            gamma: SVector::zeros(),
        }
    }
    fn max_diff(&self, o: &Self) -> f64 {
        let d = |a: &[f64], b: &[f64]| {
            a.iter()
                .zip(b)
                .map(|(x, y)| (x - y).abs())
                .fold(0.0, f64::max)
        };
        d(self.m.as_slice(), o.m.as_slice())
            .max(d(self.h.as_slice(), o.h.as_slice()))
            .max(d(self.phi_q.as_slice(), o.phi_q.as_slice()))
            .max(d(self.gamma.as_slice(), o.gamma.as_slice()))
    }
}

/// CasADi's function with its work arrays, allocated once.
struct Casadi {
    f: CasadiFn,
    iw: Vec<i64>,
    w: Vec<f64>,
}

impl Casadi {
    fn new(f: CasadiFn, work: WorkFn) -> Casadi {
        let (mut a, mut r, mut iw, mut w) = (0, 0, 0, 0);
        // SAFETY: CasADi's work-size query writes four integers.
        unsafe { work(&mut a, &mut r, &mut iw, &mut w) };
        assert!(
            a == 4 && r == 4,
            "unexpected CasADi signature: {a} inputs, {r} outputs"
        );
        Casadi {
            f,
            iw: vec![0; iw as usize],
            w: vec![0.0; w as usize],
        }
    }
    fn eval<const NQ: usize, const NC: usize>(
        &mut self,
        q: &SVector<f64, NQ>,
        qd: &SVector<f64, NQ>,
        t: f64,
        o: &mut Terms<NQ, NC>,
    ) {
        let arg = [q.as_ptr(), qd.as_ptr(), &t as *const f64, std::ptr::null()];
        let res = [
            o.m.as_mut_ptr(),
            o.h.as_mut_ptr(),
            o.phi_q.as_mut_ptr(),
            o.gamma.as_mut_ptr(),
        ];
        // SAFETY: inputs and outputs are dense buffers of the sizes CasADi's
        // sparsity patterns declare (nq, nq, 1, no parameters; nq x nq, nq,
        // nc x nq, nc column-major); work arrays are sized by its query.
        let status = unsafe {
            (self.f)(
                arg.as_ptr(),
                res.as_ptr(),
                self.iw.as_mut_ptr(),
                self.w.as_mut_ptr(),
                0,
            )
        };
        debug_assert_eq!(status, 0);
    }
}

/// flexdyn's operation count of the fused `dynamics_terms` (add + mul + div
/// + call), read from the `@generated` header.
fn flexdyn_ops(source: &str) -> (u64, u64) {
    let line = source
        .lines()
        .find(|l| {
            l.trim_start_matches("//")
                .trim_start()
                .starts_with("dynamics_terms ")
        })
        .expect("op count line");
    let n: Vec<u64> = line
        .split_whitespace()
        .filter_map(|w| w.parse().ok())
        .collect();
    (n.iter().sum(), n[3])
}

#[allow(clippy::too_many_arguments)]
fn compare<M, const NQ: usize, const NC: usize, const NU: usize>(
    c: &mut Criterion,
    name: &str,
    model: &M,
    mut casadi: Casadi,
    source: &str,
    casadi_ops: (u64, u64),
) where
    M: Model<NQ, NC, NU>,
{
    let q = SVector::<f64, NQ>::from_fn(|i, _| 0.3 + 0.11 * i as f64);
    let qd = SVector::<f64, NQ>::from_fn(|i, _| 0.5 - 0.07 * i as f64);
    let t = 0.25;
    let (mut ours, mut theirs) = (Terms::<NQ, NC>::zeros(), Terms::<NQ, NC>::zeros());
    model.dynamics_terms(
        &q,
        &qd,
        t,
        &mut ours.m,
        &mut ours.h,
        &mut ours.phi_q,
        &mut ours.gamma,
    );
    casadi.eval(&q, &qd, t, &mut theirs);
    let diff = ours.max_diff(&theirs);
    assert!(
        diff < 1e-9,
        "{name}: flexdyn and CasADi disagree by {diff:e}"
    );
    let (ops, calls) = flexdyn_ops(source);
    println!(
        "{name}: operations for M, h, Phi_q, gamma: flexdyn {ops} ({calls} calls), CasADi {} ({} calls); outputs agree to {diff:.1e}",
        casadi_ops.0, casadi_ops.1
    );
    let mut g = c.benchmark_group(format!("{name}/m_h_phiq_gamma"));
    let mut x = q;
    g.bench_function("flexdyn_rust", |b| {
        b.iter(|| {
            x[0] += 1e-9;
            model.dynamics_terms(
                black_box(&x),
                &qd,
                t,
                &mut ours.m,
                &mut ours.h,
                &mut ours.phi_q,
                &mut ours.gamma,
            );
            black_box(&ours.h);
        })
    });
    let mut x = q;
    g.bench_function("casadi_c", |b| {
        b.iter(|| {
            x[0] += 1e-9;
            casadi.eval(black_box(&x), &qd, t, &mut theirs);
            black_box(&theirs.h);
        })
    });
    g.finish();
}

fn benches(c: &mut Criterion) {
    compare(
        c,
        "slider_crank",
        &slider_crank::SliderCrank,
        Casadi::new(slider_crank_terms, slider_crank_terms_work),
        include_str!(concat!(env!("OUT_DIR"), "/flexdyn/slider_crank.rs")),
        casadi_ops::SLIDER_CRANK,
    );
    compare(
        c,
        "five_bar",
        &five_bar::FiveBar,
        Casadi::new(five_bar_terms, five_bar_terms_work),
        include_str!(concat!(env!("OUT_DIR"), "/flexdyn/five_bar.rs")),
        casadi_ops::FIVE_BAR,
    );
    compare(
        c,
        "parallel_robot_rigid",
        &parallel_robot_rigid::ParallelRobotRigid,
        Casadi::new(parallel_robot_rigid_terms, parallel_robot_rigid_terms_work),
        include_str!(concat!(env!("OUT_DIR"), "/flexdyn/parallel_robot_rigid.rs")),
        casadi_ops::PARALLEL_ROBOT_RIGID,
    );
}

criterion_group!(group, benches);
criterion_main!(group);
