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
