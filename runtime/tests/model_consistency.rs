//! Verifies the hand-written test models against their own energy functions
//! and constraint residuals by finite differences (Lagrange's equations), so
//! that the solver tests rest on independently checked equations.

mod models;

use flexdyn_runtime::Model;
use models::*;

fn scale_tol(reference: f64, tol: f64) -> f64 {
    tol * reference.abs().max(1.0)
}

/// Checks M against T, h against Lagrange's equations of T and V, Phi_q,
/// Phi_t and gamma against finite differences of Phi. Assumes no
/// non-conservative forces in `h`.
fn check_model<M, const NQ: usize, const NC: usize, const NU: usize>(
    model: &M,
    q: &V<NQ>,
    qd: &V<NQ>,
    t: f64,
) where
    M: Model<NQ, NC, NU>,
{
    let name = M::NAME;
    // Mass matrix by polarisation of T.
    let mut m = Mat::<NQ, NQ>::zeros();
    model.mass_matrix(q, t, &mut m);
    let unit = |i: usize| {
        let mut e = V::<NQ>::zeros();
        e[i] = 1.0;
        e
    };
    for i in 0..NQ {
        for j in 0..NQ {
            let mij = if i == j {
                2.0 * model.kinetic_energy(q, &unit(i), t)
            } else {
                model.kinetic_energy(q, &(unit(i) + unit(j)), t)
                    - model.kinetic_energy(q, &unit(i), t)
                    - model.kinetic_energy(q, &unit(j), t)
            };
            assert!(
                (mij - m[(i, j)]).abs() <= scale_tol(mij, 1e-12),
                "{name}: M[{i},{j}] {} vs {}",
                m[(i, j)],
                mij
            );
        }
    }
    // Bias: h = (d/dq (M qd)) qd - dT/dq + dV/dq.
    let eps = 1e-6;
    let mut mp = Mat::<NQ, NQ>::zeros();
    let mut mm = Mat::<NQ, NQ>::zeros();
    model.mass_matrix(&(q + qd * eps), t, &mut mp);
    model.mass_matrix(&(q - qd * eps), t, &mut mm);
    let mut expected = (mp * qd - mm * qd) / (2.0 * eps);
    for k in 0..NQ {
        let (qp, qm) = (q + unit(k) * eps, q - unit(k) * eps);
        let dt_dq =
            (model.kinetic_energy(&qp, qd, t) - model.kinetic_energy(&qm, qd, t)) / (2.0 * eps);
        let dv_dq = (model.potential_energy(&qp, t) - model.potential_energy(&qm, t)) / (2.0 * eps);
        expected[k] += -dt_dq + dv_dq;
    }
    let mut h = V::<NQ>::zeros();
    model.bias(q, qd, t, &mut h);
    for k in 0..NQ {
        assert!(
            (h[k] - expected[k]).abs() <= scale_tol(expected[k], 1e-7),
            "{name}: h[{k}] {} vs {}",
            h[k],
            expected[k]
        );
    }
    if NC == 0 {
        return;
    }
    // Constraint Jacobian.
    let mut jac = Mat::<NC, NQ>::zeros();
    model.constraint_jacobian(q, t, &mut jac);
    for k in 0..NQ {
        let (mut pp, mut pm) = (V::<NC>::zeros(), V::<NC>::zeros());
        model.constraints(&(q + unit(k) * eps), t, &mut pp);
        model.constraints(&(q - unit(k) * eps), t, &mut pm);
        let col = (pp - pm) / (2.0 * eps);
        for i in 0..NC {
            assert!(
                (jac[(i, k)] - col[i]).abs() <= 1e-8,
                "{name}: Phi_q[{i},{k}]"
            );
        }
    }
    // Phi_t.
    let (mut pp, mut pm, mut pt) = (V::<NC>::zeros(), V::<NC>::zeros(), V::<NC>::zeros());
    model.constraints(q, t + eps, &mut pp);
    model.constraints(q, t - eps, &mut pm);
    model.constraint_time_derivative(q, t, &mut pt);
    assert!(
        ((pp - pm) / (2.0 * eps) - pt).amax() <= 1e-8,
        "{name}: Phi_t"
    );
    // gamma = -d/ds [Phi_q qd + Phi_t] along q + s qd, t + s.
    let vel = |s: f64| {
        let (mut j, mut p) = (Mat::<NC, NQ>::zeros(), V::<NC>::zeros());
        model.constraint_jacobian(&(q + qd * s), t + s, &mut j);
        model.constraint_time_derivative(&(q + qd * s), t + s, &mut p);
        j * qd + p
    };
    let expected_gamma = -(vel(eps) - vel(-eps)) / (2.0 * eps);
    let mut gamma = V::<NC>::zeros();
    model.constraint_rhs(q, qd, t, &mut gamma);
    for i in 0..NC {
        assert!(
            (gamma[i] - expected_gamma[i]).abs() <= scale_tol(expected_gamma[i], 1e-7),
            "{name}: gamma[{i}] {} vs {}",
            gamma[i],
            expected_gamma[i]
        );
    }
}

#[test]
fn pendulum_is_consistent() {
    check_model(
        &Pendulum::default(),
        &V::<1>::new(0.7),
        &V::<1>::new(-1.3),
        0.0,
    );
}

#[test]
fn double_pendulum_is_consistent() {
    check_model(
        &DoublePendulum::default(),
        &V::<2>::new(0.7, -0.4),
        &V::<2>::new(1.1, -2.3),
        0.0,
    );
}

#[test]
fn slider_crank_is_consistent() {
    let m = SliderCrank::default();
    check_model(
        &m,
        &V::<3>::new(0.9, 0.25, 0.35),
        &V::<3>::new(3.0, -1.2, 0.4),
        0.0,
    );
    // The assembled state satisfies the position and velocity constraints.
    let s = m.consistent_state(1.1, 4.0);
    let d = flexdyn_runtime::constraint_drift(&m, &s);
    assert!(d.position < 1e-15 && d.velocity < 1e-14, "{d:?}");
}

#[test]
fn five_bar_is_consistent() {
    let m = FiveBar::<2>::default();
    let q = m.assemble(0.03, 0.32);
    check_model(&m, &q, &V::<6>::new(0.5, -1.0, 0.7, 0.2, -0.3, 0.4), 0.0);
    let mut phi = V::<4>::zeros();
    m.constraints(&q, 0.0, &mut phi);
    assert!(phi.amax() < 1e-15, "assembly: {phi}");
}

#[test]
fn spring_chain_and_elastic_pendulum_are_consistent() {
    let chain = SpringChain::<4>::stiff();
    check_model(
        &chain,
        &V::<4>::new(0.01, 0.011, 0.0105, 0.012),
        &V::<4>::new(0.1, -0.2, 0.3, 0.05),
        0.0,
    );
    check_model(
        &ElasticPendulum::default(),
        &V::<2>::new(1.0001, 0.4),
        &V::<2>::new(0.01, -0.8),
        0.0,
    );
    check_model(
        &CartesianPendulum::default(),
        &V::<2>::new(0.6, -0.8),
        &V::<2>::new(0.8, 0.6),
        0.0,
    );
    check_model(
        &TouchingSpheres::default(),
        &V::<3>::new(0.9, 0.3, -0.2),
        &V::<3>::new(0.1, -0.4, 0.7),
        0.0,
    );
}

#[test]
fn control_test_models_are_consistent() {
    check_model(
        &RotatingArm::default(),
        &V::<2>::new(0.4, 0.55),
        &V::<2>::new(2.5, -0.3),
        0.0,
    );
    check_model(
        &AbsorberCrank::default(),
        &V::<4>::new(0.9, 0.25, 0.35, 0.47),
        &V::<4>::new(3.0, -1.2, 0.4, -0.6),
        0.0,
    );
    check_model(
        &CrossedCarts::default(),
        &V::<2>::new(0.4, -0.2),
        &V::<2>::new(1.5, -0.7),
        0.0,
    );
}
