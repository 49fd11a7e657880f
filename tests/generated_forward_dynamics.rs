//! The generated `forward_dynamics` (`qdd = M^-1 (f - h)` as one program,
//! `M = L^T D L` factored on the expression graph) of every shipped
//! unconstrained scene against a dense solve of the same scene's generated
//! `M` and `h` by nalgebra's Cholesky factorisation, at seeded states in the
//! declared ranges; its pivots against the factorisation's; constrained
//! scenes have none; and the runtime's `accelerations` takes it.

mod common;

use flexdyn::scenes as compiled;
use nalgebra::{DMatrix, DVector};

/// States per scene.
const STATES: usize = 20;

#[test]
fn generated_forward_dynamics_solves_the_generated_mass_matrix() {
    let mut checked = 0;
    let mut rng = common::rng(11);
    for (_, scene) in common::scenes() {
        let model = compiled::model(&scene.name).expect("compiled in");
        let (nq, nc) = (model.nq(), model.nc());
        let (mut qdd, mut d) = (vec![0.0; nq], vec![0.0; nq]);
        let zeros = vec![0.0; nq];
        let generated = model.forward_dynamics(&zeros, &zeros, &zeros, 0.0, &mut qdd, &mut d);
        assert_eq!(
            generated,
            nc == 0 && nq <= 40,
            "{}: forward_dynamics generated: {generated}",
            scene.name
        );
        if !generated {
            continue;
        }
        for k in 0..STATES {
            let (q, qd, t) = common::random_state(&scene, &mut rng);
            let f: Vec<f64> = (0..nq)
                .map(|i| 3.0 * (i as f64 + 1.0).sin() + k as f64)
                .collect();
            assert!(model.forward_dynamics(&q, &qd, &f, t, &mut qdd, &mut d));
            let (mut m, mut h) = (vec![0.0; nq * nq], vec![0.0; nq]);
            model.mass_matrix(&q, t, &mut m);
            model.bias(&q, &qd, t, &mut h);
            let m = DMatrix::from_column_slice(nq, nq, &m);
            let rhs = DVector::from_vec(f) - DVector::from_vec(h);
            let expected = m
                .clone()
                .cholesky()
                .unwrap_or_else(|| panic!("{}: M is not positive definite", scene.name))
                .solve(&rhs);
            let scale = expected.amax().max(1.0);
            let error = (DVector::from_column_slice(&qdd) - &expected).amax() / scale;
            assert!(
                error <= 1e-12,
                "{} state {k}: generated forward dynamics off by {error:e} of {scale:e}",
                scene.name
            );
            // D of M = L^T D L relative to M's diagonal, eliminating from
            // the last coordinate: the last is 1, and det M = prod d_k M_kk.
            assert!((d[nq - 1] - 1.0).abs() <= 1e-14, "{}: {d:?}", scene.name);
            let det: f64 = (0..nq).map(|k| d[k] * m[(k, k)]).product();
            let dense = m.determinant();
            assert!(
                (det - dense).abs() <= 1e-9 * dense.abs(),
                "{} state {k}: pivots give det {det:e}, M has {dense:e}",
                scene.name
            );
            assert!(
                d.iter().all(|&p| p > 0.0 && p <= 1.0 + 1e-12),
                "{}: relative pivots {d:?}",
                scene.name
            );
            checked += 1;
        }
    }
    assert!(checked >= 5 * STATES, "{checked} states checked");
}

/// The runtime's forward dynamics of an unconstrained scene is the
/// generated one, bit for bit.
#[test]
fn accelerations_take_the_generated_forward_dynamics() {
    use flexdyn_runtime::{accelerations, DynamicsConfig};
    use nalgebra::SVector;
    let model = flexdyn::scenes::double_pendulum::DoublePendulum;
    let (q, qd) = (SVector::from([0.3, -0.7]), SVector::from([1.1, 0.4]));
    let tau = SVector::<f64, 2>::from([0.5, -0.25]);
    let a = accelerations(&model, &DynamicsConfig::default(), &q, &qd, 0.2, &tau).unwrap();
    let (mut qdd, mut d) = (SVector::zeros(), SVector::zeros());
    let mut b = nalgebra::SMatrix::<f64, 2, 2>::zeros();
    flexdyn_runtime::Model::actuator_map(&model, &mut b);
    let f = b * tau;
    assert!(flexdyn_runtime::Model::forward_dynamics(
        &model, &q, &qd, &f, 0.2, &mut qdd, &mut d
    ));
    assert_eq!(a.qdd, qdd);
    assert_eq!(a.condition, 1.0);
}

/// The generated `forward_dynamics_derivatives` of every shipped
/// unconstrained scene that asks for `dynamics_derivatives`: its `qdd` and
/// pivots are `forward_dynamics`'s, its `qdd_f` inverts the generated `M`,
/// and its `qdd_q`, `qdd_qd` are central differences of `forward_dynamics`
/// (step 1e-6, agreement to 1e-6 of each matrix's scale, against a
/// truncation error of about 1e-12 and a rounding error of about 1e-10).
#[test]
fn forward_dynamics_derivatives_differentiate_the_forward_dynamics() {
    let mut checked = 0;
    let mut rng = common::rng(12);
    for (_, scene) in common::scenes() {
        let model = compiled::model(&scene.name).expect("compiled in");
        let nq = model.nq();
        let zeros = vec![0.0; nq];
        let generated = derivatives(model.as_ref(), &zeros, &zeros, &zeros, 0.0).is_some();
        assert_eq!(
            generated,
            scene.outputs.dynamics_derivatives && model.nc() == 0 && nq <= 40,
            "{}: forward_dynamics_derivatives generated: {generated}",
            scene.name
        );
        if !generated {
            continue;
        }
        for k in 0..STATES {
            let (q, qd, t) = common::random_state(&scene, &mut rng);
            let f: Vec<f64> = (0..nq)
                .map(|i| (i as f64 + 0.5).cos() - 0.1 * k as f64)
                .collect();
            let [qdd, d, qdd_q, qdd_qd, qdd_f] =
                derivatives(model.as_ref(), &q, &qd, &f, t).expect("generated");
            let (mut alone, mut pivots) = (vec![0.0; nq], vec![0.0; nq]);
            assert!(model.forward_dynamics(&q, &qd, &f, t, &mut alone, &mut pivots));
            let close = |a: &[f64], b: &[f64], tolerance: f64| {
                let scale = b.iter().fold(1.0f64, |m, x| m.max(x.abs()));
                let error = a
                    .iter()
                    .zip(b)
                    .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
                error <= tolerance * scale
            };
            assert!(close(&qdd, &alone, 1e-14), "{} state {k}: qdd", scene.name);
            assert!(
                close(&d, &pivots, 1e-14),
                "{} state {k}: pivots",
                scene.name
            );
            let mut m = vec![0.0; nq * nq];
            model.mass_matrix(&q, t, &mut m);
            let product =
                DMatrix::from_column_slice(nq, nq, &m) * DMatrix::from_column_slice(nq, nq, &qdd_f);
            let identity = DMatrix::<f64>::identity(nq, nq);
            assert!(
                close(product.as_slice(), identity.as_slice(), 1e-12),
                "{} state {k}: M qdd_f = {product}",
                scene.name
            );
            // Central differences, column j of d qdd/dq and d qdd/dqd.
            let step = 1e-6;
            let difference = |along_q: bool, j: usize| -> Vec<f64> {
                let at = |sign: f64| {
                    let (mut x, mut v) = (q.clone(), qd.clone());
                    let moved = if along_q { &mut x } else { &mut v };
                    moved[j] += sign * step;
                    let (mut a, mut p) = (vec![0.0; nq], vec![0.0; nq]);
                    assert!(model.forward_dynamics(&x, &v, &f, t, &mut a, &mut p));
                    a
                };
                let (plus, minus) = (at(1.0), at(-1.0));
                plus.iter()
                    .zip(&minus)
                    .map(|(a, b)| (a - b) / (2.0 * step))
                    .collect()
            };
            for (along_q, exact) in [(true, &qdd_q), (false, &qdd_qd)] {
                let numeric: Vec<f64> = (0..nq).flat_map(|j| difference(along_q, j)).collect();
                assert!(
                    close(exact, &numeric, 1e-6),
                    "{} state {k}: d qdd/d{} {exact:?} against differences {numeric:?}",
                    scene.name,
                    if along_q { "q" } else { "qd" }
                );
            }
            checked += 1;
        }
    }
    assert!(checked >= 2 * STATES, "{checked} states checked");
}

/// `(qdd, d, qdd_q, qdd_qd, qdd_f)` of `forward_dynamics_derivatives`, or
/// `None` where the model has no such program.
fn derivatives(
    model: &dyn flexdyn::dynamic::DynModel,
    q: &[f64],
    qd: &[f64],
    f: &[f64],
    t: f64,
) -> Option<[Vec<f64>; 5]> {
    let n = q.len();
    let [mut qdd, mut d, mut qdd_q, mut qdd_qd, mut qdd_f] =
        [n, n, n * n, n * n, n * n].map(|len| vec![0.0; len]);
    let out = flexdyn::dynamic::FdDerivatives {
        qdd: &mut qdd,
        d: &mut d,
        qdd_q: &mut qdd_q,
        qdd_qd: &mut qdd_qd,
        qdd_f: &mut qdd_f,
    };
    model
        .forward_dynamics_derivatives(q, qd, f, t, out)
        .then_some([qdd, d, qdd_q, qdd_qd, qdd_f])
}
