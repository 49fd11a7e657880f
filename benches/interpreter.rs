//! The interpreter (`flexdyn_codegen::interpret`, a scene file evaluated at
//! run time) against the compiled module of the same scene: `dynamics_terms`
//! and `bias` of the pendulum, the four-bar, the five-bar and the UR5, both without
//! allocation (preallocated outputs, reused scratch); and the interpreter's
//! batches (`Tape::eval_batch`, [`BATCH`] states in one call, timed per
//! call: divide by [`BATCH`] for a state). Run with
//! `cargo bench --bench interpreter`.

use std::path::Path;

use criterion::{black_box, criterion_group, criterion_main, Criterion};
use flexdyn::codegen::interpret::{Function, Interpreted, Scratch, LANES};
use flexdyn::runtime::nalgebra::{SMatrix, SVector};
use flexdyn::runtime::Model;
use flexdyn::scenes::{five_bar::FiveBar, four_bar::FourBar, pendulum::Pendulum, ur5::Ur5};

/// States in one batched call.
const BATCH: usize = 8 * LANES;

/// A state of `nq` coordinates away from special angles.
fn state(nq: usize) -> (Vec<f64>, Vec<f64>) {
    let x = |i: usize, s: f64| (0.7 + i as f64 * s).sin();
    (
        (0..nq).map(|i| x(i, 1.3)).collect(),
        (0..nq).map(|i| x(i, 0.4)).collect(),
    )
}

fn compare<M, const NQ: usize, const NC: usize, const NU: usize>(c: &mut Criterion, model: &M)
where
    M: Model<NQ, NC, NU>,
{
    let scene = M::NAME;
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("scenes/{scene}.toml"));
    let it = Interpreted::load(&path).unwrap_or_else(|e| panic!("{e}"));
    let params: Vec<f64> = it.parameters().iter().map(|(_, v)| *v).collect();
    let (q, qd) = state(NQ);
    let (sq, sqd) = (
        SVector::<f64, NQ>::from_column_slice(&q),
        SVector::from_column_slice(&qd),
    );
    let mut m = SMatrix::<f64, NQ, NQ>::zeros();
    let mut h = SVector::<f64, NQ>::zeros();
    let mut j = SMatrix::<f64, NC, NQ>::zeros();
    let mut g = SVector::<f64, NC>::zeros();
    c.bench_function(&format!("{scene}/dynamics_terms/compiled"), |b| {
        b.iter(|| {
            model.dynamics_terms(black_box(&sq), &sqd, 0.0, &mut m, &mut h, &mut j, &mut g);
            black_box((&m, &h, &j, &g));
        })
    });
    c.bench_function(&format!("{scene}/bias/compiled"), |b| {
        b.iter(|| {
            model.bias(black_box(&sq), &sqd, 0.0, &mut h);
            black_box(&h);
        })
    });
    let mut scratch = Scratch::default();
    for f in [Function::DynamicsTerms, Function::Bias] {
        let tape = it.tape(f).expect("core function");
        let mut out = vec![0.0; tape.output_len()];
        c.bench_function(&format!("{scene}/{}/interpreted", f.name()), |b| {
            b.iter(|| {
                tape.eval(black_box(&q), &qd, 0.0, &params, &mut scratch, &mut out);
                black_box(&out);
            })
        });
        let mut lanes = Scratch::<LANES>::default();
        let (qs, qds) = (q.repeat(BATCH), qd.repeat(BATCH));
        let (ts, mut outs) = ([0.0; BATCH], vec![0.0; BATCH * tape.output_len()]);
        c.bench_function(&format!("{scene}/{}/interpreted_batch", f.name()), |b| {
            b.iter(|| {
                tape.eval_batch(
                    black_box(&qs),
                    &qds,
                    &[],
                    &ts,
                    &params,
                    &mut lanes,
                    &mut outs,
                );
                black_box(&outs);
            })
        });
    }
}

fn interpreter(c: &mut Criterion) {
    compare(c, &Pendulum::default());
    compare(c, &FourBar);
    compare(c, &FiveBar);
    compare(c, &Ur5);
}

criterion_group!(benches, interpreter);
criterion_main!(benches);
